"""`kinema bench TARGET`: timing benchmarks of kinema's hot paths on real data.

Each target is a sub-command registered by a ``_register_<target>`` function below (``bench bvh``,
``bench train``, ``bench generate``, ``bench all``), so a benchmark is always reproducible from the
command line. Thread counts go through kinema.runtime.configure_threads like every other command.
"""

from __future__ import annotations

import argparse
import struct
import time
from collections.abc import Callable
from pathlib import Path

from kinema.cli._args import add_guidance_cache_arguments, add_precision_argument, positive_float, positive_int
from kinema.cli.batch import register_bench as register_batch_bench
from kinema.cli.bench_keyjoint_planning import register_bench as register_keyjoint_planning_bench
from kinema.cli.bench_objectives import register_bench as register_objectives_bench
from kinema.cli.bench_stream import register_bench as register_stream_bench
from kinema.errors import DataError
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    """Add ``bench`` with one sub-command per benchmark target to the top-level parser."""
    p = sub.add_parser("bench", help="time kinema's hot paths on real data", description=__doc__)
    targets = p.add_subparsers(dest="target", required=True, metavar="TARGET")
    _register_bvh(targets)
    _register_gltf(targets)
    _register_io(targets)
    _register_train(targets)
    _register_train_modes(targets)
    _register_generate(targets)
    register_batch_bench(targets)
    register_objectives_bench(targets)
    register_keyjoint_planning_bench(targets)
    register_stream_bench(targets)
    _register_all(targets)


_positive_int = positive_int


# ----------------------------------------------------------------------------- bench bvh


def _register_bvh(targets) -> None:
    p = targets.add_parser(
        "bvh",
        help="parse every *.bvh.gz of a dataset, raw and converted to Motion",
        description="Time parse_bvh (raw layer) and read_bvh (parse + conversion to Motion) over every "
        "*.bvh.gz under --root; MB/s counts uncompressed BVH text.",
    )
    p.add_argument(
        "--root",
        type=Path,
        default=None,
        help="folder searched recursively (default: ../shared/datasets/bandai-namco, from the cwd)",
    )
    p.add_argument(
        "--limit", type=_positive_int, default=None, help="only the first N files (sorted by path)"
    )
    p.add_argument(
        "--scale", type=float, default=0.01, help="length scale for read_bvh (default 0.01: cm -> m)"
    )
    p.add_argument(
        "--threads",
        type=_positive_int,
        default=1,
        help="torch intra-op threads (default 1: per-clip tensors are small, and extra threads on a "
        "busy machine slow the conversion down by orders of magnitude)",
    )
    p.set_defaults(func=run_bench_bvh)


def _text_bytes(path: Path) -> int:
    """Uncompressed size of a gzip file from its trailer (ISIZE, exact below 4 GiB)."""
    with path.open("rb") as fh:
        fh.seek(-4, 2)
        return struct.unpack("<I", fh.read(4))[0]


def run_bench_bvh(args) -> int:
    """Parse the files twice (raw, then to Motion) and print a throughput table."""
    from tqdm import tqdm

    from kinema.io.bvh import parse_bvh, read_bvh
    from kinema.runtime import configure_threads

    configure_threads(args.threads)

    root = args.root if args.root is not None else Path.cwd().parent / "shared" / "datasets" / "bandai-namco"
    files = sorted(root.rglob("*.bvh.gz")) if root.is_dir() else []
    if args.limit is not None:
        files = files[: args.limit]
    if not files:
        raise DataError(f"no *.bvh.gz files under {root}")
    try:
        megabytes = sum(_text_bytes(f) for f in files) / 1e6
    except (OSError, struct.error) as err:
        raise DataError(f"cannot read gzip sizes under {root}: {err}") from None

    def raw(path: Path) -> tuple[int, float]:
        data = parse_bvh(path)
        return data.num_frames, data.num_frames * data.frame_time

    def motion(path: Path) -> tuple[int, float]:
        m = read_bvh(path, scale=args.scale)
        return m.num_frames, m.duration

    stages: list[tuple[str, Callable[[Path], tuple[int, float]]]] = [
        ("raw parse", raw),
        ("to Motion", motion),
    ]
    rows = []
    for label, fn in stages:
        frames, seconds = 0, 0.0
        start = time.perf_counter()
        for path in tqdm(files, desc=label, unit="file", mininterval=0.5):
            n, s = fn(path)
            frames += n
            seconds += s
        elapsed = time.perf_counter() - start
        rows.append(
            (label, len(files), frames, seconds / 3600, elapsed, len(files) / elapsed, megabytes / elapsed)
        )

    print(
        f"BVH benchmark: {len(files)} files under {root} ({megabytes:.1f} MB of BVH text, "
        f"{args.threads} torch thread{'s' if args.threads > 1 else ''})"
    )
    header = (
        f"{'stage':<10} {'files':>6} {'frames':>9} {'hours':>7} {'seconds':>8} {'files/s':>8} {'MB/s':>7}"
    )
    print(header)
    print("-" * len(header))
    for label, n, frames, hours, elapsed, fps, mbps in rows:
        print(f"{label:<10} {n:>6} {frames:>9} {hours:>7.3f} {elapsed:>8.2f} {fps:>8.1f} {mbps:>7.1f}")
    return 0


