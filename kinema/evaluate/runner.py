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

import platform
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.evaluate.phrasings import run_phrasings
from kinema.evaluate.scores import COLUMNS, by_keyframes, by_kind, finite, score_motion, summarize
from kinema.evaluate.suite import CASE_KINDS, case_ground_truth, case_targets
from kinema.evaluate.timeline import run_timeline_case, timeline_summary
from kinema.motion.core import Motion
from kinema.representation.kimodo_features import motion_to_features

MODE_NAMES = {False: "raw", True: "post"}
ROWS = ("ground_truth", "raw", "post")
R_BATCH = 32


@dataclass
class EvalResults:
    """``data``: the JSON-ready results (report.json without the plot list); ``motions``: case id ->
    {"ground_truth" | "raw" | "post": Motion}."""

    data: dict
    motions: dict[str, dict[str, Motion]] = field(default_factory=dict)
    cases: list[dict] = field(default_factory=list)


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
    from kinema.human.targets import run_postprocess

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


#: fields of a case copied into its report record
RECORD_KEYS = ("id", "kind", "parts", "clip_id", "prompt", "with_text", "perturbed", "seconds", "num_keyframes")


@dataclass
class _SuiteRun:
    """What the case loop of `run_suite` gathers: report records, motions per case and row, per-row
    constraint deviations, the text cases, the timeline cases and their segments, and timings."""

    modes: list[str]
    rows: list[str]
    records: list[dict] = field(default_factory=list)
    motions: dict = field(default_factory=dict)
    devs: dict = field(default_factory=dict)
    text_ids: list[int] = field(default_factory=list)
    timelines: list[dict] = field(default_factory=list)
    tl_segments: dict = field(default_factory=dict)
    gen_seconds: float = 0.0
    post_seconds: float = 0.0

    def __post_init__(self) -> None:
        self.devs = {r: [] for r in self.rows}
        self.tl_segments = {r: [] for r in self.rows}


def _dataset(case: dict, model, datasets: dict):
    """The case's checked source dataset (loaded once per (data, split) into ``datasets``)."""
    if case["kind"] not in CASE_KINDS:
        raise KinemaError(f"case {case.get('id')}: unknown kind {case['kind']!r}")
    if abs(float(case["fps"]) - model.fps) > 1e-6:
        raise KinemaError(f"case {case['id']} is at {case['fps']:g} fps but the model runs at {model.fps:g} fps")
    key = (case["source"]["data"], case["source"]["split"])
    if key not in datasets:
        from kinema.data.dataset import MotionDataset

        datasets[key] = MotionDataset(*key)
    return datasets[key]


def _run_case(model, i: int, case: dict, data, run: _SuiteRun, seed: int, steps, guidance) -> None:
    """Generate case ``i`` once (raw), post-process it for the ``post`` mode, score every row."""
    t0 = time.perf_counter()
    if case["kind"] == "timeline":
        rec, run.motions[case["id"]], segs = run_timeline_case(
            model, case, run.modes, seed * 100003 + i, steps, guidance, data, _post
        )
        run.gen_seconds += time.perf_counter() - t0
        run.records.append(rec)
        run.timelines.append(case)
        for row, ms in segs.items():
            run.tl_segments[row] += ms
        return
    gt, targets = case_ground_truth(case, data), case_targets(case, model.skeleton)
    raw = model.generate(
        case["prompt"], seconds=case["seconds"], constraints=case["constraints"] or None, samples=1, steps=steps,
        guidance=guidance, seed=seed * 100003 + i, postprocess=False, heading=case["heading"],
    )[0]  # fmt: skip
    out = {"ground_truth": gt} | ({"raw": raw} if "raw" in run.modes else {})
    if "post" in run.modes:
        t1 = time.perf_counter()
        out["post"] = _post(model, raw, case)
        run.post_seconds += time.perf_counter() - t1
    run.gen_seconds += time.perf_counter() - t0
    scored = {}
    for row, m in out.items():
        scored[row], d = score_motion(m, targets)
        run.devs[row] += d
    run.motions[case["id"]] = out
    if case["kind"] == "text":
        run.text_ids.append(i)
    run.records.append({k: case[k] for k in RECORD_KEYS} | {"metrics": scored})


def _multimodality(model, cases, run: _SuiteRun, n_mm: int, mm_samples: int, seed: int, steps, guidance, bar) -> dict:
    """``mm_samples`` extra text-only samples of the first ``n_mm`` text cases, per mode."""
    mm: dict[str, list[list[Motion]]] = {r: [] for r in run.modes}
    for k, i in enumerate(run.text_ids[:n_mm]):
        case = cases[i]
        t0 = time.perf_counter()
        group = model.generate(
            case["prompt"], seconds=case["seconds"], samples=mm_samples, steps=steps, guidance=guidance,
            seed=seed * 100003 + 50021 + k, postprocess=False,
        )  # fmt: skip
        if "raw" in run.modes:
            mm["raw"].append(group)
        if "post" in run.modes:
            t1 = time.perf_counter()
            mm["post"].append([_post(model, m, case) for m in group])
            run.post_seconds += time.perf_counter() - t1
        run.gen_seconds += time.perf_counter() - t0
        bar.update(1)
    return mm


