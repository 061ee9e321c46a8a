"""Measure how multi-prompt timelines follow their prompts and how smooth their joins are.

For each timeline (walk -> bow -> wave and bow -> wave -> walk, 4 s per segment) and seed, raw and
post-processed: the bow segment's largest trunk lean (pelvis -> head from vertical, degrees), the wave
segment's highest right hand over the head (m), the walk segment's mean pelvis ground speed (m/s), and
the joins: the largest joint speed (m/s) and acceleration (m/s^2) on frames within ``JOIN`` s of a
segment boundary against the 99th percentile of the same per-frame maxima elsewhere, plus the peak
pelvis speed at the joins. Usage (from the repository root):

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 python scripts/timeline_joins.py --seeds 0 1 2 3 [--steps N]

``--bow-depth`` instead prints, per seed, the largest lean of "A person bows." alone (4 s) and of the bow
segment of walk -> bow -> wave, raw.
"""

from __future__ import annotations

import argparse
import json

import torch

import kinema
from kinema.human.targets import run_postprocess

WALK, BOW, WAVE = "A person walks forward.", "A person bows.", "A person waves their right hand."
TIMELINES = {"walk_bow_wave": [WALK, BOW, WAVE], "bow_wave_walk": [BOW, WAVE, WALK]}
SECONDS = 4.0
JOIN = 0.75  # seconds either side of a boundary that count as the join


def trunk_lean(motion) -> torch.Tensor:
    """(T,) angle of pelvis -> head from vertical, degrees."""
    names, p = list(motion.skeleton.names), motion.positions.double()
    up = p[:, names.index("Head")] - p[:, 0]
    return torch.rad2deg(torch.acos(up[:, 1] / up.norm(dim=-1)))


def measures(motion, prompts: list[str]) -> dict[str, float]:
    names, p, fps = list(motion.skeleton.names), motion.positions.double(), motion.fps
    n = round(SECONDS * fps)
    seg = {prompt: slice(i * n, (i + 1) * n) for i, prompt in enumerate(prompts)}
    lean = trunk_lean(motion)
    over = p[:, names.index("Hand_R"), 1] - p[:, names.index("Head"), 1]
    ground = (p[1:, 0, [0, 2]] - p[:-1, 0, [0, 2]]).norm(dim=-1) * fps
    vel = (p[1:] - p[:-1]) * fps
    speed = vel.norm(dim=-1).amax(-1)  # (T-1,) fastest joint per frame
    acc = ((vel[1:] - vel[:-1]) * fps).norm(dim=-1).amax(-1)  # (T-2,)
    near = torch.zeros(p.shape[0], dtype=torch.bool)
    for i in range(1, len(prompts)):
        near[max(0, i * n - round(JOIN * fps)) : i * n + round(JOIN * fps)] = True
    pelvis = vel[:, 0].norm(dim=-1)
    return {
        "bow_lean_deg": float(lean[seg[BOW]].max()),
        "wave_hand_over_head_m": float(over[seg[WAVE]].max()),
        "walk_speed_ms": float(ground[seg[WALK]][: n - 1].mean()),
        "join_speed_peak": float(speed[near[1:]].max()),
        "inside_speed_p99": float(torch.quantile(speed[~near[1:]], 0.99)),
        "join_acc_peak": float(acc[near[2:]].max()),
        "inside_acc_p99": float(torch.quantile(acc[~near[2:]], 0.99)),
        "join_pelvis_speed_peak": float(pelvis[near[1:]].max()),
    }


def bow_depth(model, seeds: list[int], steps: int | None) -> None:
    """Largest trunk lean (deg) of the bow alone and of the walk -> bow -> wave bow segment, per seed."""
    prompts = TIMELINES["walk_bow_wave"]
    for seed in seeds:
        alone = model.generate(BOW, seconds=SECONDS, seed=seed, steps=steps, postprocess=False)[0]
        chain = model.generate([(p, SECONDS) for p in prompts], seed=seed, steps=steps, postprocess=False)[0]
        row = {"alone": float(trunk_lean(alone).max()), "after_walk": measures(chain, prompts)["bow_lean_deg"]}
        print(json.dumps({"seed": seed, "steps": steps, **{k: round(v, 1) for k, v in row.items()}}), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--timelines", nargs="+", default=list(TIMELINES))
    ap.add_argument("--bow-depth", action="store_true", help="bow alone vs after a walk, per seed")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = kinema.load_model("default")
    if args.bow_depth:
        bow_depth(model, args.seeds, args.steps)
        return
    for name in args.timelines:
        prompts = TIMELINES[name]
        for seed in args.seeds:
            raw = model.generate([(p, SECONDS) for p in prompts], seed=seed, steps=args.steps, postprocess=False)[0]
            post, _ = run_postprocess(raw, [], model.representation)  # what generate(postprocess=True) does
            for mode, motion in (("raw", raw), ("post", post)):
                row = {k: round(v, 3) for k, v in measures(motion, prompts).items()}
                print(json.dumps({"timeline": name, "seed": seed, "mode": mode, **row}), flush=True)


if __name__ == "__main__":
    main()
