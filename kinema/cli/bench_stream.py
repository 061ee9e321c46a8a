"""``kinema bench stream``: real time, latency, memory and window timings of a long live stream
(kinema.bench.stream; the table in docs/stream.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinema.cli._args import positive_float, positive_int
from kinema.errors import KinemaError


def register_bench(targets) -> None:
    p = targets.add_parser(
        "stream",
        help="live stream: real-time factor on 1 and 2 threads, command latency, memory, time per window",
        description="Runs the same scripted live stream (a command every 6 s: walk, steer, bow, wave, jog, "
        "...) once per thread count and prints one row each (docs/stream.md).",
    )
    p.add_argument("--seconds", type=positive_float, default=600.0, help="seconds of motion per stream (default 600)")
    p.add_argument("--threads", type=positive_int, nargs="+", default=[1, 2], help="thread counts (default 1 2)")
    p.add_argument("--model", default="default", help="the model streamed (default: the shipped human model)")
    p.add_argument("--window-seconds", type=positive_float, default=3.0, help="seconds of one window (default 3)")
    p.add_argument("--steps", type=positive_int, help="DDIM steps per window (default: the stream's 10)")
    p.add_argument("--out", type=Path, help="also write the rows as JSON here")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import torch  # imported here: building the CLI's parser loads no model code (every command starts faster)

    from kinema.atomic_files import atomic_write_text
    from kinema.bench.stream import markdown, run_stream
    from kinema.generate import load_model
    from kinema.runtime import text_cache_dir

    if args.seconds > 7200:
        raise KinemaError(f"--seconds: at most 7200 (two hours of motion), got {args.seconds:g}")
    model = load_model(args.model, text_cache=text_cache_dir())
    model.generate("A person walks forward.", seconds=1, steps=1, postprocess=False)  # warm up
    rows = []
    for threads in args.threads:
        row = run_stream(model, args.seconds, threads, args.window_seconds, args.steps)
        print(f"{threads} thread(s): {row.realtime_wall:.1f}x real time (wall), {row.realtime_cpu:.1f}x (CPU)",
              flush=True)
        rows.append(row)
    print(f"torch {torch.__version__}, model {args.model}, {args.seconds:g} s of motion per stream")
    print(markdown(rows))
    if args.out is not None:
        atomic_write_text(args.out, json.dumps([r.to_json() for r in rows], indent=1) + "\n")
        print(f"wrote {args.out}")
    return 0