def _add_text_metrics(summary, ret, cases, run: _SuiteRun, mm, seed: int, warn, text_cache) -> None:
    """R-precision, FID, diversity, multimodality, coverage/novelty of the text cases into ``summary``."""
    caps = [cases[i]["prompt"] for i in run.text_ids]
    train_emb = None
    try:
        src = cases[run.text_ids[0]]["source"]["data"] if run.text_ids else None
        train_emb = train_embeddings(ret, src) if src else None
    except (KinemaError, OSError, KeyError) as err:
        warn.append(f"coverage/novelty skipped: no train split to compare with ({err})")
    gen = {r: [run.motions[cases[i]["id"]][r] for i in run.text_ids] for r in run.rows}
    tm = text_metrics(ret, caps, gen, mm, seed, warn, text_cache, train_emb)
    for r in run.rows:
        summary[r].update(tm[r])


def _meta(model, cases: list[dict], modes: list[str], steps, seed: int, guidance) -> dict:
    """The report's ``meta``: what was evaluated, how, on what machine."""
    return {
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
    }


def _timeline_table(run: _SuiteRun, ret, text_cache) -> dict | None:
    """The timeline row (kinema.evaluate.timeline.timeline_summary), None without timeline cases."""
    if not run.timelines:
        return None
    captions = [s["prompt"] for c in run.timelines for s in c["segments"]]
    tl_records = [r for r in run.records if r["kind"] == "timeline"]
    return timeline_summary(tl_records, captions, run.tl_segments, ret, text_cache, _embed)


def _tables(run: _SuiteRun, summary: dict) -> dict:
    """The report's summary table and its breakdowns by case kind and by keyframe count."""
    return {
        "table": {r: {c: summary[r].get(c) for c in COLUMNS} for r in run.rows},
        "by_kind": by_kind(run.records, run.rows),
        "by_keyframes": by_keyframes(run.records, run.rows),
    }


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
    t_start, warn = time.perf_counter(), []
    datasets = {} if datasets is None else datasets
    run = _SuiteRun(modes, ["ground_truth", *modes])
    ret = _load_retrieval(retrieval, warn)
    n_mm = min(mm_prompts, sum(c["kind"] == "text" for c in cases)) if ret is not None and mm_samples > 1 else 0
    mm = _generate_cases(model, cases, run, n_mm, mm_samples, seed, steps, guidance, datasets, progress)
    summary = summarize(run.records, run.rows, run.devs)
    text_info = {"cases": len(run.text_ids), "r_batch_size": R_BATCH, "mm_prompts": len(mm[modes[0]]),
                 "mm_samples": mm_samples, "retrieval": None}  # fmt: skip
    if ret is not None:
        text_info["retrieval"] = _retrieval_name(retrieval)
        _add_text_metrics(summary, ret, cases, run, mm, seed, warn, text_cache)
    tl_table = _timeline_table(run, ret, text_cache)
    t_phr = time.perf_counter()
    phr = run_phrasings(
        model, cases, run.motions, datasets, ret, samples=phrasings, seed=seed, steps=steps, guidance=guidance,
        text_cache=text_cache, embed=_embed, warn=warn, progress=progress,
    ) if phrasings else None  # fmt: skip
    timing = {
        "wall_seconds": time.perf_counter() - t_start,
        "generate_seconds": run.gen_seconds,
        "postprocess_seconds": run.post_seconds,
        "seconds_per_case": run.gen_seconds / max(1, len(cases) + len(mm[modes[0]]) * mm_samples),
        "phrasings_seconds": time.perf_counter() - t_phr if phrasings else None,
    }
    tables = _tables(run, summary)
    data = {"format": "kinema-eval-report", "version": 1, "meta": _meta(model, cases, modes, steps, seed, guidance),
            "timing": timing, "table": tables["table"], "text": text_info, "by_kind": tables["by_kind"],
            "by_keyframes": tables["by_keyframes"], "timeline": tl_table, "phrasings": phr, "cases": run.records,
            "warnings": warn}  # fmt: skip
    return EvalResults(finite(data), run.motions, list(cases))


def _generate_cases(model, cases, run: _SuiteRun, n_mm: int, mm_samples: int, seed: int, steps, guidance,
                    datasets: dict, progress: bool):
    """Generate and score every case into ``run``, then ``n_mm`` x ``mm_samples`` multimodality samples
    (returned, per mode), under one progress bar."""
    bar = _bar(len(cases) + n_mm, progress, "evaluate")
    for i, case in enumerate(cases):
        _run_case(model, i, case, _dataset(case, model, datasets), run, seed, steps, guidance)
        bar.update(1)
    mm = _multimodality(model, cases, run, n_mm, mm_samples, seed, steps, guidance, bar)
    bar.close()
    return mm

