"""``kinema bench objectives``: the noise-optimisation trade-off curve (kinema.bench.objectives)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinema.atomic_files import atomic_write_bytes
from kinema.bench.objectives import HEADER, SETTINGS, TASKS, bench_objectives, parse_settings
from kinema.cli._args import positive_float, positive_int
from kinema.runtime import text_cache_dir


def register_bench(targets) -> None:
    p = targets.add_parser(
        "objectives",
        help="objective error vs seconds for noise-optimisation settings",
        description="Generates the same motions with one objective for several (DDIM steps, iterations) "
        "settings and prints objective error against seconds (docs/objectives.md). Default settings: "
        + " ".join(f"{s}x{i}" for s, i in SETTINGS),
    )
    p.add_argument("--task", choices=sorted(TASKS), default="reach", help="objective measured (default reach)")
    p.add_argument("--seconds", type=positive_float, default=5.0, help="motion length (default 5)")
    p.add_argument("--seeds", type=positive_int, default=1, help="motions per setting (seeds 0..N-1)")
    p.add_argument("--settings", nargs="+", metavar="STEPSxITERS", help="e.g. 3x4 5x12 (default: a 6-point curve)")
    p.add_argument("--out", type=Path, help="also write the rows as JSON here")
    p.add_argument("--threads", type=positive_int, help="torch threads (default: kinema.runtime's choice)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.generate import load_model
    from kinema.runtime import configure_threads

    settings = parse_settings(args.settings)
    threads = configure_threads(args.threads)
    model = load_model("default", text_cache=text_cache_dir())
    print(
        f"objective {args.task!r}, {args.seconds:g}-s motion, {args.seeds} seed(s), {threads} thread(s); "
        "error in cm (optimised: after noise optimisation; raw: after snapping; final: post-processed)"
    )
    print(HEADER)
    rows = bench_objectives(model, args.task, args.seconds, args.seeds, settings)
    if args.out is not None:
        atomic_write_bytes(
            args.out, (json.dumps({"task": args.task, "seconds": args.seconds, "rows": rows}, indent=1) + "\n").encode()
        )
    return 0
