"""Timeline cases of the evaluation suite (issue 18): do multi-prompt timelines follow every prompt?

A ``timeline`` case chains 2-4 segments, each the first caption of a different clip of the split, held
for that clip's length clamped to [2.5, 4] s. It is generated as one timeline
(``model.generate([(prompt, seconds), ...])``) and scored on:

- per-segment text following: the segment's frames of the output are embedded with the retrieval model
  and ranked against the captions of every timeline segment of the suite (R@1 / R@3, chance k / N); the
  ground-truth row ranks the segments' own clip crops the same way;
- join smoothness: mean joint speed (m/s) and acceleration (m/s^2) over all joints on the frames near
  each join (``JOIN_BEFORE`` s before the segment boundary, inside the regenerated join window, to
  ``JOIN_AFTER`` s after it) against the frames away from every join, and the peak (largest joint, any
  join frame) against the 99th percentile of the same quantity inside;
- foot skate, contact accuracy and jerk of the whole motion (metrics of kinema.evaluate.metrics); the
  ground truth pools its segment crops.

Frames are at the dataset fps; speeds are finite differences of global joint positions.
"""

from __future__ import annotations

import random
from pathlib import Path

import torch

from kinema.evaluate import distribution as D
from kinema.evaluate import metrics as M
from kinema.evaluate.suite import ground_truth_motion
from kinema.motion.core import Motion
from kinema.pipeline.timeline import Segment
from kinema.pipeline.timeline import segment_bounds as _bounds

SEGMENTS = (2, 4)  # segments per case, inclusive
SEGMENT_SECONDS = (2.5, 4.0)  # each segment: its clip's length clamped to this range
JOIN_BEFORE, JOIN_AFTER = 0.5, 0.25  # seconds around a segment boundary that count as the join
SMOOTHNESS_KEYS = ("join_speed", "inside_speed", "join_acc", "inside_acc", "join_acc_peak", "inside_acc_p99")


def build_timeline_cases(dataset, data_dir, split: str, num_cases: int, seed: int, first_id: int) -> list[dict]:
    """``num_cases`` timeline cases drawn deterministically (for ``seed``) from the clips of ``dataset``.

    Case ids continue from ``first_id`` (after the other cases of the suite)."""
    fps = dataset.fps
    lo = round(SEGMENT_SECONDS[0] * fps)
    rng = random.Random(f"kinema-suite-timeline:{seed}")
    pool = [i for i, r in enumerate(dataset.clips) if r["length"] >= lo and r["captions"]]
    if num_cases > 0 and len(pool) < SEGMENTS[1]:
        raise ValueError(
            f"{data_dir}: split {split!r} has {len(pool)} captioned clips of "
            f"{SEGMENT_SECONDS[0]:g} s or more; timeline cases need {SEGMENTS[1]}"
        )
    cases = []
    for k in range(num_cases):
        segs = []
        for i in rng.sample(pool, rng.randint(*SEGMENTS)):
            rec = dataset.clips[i]
            n = min(rec["length"], round(SEGMENT_SECONDS[1] * fps))
            segs.append(
                {
                    "prompt": rec["captions"][0],
                    "seconds": n / fps,
                    "clip_id": rec["clip_id"],
                    "start": rng.randint(0, rec["length"] - n),
                    "frames": n,
                }
            )
        seconds = sum(s["seconds"] for s in segs)
        cases.append(
            {
                "id": f"{first_id + k:04d}-timeline",
                "kind": "timeline",
                "parts": [],
                "clip_id": segs[0]["clip_id"],
                "caption": segs[0]["prompt"],
                "prompt": " | ".join(s["prompt"] for s in segs),
                "with_text": True,
                "seconds": seconds,
                "num_frames": sum(s["frames"] for s in segs),
                "fps": fps,
                "heading": 0.0,
                "perturbed": False,
                "num_keyframes": None,
                "constraints": [],
                "segments": segs,
                "source": {
                    "data": str(data_dir),
                    "split": split,
                    "segments": [{k2: s[k2] for k2 in ("clip_id", "start", "frames")} for s in segs],
                },
            }
        )
    return cases


def segment_bounds(case: dict) -> list[int]:
    """Output frame boundaries ``[0, b_1, ..., T]`` of a case's segments (the generator's rounding)."""
    return _bounds([Segment(s["prompt"], s["seconds"]) for s in case["segments"]], case["fps"])


def ground_truth_segments(case: dict, dataset) -> list[Motion]:
    """The clip crop of every segment of a case, each starting at the origin facing +Z."""
    by_id = {r["clip_id"]: i for i, r in enumerate(dataset.clips)}
    out = []
    for s in case["segments"]:
        if s["clip_id"] not in by_id:
            raise ValueError(f"case {case['id']}: clip {s['clip_id']!r} is not in {dataset.dir} ({dataset.split})")
        feats = dataset[by_id[s["clip_id"]]]["features"][s["start"] : s["start"] + s["frames"]]
        out.append(ground_truth_motion(feats, dataset))
    return out


