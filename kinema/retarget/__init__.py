"""Retargeting: a motion on one skeleton onto another rig (a user's character), by concept:

- kinema.retarget.names: humanoid slots and the joint-name tables of Mixamo, UE5, Unity/VRM,
  Rigify, CMU, Bandai and Quaternius;
- kinema.retarget.detect: which joint is which slot (names, the tree, the rest-pose geometry
  (kinema.retarget.geometry), the rig overrides JSON); `is_humanoid`;
- kinema.retarget.mapping: which target joint follows which source joint; constraint joint names of a
  character in the model's names;
- kinema.retarget.align: world-direction rest alignment (T-pose source, A-pose target, any bone axes);
- kinema.retarget.proportions: body scale by leg length, placement, the floor;
- kinema.retarget.legs: planted contacts held, two-bone leg IK, IK feet that hang off the leg;
- kinema.retarget.core: `retarget(motion, target) -> Motion`;
- kinema.retarget.targets: `meet_targets`, hand/foot world targets of constraints met on the character;
- kinema.retarget.quality: direction error, skate, lowest joint, bone-length drift;
- kinema.retarget.character / fbx / fbx_writer: characters from GLB, BVH, FBX (ufbx) and npz, and
  writing the result as GLB, BVH, npz or FBX (through Blender).

See docs/retarget.md.
"""

from kinema.retarget.character import Character, load_character, save_character_motion
from kinema.retarget.core import retarget
from kinema.retarget.detect import HumanoidMap, find_humanoid, is_humanoid
from kinema.retarget.mapping import JointMap, build_joint_map, constraint_joint_names, model_joint_name
from kinema.retarget.quality import retarget_report
from kinema.retarget.targets import meet_targets

__all__ = [
    "Character",
    "HumanoidMap",
    "JointMap",
    "build_joint_map",
    "constraint_joint_names",
    "find_humanoid",
    "is_humanoid",
    "load_character",
    "meet_targets",
    "model_joint_name",
    "retarget",
    "retarget_report",
    "save_character_motion",
]
