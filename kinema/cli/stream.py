"""`kinema stream --script S.jsonl --seconds N --out OUT`: a scripted live stream (kinema.stream).

The script's timed commands (prompt, steer, target, clear; docs/stream.md) are played into a
`MotionStream` of the model; the whole stream is written with ``Motion.save`` (.bvh, .bvh.gz, .npz,
.glb, .json) and a JSON log next to it (``--log``, default ``OUT`` with ``.stream.json``): each
command's latency (seconds of motion until the first frame that obeys it, wall seconds until that
frame was generated), each window's timings and the real-time factor.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import add_precision_argument, positive_int
from kinema.errors import KinemaError


def register(sub) -> None:
    """Add the `stream` sub-command to the top-level parser."""
    p = sub.add_parser("stream", help="play a script of timed prompt/steer/target commands into a live stream")
    p.add_argument("--script", type=Path, required=True, help="JSON lines: {\"t\": 0, \"prompt\": \"...\"}, ...")
    p.add_argument("--seconds", type=float, required=True, help="seconds of motion to stream")
    p.add_argument("--out", type=Path, required=True, help="the whole stream: .bvh, .bvh.gz, .npz, .glb or .json")
    p.add_argument("--log", type=Path, help="JSON log of latencies and window timings (default OUT.stream.json)")
    p.add_argument("--model", default="default", help="'default' (shipped human model), 'creatures' or a model folder")
    p.add_argument("--rig", help="the character of an any-rig model (e.g. --model creatures): a GLB/glTF or BVH "
                                 "file or a training rig id")
    p.add_argument("--threads", type=positive_int, help="CPU threads for torch (default: KINEMA_THREADS, else "
                                                         "1-2 by load)")
    p.add_argument("--window-seconds", type=float,
                   help="seconds of one generated window (default 3, or the model's window if shorter: creatures 2)")
    p.add_argument("--lookahead", type=float, default=0.15,
                   help="seconds kept ahead of the played frames when a command arrives (default 0.15)")
    p.add_argument("--steps", type=positive_int, help="DDIM steps per window (default 10)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the first window (default 0)")
    add_precision_argument(p)
    p.set_defaults(func=run)


def log_path(out: Path) -> Path:
    """``walk.bvh`` -> ``walk.stream.json``."""
    name = out.name
    for suffix in (".bvh.gz", out.suffix):
        if suffix and name.lower().endswith(suffix):
            name = name[: -len(suffix)]
            break
    return out.with_name(name + ".stream.json")


def run(args: argparse.Namespace) -> int:
    # imported here like every sub-command's work, so that `kinema --help` does not load torch
    import json

    from kinema.atomic_files import atomic_write_text, check_output_path
    from kinema.generate import load_model
    from kinema.input_files import check_input_file
    from kinema.pipeline.request import GenerationRequest
    from kinema.runtime import configure_threads, text_cache_dir
    from kinema.stream import open_stream
    from kinema.stream.script import MAX_SECONDS, read_script, run_script

    check_input_file(args.script, "stream script")
    commands = read_script(args.script)
    if not (args.seconds > 0 and args.seconds <= MAX_SECONDS):
        raise KinemaError(f"--seconds must be in (0, {MAX_SECONDS:g}], got {args.seconds:g}")
    log = args.log or log_path(args.out)
    check_output_path(args.out)
    check_output_path(log)
    threads = configure_threads(args.threads)
    model = load_model(args.model, text_cache=text_cache_dir())
    request = GenerationRequest(seed=args.seed, rig=args.rig)
    stream = open_stream(model, request, window_seconds=args.window_seconds, lookahead=args.lookahead,
                         steps=args.steps)
    played = run_script(stream, commands, args.seconds)
    out = played.motion.save(args.out)
    report = played.log() | {"threads": threads, "script": str(args.script), "out": str(out)}
    atomic_write_text(log, json.dumps(report, indent=1) + "\n")
    latencies = [c["latency_seconds"] for c in report["commands"]]
    print(f"wrote {out}: {played.motion.duration:.2f} s, {played.motion.num_frames} frames @ "
          f"{played.motion.fps:g} fps in {played.wall_seconds:.2f} s wall ({played.realtime_factor:.1f}x real "
          f"time, {threads} thread(s)); {len(latencies)} commands, latency up to "
          f"{max(latencies, default=0):.2f} s of motion; log {log}")
    joins = report["joins"]
    if joins["joins"]:
        print(f"joins ({joins['joins']}): pelvis speed change {joins['join_speed_change']:.1f} m/s^2 against the "
              f"windows' own largest {joins['inside_speed_change_max']:.1f}, joint acceleration "
              f"{joins['join_acceleration']:.0f} against {joins['inside_acceleration_max']:.0f}"
              f"{'' if joins['ok'] else ' (a pop: a join goes beyond the windows themselves)'}")
    return 0