def join_smoothness(motion: Motion, bounds: list[int]) -> dict[str, float | None]:
    """Joint speed / acceleration near the joins (inner ``bounds``) vs away from them (see module doc)."""
    P = motion.positions.double()
    fps = motion.fps
    speed = (P[1:] - P[:-1]).norm(dim=-1) * fps  # (T-1, J), between frames t and t+1
    acc = (P[2:] - 2 * P[1:-1] + P[:-2]).norm(dim=-1) * fps * fps  # (T-2, J), at frame t+1
    T = P.shape[0]
    near = torch.zeros(T, dtype=torch.bool)
    for b in bounds[1:-1]:
        near[max(0, b - round(JOIN_BEFORE * fps)) : min(T, b + round(JOIN_AFTER * fps) + 1)] = True
    sj, si = near[1:], ~near[1:]
    aj, ai = near[1:-1], ~near[1:-1]

    def mean(x, m):
        return float(x[m].mean()) if bool(m.any()) else None

    return {
        "join_speed": mean(speed, sj),
        "inside_speed": mean(speed, si),
        "join_acc": mean(acc, aj),
        "inside_acc": mean(acc, ai),
        "join_acc_peak": float(acc[aj].max()) if bool(aj.any()) else None,
        "inside_acc_p99": float(torch.quantile(acc[ai].amax(-1), 0.99)) if bool(ai.any()) else None,
    }


def motion_quality(motions: list[Motion]) -> dict[str, float | None]:
    """Foot skate (pooled over the motions' contact samples), contact accuracy and jerk (means)."""
    pairs = [M.foot_skate_with_count(m) for m in motions]
    n = sum(c for _, c in pairs)
    return {
        "foot_skate_cm_s": None if n == 0 else sum(v * c for v, c in pairs) / n,
        "contact_acc": sum(M.contact_accuracy(m) for m in motions) / len(motions),
        "jerk": sum(M.jerk(m) for m in motions) / len(motions),
    }


def crop_segments(motion: Motion, bounds: list[int]) -> list[Motion]:
    """The frames of each segment of a generated timeline."""
    return [motion.crop(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def run_timeline_case(model, case: dict, modes: list[str], seed: int, steps, guidance, dataset, post) -> tuple:
    """Generate and score one timeline case: (record, {row: Motion}, {row: [segment Motions]}).

    ``post(model, motion, case)`` post-processes a raw motion (the runner's)."""
    segments = [(s["prompt"], s["seconds"]) for s in case["segments"]]
    raw = model.generate(segments, samples=1, steps=steps, guidance=guidance, seed=seed, postprocess=False)[0]
    bounds = segment_bounds(case)
    gt = ground_truth_segments(case, dataset)
    gen = {"raw": raw} if "raw" in modes else {}
    if "post" in modes:
        gen["post"] = post(model, raw, case)
    metrics = {"ground_truth": motion_quality(gt) | dict.fromkeys(SMOOTHNESS_KEYS)}
    for row, m in gen.items():
        metrics[row] = motion_quality([m]) | join_smoothness(m, bounds)
    for row in metrics:  # the constraint columns of the main table: a timeline case has none
        metrics[row].update(
            fullbody_pos_cm=None,
            ee_pos_cm=None,
            ee_rot_deg=None,
            root2d_pos_cm=None,
            pelvis_p95_cm=None,
            jitter=None,
            foot_skate_samples=0,
        )
    keys = ("id", "kind", "parts", "clip_id", "prompt", "with_text", "perturbed", "seconds", "num_keyframes")
    record = {k: case[k] for k in keys} | {"segments": len(segments), "metrics": metrics}
    segs = {"ground_truth": gt} | {row: crop_segments(m, bounds) for row, m in gen.items()}
    return record, {"ground_truth": gt[0]} | gen, segs


def timeline_summary(
    records: list[dict],
    captions: list[str],
    segments: dict[str, list[Motion]],
    retrieval,
    text_cache: Path | None,
    embed,
) -> dict:
    """Per row: cases, segments, R@1/R@3 of each segment against its own caption (``None`` without a
    retrieval model), skate / contact / jerk and the join smoothness means over the cases.

    ``embed(retrieval, motions)`` gives retrieval embeddings (the runner's)."""
    out = {}
    for row, motions in segments.items():
        mets = [r["metrics"][row] for r in records]
        vals = {k: _mean(m.get(k) for m in mets) for k in ("contact_acc", "jerk", *SMOOTHNESS_KEYS)}
        vals["foot_skate_cm_s"] = _mean(m["foot_skate_cm_s"] for m in mets)
        vals.update(cases=len(records), segments=len(motions), r1=None, r3=None)
        if retrieval is not None and len(motions) >= 2:
            with torch.no_grad():
                text = retrieval.encode_captions(captions, cache_dir=text_cache)
                r = D.r_precision(text, embed(retrieval, motions), ks=(1, 3))
            vals.update(r1=r[1], r3=r[3])
        out[row] = vals
    return out


def _mean(values) -> float | None:
    vals = [v for v in values if v is not None]
    return None if not vals else float(sum(vals) / len(vals))
