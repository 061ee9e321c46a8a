"""Does a long prompt keep going, at the speed its words ask? (issue 57)

Held-out phrasings (written before the phase-captioned training, never training captions; checked by
``--check-captions``), 10 s each, seeds 0-2, default settings: mean pelvis ground speed over 1-4 s and
7-10 s, their ratio, and the 10-s mean; a 60-s walk's mean speed per 10-s block.

    python scripts/long_motion_probe.py --out out/long_probe.json [--model DIR] [--long 60]
"""

from __future__ import annotations

import argparse
import json
import time

import kinema

HELDOUT = {
    "stroll": ("Someone takes an unhurried stroll straight ahead.", "A woman strolls along at her leisure."),
    "walk": ("A man makes his way forward on foot.", "Somebody walks along the street."),
    "jog": ("A runner jogs along at a relaxed pace.", "Someone is jogging straight ahead."),
    "run": ("A man runs quickly down the road.", "Somebody runs hard and keeps going."),
}
LONG_WALK = "A woman walks along the path for a long time."


def mean_speed(motion, t0: float, t1: float) -> float:
    xz = motion.root_translation[:, [0, 2]].double()
    fps = motion.fps
    a, b = int(round(t0 * fps)), min(int(round(t1 * fps)), motion.num_frames - 1)
    steps = (xz[a + 1 : b + 1] - xz[a:b]).norm(dim=-1)
    return float(steps.sum()) / max((b - a) / fps, 1e-9)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="default")
    ap.add_argument("--out", default="out/long_probe.json")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--long", type=float, default=60.0, help="seconds of the long walk (0: skip)")
    ap.add_argument("--save-dir", default=None, help="also save each motion as BVH here")
    args = ap.parse_args()
    model = kinema.load_model(args.model)
    rows = []
    for group, prompts in HELDOUT.items():
        for prompt in prompts:
            for seed in range(args.seeds):
                t = time.perf_counter()
                res = model.generate(prompt, seconds=args.seconds, seed=seed)
                wall = time.perf_counter() - t
                m = res[0]
                early, late = mean_speed(m, 1, 4), mean_speed(m, args.seconds - 3, args.seconds)
                row = dict(group=group, prompt=prompt, seed=seed, early=early, late=late,
                           ratio=late / max(early, 1e-9), mean=mean_speed(m, 0, args.seconds), wall=wall,
                           grounding=res.report.prompts[0].get("grounding"))
                rows.append(row)
                if args.save_dir:
                    m.save(f"{args.save_dir}/{group}_{prompts.index(prompt)}_s{seed}.bvh")
                print(f"{group:6s} s{seed} early {early:.2f} late {late:.2f} ratio {row['ratio']:.2f} "
                      f"mean {row['mean']:.2f} m/s  {wall:.1f}s  {prompt}", flush=True)
    summary = {}
    for group in HELDOUT:
        g = [r for r in rows if r["group"] == group]
        summary[group] = dict(mean=sum(r["mean"] for r in g) / len(g), ratio=sum(r["ratio"] for r in g) / len(g),
                              min_ratio=min(r["ratio"] for r in g), kept=sum(r["ratio"] >= 0.75 for r in g), n=len(g))
        print(f"{group:6s} mean {summary[group]['mean']:.2f} m/s  ratio mean {summary[group]['ratio']:.2f} "
              f"min {summary[group]['min_ratio']:.2f}  kept {summary[group]['kept']}/{len(g)}")
    blocks = []
    if args.long > 0:
        t = time.perf_counter()
        m = model.generate(LONG_WALK, seconds=args.long, seed=0)[0]
        blocks = [mean_speed(m, k, min(k + 10, args.long)) for k in range(0, int(args.long), 10)]
        print(f"{args.long:g}-s walk ({time.perf_counter() - t:.1f} s): blocks " + " ".join(f"{b:.2f}" for b in blocks))
        if args.save_dir:
            m.save(f"{args.save_dir}/long_walk.bvh")
    with open(args.out, "w") as f:
        json.dump(dict(model=args.model, rows=rows, summary=summary, long_walk_blocks=blocks), f, indent=1)


if __name__ == "__main__":
    main()
