"""`kinema bench all`: every speed number in one report (report.md + report.json), like `kinema evaluate`.

Sections: training step time per preset (kinema.bench.train), generation latency vs DDIM steps with and
without constraints and post-processing, and cold start (kinema.bench.generate). JSON keys:
``meta`` (torch version, threads, model, machine), ``train`` (list of rows: config, params_m, batch,
frames, step_s, samples_per_s, gflops_per_step, fwd3_ms), ``generate`` (rows: steps, constraints,
postprocess, seconds) and ``cold_start_s``.
"""

from __future__ import annotations

import json
import platform
from dataclasses import asdict
from pathlib import Path

import torch

from kinema.bench.generate import bench_generate, cold_start
from kinema.bench.generate import format_table as generate_table
from kinema.bench.train import bench_config
from kinema.bench.train import format_table as train_table
from kinema.io.atomic import atomic_write_bytes


def run_all(model: str | None, configs=("tiny", "small", "small-1stage"), steps=(10, 25, 50, 100),
            seconds: float = 5.0, repeats: int = 2, progress: bool = True) -> dict:
    """Collect every benchmark; the generation part needs a model (skipped when ``model`` is None)."""
    from tqdm.auto import tqdm

    train_rows = [bench_config(c) for c in tqdm(configs, desc="bench train", disable=not progress)]
    out = {
        "meta": {"torch": torch.__version__, "threads": torch.get_num_threads(), "model": model,
                 "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
                 "cpu_count": __import__("os").cpu_count()},
        "train": [asdict(r) for r in train_rows],
        "generate": [],
        "cold_start_s": None,
        "seconds": seconds,
    }
    if model is not None:
        out["generate"] = [asdict(r) for r in bench_generate(model, steps, seconds, repeats)]
        out["cold_start_s"] = cold_start(model, seconds=seconds)
    return out


def write_bench_report(result: dict, out_dir: str | Path) -> Path:
    """report.md (the printed tables) + report.json, written atomically into ``out_dir``."""
    from kinema.bench.generate import GenerateBenchRow
    from kinema.bench.train import TrainBenchRow

    out_dir = Path(out_dir)
    meta = result["meta"]
    lines = ["# kinema benchmarks", "",
             f"torch {meta['torch']}, {meta['threads']} threads, {meta['cpu_count']} CPUs ({meta['machine']})", "",
             "## Training step (batch x frames, AdamW, full two-stage forward + backward)", "", "```",
             train_table([TrainBenchRow(**r) for r in result["train"]]), "```", ""]
    if result["generate"]:
        lines += [f"## Generation latency (model {meta['model']})", "", "```",
                  generate_table([GenerateBenchRow(**r) for r in result["generate"]], result["cold_start_s"],
                                 result["seconds"]), "```", ""]
    text = "\n".join(lines)
    atomic_write_bytes(out_dir / "report.md", text.encode())
    atomic_write_bytes(out_dir / "report.json", json.dumps(result, indent=1).encode())
    return out_dir / "report.md"
