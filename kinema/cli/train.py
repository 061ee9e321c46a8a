"""`kinema train`: train a denoiser on a built dataset; `kinema train plot --out RUN`: loss curves as PNG."""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import positive_float, positive_int, unit_float
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    """Add the `train` sub-command (runtime options: --threads, --device, --bf16, --minutes; docs/training.md)."""
    p = sub.add_parser("train",
                       help="train a motion diffusion model (also: `kinema train plot --out RUN`: loss curves)")
    p.add_argument("action", nargs="?", default="run", choices=["run", "plot"],
                   help="'plot' writes loss curves of an existing run (give the run folder with --out)")
    p.add_argument("--config", help="model preset: tiny, small (default), small-1stage, paper")
    p.add_argument("--data", type=Path, help="dataset folder from `kinema data build`")
    p.add_argument("--out", type=Path, required=True, help="run folder, e.g. runs/NAME")
    p.add_argument("--steps", type=int, help="total optimisation steps (both phases)")
    p.add_argument("--batch-size", type=int)
    p.add_argument("--lr", type=float)
    p.add_argument("--warmup", type=int, help="learning-rate warm-up steps (default 500; fewer for a short fine-tune)")
    p.add_argument("--optimizer", choices=["adamw", "adam-atan2"])
    p.add_argument("--phase1-fraction", type=float, help="share of steps in text-only phase 1 (default 0.5)")
    _add_draw_arguments(p)
    p.add_argument("--foot-contact", type=float,
                   help="weight of the foot-contact consistency loss (velocity of joints the data says are "
                        "planted -> 0; default 0 = off); docs/training.md")
    p.add_argument("--text-whiten", type=float,
                   help="train the text projection in whitened caption-embedding coordinates, eigenvalues shrunk "
                        "by X * the largest (0 < X <= 1; default 0 = off); docs/training.md")
    p.add_argument("--ckpt-every", type=int)
    p.add_argument("--log-every", type=int)
    p.add_argument("--seed", type=int)
    p.add_argument("--text-encoder", help="text encoder id (default minilm-l6-v2)")
    p.add_argument("--cache-dir", type=Path, default=text_cache_dir(), help="text embedding cache")
    p.add_argument("--resume", action="store_true", help="continue the newest checkpoint in --out")
    _add_fine_tune_arguments(p)
    p.add_argument("--stop-after", type=int, help="stop after this many steps of this invocation")
    p.add_argument("--minutes", type=positive_float,
                   help="time budget: stop cleanly after this many minutes of training (checkpoint written; "
                        "--resume continues)")
    p.add_argument("--device", default=None,
                   help="torch device to train on: cpu (default) or cuda[:N]; batches are drawn on the CPU "
                        "either way, so a run is reproducible across devices up to float rounding")
    p.add_argument("--bf16", action="store_true",
                   help="bfloat16 autocast of the forward pass (loss and weights stay float32): on CUDA, and on "
                        "CPUs with AMX for presets from 'medium' up (1.22x there; no gain at 'small'; "
                        "docs/training.md)")
    p.add_argument("--threads", type=positive_int,
                   help="torch CPU threads (default: KINEMA_THREADS, else chosen by kinema.runtime; see docs/speed.md)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run)


def _add_draw_arguments(p: argparse.ArgumentParser) -> None:
    """What a batch draws: clips by content (--content-*), window lengths (--crop-min-fraction) and noise
    levels (--high-noise-*)."""
    p.add_argument("--content-balance", type=float,
                   help="draw clips with weight (clips of the same content) ** -X: 0 uniform (default), 0.5 "
                        "square-root balancing of rare contents")
    p.add_argument("--content-weight", nargs="+", type=_content_factor, metavar="CONTENT=X",
                   help="multiply the sampling weight of the clips of these contents (clips.json 'content') by X, "
                        "after --content-balance, e.g. punch-left=5 punch-right=5")
    p.add_argument("--crop-min-fraction", type=float,
                   help="shortest training window as a fraction of the longest clip in its length bucket "
                        "(0 < X <= 1; default 0.5); docs/training.md")
    p.add_argument("--high-noise-share", type=unit_float,
                   help="chance that a row whose clip reaches beyond --high-noise-min-std normalised units is "
                        "trained at a step where the noise hides it, so it is learned from the text (0-1; "
                        "default 0 = off; for fine-tunes on clips far outside the statistics; docs/training.md)")
    p.add_argument("--high-noise-min-std", type=positive_float,
                   help="rows whose clip reaches beyond this many normalised units get --high-noise-share "
                        "(default 8)")
    p.add_argument("--high-noise-visible", type=positive_float,
                   help="--high-noise-share rows are drawn from the steps where their clip's largest value is at "
                        "most this many noise standard deviations (default 1; smaller hides it deeper)")


def _add_fine_tune_arguments(p: argparse.ArgumentParser) -> None:
    """Where a fine-tune starts (--init-from) and what keeps it near a teacher (--anchor*)."""
    p.add_argument("--init-from", help="fine-tune: start from this model's weights (an exported model, 'default' "
                                       "for the shipped one, or a run/checkpoint folder); optimiser and step "
                                       "start fresh")
    p.add_argument("--anchor", metavar="MODEL",
                   help="fine-tune: pull the predictions on the clips of --anchor-datasets towards this frozen "
                        "model's ('default' or a folder in the run's statistics: learning without forgetting, "
                        "meant to keep the contents it knows; docs/training.md)")
    p.add_argument("--anchor-weight", type=positive_float, help="weight of the --anchor term (default 1)")
    p.add_argument("--datasets", nargs="+", metavar="NAME",
                   help="train only on the clips of these datasets of the build (clips.json 'dataset'; default: "
                        "all), e.g. an action expert's fine-tune on the new actions alone (docs/training.md)")
    p.add_argument("--anchor-datasets", nargs="+", metavar="NAME",
                   help="datasets (the build's clips.json 'dataset') whose clips are anchored (default: all)")


# Settings a resumed run may change: the schedule (length, phase boundary, how clips are weighted) and
# how often it reports. Everything else (model, data, optimiser) must match the checkpoint it continues.
_RESUME_SCHEDULE = ("steps", "phase1_fraction", "content_balance", "content_weight", "ckpt_every", "log_every")


def _content_factor(text: str) -> tuple[str, float]:
    """``--content-weight``'s CONTENT=X (argparse type)."""
    content, sep, factor = text.rpartition("=")
    try:
        value = float(factor)
    except ValueError:
        value = None
    if not sep or not content or value is None:
        raise argparse.ArgumentTypeError(f"expected CONTENT=X with a number X (e.g. punch-left=5), got {text!r}")
    return content, value


def _init_path(name: str | None) -> str | None:
    """``--init-from`` as a path string ('default' names the shipped model); missing folders fail here."""
    if name is None:
        return None
    from kinema.generate import resolve_model_path

    return str(resolve_model_path(name))


def _config_from_args(args: argparse.Namespace):
    import json

    from kinema.errors import KinemaError
    from kinema.train.trainer import TrainConfig

    overrides = {
        "model": args.config, "steps": args.steps, "batch_size": args.batch_size, "lr": args.lr,
        "warmup": args.warmup,
        "optimizer": args.optimizer, "phase1_fraction": args.phase1_fraction, "ckpt_every": args.ckpt_every,
        "content_balance": args.content_balance,
        "content_weight": None if args.content_weight is None else dict(args.content_weight),
        "log_every": args.log_every, "seed": args.seed,
        "text_encoder": args.text_encoder, "init_from": _init_path(args.init_from),
        "foot_contact": args.foot_contact, "text_whiten": args.text_whiten,
        "crop_min_fraction": args.crop_min_fraction, "high_noise_share": args.high_noise_share,
        "high_noise_min_std": args.high_noise_min_std, "high_noise_visible": args.high_noise_visible,
        "anchor": None if args.anchor is None else _init_path(args.anchor), "anchor_weight": args.anchor_weight,
        "anchor_datasets": args.anchor_datasets, "datasets": args.datasets,
    }
    saved = args.out / "train_config.json"
    if args.resume and saved.exists():
        base = TrainConfig.from_dict(json.loads(saved.read_text()))
        clash = {k: v for k, v in overrides.items()
                 if v is not None and k not in _RESUME_SCHEDULE and getattr(base, k) != v}
        if clash:
            raise KinemaError(f"--resume keeps the run's settings; these differ from {saved}: {sorted(clash)}")
        for k in _RESUME_SCHEDULE:
            if overrides[k] is not None:
                setattr(base, k, overrides[k])
        return base
    cfg = TrainConfig()
    for k, v in overrides.items():
        if v is not None:
            setattr(cfg, k, v)
    return cfg


def run(args: argparse.Namespace) -> int:
    """Plot a run's losses, or build a Trainer from the arguments (or the run being resumed) and train."""
    from kinema.errors import KinemaError

    if args.action == "plot":
        from kinema.train.plot import plot_losses

        print(f"wrote {plot_losses(args.out)}")
        return 0
    if args.data is None:
        raise KinemaError("kinema train needs --data DIR (a folder made by `kinema data build`)")
    from kinema.runtime import configure_threads, resolve_device
    from kinema.train.trainer import Trainer

    configure_threads(args.threads, cap=None)
    device = resolve_device(args.device)
    cfg = _config_from_args(args)
    if not args.resume and (args.out / "latest").exists():
        raise KinemaError(f"{args.out} already holds a run; pass --resume to continue it or choose another --out")
    trainer = Trainer(cfg, args.data, args.out, cache_dir=args.cache_dir, device=device, bf16=args.bf16)
    if args.resume and trainer.resume():
        print(f"resumed {args.out} at step {trainer.step}")
    elif cfg.init_from:
        print(f"fine-tuning from {trainer.init_weights(cfg.init_from)}")
    n = trainer.model.num_parameters()
    if trainer.rank == 0:
        print(f"model {cfg.model}: {n / 1e6:.2f} M parameters; {len(trainer.dataset)} training clips; "
              f"{cfg.steps} steps (phase 1: {trainer.phase1_steps})")
    last = trainer.run(progress=not args.no_progress, stop_after=args.stop_after, minutes=args.minutes)
    if trainer.stopped_by_budget and trainer.rank == 0:
        print(f"time budget of {args.minutes:g} min spent: stopped at step {trainer.step} of {cfg.steps} "
              "(--resume continues)")
    if last is not None:
        print(f"checkpoint: {last}")
    return 0