# ----------------------------------------------------------------------------- bench gltf / io


def _register_gltf(targets) -> None:
    p = targets.add_parser("gltf", help="read every *.glb/*.gltf of a folder (container, then rig + clips)",
                           description="Time kinema.io.gltf over every glTF file under --root (kinema.bench.gltf).")
    p.add_argument("--root", type=Path, default=None,
                   help="folder searched recursively (default: ../shared/datasets/quaternius, from the cwd)")
    p.add_argument("--limit", type=_positive_int, default=None, help="only the first N files (sorted by path)")
    p.set_defaults(func=run_bench_gltf)


def run_bench_gltf(args) -> int:
    from kinema.bench.gltf import bench_gltf, format_rows, gltf_files
    from kinema.runtime import configure_threads

    configure_threads(1)
    root = args.root if args.root is not None else Path.cwd().parent / "shared" / "datasets" / "quaternius"
    files = gltf_files(root, args.limit)
    print(format_rows(bench_gltf(files), root, sum(f.stat().st_size for f in files) / 1e6))
    return 0


def _register_io(targets) -> None:
    p = targets.add_parser("io", help="bench bvh and bench gltf on their default datasets",
                           description="Both file readers: `bench bvh` (Bandai Namco) then `bench gltf` (Quaternius).")
    p.add_argument("--bvh-root", type=Path, default=None, help="BVH folder (default ../shared/datasets/bandai-namco)")
    p.add_argument("--gltf-root", type=Path, default=None, help="glTF folder (default ../shared/datasets/quaternius)")
    p.add_argument("--limit", type=_positive_int, default=None, help="only the first N files of each")
    p.set_defaults(func=run_bench_io)


def run_bench_io(args) -> int:
    bvh = argparse.Namespace(root=args.bvh_root, limit=args.limit, scale=0.01, threads=1)
    run_bench_bvh(bvh)
    print()
    return run_bench_gltf(argparse.Namespace(root=args.gltf_root, limit=args.limit))


# ----------------------------------------------------------------------------- bench train


def _register_train(targets) -> None:
    p = targets.add_parser("train", help="training step time, samples/s and FLOPs per model preset",
                           description="Time full training steps (forward, loss, backward, AdamW) on synthetic "
                           "features of the real size; also one batch-3 inference forward pass.")
    p.add_argument("--configs", nargs="+", default=["tiny", "small", "small-1stage"],
                   help="presets to time (default: tiny small small-1stage)")
    p.add_argument("--batch-size", type=_positive_int, default=32)
    p.add_argument("--frames", type=_positive_int, default=100, help="frames per sample (100 = 5 s @ 20 fps)")
    p.add_argument("--joints", type=_positive_int, default=21)
    p.add_argument("--repeats", type=_positive_int, default=3)
    p.add_argument("--threads", type=_positive_int, default=None,
                   help="torch threads (default: KINEMA_THREADS, else chosen by kinema.runtime)")
    p.add_argument("--load", type=int, nargs="+", default=None, metavar="N",
                   help="also compare thread counts (--thread-counts) on the first preset's step, with N "
                        "busy-loop processes running (0 = quiet), interleaved")
    p.add_argument("--thread-counts", type=_positive_int, nargs="+", default=[1, 2])
    p.set_defaults(func=_run_train)


