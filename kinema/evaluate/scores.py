"""Scoring of one evaluated motion and the report's summary tables (kinema.evaluate.runner uses them).

``score_motion`` measures a motion against its case's targets (kinema.evaluate.metrics); ``summarize``,
``by_kind`` and ``by_keyframes`` turn the per-case records into the report's table and breakdowns;
``finite`` makes the report strict JSON. Units: cm, degrees, cm/s as in docs/evaluation.md.
"""

from __future__ import annotations

import math

import torch

from kinema.evaluate import metrics as M
from kinema.evaluate.suite import CASE_KINDS
from kinema.motion.core import Motion

#: summary columns, in the order of the report table (docs/evaluation.md documents each)
COLUMNS = (
    "r1_whole",
    "r3_whole",
    "r3_batch32",
    "fid",
    "diversity",
    "multimodality",
    "coverage_auc",
    "novelty_auc",
    "foot_skate_cm_s",
    "contact_acc",
    "fullbody_pos_cm",
    "ee_pos_cm",
    "ee_rot_deg",
    "root2d_pos_cm",
    "pelvis_p95_cm",
    "jerk",
)
CASE_METRICS = (
    "foot_skate_cm_s",
    "contact_acc",
    "jerk",
    "jitter",
    "fullbody_pos_cm",
    "ee_pos_cm",
    "ee_rot_deg",
    "root2d_pos_cm",
    "pelvis_p95_cm",
)


def _weighted(pairs: list[tuple[float, int]]) -> float | None:
    n = sum(w for _, w in pairs)
    return None if n == 0 else sum(v * w for v, w in pairs) / n


def score_motion(motion: Motion, targets: dict) -> tuple[dict, list[float]]:
    """(metrics of one motion against a case's targets, its pelvis deviations in cm).

    Constraint errors are averaged over every constrained (frame, joint) of the case; a type the case
    does not constrain is None."""
    skate, count = M.foot_skate_with_count(motion)
    out = {
        "foot_skate_cm_s": skate,
        "foot_skate_samples": count,
        "contact_acc": M.contact_accuracy(motion),
        "jerk": M.jerk(motion),
        "jitter": M.jitter(motion),
    }
    fb = [(M.fullbody_position_error(motion, f, p), len(f)) for f, p in targets["fullbody"]]
    eep = [
        (M.end_effector_position_error(motion, j, f, p), len(f))
        for j, f, p, _ in targets["end_effector"]
        if p is not None
    ]
    eer = [
        (M.end_effector_rotation_error(motion, j, f, q), len(f))
        for j, f, _, q in targets["end_effector"]
        if q is not None
    ]
    r2 = [(M.root2d_error(motion, f, xz), len(f)) for f, xz in targets["root2d"]]
    dev = [float(d) for f, xz in targets["root2d"] for d in M.pelvis_deviations(motion, f, xz)]
    out.update(
        fullbody_pos_cm=_weighted(fb),
        ee_pos_cm=_weighted(eep),
        ee_rot_deg=_weighted(eer),
        root2d_pos_cm=_weighted(r2),
        pelvis_p95_cm=_p95(dev),
    )
    return out, dev


def _p95(values: list[float]) -> float | None:
    return None if not values else float(torch.quantile(torch.tensor(values, dtype=torch.float64), 0.95))


def _mean(values) -> float | None:
    vals = [v for v in values if v is not None]
    return None if not vals else float(sum(vals) / len(vals))


def summarize(records: list[dict], rows: list[str], devs: dict) -> dict:
    """Table values per row: quality over text cases (pooled skate), constraint errors over cases."""
    out = {}
    text = [r for r in records if r["kind"] == "text"]
    for row in rows:
        mets = [r["metrics"][row] for r in text]
        out[row] = {
            "foot_skate_cm_s": _weighted([(m["foot_skate_cm_s"], m["foot_skate_samples"]) for m in mets]),
            "contact_acc": _mean(m["contact_acc"] for m in mets),
            "jerk": _mean(m["jerk"] for m in mets),
            **{
                k: _mean(r["metrics"][row][k] for r in records)
                for k in ("fullbody_pos_cm", "ee_pos_cm", "ee_rot_deg", "root2d_pos_cm")
            },
            "pelvis_p95_cm": _p95(devs[row]),
        }
    return out


def by_kind(records: list[dict], rows: list[str]) -> dict:
    out = {}
    for row in rows:
        out[row] = {}
        for kind in CASE_KINDS:
            sel = [r["metrics"][row] for r in records if r["kind"] == kind]
            if sel:
                out[row][kind] = {"cases": len(sel)} | {k: _mean(m[k] for m in sel) for k in CASE_METRICS}
    return out


def by_keyframes(records: list[dict], rows: list[str]) -> dict:
    """kind -> row -> list of {num_keyframes, cases, error} (fullbody cm, end-effector cm, root 2D cm)."""
    metric = {
        "fullbody_sparse": "fullbody_pos_cm",
        "inbetween": "fullbody_pos_cm",
        "end_effector": "ee_pos_cm",
        "waypoints": "root2d_pos_cm",
    }
    out: dict = {}
    for kind, key in metric.items():
        sel = [r for r in records if r["kind"] == kind and r["num_keyframes"]]
        if not sel:
            continue
        out[kind] = {"metric": key}
        for row in rows:
            ks = sorted({r["num_keyframes"] for r in sel})
            out[kind][row] = [
                {
                    "num_keyframes": k,
                    "cases": sum(r["num_keyframes"] == k for r in sel),
                    "error": _mean(r["metrics"][row][key] for r in sel if r["num_keyframes"] == k),
                }
                for k in ks
            ]
    return out


def finite(x):
    """NaN/inf -> None so that report.json is strict JSON."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite(v) for v in x]
    return x
