"""`kinema retrieval`: train the text-motion retrieval model and measure its retrieval accuracy.

    kinema retrieval train --data DIR --out DIR [--steps 1000] [--batch-size 128] [--lr 5e-4] [--seed 0]
                           [--text-encoder minilm-l6-v2] [--cache-dir DIR] [--half] [--threads N]
                           [--max-minutes M] [--eval-split test|none]
    kinema retrieval eval --data DIR [--model DIR] [--split test] [--json FILE] [--threads N]

The model is the embedding used for R-precision and FID (Kimodo Sec. 6.1); ``--model`` defaults to the
weights shipped in kinema/assets/retrieval. See kinema.evaluate.retrieval_train for the protocols.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from kinema.cli._args import positive_int
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    """Add the `retrieval` sub-command (with `train` and `eval`) to the top-level parser."""
    p = sub.add_parser("retrieval", help="train / evaluate the text-motion retrieval model (R@k, FID embedding)",
                       description="Train or evaluate the TMR-style text-motion retrieval model.")
    rsub = p.add_subparsers(dest="retrieval_command", required=True)

    t = rsub.add_parser("train", help="train a retrieval model on the train split of a build")
    t.add_argument("--data", type=Path, required=True, help="dataset folder from `kinema data build`")
    t.add_argument("--out", type=Path, required=True, help="folder for model.safetensors + config.json")
    t.add_argument("--steps", type=_positive_int, default=1000, help="optimisation steps (default 1000)")
    t.add_argument("--batch-size", type=_positive_int, default=128, help="clips per batch (default 128)")
    t.add_argument("--lr", type=float, default=5e-4, help="peak learning rate (default 5e-4)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--text-encoder", default="minilm-l6-v2", help="frozen text encoder id")
    t.add_argument("--cache-dir", type=Path, default=text_cache_dir(), help="text embedding cache")
    t.add_argument("--half", action="store_true", help="store float16 weights (half the size)")
    t.add_argument("--eval-split", default="test", help="split evaluated after training ('none' to skip)")
    t.add_argument("--max-minutes", type=float, default=None, help="safety stop after this much training time")
    t.add_argument("--no-progress", action="store_true")
    _common(t)
    t.set_defaults(func=_train)

    e = rsub.add_parser("eval", help="R@1/3/10 of a retrieval model on ground-truth clips")
    e.add_argument("--data", type=Path, required=True, help="dataset folder from `kinema data build`")
    e.add_argument("--model", type=Path, default=None, help="model folder (default: the shipped weights)")
    e.add_argument("--split", default="test", choices=["train", "val", "test", "all"])
    e.add_argument("--cache-dir", type=Path, default=text_cache_dir(), help="text embedding cache")
    e.add_argument("--json", type=Path, default=None, help="also write the metrics as JSON here")
    _common(e)
    e.set_defaults(func=_eval)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=_positive_int, help="torch CPU threads (default: torch's choice)")


_positive_int = positive_int


def _threads(args) -> None:
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)


def _train(args) -> int:
    from kinema.evaluate.retrieval_train import evaluate_retrieval, format_metrics, train_retrieval

    _threads(args)
    command = "kinema " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["retrieval"] else None
    model = train_retrieval(args.data, args.out, steps=args.steps, batch_size=args.batch_size, lr=args.lr,
                            seed=args.seed, text_encoder=args.text_encoder, cache_dir=args.cache_dir,
                            half=args.half, progress=not args.no_progress, command=command,
                            max_seconds=None if args.max_minutes is None else 60 * args.max_minutes)
    info = model.info
    print(f"wrote {args.out}: {info['steps_done']} of {info['steps']} steps in {info['wall_seconds']:.0f} s, "
          f"final loss {info['loss_curve'][-1][1]:.3f}")
    if args.eval_split != "none":
        print(format_metrics(evaluate_retrieval(model, args.data, args.eval_split, cache_dir=args.cache_dir)))
    return 0


def _eval(args) -> int:
    from kinema.evaluate.retrieval import load_retrieval
    from kinema.evaluate.retrieval_train import evaluate_retrieval, format_metrics, save_metrics

    _threads(args)
    model = load_retrieval(args.model)
    res = evaluate_retrieval(model, args.data, args.split, cache_dir=args.cache_dir)
    print(format_metrics(res))
    if args.json:
        save_metrics(res, args.json)
        print(f"wrote {args.json}")
    return 0
