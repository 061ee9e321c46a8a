"""Robot demonstrations for docs/robots.md: prompts generated with the default model (and captured Bandai
Namco clips) retargeted onto a robot (the Unitree G1 by default), replayed in MuJoCo, drawn as a human
filmstrip above the robot's, and measured in two markdown tables: the replay, and what a tracker needs
(joint speeds, steps, MuJoCo inverse dynamics: kinema.robot.dynamics).

    python scripts/robot_demos.py --out docs/images [--robot g1|h1|MJCF] [--steps 10] [--seconds 4] \
        [--seeds 0 1 2] [--bandai ../shared/datasets/bandai-namco]

Writes ``robot_<name>.png`` (``robot_<robot>_<name>.png`` for a robot other than the G1) per case for the
first seed and prints the tables. Look at the pictures before shipping them.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

import kinema
from kinema.render import render_filmstrip
from kinema.robot import dynamics_report, load_robot, replay_report, retarget_to_robot
from kinema.robot.drawing import robot_motion_for_drawing

PROMPTS = [
    ("walk", "A person walks forward."),
    ("left_hand", "A person raises their left hand."),
    ("bow", "A person bows."),
]
CLIPS = [
    ("bandai_walk", "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh.gz"),
    ("bandai_bow", "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_bow_normal_001.bvh.gz"),
]
HEADER = (
    "| case | frames | range overshoot (rad) | lowest sole (cm) | planted-sole slide (m/s) | planted share "
    "| travel human / robot (m) | leg overlap (cm) | retarget (s) |\n|---|---|---|---|---|---|---|---|---|"
)
TRACKER_HEADER = (
    "| case | seed | fastest joint (% of limit) | steps / least swing clearance (cm) | peak torque (% of limit) "
    "| base residual over 0.25 s (% of weight) | per frame: peak / mean (%) | self-penetration (cm) | feasible |\n"
    "|---|---|---|---|---|---|---|---|---|"
)


def stacked(top: Path, bottom: Path, out: Path) -> None:
    """The two PNGs one above the other, left-aligned, on white."""
    a, b = Image.open(top).convert("RGB"), Image.open(bottom).convert("RGB")
    sheet = Image.new("RGB", (max(a.width, b.width), a.height + b.height), "white")
    sheet.paste(a, (0, 0))
    sheet.paste(b, (0, a.height))
    sheet.save(out)


def case_rows(name: str, label: str, human, robot, out_dir: Path | None, seed: str) -> tuple[str, str]:
    """Retarget, replay, draw (into ``out_dir`` unless None); the rows of one case in the two tables."""
    start = time.perf_counter()
    robot_motion = retarget_to_robot(human, robot)
    seconds = time.perf_counter() - start
    rep = replay_report(robot_motion, robot)
    dyn = dynamics_report(robot_motion, robot)
    root = human.positions[:, human.skeleton.roles["pelvis"]].numpy()
    human_travel = float(np.linalg.norm(root[-1, [0, 2]] - root[0, [0, 2]]))
    if out_dir is not None:
        title = {"g1": "Unitree G1", "h1": "Unitree H1"}.get(robot.name, Path(robot.name).stem)
        with tempfile.TemporaryDirectory() as tmp:
            a = render_filmstrip(human, Path(tmp) / "h.png", frames=8, title=f"human: {label}")
            b = render_filmstrip(
                robot_motion_for_drawing(robot_motion, robot), Path(tmp) / "r.png", frames=8, title=f"{title}: {label}"
            )
            stacked(a, b, out_dir / (f"robot_{name}.png" if robot.name == "g1" else f"robot_{robot.name}_{name}.png"))
    steps = f"{rep.steps} / {100 * rep.swing_clearance:.1f}" if rep.steps else "0 / -"
    speed = f"{100 * dyn.speed.value:.0f} ({dyn.speed.what})" if dyn.speed else "no limits"
    torque = f"{100 * dyn.torque.value:.0f} ({dyn.torque.what})" if dyn.torque else "no limits"
    window = dyn.residual_force_window
    collision = "-" if dyn.collision is None else f"{100 * dyn.collision.value:.1f}"
    return (
        f"| {label} | {robot_motion.num_frames} | {rep.range_overshoot:.3f} | {100 * rep.lowest_sole:+.1f} "
        f"| {rep.planted_slide:.3f} | {rep.planted_fraction:.2f} | {human_travel:.2f} / {rep.travel:.2f} "
        f"| {100 * rep.leg_overlap:.1f} | {seconds:.2f} |",
        f"| {label} | {seed} | {speed} | {steps} | {torque} | {100 * window.value:.0f} ({window.what}) "
        f"| {100 * dyn.residual_force.value:.0f} / {100 * dyn.residual_force_mean:.0f} | {collision} "
        f"| {'yes' if dyn.feasible else 'no'} |",
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/images"))
    ap.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--robot", default="g1", help="'g1' (default), 'h1' or an MJCF file")
    ap.add_argument("--bandai", type=Path, default=Path("../shared/datasets/bandai-namco"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    model, robot = kinema.load_model(), load_robot(args.robot)
    rows = []
    for name, prompt in PROMPTS:
        for k, seed in enumerate(args.seeds):
            options = {"seconds": args.seconds, "seed": seed} | ({"steps": args.steps} if args.steps else {})
            human = model.generate(prompt, **options)[0]
            rows.append(case_rows(name, f'"{prompt}"', human, robot, args.out if k == 0 else None, str(seed)))
            print(*rows[-1], sep="\n", flush=True)
    for name, clip in CLIPS:
        if (args.bandai / clip).is_file():
            human = kinema.load_motion(args.bandai / clip, scale=0.01)
            rows.append(case_rows(name, f"captured {Path(clip).name}", human, robot, args.out, "-"))
            print(*rows[-1], sep="\n", flush=True)
    print(HEADER)
    print("\n".join(r[0] for r in rows))
    print(TRACKER_HEADER)
    print("\n".join(r[1] for r in rows))


if __name__ == "__main__":
    main()
