"""Issue 34's measures of the creatures model on held-out rigs, per source file (skeleton), against the
file's own clips:

    python scripts/anyrig_gait_check.py --model creatures --data cache/quat20 --splits val test \
        --seconds 4 --steps 20 --seeds 0 1 --out out/gait_creatures.json

For every legged file of the splits (a walk among its clips), one motion per seed for each of: its walk
caption asked to go forward ("A deer walks forward."), its run or gallop caption, its idle caption
(kinema.evaluate.anyrig.locomotion.probe_prompts), generated on the file's own skeleton in the build's
units (rest pose 1 across: lengths are body sizes) with post-processing, as a user gets them. Measured
(kinema.evaluate.anyrig.locomotion): forward share and net turn of the walk, idle drift, ground speed of
run/gallop over walk, and the foot-to-leg gap (kinema.rig.ties: every tied joint's distance to its
anchor over the largest the file's own clips show) over all of them. The "done when" of the issue:
forward share >= 0.6, net turn <= 60 deg, idle drift <= 0.1, run/walk >= 1.3, gap <= 1.15. Medians over
seeds are reported, with the worst seed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch

from kinema.data.motion_cache import MotionCache
from kinema.evaluate.anyrig.locomotion import foot_gap_ratio, ground_measures, probe_prompts, rig_ties
from kinema.generate import load_model
from kinema.representation.joint import JointRepresentation
from kinema.rig import Rig

GOALS = {
    "forward_share": (">=", 0.6),
    "net_turn_deg": ("<=", 60.0),
    "idle_drift": ("<=", 0.1),
    "run_walk": (">=", 1.3),
    "gap": ("<=", 1.15),
}


def _ok(key: str, value: float | None) -> bool | None:
    if value is None:
        return None
    op, bound = GOALS[key]
    return value >= bound if op == ">=" else value <= bound


def check_file(model, cache: MotionCache, key: str, *, seconds: float, steps: int, seeds: list[int]) -> dict | None:
    idx = [i for i, r in enumerate(cache.clips) if r["skeleton"] == key and "prop" not in r["flags"]]
    contents = [cache.clips[i]["content"] for i in idx]
    if "walk" not in contents:
        return None
    clips = [cache.motion(i).to(torch.float64) for i in idx]
    rig = Rig.from_skeleton(clips[0].skeleton)
    rep = JointRepresentation(rig, model.fps)
    prompts = probe_prompts(contents, [cache.clips[i]["captions"][0] for i in idx])
    ties = rig_ties(rep, clips)
    rows: dict[str, list] = {k: [] for k in GOALS}
    speeds: dict[str, list] = {}
    for seed in seeds:
        gaps, got = [], {}
        for action, prompt in sorted(prompts.items()):
            m = model.generate(prompt, rig=rig, seconds=seconds, steps=steps, seed=seed)[0].to(torch.float64)
            got[action] = ground_measures(m, rep)
            speeds.setdefault(action, []).append(got[action]["speed"])
            gaps.append(foot_gap_ratio(m, ties))
        rows["forward_share"].append(got["walk"]["forward_share"])
        rows["net_turn_deg"].append(got["walk"]["net_turn_deg"])
        rows["idle_drift"].append(got["idle"]["drift"] if "idle" in got else None)
        run = got.get("run", {}).get("speed")
        rows["run_walk"].append(run / got["walk"]["speed"] if run is not None and got["walk"]["speed"] > 0 else None)
        rows["gap"].append(max((g for g in gaps if g is not None), default=None))
    own = {
        a: statistics.mean(ground_measures(c, rep)["speed"] for c, n in zip(clips, contents, strict=True) if n in names)
        for a, names in (("walk", ("walk",)), ("run", ("gallop", "run")))
        if any(n in names for n in contents)
    }
    out = {
        "file": key,
        "rig": cache.clips[idx[0]]["rig"],
        "split": cache.clips[idx[0]]["split"],
        "prompts": prompts,
        "ties": len(ties.ties),
        "seeds": seeds,
        "speed": {a: statistics.median(v) for a, v in speeds.items()},
        "speed_own": own,
    }
    for k, vals in rows.items():
        real = [v for v in vals if v is not None]
        out[k] = statistics.median(real) if real else None
        worst = None
        if real:
            op = GOALS[k][0]
            worst = min(real) if op == ">=" else max(real)
        out[f"{k}_worst"] = worst
        out[f"{k}_ok"] = _ok(k, worst)
    return out


def _cell_of(r: dict):
    """A table cell of row ``r``: ``median / worst`` of a measure, marked ok or **no** against its goal."""

    def cell(k: str, d: int = 2) -> str:
        v, w = r[k], r[f"{k}_worst"]
        mark = "" if r[f"{k}_ok"] is None else (" ok" if r[f"{k}_ok"] else " **no**")
        return "-" if v is None else f"{v:.{d}f} / {w:.{d}f}{mark}"

    return cell


def table(rows: list[dict]) -> str:
    head = (
        "| file | split | ties | forward share (median / worst) | net turn deg | idle drift | run/walk ground "
        "| foot gap x own | walk / run speed (own) |"
    )
    lines = [head, "|" + "---|" * 9]
    for r in rows:
        f = _cell_of(r)
        sp, own = r["speed"], r["speed_own"]
        spd = f"{sp.get('walk', 0):.2f} / {sp.get('run', float('nan')):.2f} ({own.get('walk', float('nan')):.2f} / "
        spd += f"{own.get('run', float('nan')):.2f})"
        lines.append(
            f"| {Path(r['file']).stem} | {r['split']} | {r['ties']} | {f('forward_share')} | "
            f"{f('net_turn_deg', 0)} | {f('idle_drift')} | {f('run_walk')} | {f('gap')} | {spd} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", default="creatures")
    p.add_argument("--data", type=Path, required=True, help="the quaternius build (with travel recovered)")
    p.add_argument("--splits", nargs="+", default=["val", "test"])
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--only", nargs="*", help="file stems to check (default: every legged file of the splits)")
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    model = load_model(a.model)
    cache = MotionCache(a.data)
    keys = sorted({r["skeleton"] for r in cache.clips if r["split"] in a.splits})
    if a.only:
        keys = [k for k in keys if Path(k).stem in a.only]
    t0, rows = time.time(), []
    for key in keys:
        r = check_file(model, cache, key, seconds=a.seconds, steps=a.steps, seeds=a.seeds)
        if r is not None:
            rows.append(r)
            print(f"{key}: {json.dumps({k: v for k, v in r.items() if k.endswith('_worst')})}", flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(
        json.dumps(
            {
                "model": a.model,
                "args": vars(a) | {"data": str(a.data), "out": str(a.out)},
                "seconds": round(time.time() - t0, 1),
                "rows": rows,
            },
            indent=1,
            default=str,
        )
        + "\n"
    )
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
