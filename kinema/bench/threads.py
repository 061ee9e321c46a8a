"""Threads benchmark: 1 vs 2 (or more) torch threads, on a quiet machine and under a synthetic CPU load.

Why: the right thread count depends on whether other processes compete for the cores (see
kinema.runtime.default_threads). Absolute times on a shared machine drift from minute to minute, so the
settings are timed interleaved (1, 2, 1, 2, ...) within one process and compared as ratios; the load is
made by ``--load N`` busy-loop subprocesses started for the measurement and killed after it.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

BUSY_LOOP = "while True:\n    pass\n"


@contextmanager
def cpu_load(n: int) -> Iterator[list[subprocess.Popen]]:
    """Run ``n`` busy-loop Python subprocesses for the duration of the block (killed on exit).

    Each burns one core at 100 %, like another engineer's job; only the processes started here are
    killed, by their handles.
    """
    procs = [subprocess.Popen([sys.executable, "-c", BUSY_LOOP], stdin=subprocess.DEVNULL,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(n)]
    try:
        time.sleep(0.3 if n else 0.0)  # let the scheduler see them before timing starts
        yield procs
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


@dataclass
class ThreadsRow:
    load: int  # busy-loop processes running during the measurement
    threads: int
    median_s: float
    min_s: float
    repeats: int
    speedup_vs_1: float  # median of 1 thread / median of this row (same load)


def time_interleaved(fn: Callable[[], object], settings: list[int], repeats: int) -> dict[int, list[float]]:
    """Call ``fn`` under each thread count in turn, ``repeats`` rounds; seconds per call for each count."""
    import torch

    before = torch.get_num_threads()
    times: dict[int, list[float]] = {n: [] for n in settings}
    try:
        for _ in range(repeats):
            for n in settings:
                torch.set_num_threads(n)
                t0 = time.perf_counter()
                fn()
                times[n].append(time.perf_counter() - t0)
    finally:
        torch.set_num_threads(before)
    return times


def bench_threads(fn: Callable[[], object], threads=(1, 2), loads=(0, 2), repeats: int = 3,
                  warmup: bool = True) -> list[ThreadsRow]:
    """Median and best seconds of ``fn`` per thread count, quiet (load 0) and under each load level."""
    settings = list(threads)
    rows = []
    if warmup:
        time_interleaved(fn, settings, 1)
    for load in loads:
        with cpu_load(load):
            times = time_interleaved(fn, settings, repeats)
        base = statistics.median(times[1 if 1 in times else settings[0]])
        for n in settings:
            med = statistics.median(times[n])
            rows.append(ThreadsRow(load, n, med, min(times[n]), repeats, base / med))
    return rows


def format_threads(rows: list[ThreadsRow], what: str) -> str:
    """The table printed by the benchmarks: one line per (load, threads)."""
    head = f"{'load procs':>10}  {'threads':>7}  {f'median s ({what})':>24}  {'best s':>8}  {'x vs 1 thread':>13}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.load:>10}  {r.threads:>7}  {r.median_s:>24.3f}  {r.min_s:>8.3f}  {r.speedup_vs_1:>13.2f}")
    return "\n".join(lines)
