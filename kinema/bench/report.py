"""`kinema bench all`: every speed number in one report (report.md + report.json), like `kinema evaluate`.

Sections: training step time per preset (kinema.bench.train) and, with a model, the generation suite
(kinema.bench.suite: latency vs DDIM steps with and without constraints and post-processing, samples per
call and durations, 1 vs 2 threads quiet and under load, the first CLI call cold and warm and its phases).
JSON keys: ``meta`` (torch version, threads, model, machine, load average), ``train`` (rows: config,
params_m, batch, frames, step_s, samples_per_s, gflops_per_step, fwd3_ms), ``generate`` (rows: steps,
constraints, postprocess, seconds), ``sweeps`` (rows: sweep, value, segments, total_s, per_motion_s),
``threads`` (rows: load, threads, median_s, min_s, repeats, speedup_vs_1), ``cli`` (cold_s, warm_s),
``phases`` (seconds per phase of a fresh process, and total) and ``cold_start_s`` (= cli cold_s).
"""

from __future__ import annotations

import json
import os
import platform
from dataclasses import asdict
from pathlib import Path

import torch

from kinema.atomic_files import atomic_write_bytes
from kinema.bench.suite import GenerateSuiteOptions, format_generate_suite, run_generate_suite
from kinema.bench.train import bench_config
from kinema.bench.train import format_table as train_table
from kinema.runtime import load_average


def run_all(model: str | None, configs=("tiny", "small", "small-1stage"), suite: GenerateSuiteOptions | None = None,
            progress: bool = True) -> dict:
    """Collect every benchmark; the generation part needs a model (skipped when ``model`` is None).

    ``suite`` chooses the generation sections and settings (default: all, full size)."""
    from tqdm.auto import tqdm

    train_rows = [bench_config(c) for c in tqdm(configs, desc="bench train", disable=not progress)]
    out = {
        "meta": {"torch": torch.__version__, "threads": torch.get_num_threads(), "model": model,
                 "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
                 "cpu_count": os.cpu_count(), "load_average": load_average()},
        "train": [asdict(r) for r in train_rows],
        "generate": [], "sweeps": [], "threads": [], "cli": None, "phases": None,
        "cold_start_s": None,
        "seconds": 5.0 if suite is None else suite.seconds,
    }
    if model is not None:
        suite = GenerateSuiteOptions(model=model) if suite is None else suite
        suite.model = model
        out.update(run_generate_suite(suite, progress=progress))
        out["cold_start_s"] = None if out["cli"] is None else out["cli"]["cold_s"]
    return out


def write_bench_report(result: dict, out_dir: str | Path) -> Path:
    """report.md (the printed tables) + report.json, written atomically into ``out_dir``."""
    from kinema.bench.train import TrainBenchRow

    out_dir = Path(out_dir)
    meta = result["meta"]
    lines = ["# kinema benchmarks", "",
             f"torch {meta['torch']}, {meta['threads']} threads, {meta['cpu_count']} CPUs ({meta['machine']})", "",
             "## Training step (batch x frames, AdamW, full two-stage forward + backward)", "", "```",
             train_table([TrainBenchRow(**r) for r in result["train"]]), "```", ""]
    if meta["model"] is not None:
        lines += [f"Generation: model {meta['model']}", "", format_generate_suite(result, fence=True)]
    text = "\n".join(lines)
    atomic_write_bytes(out_dir / "report.md", text.encode())
    atomic_write_bytes(out_dir / "report.json", json.dumps(result, indent=1).encode())
    return out_dir / "report.md"
