"""Robot demonstrations for docs/robots.md: prompts generated with the default model (and captured Bandai
Namco clips) retargeted onto the Unitree G1, replayed in MuJoCo, drawn as a human filmstrip above the
G1's, and measured in one markdown table.

    python scripts/robot_demos.py --out docs/images [--steps 10] [--seconds 4] [--seed 0] \
        [--bandai ../shared/datasets/bandai-namco]

Writes ``robot_<name>.png`` per case and prints the table. Look at the pictures before shipping them.
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
from kinema.robot import load_robot, replay_report, retarget_to_robot
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
    "| travel human / G1 (m) | leg overlap (cm) | retarget (s) |\n|---|---|---|---|---|---|---|---|---|"
)


def stacked(top: Path, bottom: Path, out: Path) -> None:
    """The two PNGs one above the other, left-aligned, on white."""
    a, b = Image.open(top).convert("RGB"), Image.open(bottom).convert("RGB")
    sheet = Image.new("RGB", (max(a.width, b.width), a.height + b.height), "white")
    sheet.paste(a, (0, 0))
    sheet.paste(b, (0, a.height))
    sheet.save(out)


def case_row(name: str, label: str, human, robot, out_dir: Path) -> str:
    """Retarget, replay, draw; the table row of one case."""
    start = time.perf_counter()
    robot_motion = retarget_to_robot(human, robot)
    seconds = time.perf_counter() - start
    rep = replay_report(robot_motion, robot)
    root = human.positions[:, human.skeleton.roles["pelvis"]].numpy()
    human_travel = float(np.linalg.norm(root[-1, [0, 2]] - root[0, [0, 2]]))
    with tempfile.TemporaryDirectory() as tmp:
        a = render_filmstrip(human, Path(tmp) / "h.png", frames=8, title=f"human: {label}")
        b = render_filmstrip(
            robot_motion_for_drawing(robot_motion, robot), Path(tmp) / "r.png", frames=8, title=f"Unitree G1: {label}"
        )
        stacked(a, b, out_dir / f"robot_{name}.png")
    return (
        f"| {label} | {robot_motion.num_frames} | {rep.range_overshoot:.3f} | {100 * rep.lowest_sole:+.1f} "
        f"| {rep.planted_slide:.3f} | {rep.planted_fraction:.2f} | {human_travel:.2f} / {rep.travel:.2f} "
        f"| {100 * rep.leg_overlap:.1f} | {seconds:.2f} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/images"))
    ap.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bandai", type=Path, default=Path("../shared/datasets/bandai-namco"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    model, robot = kinema.load_model(), load_robot("g1")
    options = {"seconds": args.seconds, "seed": args.seed} | ({"steps": args.steps} if args.steps else {})
    rows = []
    for name, prompt in PROMPTS:
        human = model.generate(prompt, **options)[0]
        rows.append(case_row(name, f'"{prompt}"', human, robot, args.out))
        print(rows[-1], flush=True)
    for name, clip in CLIPS:
        if (args.bandai / clip).is_file():
            human = kinema.load_motion(args.bandai / clip, scale=0.01)
            rows.append(case_row(name, f"captured {Path(clip).name}", human, robot, args.out))
            print(rows[-1], flush=True)
    print(HEADER)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
