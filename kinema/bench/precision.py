"""`kinema bench generate --sections speed`: issue 37's numbers, fp32 and bf16 side by side in one process.

Per precision (both loaded at once; every measurement alternates fp32 / bf16, rounds interleaved, CPU time
of this process by ``time.process_time``, so other processes on a busy machine count less):

- ``prompt_raw``: a prompt-only raw generate of ``seconds`` (no constraints, no post-processing);
- ``constrained_raw`` / ``constrained_post``: the same clip with the bench's waypoints + hand target
  (kinema.bench.generate.example_constraints), raw and post-processed, with the model's own guidance; the
  post-processing share is ``(post - raw) / post`` and ``ratio`` is ``constrained_post / prompt_raw``
  (issue 37: <= 1.25); ``separated_post`` / ``separated_ratio``: the same with the model's weights given,
  i.e. separated guidance (three denoiser branches where the shipped model's own regular CFG runs two);
- ``samples_N``: seconds per motion of a prompt-only, post-processed call of ``N`` samples;
- ``sparse_*``: sparse joint targets alone (kinema.bench.keyjoint_planning.sparse_example), raw, with the
  default (keyjoint-planned) and with ``keyjoint_model="none"``, and the worst raw target error (cm);
- ``peak``: the denoiser's matrix-multiply work per second in one guided pass of ``rows`` rows, as a
  share of this CPU's peak for a large matrix product in that precision.
"""

from __future__ import annotations

import statistics
import time

import torch

PROMPT = "A person walks forward."


def matmul_peak(dtype: torch.dtype, size: int = 1024, seconds: float = 0.5) -> float:
    """GFLOP/s of a ``size``^3 matrix product in ``dtype`` (the best of repeated runs for ``seconds``)."""
    a, b = torch.randn(size, size).to(dtype), torch.randn(size, size).to(dtype)
    a @ b
    best, t_end = float("inf"), time.process_time() + seconds
    while time.process_time() < t_end:
        t0 = time.process_time()
        a @ b
        best = min(best, time.process_time() - t0)
    return 2 * size**3 / max(best, 1e-9) / 1e9


def denoiser_gflops(denoiser, rows: int, frames: int, seconds: float = 0.5) -> tuple[float, float]:
    """(GFLOP of one forward of ``rows`` x ``frames``, GFLOP/s it runs at): matmul FLOPs counted by
    torch's FlopCounterMode in training mode (in eval mode the encoder layers run torch's fused fast path,
    which the counter does not see; the matrix products are the same), time by the best of repeated
    forwards in eval mode."""
    from torch.utils.flop_counter import FlopCounterMode

    cfg = denoiser.config
    x, t = torch.randn(rows, frames, cfg.feature_dim), torch.full((rows,), 500)
    text = torch.randn(rows, cfg.text_dim)
    with torch.no_grad():
        denoiser.train()
        try:
            with FlopCounterMode(display=False) as counter:
                denoiser(x, t, text)
        finally:
            denoiser.eval()
        flops = counter.get_total_flops()
        best, t_end = float("inf"), time.process_time() + seconds
        while time.process_time() < t_end:
            t0 = time.process_time()
            denoiser(x, t, text)
            best = min(best, time.process_time() - t0)
    return flops / 1e9, flops / max(best, 1e-9) / 1e9


