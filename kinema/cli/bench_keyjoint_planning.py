"""``kinema bench keyjoint-planning``: explicit sparse control, direct vs keyjoint-planned
(kinema.bench.keyjoint_planning)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinema.atomic_files import atomic_write_bytes
from kinema.bench.keyjoint_planning import HEADER, bench_keyjoint_planning
from kinema.cli._args import positive_float, positive_int
from kinema.runtime import text_cache_dir


def register_bench(targets) -> None:
    p = targets.add_parser(
        "keyjoint-planning",
        help="sparse control: seconds and raw error, direct vs the keyjoint model first",
        description="Generates a walk with end-effector targets every 1.5 s, with and without the keyjoint "
        "model planning first (generate --keyjoint-model), and prints seconds per motion and the raw "
        "target error for each DDIM step count.",
    )
    p.add_argument("--keyjoint-model", default="default", help="'default' (shipped) or a keyjoint model folder")
    p.add_argument("--seconds", type=positive_float, default=5.0, help="motion length (default 5)")
    p.add_argument("--steps", type=positive_int, nargs="+", default=[10, 25, 50], help="DDIM steps (default 10 25 50)")
    p.add_argument("--repeats", type=positive_int, default=2, help="motions per row (seeds 0..N-1)")
    p.add_argument("--out", type=Path, help="also write the rows as JSON here")
    p.add_argument("--threads", type=positive_int, help="torch threads (default: kinema.runtime's choice)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.atomic_files import check_output_path
    from kinema.generate import load_model
    from kinema.human.keyjoint_planning import KeyjointPlanner
    from kinema.runtime import configure_threads

    if args.out is not None:
        check_output_path(args.out)
    KeyjointPlanner.check(args.keyjoint_model)
    threads = configure_threads(args.threads)
    model = load_model("default", text_cache=text_cache_dir())
    planner = KeyjointPlanner.load(args.keyjoint_model, model.precision)  # the body model's precision
    print(f"sparse control, {args.seconds:g}-s walk, {args.repeats} seed(s), {threads} thread(s)")
    print(HEADER)
    rows = bench_keyjoint_planning(model, planner, args.seconds, args.steps, args.repeats)
    if args.out is not None:
        atomic_write_bytes(args.out, (json.dumps({"seconds": args.seconds, "rows": rows}, indent=1) + "\n").encode())
    return 0
