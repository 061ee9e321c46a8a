"""A rig given as a file: its skeleton and its own animations, read once per file version.

GLB/glTF through kinema.io.gltf, FBX through kinema.retarget.fbx (ufbx), both without their helper
joints (IK and pole targets: no skin weight, no weighted joint below); any other motion file kinema
reads (BVH, npz) is its own one animation. The any-rig pipeline resolves a rig path here and
kinema.anyrig.tied finds the rig's ties from the same animations, so each file is parsed once per
version and fps (an FBX scene is never freed, kinema.retarget.fbx: reading it per call would grow the
process with every request).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

from kinema.io.gltf import read_gltf
from kinema.io.registry import load_motion
from kinema.motion.core import Motion
from kinema.retarget.fbx import read_fbx
from kinema.skeleton import Skeleton


@dataclass(frozen=True)
class RigFile:
    skeleton: Skeleton
    clips: tuple[Motion, ...]  # the file's animations at the requested fps (none for a bare FBX rig)


def read_rig_file(path: str | Path, fps: float) -> RigFile:
    """The skeleton and animations of the rig file ``path`` at ``fps`` (cached per path, version, fps)."""
    p = Path(path)
    return _read(str(p.absolute()), p.stat().st_mtime, float(fps))


@functools.lru_cache(maxsize=8)
def _read(path: str, mtime: float, fps: float) -> RigFile:
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".glb", ".gltf"):
        asset = read_gltf(p, fps=fps)
        return RigFile(asset.skeleton, tuple(asset.motions.values()))
    if suffix == ".fbx":
        fbx = read_fbx(p, fps=fps, keep_helpers=False)
        return RigFile(fbx.skeleton, () if fbx.motion is None else (fbx.motion,))
    motion = load_motion(p)
    return RigFile(motion.skeleton, (motion,))
