"""`kinema evaluate`: score a model on the Kimodo-style test suite (docs/evaluation.md).

``kinema evaluate sfcontrol|fidelity ...`` is ``--protocol sfcontrol|fidelity``: SFControl's protocols
(kinema.cli.evaluate_sfcontrol) and caption fidelity per action (kinema.cli.evaluate_fidelity)."""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import (
    add_grounding_arguments,
    add_guidance_cache_arguments,
    add_precision_argument,
    grounding_overrides,
    non_negative_float,
    positive_int,
    seed,
)
from kinema.cli.evaluate_fidelity import add_arguments as add_fidelity_arguments
from kinema.cli.evaluate_fidelity import run_fidelity_cli
from kinema.cli.evaluate_sfcontrol import add_arguments as add_sfcontrol_arguments
from kinema.cli.evaluate_sfcontrol import run_sfcontrol
from kinema.errors import KinemaError
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="score a model on the evaluation suite (report.md, report.json, plots)")
    p.add_argument("protocol_name", nargs="?", choices=PROTOCOLS, metavar="PROTOCOL",
                   help="same as --protocol: 'suite', 'sfcontrol' or 'fidelity' (per-action caption fidelity)")
    p.add_argument("--model", required=True, help="'default' (shipped) or a run/checkpoint folder")
    p.add_argument("--data", type=Path, default=Path("cache/bandai20"), help="dataset build (default cache/bandai20)")
    p.add_argument("--split", default="test", choices=("train", "val", "test"), help="clips to draw cases from")
    p.add_argument("--cases", type=int, default=100, help="number of cases when building a suite (default 100)")
    p.add_argument("--timeline-cases", type=int, default=8,
                   help="multi-prompt timeline cases added when building a suite (default 8; 0 = none)")
    p.add_argument("--text-fraction", type=float, default=0.3,
                   help="share of text-only cases when building a suite (default 0.3; 1 = text cases only)")
    p.add_argument("--phrasings", type=int, default=3, metavar="SAMPLES",
                   help="prompts in other words: samples per probe prompt, plus the text cases again from held-out "
                        "captions (default 3; 0 = skip)")
    p.add_argument("--seed", type=seed, default=0, help="suite and generation seed")
    p.add_argument("--steps", type=positive_int, help="DDIM steps (default: the model's setting)")
    p.add_argument("--guidance", type=non_negative_float, nargs=2, metavar=("W_TEXT", "W_CONSTR"),
                   help="separated guidance weights (default: the model's setting)")
    add_grounding_arguments(p)
    p.add_argument("--imputation-only", action="store_true",
                   help="ablation: the paper's sampling (no root smoothing, start anchor, root or joint displacement)")
    p.add_argument("--out", type=Path,
                   help="output folder (default out/eval/<model name>); fidelity: the JSON file (table as .md)")
    p.add_argument("--suite", type=Path,
                   help="suite JSON: read it if it exists (same cases as an earlier run), else build and save it")
    p.add_argument("--retrieval", default="default",
                   help="retrieval model folder for R@k/FID ('default' = shipped, 'none' = skip)")
    p.add_argument("--modes", choices=("both", "raw", "post"), default="both", help="post-processing modes")
    p.add_argument("--mm", type=int, nargs=2, default=(3, 4), metavar=("PROMPTS", "SAMPLES"),
                   help="multimodality: prompts x samples (default 3 4; SAMPLES < 2 skips it)")
    p.add_argument("--filmstrips", type=int, default=4, help="rendered cases (default 4)")
    p.add_argument("--no-progress", action="store_true")
    add_sfcontrol_arguments(p)
    add_fidelity_arguments(p)
    add_precision_argument(p)
    add_guidance_cache_arguments(p)
    p.set_defaults(func=run)


PROTOCOLS = ("suite", "sfcontrol", "fidelity")


def _protocol(args: argparse.Namespace) -> str:
    """The protocol asked for, by the positional name or ``--protocol`` (they must agree when both given)."""
    name = args.protocol_name
    if name is not None and args.protocol not in ("suite", name):
        raise KinemaError(f"protocol {name!r} and --protocol {args.protocol} disagree")
    return name or args.protocol


def _apply_sampling_options(model, args: argparse.Namespace) -> None:
    """On the loaded model: grounding overrides (every row, probe and held-out case then uses them), the
    imputation-only ablation and guidance caching."""
    if grounding_overrides(args):
        model.grounding = model.grounding_settings(grounding_overrides(args))
    if args.imputation_only:
        model.root_displacement, model.root_smoothing, model.joint_sigma = False, 0.0, 0.0
    model.guidance_refresh, model.guidance_cached = args.guidance_refresh, args.guidance_cached


