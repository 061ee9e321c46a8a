"""Run a model over an evaluation suite and score it (Kimodo paper Sec. 6.1, Tables 1-2).

``run_suite(model, cases)`` generates every case once per post-processing mode (``raw`` model output
and ``post``-processed), scores each motion with kinema.evaluate.metrics, scores the ground-truth
motions the same way, and computes the text metrics (R-precision, FID, diversity, multimodality) in
the embedding space of the retrieval model. The post-processed motion of a case is the raw one run
through the same post-processing ``generate(postprocess=True)`` applies, so both modes share the
sample. The returned :class:`EvalResults` carries the JSON-ready ``data`` (docs/evaluation.md) and
the motions (for plots); kinema.evaluate.report writes them out.
"""

from __future__ import annotations

import math
import platform
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.evaluate import metrics as M
from kinema.evaluate.phrasings import run_phrasings
from kinema.evaluate.suite import CASE_KINDS, case_ground_truth, case_targets
from kinema.evaluate.timeline import run_timeline_case, timeline_summary
from kinema.motion.core import Motion
from kinema.representation.kimodo import motion_to_features

MODE_NAMES = {False: "raw", True: "post"}
ROWS = ("ground_truth", "raw", "post")
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
R_BATCH = 32


@dataclass
class EvalResults:
    """``data``: the JSON-ready results (report.json without the plot list); ``motions``: case id ->
    {"ground_truth" | "raw" | "post": Motion}."""

    data: dict
    motions: dict[str, dict[str, Motion]] = field(default_factory=dict)
    cases: list[dict] = field(default_factory=list)


# ----------------------------------------------------------------------------- per motion
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


# ----------------------------------------------------------------------------- retrieval
def _load_retrieval(retrieval, warn: list[str]):
    """The retrieval model, or None (with a warning recorded) when it is missing or disabled."""
    if retrieval is None or retrieval == "none":
        warn.append("text metrics skipped: no retrieval model requested")
        return None
    if not isinstance(retrieval, (str, Path)):
        return retrieval
    from kinema.evaluate.retrieval import default_retrieval_path, load_retrieval

    path = default_retrieval_path() if retrieval == "default" else Path(retrieval)
    try:
        return load_retrieval(path)
    except KinemaError as err:
        warn.append(f"text metrics skipped (R-precision, FID, diversity, multimodality): {err}")
        return None


def _retrieval_name(retrieval) -> str:
    if retrieval == "default":
        from kinema.evaluate.retrieval import default_retrieval_path

        return str(default_retrieval_path())
    return str(retrieval) if isinstance(retrieval, (str, Path)) else type(retrieval).__name__


def _embed(model, motions: list[Motion]) -> torch.Tensor:
    clips = []
    for m in motions:
        if abs(m.fps - model.fps) > 1e-6:
            m = m.resample(model.fps)
        clips.append(motion_to_features(m.to(torch.float32)))
    return model.encode_clips(clips)


def train_embeddings(retrieval, data_dir, limit: int = 2000) -> torch.Tensor | None:
    """Retrieval embeddings of (up to ``limit``, evenly spread) train-split clips, for novelty."""
    from kinema.data.dataset import MotionDataset

    ds = MotionDataset(data_dir, "train")
    if len(ds) == 0:
        return None
    idx = torch.linspace(0, len(ds) - 1, min(limit, len(ds))).round().long().unique().tolist()
    with torch.no_grad():
        return retrieval.encode_clips([ds[i]["features"] for i in idx])


