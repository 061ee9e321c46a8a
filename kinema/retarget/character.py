"""Characters: the rig a user brings (GLB/glTF, BVH, FBX or a kinema npz) and writing a motion on it.

``load_character(path)`` reads the rig in the file's own terms: a GLB keeps its skin, materials and
IK helper bones (a foot bone hanging from the root is part of the rig: retargeting moves it with the
leg), a BVH its joint names, offsets and length unit (a centimetre BVH stays in centimetres: the
body scale of kinema.retarget.proportions absorbs the unit), an FBX its armature, rest pose and skin
(kinema.retarget.fbx). ``save_character_motion(motion, path)`` writes by suffix: ``.glb``
(with the skin), ``.bvh``/``.bvh.gz`` (the character's names, offsets and units; a GLB or FBX rest pose
is re-based so BVH can hold it), ``.npz``, or ``.fbx`` through Blender (kinema.retarget.fbx_writer).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from kinema.errors import KinemaError
from kinema.io import load_motion, save_motion
from kinema.io.bvh import read_bvh
from kinema.io.gltf import read_gltf
from kinema.motion.core import Motion
from kinema.retarget.detect import HumanoidMap, find_humanoid
from kinema.retarget.fbx import read_fbx
from kinema.retarget.fbx_writer import write_fbx
from kinema.skeleton import Skeleton

READABLE = (".glb", ".gltf", ".bvh", ".bvh.gz", ".fbx", ".npz")
WRITABLE = (".glb", ".bvh", ".bvh.gz", ".fbx", ".npz")


def _suffix(path: Path, allowed: tuple[str, ...]) -> str | None:
    name = path.name.lower()
    return next((s for s in sorted(allowed, key=len, reverse=True) if name.endswith(s)), None)


@dataclass(frozen=True)
class Character:
    """A user's rig: its skeleton (with ``mesh`` when the file had a skin), where it came from, and the
    rig overrides JSON given for odd joint names."""

    path: Path
    skeleton: Skeleton
    kind: str
    overrides: str | Path | Mapping | None = None

    def humanoid(self) -> HumanoidMap:
        """The humanoid mapping found on this rig (kinema.retarget.detect)."""
        return find_humanoid(self.skeleton, self.overrides)

    @property
    def is_humanoid(self) -> bool:
        return self.humanoid().is_humanoid


def load_character(path: str | Path, *, overrides: str | Path | Mapping | None = None) -> Character:
    """The character rig in ``path`` (module docstring); bad files raise a one-line `KinemaError`."""
    path = Path(path)
    kind = _suffix(path, READABLE)
    if kind is None:
        raise KinemaError(f"{path}: unknown character format; kinema reads {', '.join(READABLE)}")
    if not path.is_file():
        raise KinemaError(f"{path}: no such file")
    if kind in (".glb", ".gltf"):
        skeleton = read_gltf(path, animations=[], keep_helpers=True).skeleton
    elif kind == ".fbx":
        skeleton = read_fbx(path).skeleton
    elif kind == ".npz":
        skeleton = load_motion(path).skeleton
    else:
        skeleton = read_bvh(path).skeleton
    return Character(path, skeleton, kind.lstrip(".").replace(".gz", ""), overrides)


def save_character_motion(motion: Motion, path: str | Path, *, name: str = "motion") -> Path:
    """Write ``motion`` (on a character's skeleton) by the suffix of ``path`` (module docstring)."""
    path = Path(path)
    kind = _suffix(path, WRITABLE)
    if kind is None:
        raise KinemaError(f"{path}: unknown output format; kinema writes {', '.join(WRITABLE)}")
    if kind == ".fbx":
        return write_fbx(motion, path, name=name)
    if kind == ".glb":
        return save_motion(motion, path, name=name)
    return save_motion(motion, path)
