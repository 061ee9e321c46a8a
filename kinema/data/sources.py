"""Read one motion file of any rig (BVH or GLB) for a dataset build: skeleton, clips, units.

`load_source` returns a `SourceFile`: the skeleton and every clip as a `Motion` in metres at the
requested fps, plus the helper joints (IK/pole targets of a GLB) and warnings. BVH files carry no
unit, so their lengths are taken as given (``units="m"``, ``"cm"``, ``"mm"``) or detected
(``"auto"``) from the size of the first frame: a human about 1.7 m tall reads 170 in centimetres.
glTF is metres by specification, so a GLB ignores ``units`` (its armature scale is applied by the
reader, kinema.io.gltf).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import torch

from kinema.errors import DataError, KinemaError
from kinema.motion.core import Motion

SUFFIXES = (".bvh", ".bvh.gz", ".glb")
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
UNIT_WORDS = {"m": "metres", "cm": "centimetres", "mm": "millimetres"}
#: Size (largest side of the first frame, file units) above which "auto" reads cm, then mm.
#: A 10 m creature in metres and a 10 cm one in centimetres are both rare; outside these the
#: message says how to override.
CM_ABOVE, MM_ABOVE = 10.0, 1000.0


@dataclass
class SourceFile:
    """One file read for a build (lengths in metres)."""

    path: Path
    rel: str  # path relative to the build root, POSIX separators
    kind: str  # "bvh" or "glb"
    clips: dict[str, Motion]  # clip name -> motion at the build fps
    helper_joints: tuple[str, ...] = ()
    warnings: list[str] = field(default_factory=list)
    units: str = "m"
    size: float = 0.0  # largest side of the first frame in file units (BVH), for the unit message

    @property
    def skeleton(self):
        return next(iter(self.clips.values())).skeleton


def list_sources(root: Path) -> list[Path]:
    """Motion files under ``root`` (recursively, sorted): ``.bvh``, ``.bvh.gz`` and ``.glb``."""
    return sorted(p for p in root.rglob("*") if p.is_file() and p.name.lower().endswith(SUFFIXES))


def first_frame_size(motion: Motion) -> tuple[float, bool]:
    """Largest side of the bounding box of the first frame's joints, and whether it is the height."""
    P = motion.positions[0]
    sides = P.max(0).values - P.min(0).values
    return float(sides.max()), int(sides.argmax()) == 1


def detect_units(size: float) -> str:
    """Units a BVH's first-frame size suggests: m up to 10, cm up to 1000, mm beyond."""
    if size > MM_ABOVE:
        return "mm"
    return "cm" if size > CM_ABOVE else "m"


def scale_motion(motion: Motion, factor: float, skeleton=None) -> Motion:
    """The same motion with every length (offsets, end sites, root path, animated bone translations)
    multiplied by ``factor``; ``skeleton`` may pass the already scaled skeleton to share it."""
    if factor == 1.0 and skeleton is None:
        return motion
    trans = None if motion.local_translations is None else motion.local_translations * factor
    return Motion(
        skeleton if skeleton is not None else motion.skeleton.scaled(factor),
        motion.fps,
        motion.root_translation * factor,
        motion.local_rotations,
        motion.foot_contacts,
        trans,
    )


def _load_bvh(path: Path, rel: str, fps: float, units: str) -> SourceFile:
    from kinema.io.bvh import read_bvh

    motion = read_bvh(path)
    size, _ = first_frame_size(motion)
    chosen = detect_units(size) if units == "auto" else units
    motion = scale_motion(motion, UNITS[chosen]).resample(fps)
    name = path.name
    for suffix in (".gz", ".bvh"):
        name = name[: -len(suffix)] if name.lower().endswith(suffix) else name
    return SourceFile(path, rel, "bvh", {name: motion}, units=chosen, size=size)


def _load_glb(path: Path, rel: str, fps: float) -> SourceFile:
    from kinema.io.gltf import read_gltf

    asset = read_gltf(path, fps=fps)
    if not asset.motions:
        raise DataError(f"{path}: no animations")
    clips = {}
    for name, motion in asset.motions.items():
        m = motion.resample(fps) if abs(motion.fps - fps) > 1e-9 else motion
        clips[name] = m.to(torch.float64)
    return SourceFile(path, rel, "glb", clips, tuple(asset.helper_joints), list(asset.warnings))


def load_source(path: Path, root: Path, *, fps: float, units: str = "auto") -> SourceFile:
    """Read ``path`` (under ``root``) as a `SourceFile` at ``fps``; `DataError` names the file."""
    if units != "auto" and units not in UNITS:
        raise DataError(f"unknown units {units!r}; choose one of m, cm, mm, auto")
    rel = path.relative_to(root).as_posix()
    try:
        if path.name.lower().endswith(".glb"):
            return _load_glb(path, rel, fps)
        return _load_bvh(path, rel, fps, units)
    except DataError:
        raise
    except KinemaError as exc:
        raise DataError(f"{path}: {exc}") from None


def units_messages(files: list[SourceFile], given: str) -> list[str]:
    """One line per detected unit for the BVH files of a build, e.g. "detected centimetres from a
    170-unit-tall first frame (walk.bvh, 12 files); pass --units m to override"; none when units
    were given or no BVH was read."""
    if given != "auto":
        return []
    lines = []
    for unit in UNITS:
        group = [f for f in files if f.kind == "bvh" and f.units == unit]
        if not group:
            continue
        f = group[0]
        size, tall = f.size, first_frame_size(next(iter(f.clips.values())))[1]
        other = "cm" if unit == "m" else "m"
        shape = "tall" if tall else "long"
        more = f", {len(group)} files" if len(group) > 1 else ""
        lines.append(
            f"detected {UNIT_WORDS[unit]} from a {size:.3g}-unit-{shape} first frame ({f.rel}{more}); "
            f"pass --units {other} to override"
        )
    return lines