def run(args: argparse.Namespace) -> int:
    import time

    from kinema.evaluate.phrasings import PROBE_ROLES
    from kinema.evaluate.report import write_report
    from kinema.evaluate.runner import run_suite
    from kinema.evaluate.suite import save_suite
    from kinema.generate import load_model, resolve_model_path

    args.protocol = _protocol(args)
    if args.protocol == "sfcontrol":
        return run_sfcontrol(args)
    if args.protocol == "fidelity":
        return run_fidelity_cli(args)
    t0 = time.perf_counter()
    _check_options(args)
    resolve_model_path(args.model)  # fail early on a missing model, before building anything
    out = args.out or Path("out/eval") / (Path(str(args.model)).resolve().name or "model")
    if out.exists() and not out.is_dir():
        raise KinemaError(f"{out}: exists and is not a folder")
    cases = _suite_cases(args)
    model = load_model(args.model, text_cache=text_cache_dir())
    if args.phrasings:  # the probes' measures need these joints: fail now, not after the suite
        try:
            model.skeleton.require_roles(PROBE_ROLES)
        except KinemaError as err:
            raise KinemaError(f"--phrasings: {err}; or pass --phrasings 0") from None
    _apply_sampling_options(model, args)
    save_suite(cases, out / "suite.json")
    modes = {"both": (False, True), "raw": (False,), "post": (True,)}[args.modes]
    results = run_suite(model, cases, postprocess_modes=modes, steps=args.steps, seed=args.seed,
                        progress=not args.no_progress, retrieval=args.retrieval, mm_prompts=args.mm[0],
                        mm_samples=args.mm[1], text_cache=text_cache_dir(),
                        guidance=tuple(args.guidance) if args.guidance else None, phrasings=args.phrasings)
    _print_report(write_report(results, out, filmstrips=args.filmstrips), out)
    print(f"wall time {time.perf_counter() - t0:.1f} s")
    return 0


def _check_options(args: argparse.Namespace) -> None:
    """One-line errors for option values out of range, before anything is loaded."""
    if args.cases < 1 or args.timeline_cases < 0:
        raise KinemaError("--cases must be at least 1 and --timeline-cases at least 0")
    if not 0.0 < args.text_fraction <= 1.0:
        raise KinemaError(f"--text-fraction must be in (0, 1], got {args.text_fraction:g}")
    if args.phrasings < 0:
        raise KinemaError(f"--phrasings must be at least 0 (samples per probe prompt), got {args.phrasings}")
    if args.steps is not None and args.steps < 1:
        raise KinemaError("--steps must be at least 1")
    if args.filmstrips < 0 or args.mm[0] < 0:
        raise KinemaError("--filmstrips and --mm PROMPTS must not be negative")


def _suite_cases(args: argparse.Namespace) -> list:
    """The evaluation cases: read from ``--suite`` when that file exists, else built from ``--data`` (and
    saved to ``--suite`` when given)."""
    from kinema.data.dataset import MotionDataset
    from kinema.evaluate.suite import build_suite, load_suite, save_suite
    from kinema.evaluate.timeline import build_timeline_cases

    if args.suite is not None and args.suite.exists():
        cases = load_suite(args.suite)
        print(f"suite: {len(cases)} cases from {args.suite}")
        return cases
    if not args.data.is_dir():
        raise KinemaError(f"{args.data}: dataset folder does not exist (run `kinema data build` first)")
    cases = build_suite(args.data, args.split, num_cases=args.cases, seed=args.seed, text_fraction=args.text_fraction)
    if args.timeline_cases:
        try:
            cases += build_timeline_cases(MotionDataset(args.data, args.split), args.data.resolve(), args.split,
                                          args.timeline_cases, args.seed, first_id=len(cases))
        except ValueError as err:
            raise KinemaError(str(err)) from None
    if args.suite is not None:
        save_suite(cases, args.suite)
    print(f"suite: {len(cases)} cases from {args.data} ({args.split}), seed {args.seed}")
    return cases


def _print_report(data: dict, out: Path) -> None:
    """The report's tables and warnings on stdout, and where the files are."""
    from kinema.evaluate.report import format_phrasings_table, format_table, format_timeline_table

    print()
    print(format_table(data))
    if data.get("timeline"):
        print()
        print(format_timeline_table(data))
    if data.get("phrasings"):
        print()
        print(format_phrasings_table(data))
    for w in data["warnings"]:
        print(f"warning: {w}")
    print(f"wrote {out / 'report.md'}, {out / 'report.json'}, {out / 'suite.json'} and {out / 'plots'}/")
