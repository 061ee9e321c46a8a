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

from kinema.atomic_files import atomic_write_bytes
from kinema.runtime import text_cache_dir

SPARSE_ROWS = ("direct", "keyjoint-planned", "direct + noise opt")


def add_arguments(p) -> None:
    p.add_argument(
        "--protocol",
        choices=("suite", "sfcontrol", "fidelity"),
        default="suite",
        help="'suite' (Kimodo-style test suite, default), 'sfcontrol' (sparse keyjoint control, "
        "goal reaching, implicit tasks; docs/objectives.md) or 'fidelity' (per-action caption fidelity, "
        "kinema.evaluate.fidelity)",
    )
    p.add_argument("--keyjoint-model",
                   help="sfcontrol: keyjoint model ('default' or a folder) for the keyjoint-planned rows")
    p.add_argument("--objective-steps", type=int, default=8, help="sfcontrol: noise iterations (default 8)")
    p.add_argument(
        "--sparse-rows",
        nargs="+",
        choices=SPARSE_ROWS,
        default=SPARSE_ROWS,
        help="sfcontrol: rows of the sparse protocol (default all; keyjoint-planned needs --keyjoint-model)",
    )
    p.add_argument(
        "--parts",
        nargs="+",
        choices=("sparse", "ee", "goal", "tasks"),
        default=("sparse", "goal", "tasks"),
        help="sfcontrol: which protocols to run (default sparse goal tasks; 'ee': the suite's end-effector "
        "cases (--suite, else --cases built) direct vs keyjoint-planned)",
    )


def _table(title: str, rows: dict, cols: list[tuple[str, str, str]]) -> str:
    lines = [f"### {title}", "", "| row | " + " | ".join(c[1] for c in cols) + " |", "|---|" + "---|" * len(cols)]
    for name, v in rows.items():
        lines.append(
            f"| {name} | " + " | ".join("-" if v.get(c[0]) is None else format(v[c[0]], c[2]) for c in cols) + " |"
        )
    return "\n".join(lines) + "\n"


SPARSE_COLS = [
    ("control_cm", "control error (cm)", ".2f"),
    ("skate", "skate (cm/s)", ".1f"),
    ("jerk", "jerk", ".0f"),
    ("seconds", "s / motion", ".1f"),
    ("r3_whole", "R@3 (all cases)", ".3f"),
    ("r3_batch32", "R@3 (batches of 32)", ".3f"),
    ("fid", "FID", ".2f"),
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
    from kinema.evaluate import sfcontrol as S
    from kinema.evaluate.retrieval import default_retrieval_path, load_retrieval
    from kinema.human.keyjoint_planning import KeyjointPlanner

    rows, kj = list(args.sparse_rows), None
    if args.keyjoint_model is not None:
        kj = KeyjointPlanner.load(args.keyjoint_model, model.precision)  # the body model's precision
    else:
        rows = [r for r in rows if not r.startswith("keyjoint-planned")]
    cases = S.sparse_cases(args.data, args.cases, seed=args.seed)
    raw = S.evaluate_sparse(
        model, cases, rows=rows, keyjoint=kj, steps=args.steps, objective_steps=args.objective_steps, seed=args.seed
    )
    res, warn = S.summarize(raw), []
    text = S.text_scores(load_retrieval(default_retrieval_path()), cases, raw, seed=args.seed, warn=warn)
    for row, v in res.items():
        v.update(text[row])
    res["ground truth"] = dict.fromkeys(("control_cm", "skate", "jerk", "seconds")) | text["ground_truth"]
    title = f"Sparse control ({len(cases)} test crops of 5 s, a target every 1.5 s on 3 of 6 keyjoints, raw)"
    notes = "".join(f"\n- {w}" for w in warn)
    return res, [_table(title, res, SPARSE_COLS) + notes]


EE_COLS = [
    ("cases", "cases", "d"),
    ("ee_pos_cm", "EE pos (cm)", ".2f"),
    ("ee_rot_deg", "EE rot (deg)", ".1f"),
    ("root2d_pos_cm", "2D root (cm)", ".2f"),
    ("foot_skate_cm_s", "skate (cm/s)", ".1f"),
    ("jerk", "jerk", ".0f"),
    ("seconds", "s / motion", ".2f"),
]


def _ee(args: argparse.Namespace, model) -> tuple[dict, list[str]]:
    from kinema.evaluate import sfcontrol_suite as E
    from kinema.evaluate.suite import build_suite, load_suite, save_suite
    from kinema.human.keyjoint_planning import KeyjointPlanner

    if args.suite is not None and args.suite.exists():
        cases = load_suite(args.suite)
    else:
        cases = build_suite(args.data, args.split, num_cases=args.cases, seed=args.seed)
        if args.suite is not None:
            save_suite(cases, args.suite)
    kj = None if args.keyjoint_model is None else KeyjointPlanner.load(args.keyjoint_model, model.precision)
    per_case = E.evaluate_suite_ee(model, cases, planner=kj, steps=args.steps, seed=args.seed)
    res = E.summarize_suite(per_case)
    title = f"Suite end-effector cases ({len(cases)}-case suite, {args.split} split, seed {args.seed}, raw)"
    return {"summary": res, "cases": per_case}, [_table(title, res, EE_COLS)]


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
    from kinema.generate import load_model

    t0 = time.perf_counter()
    out = args.out or Path("out/eval/sfcontrol")
    model = load_model(args.model, text_cache=text_cache_dir())
    report, md = {"cases": args.cases, "steps": args.steps, "objective_steps": args.objective_steps}, []
    for part, fn in (("sparse", _sparse), ("ee", _ee), ("goal", _goal), ("tasks", _tasks)):
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
