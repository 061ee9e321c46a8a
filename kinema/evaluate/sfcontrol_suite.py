"""The test suite's end-effector cases, direct against keyjoint-planned (issue 17's "done when").

The cases are the Kimodo-style suite's (kinema.evaluate.suite: ``kinema evaluate`` builds or reads the
same file), restricted to those with end-effector *position* targets (the ``end_effector`` kind and the
``mixed`` cases holding one). Each is generated exactly as the suite runner does (same prompt, length,
constraints, heading and seed ``seed * 100003 + i`` with ``i`` the case's index in the whole suite,
raw), once as today (direct) and once with the keyjoint model planning first
(``keyjoint_model``, kinema.human.keyjoint_planning), and scored with the runner's own metrics.
"""

from __future__ import annotations

import statistics
import time

from kinema.evaluate.runner import score_motion
from kinema.evaluate.suite import EFFECTORS, case_targets

SUITE_ROWS = ("direct", "keyjoint-planned")
METRICS = ("ee_pos_cm", "ee_rot_deg", "root2d_pos_cm", "fullbody_pos_cm", "foot_skate_cm_s", "jerk", "seconds")


def has_ee_positions(case: dict) -> bool:
    """Whether a suite case pins an end-effector position somewhere."""
    return any(
        (c["type"] in EFFECTORS or c["type"] == "end-effector") and "positions" in c for c in case["constraints"]
    )


def ee_cases(cases: list[dict]) -> list[tuple[int, dict]]:
    """``(index in the suite, case)`` of the cases with end-effector position targets."""
    return [(i, c) for i, c in enumerate(cases) if c["kind"] != "timeline" and has_ee_positions(c)]


def evaluate_suite_ee(
    model, cases: list[dict], *, planner=None, steps: int | None = None, seed: int = 0, progress=print
) -> dict:
    """Per row (``direct``, and ``keyjoint-planned`` when ``planner`` is given): per-case metrics
    (``{"id", "kind", **METRICS}``) of the suite's end-effector cases."""
    rows = ["direct"] + (["keyjoint-planned"] if planner is not None else [])
    out: dict = {r: [] for r in rows}
    picked = ee_cases(cases)
    for n, (i, case) in enumerate(picked):
        targets = case_targets(case, model.skeleton)
        for row in rows:
            t0 = time.perf_counter()
            motion = model.generate(
                case["prompt"],
                seconds=case["seconds"],
                constraints=case["constraints"],
                steps=steps,
                seed=seed * 100003 + i,
                postprocess=False,
                heading=case["heading"],
                keyjoint_model=planner if row == "keyjoint-planned" else "none",
            )[0]
            seconds = time.perf_counter() - t0
            metrics, _ = score_motion(motion, targets)
            out[row].append(
                {
                    "id": case["id"],
                    "kind": case["kind"],
                    **{k: metrics.get(k) for k in METRICS[:-1]},
                    "seconds": seconds,
                }
            )
        progress(
            f"case {n + 1}/{len(picked)} {case['id']}: "
            + ", ".join(f"{r} {out[r][-1]['ee_pos_cm']:.2f} cm" for r in rows)
        )
    return out


def summarize_suite(result: dict) -> dict:
    """Mean of each metric over the cases that have it (as the suite report averages), per row."""
    table = {}
    for row, recs in result.items():
        vals = {k: [r[k] for r in recs if r[k] is not None] for k in METRICS}
        table[row] = {k: (statistics.fmean(v) if v else float("nan")) for k, v in vals.items()}
        table[row]["cases"] = len(recs)
    return table
