"""`kinema train-anyrig-root`: train the root stage of an any-rig model (kinema.model.anyrig.root_stage)."""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import content_share, non_negative_float, positive_float, positive_int
from kinema.cli.train_anyrig import model_folder, start_run
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    p = sub.add_parser("train-anyrig-root",
                       help="train an any-rig model's root stage (the root row denoised first, from text and rig)")
    p.add_argument("--model", required=True,
                   help="the any-rig model the stage belongs to: a model folder, a run, or 'creatures'")
    p.add_argument("--data", type=Path, required=True, help="the multi-rig build the model trained on")
    p.add_argument("--out", type=Path, required=True, help="run folder, e.g. runs/creatures-root")
    p.add_argument("--steps", type=positive_int, help="total optimisation steps (default 6000)")
    p.add_argument("--lr", type=positive_float)
    p.add_argument("--batch-size", type=positive_int, help="windows per batch (default 64)")
    p.add_argument("--width", type=positive_int, help="token width (default 128)")
    p.add_argument("--layers", type=positive_int, help="blocks (default 4)")
    p.add_argument("--variants", type=int, help="rig-augmented copies per clip (default 2)")
    p.add_argument("--velocity-weight", type=positive_float,
                   help="x the loss on the root's ground velocity (default 1)")
    p.add_argument("--path-weight", type=non_negative_float,
                   help="weight of the ground-path loss: the velocity error summed over the window (default 0)")
    p.add_argument("--content-share", type=content_share, action="append", metavar="CONTENT=SHARE",
                   help="draw this share of every batch from the clips of this content, e.g. idle=0.25 (repeatable)")
    p.add_argument("--ckpt-every", type=positive_int)
    p.add_argument("--log-every", type=positive_int)
    p.add_argument("--seed", type=int)
    p.add_argument("--cache-dir", type=Path, default=text_cache_dir(), help="text embedding cache")
    p.add_argument("--resume", action="store_true", help="continue the newest checkpoint in --out")
    p.add_argument("--minutes", type=positive_float, help="stop cleanly after this many minutes (checkpoint written)")
    p.add_argument("--threads", type=positive_int, help="torch CPU threads (default chosen by kinema.runtime)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.train.anyrig.root_stage import RootStageTrainConfig, RootStageTrainer

    start_run(args)
    names = ("steps", "lr", "batch_size", "width", "layers", "variants", "velocity_weight", "path_weight",
             "ckpt_every", "log_every", "seed")
    settings = {k: getattr(args, k) for k in names if getattr(args, k) is not None}
    if args.content_share:
        settings["content_shares"] = dict(args.content_share)
    cfg = RootStageTrainConfig(model=str(model_folder(args.model, "--model")), **settings)
    trainer = RootStageTrainer(cfg, args.data, args.out, text_cache=args.cache_dir,
                               log=lambda s: print(s, flush=True))
    if args.resume:
        trainer.resume()
    print(f"wrote {trainer.run(minutes=args.minutes)}")
    return 0
