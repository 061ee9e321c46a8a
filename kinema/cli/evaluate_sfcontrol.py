"""`kinema evaluate --protocol sfcontrol`: SFControl's protocols, small (kinema.evaluate.sfcontrol*).

Writes ``report.md`` (tables) and ``report.json`` into ``--out`` (default out/eval/sfcontrol). Cases:
``--cases`` sparse-control crops, ``--cases`` goal crops and ``--cases`` seeds per implicit task; a
shared 2-core CPU affords a handful (the report says how many).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from kinema.io.atomic import atomic_write_bytes

SPARSE_ROWS = ("single-stage", "two-stage", "two-stage (root path)", "single-stage + noise opt")


def add_arguments(p) -> None:
    p.add_argument(
        "--protocol",
        choices=("suite", "sfcontrol"),
        default="suite",
        help="'suite' (Kimodo-style test suite, default) or 'sfcontrol' (sparse keyjoint control, "
        "goal reaching, implicit tasks; docs/objectives.md)",
    )
    p.add_argument("--keyjoint-model", type=Path, help="sfcontrol: keyjoint model folder for the two-stage row")
    p.add_argument("--objective-steps", type=int, default=8, help="sfcontrol: noise iterations (default 8)")
    p.add_argument(
        "--sparse-rows",
        nargs="+",
        choices=SPARSE_ROWS,
        default=SPARSE_ROWS,
        help="sfcontrol: rows of the sparse protocol (default all; two-stage needs --keyjoint-model)",
    )
    p.add_argument(
        "--parts",
        nargs="+",
        choices=("sparse", "goal", "tasks"),
        default=("sparse", "goal", "tasks"),
        help="sfcontrol: which protocols to run (default all)",
    )


def _table(title: str, rows: dict, cols: list[tuple[str, str, str]]) -> str:
    lines = [f"### {title}", "", "| row | " + " | ".join(c[1] for c in cols) + " |", "|---|" + "---|" * len(cols)]
    for name, v in rows.items():
        lines.append(f"| {name} | " + " | ".join(format(v[c[0]], c[2]) for c in cols) + " |")
    return "\n".join(lines) + "\n"


SPARSE_COLS = [
    ("control_cm", "control error (cm)", ".2f"),
    ("skate", "skate (cm/s)", ".1f"),
    ("jerk", "jerk", ".0f"),
    ("seconds", "s / motion", ".1f"),
]
GOAL_COLS = [
    ("goal_cm", "dist. to goal (cm)", ".2f"),
    ("start_cm", "dist. to start (cm)", ".2f"),
    ("skate", "skate (cm/s)", ".1f"),
    ("seconds", "s / motion", ".1f"),
]
TASK_COLS = [
    ("error_cm", "constraint error (cm)", ".2f"),
    ("skate", "skate (cm/s)", ".1f"),
    ("jerk", "jerk", ".0f"),
    ("seconds", "s / motion", ".1f"),
]


def _sparse(args: argparse.Namespace, model) -> tuple[dict, list[str]]:
    from kinema.diffusion.sampler import DDIMSampler
    from kinema.evaluate import sfcontrol as S
    from kinema.model.keyjoint import load_keyjoint_model

    rows, kj = list(args.sparse_rows), None
    if args.keyjoint_model is not None:
        kj = (load_keyjoint_model(args.keyjoint_model)[0], DDIMSampler())
    else:
        rows = [r for r in rows if not r.startswith("two-stage")]
    cases = S.sparse_cases(args.data, args.cases, seed=args.seed)
    res = S.summarize(
        S.evaluate_sparse(
            model, cases, rows=rows, keyjoint=kj, steps=args.steps, objective_steps=args.objective_steps, seed=args.seed
        )
    )
    title = f"Sparse control ({len(cases)} test crops of 5 s, a target every 1.5 s on 3 of 6 keyjoints, raw)"
    return res, [_table(title, res, SPARSE_COLS)]


def _goal(args: argparse.Namespace, model) -> tuple[dict, list[str]]:
    from kinema.evaluate import sfcontrol_tasks as K

    res = K.evaluate_goal(
        model, K.goal_cases(args.data, args.cases, seed=args.seed), objective_steps=args.objective_steps, seed=args.seed
    )
    return res, [_table(f"Goal reaching ({args.cases} test crops of 3 s, right hand, raw)", res, GOAL_COLS)]


def _tasks(args: argparse.Namespace, model) -> tuple[dict, list[str]]:
    from kinema.evaluate import sfcontrol_tasks as K

    res = K.evaluate_tasks(model, cases=args.cases, objective_steps=args.objective_steps, seed=args.seed)
    return res, [_table(f"{task} ({args.cases} seeds, raw)", rows, TASK_COLS) for task, rows in res.items()]


def run_sfcontrol(args: argparse.Namespace) -> int:
    from kinema.generate.api import load_model

    t0 = time.perf_counter()
    out = args.out or Path("out/eval/sfcontrol")
    model = load_model(args.model, text_cache=Path("cache/text"))
    report, md = {"cases": args.cases, "steps": args.steps, "objective_steps": args.objective_steps}, []
    for part, fn in (("sparse", _sparse), ("goal", _goal), ("tasks", _tasks)):
        if part in args.parts:
            report[part], tables = fn(args, model)
            md += tables
    report["wall_seconds"] = round(time.perf_counter() - t0, 1)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "report.json", (json.dumps(report, indent=1) + "\n").encode())
    atomic_write_bytes(out / "report.md", "\n".join(md).encode())
    print("\n".join(md))
    print(f"wrote {out / 'report.md'} and report.json ({report['wall_seconds']:.0f} s)")
    return 0
