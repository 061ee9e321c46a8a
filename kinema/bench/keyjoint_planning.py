"""``kinema bench keyjoint-planning``: seconds and raw target error of explicit sparse control, direct
against keyjoint-planned (the keyjoint model plans first; kinema.human.keyjoint_planning), per DDIM step count.

The constraints are a sparse-control set like the SFControl protocol's: one frame every 1.5 s, a hand
or the pelvis on each, on a walk that drifts to the side (a body that does not plan the walk misses
them by metres). Warm timings: models loaded and the prompt encoded before the clock starts.
"""

from __future__ import annotations

import statistics
import time

import torch

from kinema.representation.keyjoint import keyjoint_indices

PROMPT = "A person walks forward."
HEADER = "| DDIM steps | row | s / motion (raw) | s / motion (post-processed) | raw max target error (cm) |\n" + (
    "|---:|---|---:|---:|---:|"
)


def sparse_example(skeleton, seconds: float, fps: float) -> list[dict]:
    """End-effector targets every 1.5 s: right hand, left hand, pelvis in turn, on a walk at 1.1 m/s
    forward that drifts 0.5 m/s to the side, hands at hip height."""
    idx = keyjoint_indices(skeleton)
    slots = (idx[3], idx[2], idx[0])
    out = []
    for k, t in enumerate(t for t in (1.5, 3.0, 4.5, 6.0, 7.5, 9.0) if t < seconds):
        j = slots[k % 3]
        side = 0.0 if j == idx[0] else (-0.2 if j == idx[3] else 0.2)
        p = [0.5 * t + side, 0.9 if j == idx[0] else 0.85, 1.1 * t]
        out.append(
            {"type": "end-effector", "joint": skeleton.names[j], "frame_indices": [round(t * fps)], "positions": [p]}
        )
    return out


def _error(motion, cons) -> float:
    P = motion.positions
    sk = motion.skeleton
    return max(
        float((P[c["frame_indices"][0], sk.index(c["joint"])] - torch.tensor(c["positions"][0])).norm()) for c in cons
    )


def bench_keyjoint_planning(model, planner, seconds: float, steps_list, repeats: int = 2) -> list[dict]:
    """One row per (steps, single-/keyjoint-planned): mean seconds raw and post-processed, mean raw error."""
    cons = sparse_example(model.skeleton, seconds, model.fps)
    model.generate(PROMPT, seconds=1.0, steps=2, keyjoint_model=planner)  # warm-up: text, allocator
    rows = []
    for steps in steps_list:
        for name, kj in (("direct", "none"), ("keyjoint-planned", planner)):
            raw_s, post_s, errs = [], [], []
            for r in range(repeats):
                kw = {"seconds": seconds, "constraints": cons, "steps": steps, "seed": r, "keyjoint_model": kj}
                t0 = time.perf_counter()
                m = model.generate(PROMPT, postprocess=False, **kw)[0]
                raw_s.append(time.perf_counter() - t0)
                errs.append(_error(m, cons))
                t0 = time.perf_counter()
                model.generate(PROMPT, **kw)
                post_s.append(time.perf_counter() - t0)
            rows.append(
                {
                    "steps": steps,
                    "row": name,
                    "raw_s": statistics.fmean(raw_s),
                    "post_s": statistics.fmean(post_s),
                    "error_cm": 100 * statistics.fmean(errs),
                }
            )
            print(format_row(rows[-1]), flush=True)
    return rows


def format_row(r: dict) -> str:
    return f"| {r['steps']} | {r['row']} | {r['raw_s']:.2f} | {r['post_s']:.2f} | {r['error_cm']:.1f} |"
