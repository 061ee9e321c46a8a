"""Argument types shared by the sub-commands."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def _int_at_least(text: str, low: int, what: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if n < low:
        raise argparse.ArgumentTypeError(f"expected {what}, got {n}")
    return n


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1, with a clear message otherwise."""
    return _int_at_least(text, 1, "a positive integer")


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0, with a clear message otherwise."""
    return _int_at_least(text, 0, "an integer >= 0")


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (frame rates, durations, scales)."""
    x = _number(text)
    if not (math.isfinite(x) and x > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return x


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0 (guidance weights)."""
    x = _number(text)
    if not (math.isfinite(x) and x >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return x


def content_share(text: str) -> tuple[str, float]:
    """argparse type: ``CONTENT=SHARE``, a build's content name and a share in (0, 1]."""
    name, sep, share = text.partition("=")
    x = _number(share) if sep else math.nan
    if not (name and sep and 0.0 < x <= 1.0):
        raise argparse.ArgumentTypeError(f"expected CONTENT=SHARE with a share in (0, 1], e.g. idle=0.25, got {text!r}")
    return name, x


def finite_float(text: str) -> float:
    """argparse type: any finite number (angles)."""
    x = _number(text)
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return x


#: Seeds `torch.Generator.manual_seed` takes as they are (it wraps negative ones, overflows past 64 bits).
MAX_SEED = 2**64 - 1


def seed(text: str) -> int:
    """argparse type: a random seed, an integer in [0, 2**64 - 1]."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer seed, got {text!r}") from None
    if not 0 <= n <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected a seed in [0, 2**64 - 1], got {text!r}")
    return n


def sample_paths(out: Path, n: int) -> list[Path]:
    """Output files of ``n`` samples: ``out`` itself for one, else ``stem_00.ext``, ``stem_01.ext``, ...
    (``.bvh.gz`` counts as one suffix)."""
    if n == 1:
        return [out]
    name = out.name
    stem, suffix = (name[: -len(".bvh.gz")], ".bvh.gz") if name.lower().endswith(".bvh.gz") else (out.stem, out.suffix)
    return [out.with_name(f"{stem}_{i:02d}{suffix}") for i in range(n)]


def unit_float(text: str) -> float:
    """argparse type: a number in [0, 1] (blend weights)."""
    x = _number(text)
    if not (math.isfinite(x) and 0.0 <= x <= 1.0):
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}")
    return x


def add_precision_argument(p: argparse.ArgumentParser) -> None:
    """``--precision auto|fp32|bf16``: the denoiser's inference precision (kinema.model.precision; the
    CLI's entry point puts it into ``$KINEMA_PRECISION`` for every model the command loads)."""
    p.add_argument("--precision", choices=("auto", "fp32", "bf16"),
                   help="denoiser precision: bf16 weights where the CPU has bf16 instructions (auto, the default; "
                        "else $KINEMA_PRECISION), fp32 or bf16 (docs/speed.md)")


def add_guidance_cache_arguments(p: argparse.ArgumentParser) -> None:
    """``--guidance-refresh N`` and ``--guidance-cached text|constr``: guidance caching
    (kinema.diffusion.guidance_cache), off by default."""
    p.add_argument("--guidance-refresh", type=positive_int, default=1, metavar="N",
                   help="guidance caching: run the cached separated-guidance branch on every N-th DDIM step only "
                        "and reuse its last difference on the others (default 1 = off)")
    p.add_argument("--guidance-cached", choices=("constr", "text"), default="constr",
                   help="the branch --guidance-refresh caches (default constr)")


def add_grounding_arguments(p: argparse.ArgumentParser) -> None:
    """``--grounding WEIGHT``, ``--grounding-top-k K``, ``--grounding-temperature T`` (prompt grounding,
    kinema.model.grounding); each left out keeps the model's saved setting."""
    p.add_argument(
        "--grounding",
        type=unit_float,
        metavar="WEIGHT",
        help="prompt grounding: blend each prompt's text embedding with its nearest training captions' "
        "(0 = off, 1 = the captions alone; training captions and unknown prompts are never "
        "grounded; default: the model's setting)",
    )
    p.add_argument(
        "--grounding-top-k",
        type=positive_int,
        metavar="K",
        help="nearest training captions blended in (default: the model's setting)",
    )
    p.add_argument(
        "--grounding-temperature",
        type=positive_float,
        metavar="T",
        help="softmax temperature over their cosine similarities (default: the model's setting)",
    )


def grounding_overrides(args: argparse.Namespace) -> dict:
    """The grounding settings given on the command line, as ``Grounding`` keys (empty: none given)."""
    given = {"weight": args.grounding, "top_k": args.grounding_top_k, "temperature": args.grounding_temperature}
    return {k: v for k, v in given.items() if v is not None}
