"""`kinema render MOTION --out strip.png|anim.gif`: look at a motion without a 3D package.

A ``.png`` output is a filmstrip of ``--frames`` evenly spaced poses, a ``.gif`` an animation at
``--fps`` (see kinema.render for what is drawn and how the camera is chosen). BVH inputs are read in
the file's unit times ``--scale`` (0.01 for centimetre files such as Bandai Namco); npz and glTF files
are already metres (``--animation NAME`` picks a glTF clip, default the first). Any rig is drawn.
``--constraints c.json`` (docs/constraints.md) marks what the constraints ask for:
end-effector positions and full-body root positions as targets, root waypoints/paths on the ground;
keyframes given as ``times`` are placed at the motion's fps, ``frame_indices`` are taken as its frames.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub) -> None:
    """Add the `render` sub-command to the top-level parser."""
    p = sub.add_parser("render", help="draw a motion as a filmstrip PNG or an animated GIF")
    p.add_argument("motion", type=Path, help=".bvh, .bvh.gz, .npz, .glb or .gltf")
    p.add_argument("--animation", metavar="NAME", help="glTF input: the clip to draw (default: the first)")
    p.add_argument("--out", type=Path, required=True, help="strip.png (filmstrip) or anim.gif (animation)")
    p.add_argument("--frames", type=int, help="poses in a filmstrip (default 8; PNG only)")
    p.add_argument("--scale", type=float, help="multiply BVH lengths by this to get metres (default 1; 0.01 for cm)")
    p.add_argument("--constraints", type=Path, help="constraints JSON whose targets are marked")
    p.add_argument("--fps", type=float, help="GIF frame rate (default: the motion's, at most 20; GIF only)")
    p.add_argument("--title", help="title drawn at the top (default: the input file name)")
    p.add_argument("--robot", help="robot motion input (.csv, or .npz from `kinema robot`): 'g1', 'h1' or its MJCF "
                   "(default: the robot the npz names, else g1); --mapping as for `kinema robot`")
    p.add_argument("--mapping", type=Path, help="robot input: JSON landmark -> body mapping of the MJCF")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import math

    from kinema.atomic_files import check_output_path
    from kinema.errors import KinemaError
    from kinema.input_files import check_input_file
    from kinema.io import load_motion
    from kinema.render import render_filmstrip, render_gif
    from kinema.robot.files import is_robot_npz

    src: Path = args.motion
    check_input_file(src, "motion file")
    name = src.name.lower()
    is_bvh = name.endswith(".bvh") or name.endswith(".bvh.gz")
    is_gltf = name.endswith(".glb") or name.endswith(".gltf")
    is_robot = name.endswith(".csv") or (name.endswith(".npz") and is_robot_npz(src))
    if (args.robot is not None or args.mapping is not None) and not is_robot:
        raise KinemaError("--robot and --mapping apply to robot motions only (.csv, or .npz from `kinema robot`)")
    if not (is_bvh or is_gltf or is_robot or name.endswith(".npz")):
        raise KinemaError(f"{src}: unknown motion format (use .bvh, .bvh.gz, .npz, .glb or .gltf)")
    if args.animation is not None and not is_gltf:
        raise KinemaError("--animation applies to glTF input only (.glb, .gltf)")
    if src.stat().st_size == 0:
        raise KinemaError(f"{src}: file is empty")
    kind = args.out.suffix.lower()
    if kind not in (".png", ".gif"):
        raise KinemaError(f"{args.out}: output must be .png (filmstrip) or .gif (animation)")
    if args.scale is not None and not is_bvh:
        raise KinemaError("--scale applies to BVH input only (npz and glTF files are in metres)")
    if args.frames is not None and kind == ".gif":
        raise KinemaError("--frames applies to a .png filmstrip only (use --fps for a GIF)")
    if args.fps is not None and kind == ".png":
        raise KinemaError("--fps applies to a .gif animation only (use --frames for a filmstrip)")
    scale = 1.0 if args.scale is None else args.scale
    if not (math.isfinite(scale) and scale > 0):
        raise KinemaError(f"--scale must be a positive number, got {scale}")
    check_output_path(args.out)
    try:
        if is_robot:
            motion = robot_drawing(src, args.robot, args.mapping)
        elif is_gltf:
            motion = load_motion(src, animation=args.animation)
        else:
            motion = load_motion(src, scale=scale)
    except (EOFError, OSError) as err:  # e.g. a truncated .gz
        raise KinemaError(f"{src}: cannot read ({err})") from None
    targets = None if args.constraints is None else constraint_targets(args.constraints, motion)
    if args.constraints is not None:
        from kinema.objectives.display import objective_targets  # lazy, like the other CLI imports

        targets += objective_targets(args.constraints)
    title = args.title if args.title is not None else src.name
    if kind == ".png":
        frames = 8 if args.frames is None else args.frames
        out = render_filmstrip(motion, args.out, frames=frames, targets=targets, title=title)
    else:
        out = render_gif(motion, args.out, fps=args.fps, targets=targets, title=title)
    print(f"wrote {out}: {motion.num_frames} frames @ {motion.fps:g} fps, {motion.num_joints} joints")
    return 0


def robot_drawing(path: Path, robot: str | None, mapping: Path | None):
    """A robot motion file as a kinema Motion of the robot's body frames (kinema.robot.drawing)."""
    from kinema.errors import KinemaError
    from kinema.robot import load_robot, load_robot_motion
    from kinema.robot.drawing import robot_motion_for_drawing

    robot_motion = load_robot_motion(path, robot)
    try:
        description = load_robot(robot_motion.robot, mapping=mapping)
    except KinemaError as err:
        if robot is not None:
            raise
        raise KinemaError(
            f"{path} names robot {robot_motion.robot!r}, which cannot be loaded from here ({err}); "
            "give it with --robot g1|path/to/robot.xml"
        ) from None
    return robot_motion_for_drawing(robot_motion, description)


def constraint_targets(path: Path, motion) -> list[tuple]:
    """Render targets (see kinema.render) for the constraints in a JSON file, validated against
    ``motion`` (its skeleton, fps and length); foot-contact constraints have nothing to mark."""
    from kinema.errors import KinemaError

    try:
        from kinema.constraints import EndEffectorConstraint, FullBodyConstraint, Root2DConstraint, load_constraints
    except ImportError:
        raise KinemaError("--constraints is not supported yet: kinema.constraints is not available") from None
    targets: list[tuple] = []
    for c in load_constraints(path, motion.skeleton, motion.fps, motion.num_frames):
        frames = c.frames(motion.fps, motion.num_frames)
        if isinstance(c, EndEffectorConstraint) and c.positions is not None:
            targets += [(f, p.tolist(), c.joint) for f, p in zip(frames, c.positions, strict=True)]
        elif isinstance(c, FullBodyConstraint) and c.root_positions is not None:
            targets += [(f, p.tolist(), "pose") for f, p in zip(frames, c.root_positions, strict=True)]
        elif isinstance(c, Root2DConstraint) and c.positions is not None:
            label = "" if c.dense else "waypoint"
            targets += [(f, p.tolist(), label) for f, p in zip(frames, c.positions, strict=True)]
    return targets
