"""`kinema evaluate fidelity` (or ``--protocol fidelity``): does the model do the action its prompt names?

    kinema evaluate fidelity --model default [--seeds 0 1 2] [--seconds 4] [--actions walk-back wave ...]
                             [--steps N] [--out out/fidelity.json]

Per action of the training data (kinema.evaluate.fidelity), its own captions and held-out phrasings are
generated at each seed and measured by the action's detector; the markdown table goes to stdout and, with
``--out``, the JSON (every sample) to that file and the table next to it (same name, ``.md``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from kinema.atomic_files import atomic_write_text
from kinema.cli._args import positive_int
from kinema.errors import KinemaError


def add_arguments(p) -> None:
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2],
                   help="fidelity: seeds per prompt (default 0 1 2; a prompt holds at 2 of 3)")
    p.add_argument("--seconds", type=float, default=4.0, help="fidelity: length of each motion (default 4)")
    p.add_argument("--actions", nargs="+", metavar="ACTION",
                   help="fidelity: only these actions (content labels, or a family such as 'wave'; default all)")
    p.add_argument("--threads", type=positive_int, help="fidelity: torch CPU threads")


def run_fidelity_cli(args: argparse.Namespace) -> int:
    """Load the model, measure the actions, print the table and write ``--out`` (JSON) and its ``.md``."""
    from kinema.evaluate.fidelity import format_fidelity, resolve_actions, run_fidelity
    from kinema.generate import load_model, resolve_model_path
    from kinema.runtime import configure_threads, text_cache_dir

    if not 0.5 <= args.seconds <= 60:
        raise KinemaError(f"--seconds must be between 0.5 and 60, got {args.seconds:g}")
    if args.steps is not None and args.steps < 1:
        raise KinemaError("--steps must be at least 1")
    if args.out is not None and args.out.is_dir():
        raise KinemaError(f"{args.out}: is a folder; fidelity --out names a JSON file")
    actions = resolve_actions(args.actions)
    resolve_model_path(args.model)
    configure_threads(args.threads)
    model = load_model(args.model, text_cache=text_cache_dir())

    def done(line: str, partial: dict) -> None:  # a long run cut short keeps what it measured
        print(line, file=sys.stderr, flush=True)
        if args.out is not None:
            _write(args.out, partial | {"model": str(args.model), "partial": True}, None)

    result = run_fidelity(model, seeds=tuple(args.seeds), seconds=args.seconds, actions=actions,
                          steps=args.steps, log=done)
    result["model"] = str(args.model)
    table = format_fidelity(result)
    print(table)
    if args.out is not None:
        _write(args.out, result, table)
        print(f"wrote {args.out} and {args.out.with_suffix('.md')}")
    return 0


def _write(out: Path, result: dict, table: str | None) -> None:
    """The JSON at ``out`` and, when given, the table next to it (``.md``)."""
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    if table is not None:
        atomic_write_text(out.with_suffix(".md"), table + "\n")
