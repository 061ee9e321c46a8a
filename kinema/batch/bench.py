"""Batch throughput: motions per minute against the number of workers, through the real batch path.

Why through `run_batch`: the number includes everything a user's batch pays per motion (jobs parsing,
transfer of the files to the driver, atomic writes, the manifest), and model loading is timed apart
(``startup_s``), so the table shows the steady rate a long batch reaches. Jobs are varied prompts of
``seconds`` each; every configuration runs the same jobs in a fresh temporary folder.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from kinema.batch.runner import run_batch

PROMPTS = ("A person walks forward.", "A person runs in a circle.", "A person jumps twice.",
           "A person waves with the right hand.", "A person sits down and stands up.", "A person turns around.",
           "A person walks backwards slowly.", "A person kicks with the left foot.")


def worker_counts(top: int) -> list[int]:
    """1, 2, 4, ... up to ``top``, and ``top`` itself: the worker counts a benchmark measures."""
    return sorted({1, *[2**k for k in range(1, top.bit_length()) if 2**k <= top], top})


def write_bench_jobs(path: Path, jobs: int, seconds: float, steps: int | None) -> Path:
    """A jobs file of ``jobs`` lines cycling through `PROMPTS`, seeds 0..jobs-1."""
    lines = []
    for i in range(jobs):
        job = {"id": f"bench{i:04d}", "prompt": PROMPTS[i % len(PROMPTS)], "seconds": seconds, "seed": i}
        if steps is not None:
            job["steps"] = steps
        lines.append(json.dumps(job))
    path.write_text("\n".join(lines) + "\n")
    return path


def bench_batch(worker_counts: list[int], *, jobs: int = 8, seconds: float = 4.0, steps: int | None = None,
                model: str = "default", ray: str | None = None) -> list[dict]:
    """One row per worker count: motions, start-up seconds, run seconds and motions per minute."""
    rows = []
    for n in worker_counts:
        with tempfile.TemporaryDirectory(prefix="kinema-batch-bench-") as tmp:
            jobs_file = write_bench_jobs(Path(tmp) / "jobs.jsonl", jobs, seconds, steps)
            s = run_batch(jobs_file, Path(tmp) / "out", model=model, workers=n, ray=ray, progress=False)
        rate = 60.0 * s.done / s.run_s if s.run_s > 0 else 0.0
        rows.append({"workers": s.workers or n, "motions": s.done, "failed": s.failed, "startup_s": s.startup_s,
                     "run_s": s.run_s, "motions_per_min": rate})
    base = rows[0]["motions_per_min"] if rows and rows[0]["motions_per_min"] > 0 else None
    for r in rows:
        r["speedup"] = r["motions_per_min"] / base if base else None
    return rows


def format_table(rows: list[dict], *, seconds: float, steps: int | None, executor: str) -> str:
    """A Markdown table of `bench_batch` rows with a line saying what was measured."""
    head = (f"Batch throughput ({executor}; {seconds:g}-s motions, {steps or 'default'} DDIM steps; start-up = "
            "model loading in the workers, not counted in the rate)\n\n"
            "| workers | motions | failed | start-up s | run s | motions/min | speed-up |\n"
            "|---:|---:|---:|---:|---:|---:|---:|\n")
    body = ""
    for r in rows:
        speedup = "" if r["speedup"] is None else f"{r['speedup']:.2f}x"
        body += (f"| {r['workers']} | {r['motions']} | {r['failed']} | {r['startup_s']:.1f} | {r['run_s']:.1f} | "
                 f"{r['motions_per_min']:.1f} | {speedup} |\n")
    return head + body