def _run_train(args: argparse.Namespace) -> int:
    import torch
    from tqdm.auto import tqdm

    from kinema.bench.train import bench_config, format_table
    from kinema.runtime import configure_threads

    configure_threads(args.threads, cap=None)
    rows = [bench_config(c, args.joints, args.batch_size, args.frames, args.repeats)
            for c in tqdm(args.configs, desc="bench train")]
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    print(format_table(rows))
    if args.load:
        from kinema.bench.threads import bench_threads, format_threads
        from kinema.bench.train import make_train_step

        step = make_train_step(args.configs[0], args.joints, args.batch_size, args.frames)[1]
        table = bench_threads(step, args.thread_counts, args.load, args.repeats)
        print(format_threads(table, f"{args.configs[0]} train step"))
    return 0


def _register_train_modes(targets) -> None:
    from kinema.bench.train_modes import MODES

    p = targets.add_parser("train-modes", help="training speed and loss parity: fp32 vs bf16 autocast vs torch.compile",
                           description="Train one Trainer per mode on the same data and seed, steps interleaved; "
                           "prints seconds per step, speed-up over fp32 and the loss difference.")
    p.add_argument("--data", type=Path, required=True, help="dataset folder from `kinema data build`")
    p.add_argument("--configs", nargs="+", default=["small"], help="presets (default: small)")
    p.add_argument("--modes", nargs="+", choices=list(MODES), default=["fp32", "bf16", "compile"])
    p.add_argument("--steps", type=_positive_int, default=300)
    p.add_argument("--batch-size", type=_positive_int, default=32)
    p.add_argument("--warmup", type=_positive_int, default=20, help="first steps timed apart (compilation)")
    p.add_argument("--cache-dir", type=Path, default=text_cache_dir(), help="text embedding cache")
    p.add_argument("--json", type=Path, help="also write rows and loss curves to this JSON file")
    p.add_argument("--threads", type=_positive_int, default=None,
                   help="torch threads (default: KINEMA_THREADS, else chosen by kinema.runtime)")
    p.set_defaults(func=_run_train_modes)


def _run_train_modes(args: argparse.Namespace) -> int:
    import json
    from dataclasses import asdict

    import torch

    from kinema.bench.train_modes import bench_train_modes, format_modes
    from kinema.runtime import configure_threads

    threads = configure_threads(args.threads, cap=None)
    rows, curves = [], {}
    for config in args.configs:
        r, c = bench_train_modes(args.data, config, args.modes, args.steps, args.batch_size, args.warmup,
                                 tail=min(100, args.steps), cache_dir=args.cache_dir)
        rows += r
        curves[config] = c
        print(format_modes(r, min(100, args.steps)), flush=True)
    print(f"torch {torch.__version__}, {threads} threads, batch {args.batch_size}")
    print(format_modes(rows, min(100, args.steps)))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": [asdict(r) for r in rows], "losses": curves}))
    return 0


# ----------------------------------------------------------------------------- bench generate


def _add_generate_options(p, model_default: str | None) -> None:
    """Options shared by `bench generate` and `bench all` (see kinema.bench.suite)."""
    from kinema.bench.suite import SECTIONS

    p.add_argument("--model", default=model_default, help="'default' or a run/checkpoint folder")
    p.add_argument("--sections", nargs="+", choices=SECTIONS, default=None,
                   help=f"generation sections to run (default: all of {' '.join(SECTIONS)})")
    p.add_argument("--quick", action="store_true", help="fewer settings and repeats (about a minute)")
    p.add_argument("--steps", type=_positive_int, nargs="+", default=None, help="DDIM steps (default 10 25 50 100)")
    p.add_argument("--repeats", type=_positive_int, default=None, help="repeats per steps setting (default 2)")
    p.add_argument("--samples", type=_positive_int, nargs="+", default=None, help="samples per call (1 4 16)")
    p.add_argument("--durations", type=positive_float, nargs="+", default=None, help="seconds (5 10 20 40)")
    p.add_argument("--lengths", type=positive_float, nargs="+", default=None,
                   help="seconds of the lengths section's walk and run (5 10 60)")
    p.add_argument("--thread-counts", type=_positive_int, nargs="+", default=None, help="threads compared (1 2)")
    p.add_argument("--load", type=int, nargs="+", default=None, metavar="N",
                   help="busy-loop processes for the threads section; 0 = quiet (default 0 2)")
    p.add_argument("--thread-repeats", type=_positive_int, default=None, help="rounds per thread count (3)")
    p.add_argument("--threads", type=_positive_int, default=None,
                   help="torch threads outside the threads section (default: KINEMA_THREADS, else kinema.runtime)")


