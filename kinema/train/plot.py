"""Loss-curve plots from a run's ``log.jsonl``."""

from __future__ import annotations

import json
from pathlib import Path

from kinema.errors import KinemaError
from kinema.train.losses import TERMS


def read_log(run_dir: Path) -> list[dict]:
    path = Path(run_dir) / "log.jsonl"
    if not path.exists():
        raise KinemaError(f"{path}: no training log (is this a run folder?)")
    records = []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            raise KinemaError(f"{path}:{n}: not a JSON line") from None
    if not records:
        raise KinemaError(f"{path}: empty training log")
    # a resumed run may re-log steps: keep the last record of every step
    by_step = {r["step"]: r for r in records}
    return [by_step[s] for s in sorted(by_step)]


def moving_average(values: list[float], window: int) -> list[float]:
    """Trailing mean over up to ``window`` values: single-batch losses are too noisy to read a trend."""
    out, total = [], 0.0
    for i, v in enumerate(values):
        total += v
        if i >= window:
            total -= values[i - window]
        out.append(total / min(i + 1, window))
    return out


def plot_losses(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Write a PNG with the total loss and every Eq. 1 term against the step (log scale); the raw
    per-batch total is drawn faint under its moving average, the terms as moving averages."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from kinema.atomic_files import atomic_write_bytes

    run_dir = Path(run_dir)
    recs = read_log(run_dir)
    steps = [r["step"] for r in recs]
    terms = [t for t in (*TERMS, "constraint") if any(t in r for r in recs)]
    # an any-rig run logs its one x0 loss only: one panel, no empty "terms" panel beside it
    fig, axes = plt.subplots(1, 2 if terms else 1, figsize=(12 if terms else 7, 4.5), squeeze=False)
    axes = axes[0]
    window = max(1, len(recs) // 40)
    total = [r["loss"] for r in recs]
    axes[0].plot(steps, total, lw=0.6, alpha=0.35, color="C0", label="per batch")
    axes[0].plot(steps, moving_average(total, window), lw=1.6, color="C0", label=f"mean of {window} logs")
    axes[0].legend(fontsize=8)
    what = "total loss (Eq. 1)" if terms else "loss (x0 MSE, normalised features)"
    axes[0].set(title=f"{run_dir.name}: {what}", xlabel="step", ylabel="loss", yscale="log")
    for term in terms:
        pts = [(r["step"], r[term]) for r in recs if term in r]
        axes[1].plot([p[0] for p in pts], moving_average([p[1] for p in pts], window), lw=1, label=term)
    if terms:
        axes[1].set(title=f"loss terms (unweighted, mean of {window} logs)", xlabel="step", yscale="log")
        axes[1].legend(fontsize=8)
    phase2 = next((r["step"] for r in recs if r.get("phase") == 2), None)
    for ax in axes:
        ax.grid(alpha=0.3)
        if phase2 is not None:
            ax.axvline(phase2, color="k", ls="--", lw=0.8)
    fig.tight_layout()
    out = Path(out) if out else run_dir / "loss.png"
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(out, buf.getvalue())
    return out
