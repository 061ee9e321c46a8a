"""Import a BVH file with Blender's own BVH importer and dump every bone's world head position per frame.

Why: kinema promises that the BVH it writes opens in Blender with the same joint positions. This script
is the Blender half of that check (tests/test_blender.py is the other half); it runs inside Blender:

    blender -b --factory-startup --python scripts/blender_import_check.py -- IN.bvh OUT.json [FRAMES]

FRAMES is an optional comma-separated list of BVH frame indices (0-based); default: all frames.

What the importer does, and how the JSON lets the caller undo it:

- Import settings: scale 1.0 (kinema writes metres), rotate mode NATIVE (the file's Euler order),
  ``axis_forward='-Z', axis_up='Y'`` (the importer's defaults: the file is Y up, as kinema is). The
  importer turns that Y-up data into Blender's Z-up world with ``global_matrix`` (written to the JSON
  as ``axis_matrix``): Blender ``(x, y, z) = (x, -z_kinema, y_kinema)``. Multiplying Blender positions
  by the inverse (the transpose: it is a rotation) gives kinema coordinates back.
- Bone heads are the BVH joints. The importer keeps its own zero "rest" entry in front of the file's
  frames and skips it, so Blender frame ``frame_start + i`` shows BVH frame ``i`` (no frame is lost).
- The root bone's head sits at the root's OFFSET in the rest pose, but every animated frame sets it from
  the root's position channels (``channel - OFFSET`` as the pose-bone location), so posed heads are the
  channel values, which is what kinema writes as ``root_translation``: no root correction is needed.
- Zero-length leaf bones (End Site at 0, as in Bandai Namco files) get their tail nudged; heads keep
  the joint position, so they are compared like every other bone.

Debian's Blender 3.4 importer opens files with mode ``'rU'``, which its Python 3.11 rejects; the
script wraps ``builtins.open`` to drop the ``U`` (newline handling is the same without it).
"""

from __future__ import annotations

import builtins
import json
import sys
import time

import bpy
from bpy_extras.io_utils import axis_conversion

FRAME_START = 1
_real_open = builtins.open


def _open_without_u(file, mode="r", *args, **kwargs):
    """``open`` that accepts the removed ``'U'`` mode flag (Python < 3.11 ignored it anyway)."""
    if isinstance(mode, str) and "U" in mode:
        mode = mode.replace("U", "") or "r"
    return _real_open(file, mode, *args, **kwargs)


def import_and_dump(bvh_path: str, out_path: str, frames: list[int] | None = None) -> dict:
    """Import ``bvh_path`` into an empty scene, write the JSON report to ``out_path`` and return it."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    before = set(bpy.data.objects)
    started = time.perf_counter()
    builtins.open = _open_without_u
    try:
        result = bpy.ops.import_anim.bvh(
            filepath=bvh_path, target="ARMATURE", global_scale=1.0, rotate_mode="NATIVE",
            axis_forward="-Z", axis_up="Y", frame_start=FRAME_START, use_fps_scale=False,
            update_scene_fps=False, update_scene_duration=True, use_cyclic=False,
        )
    finally:
        builtins.open = _real_open
    if "FINISHED" not in result:
        raise RuntimeError(f"BVH import of {bvh_path} failed: {result}")
    import_seconds = time.perf_counter() - started
    arm = next(o for o in bpy.data.objects if o not in before and o.type == "ARMATURE")
    action = arm.animation_data.action
    first, last = (int(round(x)) for x in action.frame_range)
    num_frames = last - first + 1
    frames = list(range(num_frames)) if frames is None else frames
    bad = [f for f in frames if not 0 <= f < num_frames]
    if bad:
        raise ValueError(f"frames {bad} outside the {num_frames} imported frames")
    scene = bpy.context.scene
    names = [pb.name for pb in arm.pose.bones]
    heads = []
    for f in frames:
        scene.frame_set(FRAME_START + f)
        world = arm.matrix_world
        heads.append([list(world @ pb.head) for pb in arm.pose.bones])
    axis = axis_conversion(from_forward="-Z", from_up="Y").to_4x4()
    report = {
        "blender_version": bpy.app.version_string,
        "bvh": bvh_path,
        "frame_start": FRAME_START,
        "num_frames": num_frames,
        "frames": frames,
        "bones": names,
        "heads": heads,  # [frame][bone] = (x, y, z) in Blender's Z-up world, metres
        "axis_matrix": [list(row) for row in axis],
        "import_seconds": import_seconds,
    }
    with _real_open(out_path, "w", encoding="utf-8") as fh:
        json.dump(report, fh)
    return report


def main(argv: list[str]) -> int:
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    if len(args) not in (2, 3):
        print("usage: blender -b --python blender_import_check.py -- IN.bvh OUT.json [F0,F1,...]", file=sys.stderr)
        return 2
    frames = [int(x) for x in args[2].split(",")] if len(args) == 3 else None
    report = import_and_dump(args[0], args[1], frames)
    print(f"blender_import_check: {len(report['bones'])} bones x {len(report['frames'])} frames "
          f"-> {args[1]} (Blender {report['blender_version']})")
    return 0


if __name__ == "__main__":
    try:
        code = main(sys.argv)
    except Exception as err:  # report on one line and make Blender exit non-zero
        print(f"blender_import_check: error: {type(err).__name__}: {err}", file=sys.stderr)
        code = 1
    sys.stdout.flush()
    # Blender ignores the script's return value; leave with the status so callers can check it
    import os

    os._exit(code)
