"""Cost per second of motion at several lengths (issue 57): a walk and a run of 5, 10 and 60 s.

A prompt longer than its action's captures is made window by window (kinema.human.continuation): a run
from 2.4 s on, a walk from 5.9 s on, so the cost per second of motion shows what continuation costs
against one window. Post-processing is on and steps are the model's default, as in `kinema generate`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

PROMPTS = ("A person walks forward.", "A person runs forward.")
DURATIONS = (5.0, 10.0, 60.0)


@dataclass
class LengthRow:
    prompt: str
    seconds: float
    windows: int  # windows of a continued prompt, else segments
    wall_s: float
    per_second_s: float  # wall seconds per second of motion


def bench_lengths(model, durations=DURATIONS, prompts=PROMPTS, repeats: int = 1) -> list[LengthRow]:
    """The best of ``repeats`` calls per prompt and duration (seed r on repeat r) of a loaded model."""
    model.generate(prompts[0], seconds=1.0, steps=2)  # warm-up: text encoder, allocator
    rows = []
    for prompt in prompts:
        for seconds in durations:
            best, windows = float("inf"), 1
            for r in range(repeats):
                t0 = time.perf_counter()
                report = model.generate(prompt, seconds=float(seconds), seed=r).report
                best = min(best, time.perf_counter() - t0)
                made = report.prompts[0].get("continued") if report.prompts else None
                windows = made["windows"] if made else report.segments
            rows.append(LengthRow(prompt, float(seconds), windows, best, best / float(seconds)))
    return rows


def format_lengths(rows: list[LengthRow]) -> str:
    """One table: prompt, length, windows, wall seconds and wall seconds per second of motion."""
    head = f"{'prompt':<26}  {'seconds':>7}  {'windows':>7}  {'wall s':>8}  {'s per motion s':>14}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.prompt:<26}  {r.seconds:>7g}  {r.windows:>7}  {r.wall_s:>8.2f}  {r.per_second_s:>14.3f}")
    return "\n".join(lines)
