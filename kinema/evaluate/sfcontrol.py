"""SFControl's sparse control protocol on a dataset build (paper Sec. 4.1, Table 1 setting).

Cases: 5-s crops of test clips (first caption as the prompt), moved so the first smoothed root is over
the origin facing +Z. Targets: one frame every 1.5 s (frames 0, 30, 60, 90 at 20 fps) and, on each,
a random half (3) of the six keyjoints (pelvis, head, hands, ankles) at their ground-truth world
positions. Rows (all *raw*, no post-processing):

- ``direct``: today's sampler, each target an ``end-effector`` constraint (imputation plus the
  sampler's root/joint corrections);
- ``keyjoint-planned``: the same constraints with ``keyjoint_model``: the keyjoint model plans the six
  keyjoints, the body model follows them (kinema.human.keyjoint_planning);
- ``direct + noise opt``: direct with each target also a ``reach`` objective on its frame
  (noise optimisation, then snapping: kinema.objectives).

Metrics: control error (mean distance of the FK joint to its target, cm), foot skate (cm/s, on the
model's own contact labels), jerk, seconds per motion, and R@3 over the whole case set when the
retrieval model is available (not the paper's batch-of-32 R@3: too few cases).
"""

from __future__ import annotations

import random
import statistics
import time

import torch

from kinema.data.dataset import MotionDataset
from kinema.evaluate.metrics import foot_skate, jerk
from kinema.evaluate.runner import text_metrics
from kinema.evaluate.suite import ground_truth_motion
from kinema.motion.core import Motion
from kinema.representation.keyjoint import KEYJOINT_DIM, NUM_KEYJOINTS, keyjoint_indices, subsample_every

SECONDS, EVERY, FRACTION = 5.0, 1.5, 0.5


def sparse_cases(data_dir, num_cases: int, seed: int = 0, split: str = "test") -> list[dict]:
    """Deterministic cases: ``{"clip", "prompt", "gt": Motion, "targets": [(frame, joint, [x, y, z])]}``."""
    ds = MotionDataset(data_dir, split)
    T = round(SECONDS * ds.fps)
    rng = random.Random(seed)
    pool = [i for i, r in enumerate(ds.clips) if r["length"] >= T and not r["mirrored"]]
    picks = sorted(rng.sample(pool, min(num_cases, len(pool))))
    idx = keyjoint_indices(ds.skeleton)
    cases = []
    for i in picks:
        item = ds[i]
        start = rng.randrange(item["features"].shape[0] - T + 1)
        gt = ground_truth_motion(item["features"][start : start + T], ds)
        P = gt.positions
        targets = []
        for f in subsample_every(T, ds.fps, EVERY):
            for k in sorted(rng.sample(range(NUM_KEYJOINTS), round(FRACTION * NUM_KEYJOINTS))):
                targets.append((f, idx[k], [float(v) for v in P[f, idx[k]]]))
        cases.append({"clip": item["clip"]["clip_id"], "prompt": item["captions"][0], "gt": gt, "targets": targets})
    return cases


def control_error(motion: Motion, targets) -> float:
    """Mean distance (metres) of each targeted joint to its target on its frame."""
    P = motion.positions
    return statistics.fmean(float((P[f, j] - torch.tensor(p, dtype=P.dtype)).norm()) for f, j, p in targets)


def as_constraints(targets, skeleton) -> list[dict]:
    return [
        {"type": "end-effector", "joint": skeleton.names[j], "frame_indices": [f], "positions": [p]}
        for f, j, p in targets
    ]


def as_objectives(targets, skeleton, fps: float) -> list[dict]:
    return [
        {"type": "reach", "joint": skeleton.names[j], "target": p, "window": [f / fps, f / fps]} for f, j, p in targets
    ]


def keyjoint_targets(targets, skeleton, T: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Sparse keyjoint targets / mask ``(1, T, 20)`` of the case's targets."""
    idx = keyjoint_indices(skeleton)
    k = torch.zeros(1, T, KEYJOINT_DIM)
    m = torch.zeros_like(k)
    for f, j, p in targets:
        c = idx.index(j)
        k[0, f, 3 * c : 3 * c + 3] = torch.tensor(p)
        m[0, f, 3 * c : 3 * c + 3] = 1.0
    return k, m


def score(motion: Motion, case: dict, seconds: float) -> dict:
    return {
        "control_cm": 100 * control_error(motion, case["targets"]),
        "skate": foot_skate(motion),
        "jerk": jerk(motion),
        "seconds": seconds,
    }


def evaluate_sparse(
    model,
    cases: list[dict],
    *,
    rows,
    keyjoint=None,
    steps: int | None = None,
    objective_steps: int = 8,
    seed: int = 0,
    progress=print,
) -> dict:
    """Per row: mean metrics over the cases and the generated motions (for R@3)."""
    out = {r: {"scores": [], "motions": []} for r in rows}
    for n, case in enumerate(cases):
        sk = model.skeleton
        for row in rows:
            t0 = time.perf_counter()
            objs = as_objectives(case["targets"], sk, model.fps) if row.endswith("noise opt") else None
            m = model.generate(
                case["prompt"],
                seconds=SECONDS,
                constraints=as_constraints(case["targets"], sk),
                steps=steps,
                seed=seed,
                postprocess=False,
                objectives=objs,
                objective_steps=objective_steps if objs else None,
                keyjoint_model=keyjoint if row == "keyjoint-planned" else "none",
            )[0]
            out[row]["scores"].append(score(m, case, time.perf_counter() - t0))
            out[row]["motions"].append(m)
        progress(
            f"case {n + 1}/{len(cases)}: " + ", ".join(f"{r} {out[r]['scores'][-1]['control_cm']:.1f} cm" for r in rows)
        )
    return out


def summarize(result: dict) -> dict:
    return {
        row: {k: statistics.fmean(s[k] for s in r["scores"]) for k in r["scores"][0]}
        for row, r in result.items()
        if r["scores"]
    }


def text_scores(retrieval, cases: list[dict], result: dict, *, seed: int = 0, warn: list[str]) -> dict:
    """Per row of ``result`` (evaluate_sparse): R@3 of its motions against the cases' captions (over the
    whole set, and in batches of 32 when there are 32 cases or more) and FID against the ground-truth
    crops, all in the retrieval model's embedding space (kinema.evaluate.runner.text_metrics; None where
    undefined, with the reason in ``warn``)."""
    motions = {"ground_truth": [c["gt"] for c in cases]} | {row: r["motions"] for row, r in result.items()}
    m = text_metrics(retrieval, [c["prompt"] for c in cases], motions, {}, seed, warn)
    return {row: {k: m[row][k] for k in ("r3_whole", "r3_batch32", "fid")} for row in m}