def _cpu(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def bench_speed(model_name: str = "default", seconds: float = 5.0, rounds: int = 3,
                samples: tuple[int, ...] = (1, 4, 16), steps: int | None = None, guidance_refresh: int = 1,
                guidance_cached: str = "constr") -> dict:
    """Median CPU seconds of every measurement of the module docstring, per precision; ``guidance_refresh``
    / ``guidance_cached``: the models' guidance caching (kinema.diffusion.guidance_cache; 1 = off)."""
    from kinema.bench.generate import example_constraints
    from kinema.bench.keyjoint_planning import _error, sparse_example
    from kinema.generate import load_model

    models = {p: load_model(model_name, precision=p) for p in ("fp32", "bf16")}
    for m in models.values():
        m.guidance_refresh, m.guidance_cached = guidance_refresh, guidance_cached
    cons = example_constraints(seconds)
    any_model = models["fp32"]
    sparse = sparse_example(any_model.skeleton, seconds, any_model.fps)
    for m in models.values():
        m.generate(PROMPT, seconds=seconds, steps=2, constraints=sparse)  # warm-up: text, allocator, planner
    kw = {"seconds": seconds, "seed": 0, "steps": steps}
    times: dict[str, dict[str, list[float]]] = {p: {} for p in models}
    errors: dict[str, dict[str, float]] = {p: {} for p in models}

    def add(p: str, key: str, value: float) -> None:
        times[p].setdefault(key, []).append(value)

    for _ in range(rounds):
        for p, m in models.items():
            add(p, "prompt_raw", _cpu(lambda m=m: m.generate(PROMPT, postprocess=False, **kw)))
            add(p, "constrained_raw", _cpu(lambda m=m: m.generate(PROMPT, constraints=cons, postprocess=False, **kw)))
            add(p, "constrained_post", _cpu(lambda m=m: m.generate(PROMPT, constraints=cons, **kw)))
            weights = (m.loaded.guidance.w_text, m.loaded.guidance.w_constr)
            add(p, "separated_post", _cpu(lambda m=m, w=weights: m.generate(PROMPT, constraints=cons, guidance=w,
                                                                             **kw)))
            for n in samples:
                add(p, f"samples_{n}", _cpu(lambda m=m, n=n: m.generate(PROMPT, samples=n, **kw)) / n)
            for mode in ("default", "none"):
                out: list = []
                add(p, f"sparse_{mode}", _cpu(lambda m=m, mode=mode, out=out: out.append(m.generate(
                    PROMPT, constraints=sparse, postprocess=False, keyjoint_model=None if mode == "default" else
                    mode, **kw)[0])))
                errors[p][f"sparse_{mode}_cm"] = 100 * _error(out[0], sparse)
    result: dict = {"seconds": seconds, "rounds": rounds, "samples": list(samples),
                    "guidance_refresh": guidance_refresh, "guidance_cached": guidance_cached}
    for p, m in models.items():
        med = {k: statistics.median(v) for k, v in times[p].items()}
        med["post_share"] = (med["constrained_post"] - med["constrained_raw"]) / med["constrained_post"]
        med["ratio"] = med["constrained_post"] / med["prompt_raw"]
        med["separated_ratio"] = med["separated_post"] / med["prompt_raw"]
        med["samples_gain"] = med[f"samples_{samples[0]}"] / med[f"samples_{samples[-1]}"]
        dtype = torch.bfloat16 if p == "bf16" else torch.float32
        peak = matmul_peak(dtype)
        frames = round(seconds * m.fps)
        for rows in (2, 24):
            gflop, rate = denoiser_gflops(m.loaded.denoiser, rows, frames)
            med[f"peak_share_{rows}"] = rate / peak
        med["peak_gflops"] = peak
        result[p] = med | errors[p]
    return result


ROWS = [
    ("prompt_raw", "prompt only, raw (s)", ".3f"),
    ("constrained_raw", "waypoints + hand, raw (s)", ".3f"),
    ("constrained_post", "waypoints + hand, post-processed (s)", ".3f"),
    ("post_share", "post-processing share of that", ".1%"),
    ("ratio", "constrained + post / prompt raw", ".2f"),
    ("separated_post", "waypoints + hand, separated guidance (weights given), post-processed (s)", ".3f"),
    ("separated_ratio", "separated guidance: constrained + post / prompt raw", ".2f"),
    ("sparse_none_cm", "sparse targets, direct: worst raw error (cm)", ".1f"),
    ("sparse_default_cm", "sparse targets, default (planned): worst raw error (cm)", ".1f"),
    ("sparse_none", "sparse targets, direct (s)", ".3f"),
    ("sparse_default", "sparse targets, default (planned) (s)", ".3f"),
    ("peak_gflops", "matmul peak, 1024^3 (GFLOP/s)", ".0f"),
    ("peak_share_2", "denoiser share of peak, 2 rows (1 sample)", ".1%"),
    ("peak_share_24", "denoiser share of peak, 24 rows", ".1%"),
]


def format_speed(result: dict) -> str:
    """One table: a row per measurement, a column per precision (and bf16's speed-up)."""
    head = f"| CPU seconds, median of {result['rounds']} interleaved rounds | fp32 | bf16 |"
    lines = [head, "|---|---:|---:|"]
    rows = list(ROWS)
    for n in result["samples"]:
        rows.insert(-3, (f"samples_{n}", f"samples={n}, per motion (post-processed) (s)", ".3f"))
    rows.insert(-3, ("samples_gain", f"samples={result['samples'][0]} / samples={result['samples'][-1]} per motion",
                     ".2f"))
    for key, label, fmt in rows:
        lines.append(f"| {label} | {format(result['fp32'][key], fmt)} | {format(result['bf16'][key], fmt)} |")
    return "\n".join(lines)
