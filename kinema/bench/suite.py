"""The generation benchmark suite shared by `kinema bench generate` and `kinema bench all`.

Why one place: both commands must measure the same things the same way, and ``bench all`` must be able
to write every table into report.md / report.json. Sections (each optional):

- ``steps``: seconds per motion vs DDIM steps, with/without constraints and post-processing;
- ``sweeps``: samples per call (1/4/16) and durations (5/10/20/40 s);
- ``threads``: 1 vs 2 threads interleaved, quiet and under ``load`` busy-loop processes;
- ``cold``: the first `kinema generate` of a fresh process (cold and warm) and its phases;
- ``lengths``: cost per second of motion of a walk and a run at 5, 10 and 60 s (kinema.bench.lengths:
  long prompts are continued window by window);
- ``speed``: fp32 vs bf16 interleaved: post-processing share, constrained vs prompt-only cost, samples
  per motion, sparse targets planned by default, the denoiser's share of the matmul peak
  (kinema.bench.precision).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

SECTIONS = ("steps", "sweeps", "lengths", "threads", "cold", "speed")


@dataclass
class GenerateSuiteOptions:
    """What to measure; ``quick()`` gives a run of about a minute on a 2-core machine."""

    model: str = "default"
    sections: tuple[str, ...] = SECTIONS
    steps: tuple[int, ...] = (10, 25, 50, 100)
    seconds: float = 5.0
    repeats: int = 2
    samples: tuple[int, ...] = (1, 4, 16)
    durations: tuple[float, ...] = (5.0, 10.0, 20.0, 40.0)
    lengths: tuple[float, ...] = (5.0, 10.0, 60.0)
    sweep_repeats: int = 1
    threads: tuple[int, ...] = (1, 2)
    loads: tuple[int, ...] = (0, 2)
    thread_repeats: int = 3
    guidance_refresh: int = 1  # speed section: guidance caching (kinema.diffusion.guidance_cache); 1 = off
    guidance_cached: str = "constr"

    @classmethod
    def quick(cls, **kw) -> GenerateSuiteOptions:
        """Fewer settings and repeats: for a quick look, or for CI."""
        base = dict(steps=(10, 50), repeats=1, samples=(1, 4), durations=(5.0, 20.0), thread_repeats=2)
        base.update(kw)
        return cls(**base)


def run_generate_suite(opts: GenerateSuiteOptions, progress: bool = True) -> dict:
    """Run the chosen sections; returns a JSON-able dict (keys: generate, sweeps, threads, cli, phases)."""
    from kinema.bench.cold import cli_times, phase_breakdown
    from kinema.bench.generate import bench_generate, bench_sweeps
    from kinema.bench.threads import bench_threads

    out: dict = {"seconds": opts.seconds, "generate": [], "sweeps": [], "lengths": [], "threads": [], "cli": None,
                 "phases": None, "speed": None, "options": asdict(opts)}

    def say(msg: str) -> None:
        if progress:
            print(f"[bench generate] {msg}", flush=True)

    model = None
    if {"sweeps", "lengths", "threads"} & set(opts.sections):
        from kinema.generate import load_model

        model = load_model(opts.model)
    if "steps" in opts.sections:
        say(f"DDIM steps {list(opts.steps)} x constraints x post-processing")
        out["generate"] = [asdict(r) for r in bench_generate(opts.model, opts.steps, opts.seconds, opts.repeats)]
    if "sweeps" in opts.sections:
        say(f"samples {list(opts.samples)}, durations {list(opts.durations)}")
        out["sweeps"] = [asdict(r) for r in bench_sweeps(model, opts.samples, opts.durations,
                                                          repeats=opts.sweep_repeats)]
    if "lengths" in opts.sections:
        from kinema.bench.lengths import bench_lengths

        say(f"cost per second of motion at {list(opts.lengths)} s (walk, run)")
        out["lengths"] = [asdict(r) for r in bench_lengths(model, opts.lengths)]
    if "threads" in opts.sections:
        say(f"threads {list(opts.threads)} at loads {list(opts.loads)} (busy-loop processes)")

        def one() -> None:
            model.generate("A person walks forward.", seconds=opts.seconds, seed=0)

        out["threads"] = [asdict(r) for r in bench_threads(one, opts.threads, opts.loads, opts.thread_repeats)]
    if "speed" in opts.sections:
        from kinema.bench.precision import bench_speed

        say(f"fp32 vs bf16, post-processing share, samples {list(opts.samples)}, sparse targets (interleaved)")
        out["speed"] = bench_speed(opts.model, opts.seconds, rounds=max(opts.repeats, 1), samples=opts.samples,
                                   guidance_refresh=opts.guidance_refresh, guidance_cached=opts.guidance_cached)
    if "cold" in opts.sections:
        say("first `kinema generate` in a fresh process (cold, warm, phases)")
        out["cli"] = cli_times(opts.model, opts.seconds)
        out["phases"] = phase_breakdown(opts.model, opts.seconds)
    return out


def format_generate_suite(result: dict, fence: bool = False) -> str:
    """Every measured section as titled tables (``fence``: wrapped in ``` for markdown)."""
    from kinema.bench.cold import format_cold
    from kinema.bench.generate import GenerateBenchRow, SweepRow, format_sweeps, format_table
    from kinema.bench.threads import ThreadsRow, format_threads

    seconds = result.get("seconds", 5.0)
    blocks = []
    if result.get("generate"):
        blocks.append((f"Generation latency: seconds per {seconds:g}-s motion vs DDIM steps (warm)",
                       format_table([GenerateBenchRow(**r) for r in result["generate"]], None, seconds)))
    if result.get("sweeps"):
        blocks.append(("Samples per call and motion length (warm, default steps, post-processing on)",
                       format_sweeps([SweepRow(**r) for r in result["sweeps"]])))
    if result.get("lengths"):
        from kinema.bench.lengths import LengthRow, format_lengths

        blocks.append(("Cost per second of motion by length (continued window by window past the captures)",
                       format_lengths([LengthRow(**r) for r in result["lengths"]])))
    if result.get("threads"):
        blocks.append(("Torch threads, quiet and under load (interleaved; load = busy-loop processes)",
                       format_threads([ThreadsRow(**r) for r in result["threads"]], f"{seconds:g}-s motion")))
    if result.get("speed"):
        from kinema.bench.precision import format_speed

        blocks.append(("fp32 vs bf16: post-processing, samples, sparse targets, matmul peak (issue 37)",
                       format_speed(result["speed"])))
    if result.get("cli") or result.get("phases"):
        blocks.append(("First `kinema generate` in a fresh process", format_cold(result.get("cli"),
                                                                                  result.get("phases"))))
    parts = []
    for title, table in blocks:
        parts += [f"## {title}" if fence else title, ""]
        parts += ["```", table, "```", ""] if fence else [table, ""]
    return "\n".join(parts)