def text_metrics(
    retrieval,
    captions: list[str],
    motions: dict[str, list[Motion]],
    mm: dict[str, list[list[Motion]]],
    seed: int,
    warn: list[str],
    text_cache=None,
    train_emb: torch.Tensor | None = None,
) -> dict:
    """Per row: R@1/R@3 over the whole text set, R@3 in batches of 32, FID against the GT embeddings,
    diversity, multimodality, and coverage/novelty AUC (Dragon App. C: coverage of the GT test motions,
    novelty against the train clips; needs ``train_emb``) — None where undefined."""
    from kinema.evaluate import distribution as D

    N = len(captions)
    out = {
        row: dict.fromkeys(
            ("r1_whole", "r3_whole", "r3_batch32", "fid", "diversity", "multimodality", "coverage_auc", "novelty_auc")
        )
        for row in motions
    }
    if N == 0:
        return out
    with torch.no_grad():
        text = retrieval.encode_captions(captions, cache_dir=text_cache)
        emb = {row: _embed(retrieval, ms) for row, ms in motions.items()}
    if N < R_BATCH:
        warn.append(f"R@3 (batch {R_BATCH}) skipped: only {N} text cases")
    if N < 2:
        warn.append("FID and diversity skipped: they need at least 2 text cases")
    for row, e in emb.items():
        r = D.r_precision(text, e, ks=(1, 3))
        out[row].update(r1_whole=r[1], r3_whole=r[3])
        if N >= R_BATCH:
            g = torch.Generator().manual_seed(seed)
            out[row]["r3_batch32"] = D.r_precision(text, e, ks=(3,), batch_size=R_BATCH, generator=g)[3]
        if N >= 2:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                out[row]["fid"] = D.fid(emb["ground_truth"], e)
            warn += [f"FID ({row}): {w.message}" for w in caught]
            out[row]["diversity"] = D.diversity(e, pairs=min(300, N), generator=torch.Generator().manual_seed(seed))
        if train_emb is not None:
            cn = D.coverage_novelty_auc(e, train_emb, emb["ground_truth"])
            out[row].update(coverage_auc=float(cn.coverage_auc), novelty_auc=float(cn.novelty_auc))
        groups = mm.get(row) or []
        if groups:
            with torch.no_grad():
                g_emb = [_embed(retrieval, grp) for grp in groups]
            out[row]["multimodality"] = D.multimodality(g_emb, generator=torch.Generator().manual_seed(seed))
    return out


# ----------------------------------------------------------------------------- the run
def _post(model, motion: Motion, case: dict) -> Motion:
    from kinema.constraints import load_constraints
    from kinema.generate.targets import run_postprocess

    cons = (
        load_constraints(case["constraints"], model.skeleton, model.fps, motion.num_frames)
        if case["constraints"]
        else []
    )
    return run_postprocess(motion, cons, model.representation)[0]


def _guidance_meta(model, guidance):
    """The guidance a run used, for the report: explicit weights, a Guidance, or the model's default."""
    if isinstance(guidance, (tuple, list)):
        return [float(w) for w in guidance]
    if guidance is None:
        guidance = getattr(getattr(model, "loaded", None), "guidance", None)
    return None if guidance is None else guidance.to_dict()


def _bar(total: int, progress: bool, desc: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, disable=not progress, unit="gen")


