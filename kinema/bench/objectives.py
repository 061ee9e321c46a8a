"""``kinema bench objectives``: objective error against seconds for noise-optimisation settings.

Noise optimisation (kinema.human.noise_optimisation) costs one forward and one backward pass through a
``ddim_steps`` chain per iteration, so its price is set by (DDIM steps, iterations). For each setting
this generates the same motions (prompt, seconds, seeds) with one objective and reports the objective's
value before optimisation, after it (``optimised``), after snapping (raw output) and after
post-processing, with the wall time of the whole ``generate`` call. Values: metres; times: seconds.
"""

from __future__ import annotations

import statistics
import time

from kinema.errors import KinemaError

#: (DDIM steps, iterations) measured by default: from a preview-like 3 x 4 up to 10 x 12
SETTINGS = ((3, 0), (3, 4), (3, 8), (5, 8), (5, 12), (10, 8))
TASKS = {
    "reach": (
        "A person walks forward.",
        {"type": "reach", "joint": "Hand_R", "target": [0.8, 1.3, 2.5], "window": [2.0, 4.0]},
    ),
    "path": (
        "A person walks forward.",
        {
            "type": "path-time-agnostic",
            "joint": "Hips",
            "path": [[0.0, 0.5], [0.2, 2.0], [1.2, 3.0], [2.4, 3.3]],
            "window": [0.5, 4.5],
        },
    ),
    "hand-to-head": (
        "A person stands still.",
        {"type": "hand-to-head", "hand": "right", "distance": 0.1, "window": [1.0, 4.0]},
    ),
}


def parse_settings(texts) -> list[tuple[int, int]]:
    if not texts:
        return list(SETTINGS)
    out = []
    for t in texts:
        try:
            s, i = (int(v) for v in t.lower().split("x"))
        except ValueError:
            raise KinemaError(f"--settings {t!r}: expected STEPSxITERS such as 5x12") from None
        if s < 1 or i < 0:
            raise KinemaError(f"--settings {t!r}: steps must be >= 1 and iterations >= 0")
        out.append((s, i))
    return out


def bench_objectives(model, task: str, seconds: float, seeds: int, settings) -> list[dict]:
    """One row per (steps, iterations): median seconds and mean objective values over the seeds."""
    prompt, obj = TASKS[task]
    rows = []
    for steps, iters in settings:
        runs = []
        for seed in range(seeds):
            t0 = time.perf_counter()
            res = model.generate(
                prompt, seconds=seconds, steps=steps, seed=seed, objectives=[obj], objective_steps=iters
            )
            o = res.report.objectives["objectives"][0]
            runs.append(
                {"seconds": time.perf_counter() - t0, **{k: o[k][0] for k in ("before", "optimised", "after", "final")}}
            )
        rows.append(
            {
                "steps": steps,
                "iterations": iters,
                "seconds": statistics.median(r["seconds"] for r in runs),
                **{k: statistics.fmean(r[k] for r in runs) for k in ("before", "optimised", "after", "final")},
            }
        )
        print(format_row(rows[-1]), flush=True)
    return rows


def format_row(r: dict) -> str:
    return (
        f"  {r['steps']:>5}  {r['iterations']:>10}  {r['seconds']:>7.1f}  {100 * r['before']:>9.1f}  "
        f"{100 * r['optimised']:>9.1f}  {100 * r['after']:>9.1f}  {100 * r['final']:>9.1f}"
    )


HEADER = "  steps  iterations  seconds     before  optimised        raw      final"
