"""`kinema train-anyrig`: train the any-rig (creatures) model on a multi-rig build or manifest."""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import positive_float, positive_int
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    p = sub.add_parser("train-anyrig", help="train the any-rig model (one token per joint) on many skeletons")
    p.add_argument("--config", default="anyrig-small", help="model preset: anyrig-tiny, anyrig-small (default)")
    p.add_argument("--data", type=Path, required=True, help="multi-rig build or manifest")
    p.add_argument("--out", type=Path, required=True, help="run folder, e.g. runs/creatures")
    p.add_argument("--steps", type=positive_int, help="total optimisation steps (default 4000)")
    p.add_argument("--lr", type=positive_float)
    p.add_argument(
        "--token-budget",
        type=positive_int,
        help="batch size x joints per batch (default 256: 32 fish windows or 5 fox windows)",
    )
    p.add_argument(
        "--root-weight",
        type=positive_float,
        help="the root row's share of the loss, in joint rows (default 1; 10 puts ground path and heading first)",
    )
    p.add_argument("--variants", type=int, help="rig-augmented copies per clip (default 2; 0 = no augmentation)")
    p.add_argument("--no-tree-pe", action="store_true", help="ablation: no TreePE")
    p.add_argument("--no-rest-pe", action="store_true", help="ablation: no RestPE")
    p.add_argument("--no-hop-bias", action="store_true", help="ablation: no hop-distance attention bias")
    p.add_argument("--ckpt-every", type=positive_int)
    p.add_argument("--log-every", type=positive_int)
    p.add_argument("--seed", type=int)
    p.add_argument("--cache-dir", type=Path, default=text_cache_dir(), help="text embedding cache")
    p.add_argument("--resume", action="store_true", help="continue the newest checkpoint in --out")
    p.add_argument(
        "--init-from",
        help="fine-tune: start from this any-rig model's weights (an exported model folder, a run, or "
        "'creatures' for the shipped one); normalisation statistics come from --data",
    )
    p.add_argument("--minutes", type=positive_float, help="stop cleanly after this many minutes (checkpoint written)")
    p.add_argument("--threads", type=positive_int, help="torch CPU threads (default chosen by kinema.runtime)")
    p.set_defaults(func=run)


def _settings(args: argparse.Namespace) -> dict:
    names = {
        "steps": "steps",
        "lr": "lr",
        "token_budget": "token_budget",
        "variants": "variants",
        "root_weight": "root_weight",
        "ckpt_every": "ckpt_every",
        "log_every": "log_every",
        "seed": "seed",
    }
    return {k: getattr(args, a) for a, k in names.items() if getattr(args, a) is not None}


def model_folder(name: str, option: str = "--init-from") -> Path:
    """A model name shipped with kinema (``creatures``) or a folder path."""
    from kinema.errors import KinemaError

    shipped = Path(__file__).resolve().parents[1] / "assets" / "models" / name
    path = shipped if shipped.is_dir() and not Path(name).exists() else Path(name)
    if not path.exists():
        raise KinemaError(f"{option} {name}: no such model folder")
    return path


def start_run(args: argparse.Namespace) -> None:
    """Threads set, ``--variants`` checked, and ``--out`` free unless ``--resume`` (any-rig training commands)."""
    from kinema.errors import KinemaError
    from kinema.runtime import configure_threads

    configure_threads(args.threads, cap=None)
    if args.variants is not None and args.variants < 0:
        raise KinemaError(f"--variants must be >= 0, got {args.variants}")
    if not args.resume and (args.out / "latest").exists():
        raise KinemaError(f"{args.out} already holds a run; pass --resume to continue it or choose another --out")


def run(args: argparse.Namespace) -> int:
    from kinema.model.anyrig.config import get_anyrig_config
    from kinema.train.anyrig.trainer import AnyRigTrainConfig, AnyRigTrainer

    start_run(args)
    model_config = get_anyrig_config(
        args.config, tree_pe=not args.no_tree_pe, rest_pe=not args.no_rest_pe, hop_bias=not args.no_hop_bias
    )
    trainer = AnyRigTrainer(
        model_config,
        AnyRigTrainConfig(**_settings(args)),
        args.data,
        args.out,
        text_cache=args.cache_dir,
        log=lambda s: print(s, flush=True),
    )
    if args.init_from:
        trainer.cfg.init_from = str(args.init_from)
    resumed = trainer.resume() if args.resume else False
    if args.init_from and not resumed:
        print(f"fine-tuning from {trainer.init_weights(model_folder(args.init_from))}", flush=True)
    ckpt = trainer.run(minutes=args.minutes)
    print(f"wrote {ckpt}")
    return 0
