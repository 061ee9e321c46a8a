"""`kinema bench generate`: seconds per motion vs DDIM steps, with/without constraints and post-processing,
vs the number of samples per call and vs the duration, plus cold start (fresh process: import + model
load + text encoder + one motion). Thread counts are in kinema.bench.threads, the first CLI call and its
phases in kinema.bench.cold. Everything here is warm: model loaded and prompt encoded before timing."""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass


@dataclass
class GenerateBenchRow:
    steps: int
    constraints: bool
    postprocess: bool
    seconds: float


def example_constraints(seconds: float) -> list[dict]:
    """Waypoints and a right-hand target: a typical light authoring set-up."""
    return [
        {"type": "root2d", "times": [seconds * 0.5, seconds - 0.05], "smooth_root_2d": [[0.0, 1.5], [0.5, 3.0]]},
        {"type": "right-hand", "times": [seconds * 0.5], "positions": [[0.3, 1.5, 1.7]]},
    ]


def bench_generate(model_path: str, steps_list=(10, 25, 50, 100), seconds: float = 5.0, repeats: int = 2,
                   prompt: str = "A person walks forward.") -> list[GenerateBenchRow]:
    """Time ``model.generate`` (warm: model already loaded, text cached) for each setting."""
    from kinema.generate import load_model

    model = load_model(model_path)
    model.generate(prompt, seconds=1.0, steps=2)  # warm-up: text encoder, allocator
    rows = []
    for steps in steps_list:
        for cons in (False, True):
            for post in (False, True):
                c = example_constraints(seconds) if cons else None
                t0 = time.perf_counter()
                for r in range(repeats):
                    model.generate(prompt, seconds=seconds, constraints=c, steps=steps, seed=r, postprocess=post)
                rows.append(GenerateBenchRow(steps, cons, post, (time.perf_counter() - t0) / repeats))
    return rows


@dataclass
class SweepRow:
    sweep: str  # "samples" (motions per call) or "seconds" (duration of each motion)
    value: float
    segments: int  # model windows per motion (a long motion is a timeline of overlapping segments)
    total_s: float  # one generate call
    per_motion_s: float


def bench_sweeps(model, samples=(1, 4, 16), durations=(5.0, 10.0, 20.0, 40.0), steps: int | None = None,
                 repeats: int = 1, prompt: str = "A person walks forward.") -> list[SweepRow]:
    """Seconds per call and per motion for several ``samples`` (5-s motions) and ``durations`` (1 sample).

    ``model`` is a loaded KinemaModel; post-processing is on, as in `kinema generate`.
    """
    model.generate(prompt, seconds=1.0, steps=2)  # warm-up: text encoder, allocator
    rows = []
    for sweep, values in (("samples", samples), ("seconds", durations)):
        for v in values:
            kw = dict(samples=int(v), seconds=5.0) if sweep == "samples" else dict(samples=1, seconds=float(v))
            best, segs = float("inf"), 1
            for r in range(repeats):
                t0 = time.perf_counter()
                res = model.generate(prompt, steps=steps, seed=r, **kw)
                best = min(best, time.perf_counter() - t0)
                segs = res.report.segments
            rows.append(SweepRow(sweep, float(v), segs, best, best / kw["samples"]))
    return rows


def format_sweeps(rows: list[SweepRow]) -> str:
    """One table: samples per call and durations, seconds per call and per motion."""
    head = f"{'sweep':>8}  {'value':>6}  {'segments':>8}  {'s per call':>10}  {'s per motion':>12}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.sweep:>8}  {r.value:>6g}  {r.segments:>8}  {r.total_s:>10.3f}  {r.per_motion_s:>12.3f}")
    return "\n".join(lines)


def cold_start(model_path: str, steps: int = 50, seconds: float = 5.0) -> float:
    """Wall time of a fresh interpreter that imports kinema, loads the model and generates one motion."""
    code = (f"import kinema; m = kinema.load_model({model_path!r}); "
            f"m.generate('A person walks forward.', seconds={seconds}, steps={steps})")
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    return time.perf_counter() - t0


def format_table(rows: list[GenerateBenchRow], cold: float | None, seconds: float) -> str:
    """The DDIM-steps table (and the old one-line cold start, when given)."""
    head = f"{'DDIM steps':>10}  {'constraints':>11}  {'postprocess':>11}  {f'seconds per {seconds:g}-s motion':>26}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.steps:>10}  {'yes' if r.constraints else 'no':>11}  {'yes' if r.postprocess else 'no':>11}"
                     f"  {r.seconds:>26.3f}")
    if cold is not None:
        lines.append(f"cold start (new process: import + load model + text encoder + one 50-step motion): {cold:.2f} s")
    return "\n".join(lines)
