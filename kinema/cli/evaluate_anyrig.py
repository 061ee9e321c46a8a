"""`kinema evaluate-anyrig`: per-rig metrics of an any-rig model on train and held-out rigs, and a table
of the held-out rigs grouped by their similarity to the training rigs (kinema.evaluate.anyrig.groups)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinema.cli._args import positive_int
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    p = sub.add_parser(
        "evaluate-anyrig",
        help="per-rig skate, jerk, stretch, constraint error, coverage/novelty, caption retrieval, foot-to-leg gap, "
        "forward share, turning, idle drift, ground speed per action; held-out rigs grouped by similarity to the "
        "training rigs",
    )
    p.add_argument("--model", default="creatures", help="any-rig model: 'creatures' (shipped) or a run folder")
    p.add_argument("--data", type=Path, required=True, help="multi-rig build or manifest, e.g. cache/quat20")
    p.add_argument("--splits", nargs="+", default=["train", "val", "test"], choices=["train", "val", "test"])
    p.add_argument("--rigs", nargs="+", help="only these rig ids")
    p.add_argument("--clips", type=positive_int, default=3, help="clips (captions) per rig (default 3)")
    p.add_argument("--steps", type=positive_int, default=20, help="DDIM steps (default 20)")
    p.add_argument("--probe-seconds", type=float, default=4.0,
                   help="seconds of the idle / walk forward / run-or-gallop probes per rig (default 4; 0 = none)")
    p.add_argument("--out", type=Path, help="write the rows as JSON here")
    p.add_argument("--threads", type=positive_int, help="torch CPU threads")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.atomic_files import atomic_write_text, check_output_path
    from kinema.errors import KinemaError
    from kinema.evaluate.anyrig.groups import similarity_table, split_summary, training_shapes
    from kinema.evaluate.anyrig.suite import LOCOMOTION_HEADER, TABLE_HEADER, evaluate_split, format_locomotion_row
    from kinema.generate import load_model
    from kinema.runtime import configure_threads

    if not (args.probe_seconds >= 0 and args.probe_seconds < 600):
        raise KinemaError(f"--probe-seconds: expected 0 (no probes) to 600 seconds, got {args.probe_seconds}")
    configure_threads(args.threads)
    if args.out is not None:
        check_output_path(args.out)
    model = load_model(args.model, text_cache=text_cache_dir())
    if not model.needs_rig:
        raise KinemaError(f"--model {args.model}: not an any-rig model (it drives its own skeleton)")
    shapes = training_shapes(model.loaded.train_rigs)
    print(TABLE_HEADER)
    rows = []
    for split in args.splits:
        rows += evaluate_split(
            model, args.data, split, clips=args.clips, steps=args.steps, rigs=args.rigs, train_shapes=shapes,
            probe_seconds=args.probe_seconds,
        )
    print("\nlocomotion per rig (kinema/evaluate/anyrig/locomotion.py; body sizes, own clips in brackets):\n")
    print(LOCOMOTION_HEADER)
    for r in rows:
        print(format_locomotion_row(r))
    print("\nmedians over rigs, per split:\n")
    print(split_summary(rows))
    held = [r for r in rows if r["split"] != "train"]
    if held:
        print("\nheld-out rigs by similarity to the training rigs (kinema/evaluate/anyrig/groups.py):\n")
        print(similarity_table(held))
    if args.out is not None:
        atomic_write_text(args.out, json.dumps(rows, indent=1) + "\n")
        print(f"wrote {args.out}")
    return 0
