"""`kinema retarget MOTION --rig CHARACTER --out OUT`: a motion onto a user's character.

MOTION is a kinema ``.npz``, a ``.bvh``/``.bvh.gz`` (lengths times ``--in-scale`` must be metres:
0.01 for centimetre files), a ``.glb`` clip (``--animation``) or an ``.fbx`` (its first animation,
read in metres); CHARACTER a ``.glb``/``.gltf``, ``.bvh``, ``.fbx`` or ``.npz`` rig. OUT is written in
the character's own terms by its suffix: ``.glb`` (with the character's skin and materials), ``.bvh``
(its joint names, offsets and units), ``.npz`` or ``.fbx`` (through Blender). Humanoids map by slot,
other rigs by joint name (docs/retarget.md); ``--overrides`` is a rig overrides JSON for odd joint
names, ``--mapping`` a JSON object {character joint: motion joint} that replaces parts of the
correspondence. Prints the mapping kind, the body scale and how well the result follows the source
(direction error, skate, floor).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import positive_float


def register(sub) -> None:
    """Add the `retarget` sub-command to the top-level parser."""
    p = sub.add_parser("retarget", help="put a motion (npz, BVH, GLB clip) onto a character rig (GLB, BVH, FBX)")
    p.add_argument("motion", type=Path, help=".npz, .bvh, .bvh.gz, .glb or .fbx")
    p.add_argument("--rig", type=Path, required=True, metavar="CHARACTER", help=".glb, .gltf, .bvh, .fbx or .npz")
    p.add_argument("--out", type=Path, required=True, help=".glb, .bvh, .bvh.gz, .npz or .fbx (FBX needs Blender)")
    p.add_argument("--in-scale", type=positive_float, default=1.0, help="BVH motion: lengths times this are metres")
    p.add_argument("--animation", metavar="NAME", help="glTF motion: the clip to use (default: the first)")
    p.add_argument(
        "--overrides", type=Path, metavar="JSON", help="rig overrides JSON for the character's odd joint names"
    )
    p.add_argument(
        "--mapping", type=Path, metavar="JSON", help="{character joint: motion joint} replacing the found map"
    )
    p.set_defaults(func=run)


def _mapping(path: Path | None) -> dict | None:
    from kinema.errors import KinemaError
    from kinema.input_files import read_json_bounded

    if path is None:
        return None
    data = read_json_bounded(path, "mapping file")
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise KinemaError(f"{path}: the mapping must be a JSON object {{character joint: motion joint}}")
    return data


def _load_source(args):
    from kinema.errors import KinemaError
    from kinema.input_files import check_input_file
    from kinema.io import load_motion
    from kinema.retarget.fbx import read_fbx

    check_input_file(args.motion, "motion file")
    name = args.motion.name.lower()
    if name.endswith(".fbx"):
        motion = read_fbx(args.motion).motion
        if motion is None:
            raise KinemaError(f"{args.motion}: has no animation")
        return motion
    if name.endswith((".bvh", ".bvh.gz")):
        return load_motion(args.motion, scale=args.in_scale)
    if args.animation is not None:
        if not name.endswith((".glb", ".gltf")):
            raise KinemaError("--animation applies to glTF motions only (.glb, .gltf)")
        return load_motion(args.motion, animation=args.animation)
    return load_motion(args.motion)


def run(args: argparse.Namespace) -> int:
    from kinema.atomic_files import check_output_path
    from kinema.retarget import build_joint_map, load_character, retarget_report, save_character_motion
    from kinema.retarget.core import retarget_with_map

    check_output_path(args.out)
    motion = _load_source(args)
    character = load_character(args.rig, overrides=args.overrides)
    jm = build_joint_map(motion.skeleton, character.skeleton, _mapping(args.mapping), args.overrides)
    out = retarget_with_map(motion, jm)
    save_character_motion(out, args.out, name=args.motion.name.split(".")[0])
    r = retarget_report(motion, out, jm)
    lines = [
        f"{args.out}: {out.num_frames} frames @ {out.fps:g} fps on {character.path.name} "
        f"({character.skeleton.num_joints} joints, {len(jm.pairs)} mapped by {jm.kind}), body scale {r['scale']:.4g}",
        f"  limb directions vs source: mean {r['direction_deg_mean']:.1f} deg, max {r['direction_deg_max']:.1f} deg; "
        f"bone-length drift {r['bone_drift_mm']:.3g} mm"
        + (
            f"; largest bone turn about itself {r['twist_deg']:.0f} deg ({r['twist_bone']})"
            if "twist_bone" in r
            else ""
        ),
        f"  lowest joint {r['lowest']:.4g} (rest pose: {r['lowest_rest']:.4g})",
    ]
    if "ankle_cm" in r:
        lines.append(
            f"  planted feet above their rest height (source units): source {r['ankle_source_cm']:.2f} cm, "
            f"character {r['ankle_cm']:.2f} cm"
        )
    if "skate_source_cm_s" in r:
        lines.append(
            f"  foot skate (source units): source {r['skate_source_cm_s']:.2f} cm/s, "
            f"character {r['skate_target_cm_s']:.2f} cm/s"
        )
    print("\n".join(lines))
    return 0
