"""`kinema batch JOBS.jsonl --out DIR`: many motions, resumable, on local processes or Ray.

One JSON object per line (prompt or timeline, constraints, seed, format, ...; docs/server.md). Rerun the
same command after a crash or Ctrl-C: finished outputs are skipped. ``--bench`` prints motions per
minute against the number of workers instead (no jobs file needed).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from kinema.cli._args import add_precision_argument, positive_float, positive_int


def register(sub) -> None:
    p = sub.add_parser("batch", help="generate many motions from a JSONL jobs file (resumable; Ray scale-out)",
                       description=__doc__)
    p.add_argument("jobs", nargs="?", type=Path, help="jobs file: one JSON object per line")
    p.add_argument("--out", type=Path, help="output folder (files, manifest.jsonl)")
    p.add_argument("--model", default="default", help="'default' (shipped) or a run/checkpoint folder (on a "
                   "cluster: the same path on every node)")
    p.add_argument("--workers", type=positive_int, help="worker processes / Ray actors, each loading the model "
                   "once (default: the cores here, or the cluster's CPUs with --ray); with --bench: the largest "
                   "count measured")
    p.add_argument("--ray", metavar="local|auto|ADDRESS", help="run on Ray: 'local' starts a private local Ray, "
                   "'auto' joins the cluster Ray finds (RAY_ADDRESS or a 'ray start' on this machine), HOST:PORT "
                   "or ray://HOST:PORT joins that cluster (default: local processes, no Ray)")
    p.add_argument("--threads", type=positive_int, default=1, help="torch threads per worker (default 1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    b = p.add_argument_group("benchmark (--bench)")
    b.add_argument("--bench", action="store_true", help="print motions/min for 1..--workers workers")
    b.add_argument("--bench-jobs", type=positive_int, default=8, help="motions per configuration (default 8)")
    b.add_argument("--seconds", type=positive_float, default=4.0, help="motion length in the benchmark (default 4)")
    b.add_argument("--steps", type=positive_int, help="DDIM steps in the benchmark (default: the model's)")
    add_precision_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.errors import KinemaError

    if args.bench:
        return _bench(args)
    if args.jobs is None or args.out is None:
        raise KinemaError("kinema batch needs a jobs file and --out DIR (or --bench)")
    try:
        from kinema.batch.runner import run_batch
    except ImportError as err:
        raise KinemaError(f"kinema batch needs the batch extra: pip install 'kinema[batch]' ({err})") from None
    s = run_batch(args.jobs, args.out, model=args.model, workers=args.workers, ray=args.ray, threads=args.threads,
                  progress=not args.no_progress)
    for line in s.errors[:20]:
        print(f"kinema: failed: {line}", file=sys.stderr)
    if len(s.errors) > 20:
        print(f"kinema: ... and {len(s.errors) - 20} more failures (see the manifest)", file=sys.stderr)
    rate = f", {60 * s.done / s.run_s:.1f} motions/min on {s.workers} worker(s)" if s.run_s > 0 and s.done else ""
    print(f"kinema batch: {s.done} done, {s.skipped} already finished, {s.failed} failed of {s.total} jobs{rate}; "
          f"manifest: {args.out / 'manifest.jsonl'}")
    return 1 if s.failed else 0


def register_bench(targets) -> None:
    """``kinema bench batch``: the same benchmark as ``kinema batch --bench``, as a target of ``kinema bench``."""
    p = targets.add_parser("batch", help="batch throughput: motions per minute against the number of workers",
                           description="Runs --jobs motions through kinema batch for 1, 2, 4, ..., --workers workers "
                                       "(model loading timed apart); see docs/server.md.")
    p.add_argument("--model", default="default", help="'default' (shipped) or a run/checkpoint folder")
    p.add_argument("--workers", type=positive_int, help="largest worker count (default: the cores here)")
    p.add_argument("--jobs", dest="bench_jobs", type=positive_int, default=8, help="motions per row (default 8)")
    p.add_argument("--seconds", type=positive_float, default=4.0, help="motion length (default 4)")
    p.add_argument("--steps", type=positive_int, help="DDIM steps (default: the model's)")
    p.add_argument("--ray", metavar="local|auto|ADDRESS", help="measure Ray workers instead of local processes")
    p.set_defaults(func=_bench)


def _bench(args: argparse.Namespace) -> int:
    from kinema.batch.bench import bench_batch, format_table, worker_counts
    from kinema.runtime import cpu_cores

    counts = worker_counts(args.workers or cpu_cores())
    rows = bench_batch(counts, jobs=args.bench_jobs, seconds=args.seconds, steps=args.steps, model=args.model,
                       ray=args.ray)
    executor = f"Ray {args.ray}" if args.ray else "local processes (1 worker: in-process)"
    print(format_table(rows, seconds=args.seconds, steps=args.steps, executor=executor))
    return 0
