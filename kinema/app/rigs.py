"""The character a tab shows: the model's own skeleton, or a rig loaded from a GLB/glTF or BVH file.

An `AppRig` carries what the views and the downloads need: the skeleton, its skin (the file's mesh,
or kinema's generated bone mesh for a rig without one, kinema.mesh.bone_mesh), the contact joints found
by the rig layer (kinema.rig.Rig) and the file's own clips, resampled to the app's frame rate so that
the player's clock fits every motion. Positions are metres, Y up (the readers convert).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.io.bvh import read_bvh
from kinema.io.gltf import read_gltf
from kinema.io.gltf_writer import glb_bytes, rest_world
from kinema.mesh import SkinnedMesh, bone_mesh
from kinema.motion.contacts import foot_contacts
from kinema.motion.core import Motion
from kinema.retarget.detect import find_humanoid
from kinema.rig import Rig
from kinema.skeleton import Skeleton

RIG_SUFFIXES = (".glb", ".gltf", ".bvh", ".bvh.gz")


@dataclass(frozen=True, eq=False)
class AppRig:
    """A skeleton with its skin, contact joints and clips (name -> Motion at the app's fps)."""

    name: str
    skeleton: Skeleton
    mesh: SkinnedMesh
    contacts: tuple[int, ...]
    clips: dict[str, Motion] = field(default_factory=dict)
    own_colors: bool = False  # the mesh has the file's material colours (else it takes the sample colour)
    humanoid: bool = False  # legs, arms and head found by name (kinema.retarget.detect): the human model drives it
    source: bytes = b""  # the file's bytes (a character is handed to the pipeline as its file)

    def size(self) -> float:
        return skeleton_size(self.skeleton)

    def with_contacts(self, motion: Motion) -> Motion:
        """``motion`` with foot contact flags for this rig's contact joints when it has none."""
        if motion.foot_contacts is not None or not self.contacts:
            return motion
        flags = foot_contacts(motion.positions.detach(), motion.fps, motion.skeleton, joints=self.contacts)
        return Motion(
            motion.skeleton,
            motion.fps,
            motion.root_translation,
            motion.local_rotations,
            flags,
            motion.local_translations,
        )

    def glb(self, motion: Motion, name: str = "motion") -> bytes:
        """``motion`` (on this rig) as GLB bytes with this rig's skin."""
        return glb_bytes({name: motion}, mesh=self.mesh)


def skeleton_size(skeleton: Skeleton) -> float:
    """A skeleton's extent in its rest pose (metres, the largest of height, width, depth; at least 0.1)."""
    rest = rest_world(skeleton)[1]
    return max(0.1, float((rest.max(0) - rest.min(0)).max()))


def _contacts(skeleton: Skeleton) -> tuple[int, ...]:
    """The rig layer's contact joints, or none when it cannot tell (the skeleton is still drawn)."""
    try:
        return tuple(Rig.from_skeleton(skeleton).contacts)
    except KinemaError:
        return ()


def model_rig(skeleton: Skeleton, name: str = "model") -> AppRig:
    """The generating model's skeleton (the human: 4 contact joints, in the order generate labels them)."""
    mesh = skeleton.mesh or bone_mesh(skeleton, rest_world(skeleton))
    return AppRig(name, skeleton, mesh, _contacts(skeleton), own_colors=skeleton.mesh is not None)


def load_rig(path: str | Path, *, fps: float, scale: float = 1.0) -> AppRig:
    """A rig and its clips from a ``.glb``/``.gltf`` (every animation) or ``.bvh`` file (its one clip;
    lengths times ``scale``). Unreadable files raise a one-line `KinemaError` naming the file."""
    path = Path(path)
    if not path.name.lower().endswith(RIG_SUFFIXES):
        raise KinemaError(f"{path.name}: upload a rig as .glb, .gltf or .bvh")
    if path.suffix.lower() in (".glb", ".gltf"):
        asset = read_gltf(path, fps=fps)
        skeleton, clips = asset.skeleton, dict(asset.motions)
    else:
        motion = read_bvh(path, scale=scale)
        skeleton, clips = motion.skeleton, {path.name: motion.resample(fps).to(torch.float32)}
    rig = model_rig(skeleton, name=path.name)
    clips = {k: rig.with_contacts(m.to(torch.float32)) for k, m in clips.items() if m.num_frames > 0}
    return AppRig(
        path.name,
        skeleton,
        rig.mesh,
        rig.contacts,
        clips,
        own_colors=skeleton.mesh is not None,
        humanoid=find_humanoid(skeleton).is_humanoid,
        source=path.read_bytes(),
    )


def load_rig_bytes(name: str, content: bytes, *, fps: float, scale: float = 1.0) -> AppRig:
    """`load_rig` for an upload: parsed from a private temporary folder; errors name the upload, not the folder."""
    with tempfile.TemporaryDirectory(prefix="kinema-app-") as tmp:
        path = Path(tmp) / Path(name).name
        path.write_bytes(content)
        try:
            return load_rig(path, fps=fps, scale=scale)
        except KinemaError as err:
            raise KinemaError(str(err).replace(str(path), name)) from None