def _suite_options(args: argparse.Namespace, sections: tuple[str, ...]):
    """GenerateSuiteOptions from the shared options; unset ones keep the (quick) defaults."""
    from kinema.bench.suite import GenerateSuiteOptions
    from kinema.errors import KinemaError

    given = {"steps": args.steps, "repeats": args.repeats, "samples": args.samples, "durations": args.durations,
             "lengths": args.lengths,
             "threads": args.thread_counts, "loads": args.load, "thread_repeats": args.thread_repeats}
    if args.load is not None and any(n < 0 for n in args.load):
        raise KinemaError("--load: busy-loop process counts must be >= 0")
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in given.items() if v is not None}
    kw.update(model=args.model, sections=tuple(args.sections or sections))
    return GenerateSuiteOptions.quick(**kw) if args.quick else GenerateSuiteOptions(**kw)


def _register_generate(targets) -> None:
    p = targets.add_parser("generate", help="generation speed: DDIM steps, samples, durations, threads, cold start")
    _add_generate_options(p, "default")
    p.add_argument("--seconds", type=positive_float, default=5.0)
    p.add_argument("--no-cold-start", action="store_true", help="skip the fresh-process section")
    add_precision_argument(p)
    add_guidance_cache_arguments(p)
    p.set_defaults(func=_run_generate)


def _run_generate(args: argparse.Namespace) -> int:
    import torch

    from kinema.bench.suite import SECTIONS, format_generate_suite, run_generate_suite
    from kinema.runtime import configure_threads

    threads = configure_threads(args.threads)
    if _is_anyrig(args.model):  # a model for any rig: its own table (kinema.bench.anyrig)
        return _run_anyrig(args, threads)
    opts = _suite_options(args, SECTIONS)
    opts.seconds = args.seconds
    opts.guidance_refresh, opts.guidance_cached = args.guidance_refresh, args.guidance_cached
    if args.no_cold_start:
        opts.sections = tuple(s for s in opts.sections if s != "cold")
    result = run_generate_suite(opts)
    print(f"torch {torch.__version__}, {threads} threads, model {args.model}")
    print(format_generate_suite(result))
    return 0


def _is_anyrig(model: str | None) -> bool:
    """True when ``model`` loads as a pipeline that needs a rig per request (its bench times rigs)."""
    from kinema.errors import KinemaError
    from kinema.generate import load_model

    try:
        return model is not None and load_model(model).needs_rig
    except KinemaError:
        return False


def _run_anyrig(args: argparse.Namespace, threads: int) -> int:
    import torch

    from kinema.bench.anyrig import bench_anyrig, format_anyrig_bench
    from kinema.generate import load_model

    model = load_model(args.model)
    steps = tuple(args.steps) if args.steps else ((20,) if args.quick else (10, 20, 30))
    rows = bench_anyrig(model, seconds=args.seconds, steps_list=steps, repeats=args.repeats or (1 if args.quick else 2))
    print(f"torch {torch.__version__}, {threads} threads, model {args.model}")
    print(format_anyrig_bench(rows))
    return 0


# ----------------------------------------------------------------------------- bench all


def _register_all(targets) -> None:
    p = targets.add_parser("all", help="training and generation benchmarks into one report (report.md/json)")
    _add_generate_options(p, None)
    p.add_argument("--out", type=Path, default=Path("out/bench"), help="report folder (default out/bench)")
    p.set_defaults(func=_run_all)


def _run_all(args: argparse.Namespace) -> int:
    from kinema.bench.report import run_all, write_bench_report
    from kinema.bench.suite import SECTIONS
    from kinema.runtime import configure_threads

    configure_threads(args.threads)
    opts = _suite_options(args, SECTIONS)
    result = run_all(args.model, suite=opts)
    path = write_bench_report(result, args.out)
    print(path.read_text())
    print(f"wrote {path} and {path.with_name('report.json')}")
    return 0