def run_suite(
    model,
    cases: list[dict],
    postprocess_modes=(False, True),
    steps: int | None = None,
    seed: int = 0,
    progress: bool = True,
    retrieval="default",
    mm_prompts: int = 3,
    mm_samples: int = 4,
    guidance=None,
    text_cache=None,
    datasets: dict | None = None,
    phrasings: int = 0,
) -> EvalResults:
    """Generate and score every case; returns :class:`EvalResults` (see docs/evaluation.md).

    ``retrieval``: "default" (the shipped weights), a folder, a loaded ``RetrievalModel`` or None; when
    it cannot be loaded the text metrics are None and the reason is in ``data["warnings"]``.
    ``mm_prompts`` x ``mm_samples`` extra text-only samples measure multimodality; ``phrasings`` > 0 adds
    the probes (that many samples each) and held-out text cases of kinema.evaluate.phrasings. Case ``i`` is
    generated with seed ``seed * 100003 + i`` (its held-out phrasing too), multimodality prompt ``k`` with
    ``seed * 100003 + 50021 + k``, probe ``k`` with ``seed * 100003 + 70001 + k``."""
    modes = [MODE_NAMES[bool(p)] for p in postprocess_modes]
    if not modes or len(set(modes)) != len(modes):
        raise KinemaError(f"postprocess_modes must list False and/or True once each, got {postprocess_modes}")
    if not cases:
        raise KinemaError("the suite has no cases")
    t_start = time.perf_counter()
    warn: list[str] = []
    datasets = {} if datasets is None else datasets
    rows = ["ground_truth", *modes]
    records, motions, devs = [], {}, {r: [] for r in rows}
    gen_seconds = post_seconds = 0.0
    text_ids: list[int] = []
    timelines: list[dict] = []
    tl_segments: dict[str, list[Motion]] = {r: [] for r in rows}
    ret = _load_retrieval(retrieval, warn)
    n_mm = min(mm_prompts, sum(c["kind"] == "text" for c in cases)) if ret is not None and mm_samples > 1 else 0
    bar = _bar(len(cases) + n_mm, progress, "evaluate")
    for i, case in enumerate(cases):
        if case["kind"] not in CASE_KINDS:
            raise KinemaError(f"case {case.get('id')}: unknown kind {case['kind']!r}")
        if abs(float(case["fps"]) - model.fps) > 1e-6:
            raise KinemaError(f"case {case['id']} is at {case['fps']:g} fps but the model runs at {model.fps:g} fps")
        src = case["source"]
        key = (src["data"], src["split"])
        if key not in datasets:
            from kinema.data.dataset import MotionDataset

            datasets[key] = MotionDataset(src["data"], src["split"])
        if case["kind"] == "timeline":
            t0 = time.perf_counter()
            rec, motions[case["id"]], segs = run_timeline_case(
                model, case, modes, seed * 100003 + i, steps, guidance, datasets[key], _post
            )
            gen_seconds += time.perf_counter() - t0
            records.append(rec)
            timelines.append(case)
            for row, ms in segs.items():
                tl_segments[row] += ms
            bar.update(1)
            continue
        gt = case_ground_truth(case, datasets[key])
        targets = case_targets(case, model.skeleton)
        t0 = time.perf_counter()
        raw = model.generate(
            case["prompt"],
            seconds=case["seconds"],
            constraints=case["constraints"] or None,
            samples=1,
            steps=steps,
            guidance=guidance,
            seed=seed * 100003 + i,
            postprocess=False,
            heading=case["heading"],
        )[0]
        out = {"ground_truth": gt}
        if "raw" in modes:
            out["raw"] = raw
        if "post" in modes:
            t1 = time.perf_counter()
            out["post"] = _post(model, raw, case)
            post_seconds += time.perf_counter() - t1
        gen_seconds += time.perf_counter() - t0
        scored = {}
        for row, m in out.items():
            scored[row], d = score_motion(m, targets)
            devs[row] += d
        motions[case["id"]] = out
        if case["kind"] == "text":
            text_ids.append(i)
        records.append(
            {
                k: case[k]
                for k in (
                    "id",
                    "kind",
                    "parts",
                    "clip_id",
                    "prompt",
                    "with_text",
                    "perturbed",
                    "seconds",
                    "num_keyframes",
                )
            }
            | {"metrics": scored}
        )
        bar.update(1)
    mm: dict[str, list[list[Motion]]] = {r: [] for r in modes}
    if n_mm:
        for k, i in enumerate(text_ids[:n_mm]):
            case = cases[i]
            t0 = time.perf_counter()
            group = model.generate(
                case["prompt"],
                seconds=case["seconds"],
                samples=mm_samples,
                steps=steps,
                guidance=guidance,
                seed=seed * 100003 + 50021 + k,
                postprocess=False,
            )
            if "raw" in modes:
                mm["raw"].append(group)
            if "post" in modes:
                t1 = time.perf_counter()
                mm["post"].append([_post(model, m, case) for m in group])
                post_seconds += time.perf_counter() - t1
            gen_seconds += time.perf_counter() - t0
            bar.update(1)
    bar.close()
    summary = _summarize(records, rows, devs)
    text_info = {
        "cases": len(text_ids),
        "r_batch_size": R_BATCH,
        "mm_prompts": len(mm.get(modes[0], [])),
        "mm_samples": mm_samples,
        "retrieval": None,
    }
    if ret is not None:
        text_info["retrieval"] = _retrieval_name(retrieval)
        caps = [cases[i]["prompt"] for i in text_ids]
        train_emb = None
        try:
            src = cases[text_ids[0]]["source"]["data"] if text_ids else None
            train_emb = train_embeddings(ret, src) if src else None
        except (KinemaError, OSError, KeyError) as err:
            warn.append(f"coverage/novelty skipped: no train split to compare with ({err})")
        tm = text_metrics(
            ret,
            caps,
            {r: [motions[cases[i]["id"]][r] for i in text_ids] for r in rows},
            mm,
            seed,
            warn,
            text_cache,
            train_emb,
        )
        for r in rows:
            summary[r].update(tm[r])
    if timelines:
        captions = [s["prompt"] for c in timelines for s in c["segments"]]
        tl_records = [r for r in records if r["kind"] == "timeline"]
        tl_table = timeline_summary(tl_records, captions, tl_segments, ret, text_cache, _embed)
    t_phr = time.perf_counter()
    phr = (
        None
        if not phrasings
        else run_phrasings(
            model,
            cases,
            motions,
            datasets,
            ret,
            samples=phrasings,
            seed=seed,
            steps=steps,
            guidance=guidance,
            text_cache=text_cache,
            embed=_embed,
            warn=warn,
            progress=progress,
        )
    )
    wall, t_phr = time.perf_counter() - t_start, time.perf_counter() - t_phr
    data = {
        "format": "kinema-eval-report",
        "version": 1,
        "meta": {
            "model": str(getattr(getattr(model, "loaded", None), "path", model)),
            "fps": model.fps,
            "num_cases": len(cases),
            "kinds": {k: sum(c["kind"] == k for c in cases) for k in CASE_KINDS},
            "modes": modes,
            "steps": steps,
            "seed": seed,
            "data": sorted({c["source"]["data"] for c in cases}),
            "split": sorted({c["source"]["split"] for c in cases}),
            "torch_threads": torch.get_num_threads(),
            "machine": platform.platform(),
            "guidance": _guidance_meta(model, guidance),
            "root_displacement": bool(getattr(model, "root_displacement", False)),
            "root_smoothing": float(getattr(model, "root_smoothing", 0.0)),
            "joint_sigma": float(getattr(model, "joint_sigma", 0.0)),
            "grounding": None if getattr(model, "grounding", None) is None else model.grounding.to_dict(),
        },
        "timing": {
            "wall_seconds": wall,
            "generate_seconds": gen_seconds,
            "postprocess_seconds": post_seconds,
            "seconds_per_case": gen_seconds / max(1, len(cases) + len(mm.get(modes[0], [])) * mm_samples),
            "phrasings_seconds": t_phr if phrasings else None,
        },
        "table": {r: {c: summary[r].get(c) for c in COLUMNS} for r in rows},
        "text": text_info,
        "by_kind": _by_kind(records, rows),
        "by_keyframes": _by_keyframes(records, rows),
        "timeline": tl_table if timelines else None,
        "phrasings": phr,
        "cases": records,
        "warnings": warn,
    }
    return EvalResults(_finite(data), motions, list(cases))


def _summarize(records: list[dict], rows: list[str], devs: dict) -> dict:
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


def _by_kind(records: list[dict], rows: list[str]) -> dict:
    out = {}
    for row in rows:
        out[row] = {}
        for kind in CASE_KINDS:
            sel = [r["metrics"][row] for r in records if r["kind"] == kind]
            if sel:
                out[row][kind] = {"cases": len(sel)} | {k: _mean(m[k] for m in sel) for k in CASE_METRICS}
    return out


def _by_keyframes(records: list[dict], rows: list[str]) -> dict:
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


def _finite(x):
    """NaN/inf -> None so that report.json is strict JSON."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x
