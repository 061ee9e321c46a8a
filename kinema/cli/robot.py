"""`kinema robot MOTION --robot g1 --out walk.csv|.npz`: a kinema motion on a humanoid robot.

Reads a motion written by `kinema generate` (or any human .bvh/.npz/.glb kinema reads; ``--scale`` for
BVH units, 0.01 for centimetre files), retargets it onto the robot by inverse kinematics over its hinge
joints (kinema.robot) and writes MuJoCo poses: a CSV (time, root position and quaternion, one column per
hinge joint, radians, Z up) or an npz with the same arrays. ``--robot`` is ``g1`` (the Unitree G1 shipped
with kinema) or an MJCF file; ``--mapping`` a JSON file naming which bodies are the robot's hips, knees,
feet, shoulders, elbows and hands when its body names are not recognised (docs/robots.md). The replay
measurements (joint-range overshoot, lowest sole, planted-sole slide, travel and its ratio to the
human's, the steps' least swing clearance) are printed, then the
inverse dynamics (kinema.robot.dynamics: torques against actuator limits, the floating base's residual,
joint speeds, self-collision) and one warning line when the motion is not feasible.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.errors import KinemaError

OUTPUTS = (".csv", ".npz", ".pkl")


def register(sub) -> None:
    """Add the `robot` sub-command to the top-level parser."""
    p = sub.add_parser("robot", help="retarget a motion onto a humanoid robot (MuJoCo MJCF) as CSV/npz poses")
    p.add_argument("motion", type=Path, help="a human motion: .npz or .bvh written by `kinema generate`, .glb; or "
                   "a robot motion (.csv, or .npz from --robot) to write for a tracker")
    p.add_argument("--robot", default="g1", help="'g1' (default), 'h1' or a MuJoCo MJCF .xml humanoid")
    p.add_argument("--mapping", type=Path, help="JSON: robot landmark -> body name, for unrecognised robots")
    p.add_argument("--out", type=Path, required=True, help="walk.csv (MuJoCo qpos table) or walk.npz; with "
                   "--tracker, that tracker's file (beyondmimic: .npz, gmr: .pkl)")
    p.add_argument("--tracker", choices=("beyondmimic", "gmr"), help="write the file a motion tracker reads: "
                   "BeyondMimic's npz or GMR's pickle (docs/robots.md; .pkl alone means gmr)")
    p.add_argument("--scale", type=float, help="multiply BVH lengths by this to get metres (0.01 for cm)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # imported here like every sub-command's work, so that `kinema --help` does not load torch and mujoco
    from kinema.atomic_files import check_output_path
    from kinema.cli.report import print_warnings
    from kinema.input_files import check_input_file
    from kinema.io import load_motion
    from kinema.robot import load_robot, load_robot_motion, retarget_to_robot
    from kinema.robot.dynamics import dynamics_report
    from kinema.robot.exports import save_for_tracker
    from kinema.robot.files import is_robot_npz
    from kinema.robot.stage import replay_words, robot_measures

    suffix = args.out.suffix.lower()
    if suffix not in OUTPUTS:
        raise KinemaError(f"{args.out}: --out must end in .csv or .npz (or .pkl for --tracker gmr)")
    tracker = args.tracker or ("gmr" if suffix == ".pkl" else None)
    check_input_file(args.motion, "motion file")
    name = args.motion.name.lower()
    is_bvh = name.endswith((".bvh", ".bvh.gz"))
    if args.scale is not None and not (is_bvh and args.scale > 0):
        raise KinemaError("--scale applies to BVH input only and must be positive")
    is_robot = name.endswith(".csv") or (name.endswith(".npz") and is_robot_npz(args.motion))
    if is_robot and tracker is None:
        raise KinemaError(f"{args.motion} is a robot motion already: give --tracker to write it for a tracker")
    check_output_path(args.out)
    robot = load_robot(args.robot, mapping=args.mapping)
    if is_robot:
        robot_motion, motion = load_robot_motion(args.motion, robot.name), None
        robot_motion.check_joints(robot.joint_names, robot.name)
    else:
        try:
            motion = load_motion(args.motion, scale=args.scale or 1.0) if is_bvh else load_motion(args.motion)
        except (EOFError, OSError) as err:
            raise KinemaError(f"{args.motion}: cannot read ({err})") from None
        robot_motion = retarget_to_robot(motion, robot)
    out = robot_motion.save(args.out) if tracker is None else save_for_tracker(robot_motion, robot, args.out, tracker)
    written = f"wrote {out}{f' for {tracker}' if tracker else ''}: {robot_motion.num_frames} frames @ " \
              f"{robot_motion.fps:g} fps, {robot.num_joints} joints of {robot.name}"
    if motion is None:
        dynamics = dynamics_report(robot_motion, robot)
        print(written)
        summary, warning = dynamics.summary(), dynamics.warning()
    else:
        measured = robot_measures(motion, robot_motion, robot)
        print(f"{written}; {replay_words(measured)}")
        summary, warning = measured["dynamics_summary"], measured["warning"]
    print(f"dynamics (MuJoCo inverse dynamics): {summary}")
    print_warnings([warning] if warning else [])
    return 0
