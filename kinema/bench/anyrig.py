"""`kinema bench generate --model creatures`: seconds per motion of an any-rig model, by rig size and
DDIM steps (warm: model loaded, prompt encoded, one warm-up call before timing).

Rigs are the model's own training rigs (no files needed): the smallest, one in the middle and the
largest by joint count. Post-processing (de-jittering, foot locking, exact pass) is timed separately.
"""

from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass
class AnyRigBenchRow:
    rig: str
    joints: int
    steps: int
    postprocess: bool
    seconds: float  # wall time of one motion of ``duration`` seconds
    duration: float
    windows: int


def pick_rigs(known: list[tuple[str, int, list[str]]]) -> list[tuple[str, int]]:
    """Smallest, median and largest training rig by joints (each once)."""
    rigs = sorted(((rid, j) for rid, j, _ in known if j >= 3), key=lambda r: r[1])
    picks = [rigs[0], rigs[len(rigs) // 2], rigs[-1]] if rigs else []
    return list(dict.fromkeys(picks))


def bench_anyrig(
    model, *, seconds: float = 4.0, steps_list=(10, 20, 30), repeats: int = 2, prompt: str = "A creature walks."
) -> list[AnyRigBenchRow]:
    """Time ``model.generate`` on `pick_rigs` rigs for each DDIM step count, with and without post-processing."""
    rows = []
    for rid, joints in pick_rigs(model.known_rigs()):
        rig = model.resolve_rig(rid)
        model.generate(prompt, rig=rig, seconds=1.0, steps=2)  # warm-up
        for steps in steps_list:
            for post in (False, True):
                t0 = time.perf_counter()
                for r in range(repeats):
                    res = model.generate(prompt, rig=rig, seconds=seconds, steps=steps, seed=r, postprocess=post)
                dt = (time.perf_counter() - t0) / repeats
                rows.append(AnyRigBenchRow(rid, joints, steps, post, dt, seconds, res.report.windows))
    return rows


def format_anyrig_bench(rows: list[AnyRigBenchRow]) -> str:
    out = ["| rig | joints | seconds of motion | windows | DDIM steps | post-processing | wall s |", "|" + "---|" * 7]
    for r in rows:
        out.append(
            f"| {r.rig} | {r.joints} | {r.duration:g} | {r.windows} | {r.steps} | "
            f"{'yes' if r.postprocess else 'no'} | {r.seconds:.2f} |"
        )
    return "\n".join(out)
