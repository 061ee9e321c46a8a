"""`kinema bench TARGET`: timing benchmarks of kinema's hot paths on real data.

Each target is a sub-command registered by a ``_register_<target>`` function below (``bench bvh``
today; ``bench train`` and ``bench generate`` are meant to join it the same way), so a benchmark
is always reproducible from the command line.
"""

from __future__ import annotations

import argparse
import struct
import time
from collections.abc import Callable
from pathlib import Path

from kinema.cli._args import positive_int
from kinema.errors import DataError


def register(sub) -> None:
    """Add ``bench`` with one sub-command per benchmark target to the top-level parser."""
    p = sub.add_parser("bench", help="time kinema's hot paths on real data", description=__doc__)
    targets = p.add_subparsers(dest="target", required=True, metavar="TARGET")
    _register_bvh(targets)
    _register_train(targets)
    _register_generate(targets)
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
    import torch
    from tqdm import tqdm

    from kinema.io.bvh import parse_bvh, read_bvh

    torch.set_num_threads(args.threads)

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
    p.add_argument("--threads", type=_positive_int, default=None, help="torch threads (default: all cores)")
    p.set_defaults(func=_run_train)


def _run_train(args: argparse.Namespace) -> int:
    import torch
    from tqdm.auto import tqdm

    from kinema.bench.train import bench_config, format_table

    if args.threads:
        torch.set_num_threads(args.threads)
    rows = [bench_config(c, args.joints, args.batch_size, args.frames, args.repeats)
            for c in tqdm(args.configs, desc="bench train")]
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    print(format_table(rows))
    return 0


# ----------------------------------------------------------------------------- bench generate


def _register_generate(targets) -> None:
    p = targets.add_parser("generate", help="seconds per motion vs DDIM steps, constraints, post-processing")
    p.add_argument("--model", default="default", help="'default' or a run/checkpoint folder")
    p.add_argument("--steps", type=_positive_int, nargs="+", default=[10, 25, 50, 100])
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--repeats", type=_positive_int, default=2)
    p.add_argument("--no-cold-start", action="store_true")
    p.add_argument("--threads", type=_positive_int, default=None)
    p.set_defaults(func=_run_generate)


def _run_generate(args: argparse.Namespace) -> int:
    import torch

    from kinema.bench.generate import bench_generate, cold_start, format_table

    if args.threads:
        torch.set_num_threads(args.threads)
    rows = bench_generate(args.model, args.steps, args.seconds, args.repeats)
    cold = None if args.no_cold_start else cold_start(args.model, seconds=args.seconds)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, model {args.model}")
    print(format_table(rows, cold, args.seconds))
    return 0


# ----------------------------------------------------------------------------- bench all


def _register_all(targets) -> None:
    p = targets.add_parser("all", help="training and generation benchmarks into one report (report.md/json)")
    p.add_argument("--model", default=None, help="model for the generation part ('default' or a run folder)")
    p.add_argument("--out", type=Path, default=Path("out/bench"), help="report folder (default out/bench)")
    p.add_argument("--steps", type=_positive_int, nargs="+", default=[10, 25, 50, 100])
    p.add_argument("--repeats", type=_positive_int, default=2)
    p.set_defaults(func=_run_all)


def _run_all(args: argparse.Namespace) -> int:
    from kinema.bench.report import run_all, write_bench_report

    result = run_all(args.model, steps=args.steps, repeats=args.repeats)
    path = write_bench_report(result, args.out)
    print(path.read_text())
    print(f"wrote {path} and {path.with_name('report.json')}")
    return 0
