"""Train the keyjoint trajectory denoiser (SFControl Sec. 3.1) on a `kinema data build` cache.

Run (resumable: a second run with the same ``--out`` continues from its last checkpoint)::

    OMP_NUM_THREADS=1 python -m kinema.train.keyjoint --data cache/bandai20 --out runs/keyjoint \\
        --minutes 50 --threads 1

Each batch holds random crops (2-5 s) of training clips, moved so their first smoothed root is at the
origin and turned to a random first-frame heading (given to the model as ``c_dir``), with one random
sparse mask per crop (kinema.representation.keyjoint.sparse_mask) and 10 % of the captions dropped.
Loss: x0 MSE on real (unpadded) frames, cosine noise schedule with T = 1000. AdamW, EMA 0.999.
Checkpoints (``state.safetensors`` + ``state.json``, no pickle) every ``--save-every`` steps and at the
end; ``export`` writes the EMA weights as a model folder (kinema.model.keyjoint).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file

from kinema.atomic_files import atomic_write_bytes
from kinema.data.dataset import MotionDataset
from kinema.diffusion.schedule import NoiseSchedule
from kinema.model.keyjoint import KeyjointConfig, KeyjointDenoiser, save_keyjoint_model
from kinema.representation.flat import FlatRepresentation
from kinema.representation.keyjoint import (
    canonicalize_keyjoints,
    keyjoint_indices,
    keyjoints_from_features,
    sparse_mask,
)
from kinema.runtime import text_cache_dir
from kinema.text import get_text_encoder

MIN_FRAMES, MAX_FRAMES = 40, 100


class KeyjointData:
    """Keyjoint tracks ``(N, 20)`` and smoothed-root x/z ``(N, 2)`` of every frame of one split, the
    clips' (start, length, caption ids) and the caption embedding table."""

    def __init__(self, root: str | Path, split: str, cache_dir: Path | None, text_encoder: str = "minilm-l6-v2"):
        ds = MotionDataset(root, split)
        rep = FlatRepresentation.for_skeleton(ds.skeleton, ds.fps)
        self.fps, self.skeleton = ds.fps, ds.skeleton
        idx = keyjoint_indices(ds.skeleton)
        self.k = keyjoints_from_features(ds.features, rep, idx)
        self.root = ds.features[:, rep.root_xz].clone()
        captions = sorted({c for r in ds.clips for c in r["captions"]})
        where = {c: i for i, c in enumerate(captions)}
        self.clips = [
            (r["start"], r["length"], [where[c] for c in r["captions"]]) for r in ds.clips if r["length"] >= MIN_FRAMES
        ]
        encoder = get_text_encoder(text_encoder, cache_dir=cache_dir)
        self.text_id = encoder.id
        self.text = encoder.encode(captions).float() if captions else torch.zeros(0, encoder.dim)
        lengths = torch.tensor([c[1] for c in self.clips], dtype=torch.float64)
        self.weights = lengths / lengths.sum()

    def batch(self, size: int, g: torch.Generator, text_dropout: float = 0.1) -> dict:
        """Crops of random length, canonicalised, padded to the longest: ``k (B, T, 20)``, ``pad (B, T)``,
        ``mask (B, T, 20)``, ``text (B, 384)`` (zeros where dropped), ``c_dir (B, 2)``."""
        ids = torch.multinomial(self.weights, size, replacement=True, generator=g).tolist()
        crops, roots, texts = [], [], []
        for i in ids:
            start, length, caps = self.clips[i]
            hi = min(length, MAX_FRAMES)
            n = int(torch.randint(min(length, MIN_FRAMES), hi + 1, (), generator=g))
            s = start + int(torch.randint(length - n + 1, (), generator=g))
            crops.append(self.k[s : s + n])
            roots.append(self.root[s])
            keep = float(torch.rand((), generator=g)) >= text_dropout
            cap = caps[int(torch.randint(len(caps), (), generator=g))]
            texts.append(self.text[cap] if keep else torch.zeros(self.text.shape[1]))
        T = max(c.shape[0] for c in crops)
        k = torch.zeros(size, T, 20)
        pad = torch.zeros(size, T, dtype=torch.bool)
        mask = torch.zeros(size, T, 20)
        angle = (torch.rand(size, generator=g) * 2 - 1) * math.pi
        for b, c in enumerate(crops):
            n = c.shape[0]
            k[b, :n] = canonicalize_keyjoints(c, roots[b], angle[b])
            pad[b, :n] = True
            mask[b, :n] = sparse_mask(n, g)
        c_dir = torch.stack([torch.cos(angle), torch.sin(angle)], dim=-1)
        return {"k": k, "pad": pad, "mask": mask, "text": torch.stack(texts), "c_dir": c_dir}


def keyjoint_stats(data: KeyjointData, g: torch.Generator, crops: int = 512) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-channel mean / std over canonicalised training crops (real frames only)."""
    b = data.batch(crops, g, text_dropout=0.0)
    x = b["k"][b["pad"]]
    return x.mean(0), x.std(0)


def ema_decay(step: int, limit: float = 0.999) -> float:
    """EMA decay with warm-up, ``min(limit, (1 + step) / (10 + step))``: early averages forget the
    random initial weights (a fixed 0.999 still holds 60 % of them after 500 steps)."""
    return min(limit, (1 + step) / (10 + step))


def annealed_lr(start: float, end: float, fraction: float) -> float:
    """Cosine from ``start`` to ``end`` over the run's wall-clock budget (``fraction`` in [0, 1]): a
    resumed run with a fixed time budget ends at a low learning rate whatever its step count."""
    f = min(max(fraction, 0.0), 1.0)
    return end + 0.5 * (start - end) * (1 + math.cos(math.pi * f))


def set_lr(opt: torch.optim.Optimizer, lr: float) -> None:
    for group in opt.param_groups:
        group["lr"] = lr


def train_step(model, ema, opt, schedule, b: dict, g: torch.Generator, step: int) -> float:
    x0 = model.normalize(b["k"])
    B = x0.shape[0]
    t = schedule.sample_timesteps(B, generator=g)
    noise = torch.randn(x0.shape, generator=g)
    x_t = schedule.q_sample(x0, t, noise)
    pred = model(x_t, t, b["text"], b["c_dir"], x0 * b["mask"], b["mask"], b["pad"])
    w = b["pad"][..., None].float()
    loss = (((pred - x0) ** 2) * w).sum() / (w.sum() * x0.shape[-1])
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
    opt.step()
    decay = ema_decay(step)
    with torch.no_grad():
        for pe, pm in zip(ema.parameters(), model.parameters(), strict=True):
            pe.mul_(decay).add_(pm.detach(), alpha=1 - decay)
        for be, bm in zip(ema.buffers(), model.buffers(), strict=True):
            be.copy_(bm)
    return float(loss.detach())


def save_state(out: Path, model, ema, opt, step: int, seconds: float, log: list) -> None:
    tensors = {f"model.{k}": v.detach().contiguous() for k, v in model.state_dict().items()}
    tensors |= {f"ema.{k}": v.detach().contiguous() for k, v in ema.state_dict().items()}
    for i, st in opt.state_dict()["state"].items():
        for name, v in st.items():
            tensors[f"opt.{i}.{name}"] = torch.as_tensor(v).detach().clone().contiguous()
    tmp = out / "state.safetensors.tmp"
    save_file(tensors, str(tmp))
    tmp.replace(out / "state.safetensors")
    meta = {"step": step, "seconds": seconds, "log": log}
    atomic_write_bytes(out / "state.json", (json.dumps(meta) + "\n").encode())


def load_state(out: Path, model, ema, opt) -> tuple[int, float, list]:
    tensors = load_file(str(out / "state.safetensors"))
    meta = json.loads((out / "state.json").read_text())
    model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
    ema.load_state_dict({k[4:]: v for k, v in tensors.items() if k.startswith("ema.")})
    sd = opt.state_dict()
    for key, v in tensors.items():
        if key.startswith("opt."):
            _, i, name = key.split(".", 2)
            sd["state"].setdefault(int(i), {})[name] = v
    opt.load_state_dict(sd)
    return int(meta["step"]), float(meta["seconds"]), list(meta["log"])


def run(args: argparse.Namespace) -> Path:
    torch.set_num_threads(args.threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    g = torch.Generator().manual_seed(args.seed)
    data = KeyjointData(args.data, "train", Path(args.text_cache), args.text_encoder)
    cfg = KeyjointConfig(text_dim=data.text.shape[1])
    model, ema = KeyjointDenoiser(cfg), KeyjointDenoiser(cfg)
    model.set_normalization(*keyjoint_stats(data, torch.Generator().manual_seed(0)))
    ema.load_state_dict(model.state_dict())
    ema.eval()
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.01)
    schedule = NoiseSchedule()
    step, seconds, log = 0, 0.0, []
    if (out / "state.safetensors").exists():
        step, seconds, log = load_state(out, model, ema, opt)
        if args.reset_ema:
            ema.load_state_dict(model.state_dict())
        g.manual_seed(args.seed + step)
        print(f"resumed {out} at step {step} ({seconds / 60:.1f} min)", flush=True)
    t0, last, losses = time.perf_counter(), time.perf_counter(), []
    while time.perf_counter() - t0 < args.minutes * 60:
        if args.lr_end is not None:
            set_lr(opt, annealed_lr(args.lr, args.lr_end, (time.perf_counter() - t0) / (args.minutes * 60)))
        losses.append(train_step(model, ema, opt, schedule, data.batch(args.batch, g), g, step))
        step += 1
        if step % args.log_every == 0:
            now = time.perf_counter()
            log.append({"step": step, "loss": sum(losses) / len(losses), "minutes": (seconds + now - t0) / 60})
            print(f"step {step} loss {log[-1]['loss']:.4f} ({(now - last) / args.log_every:.3f} s/step)", flush=True)
            losses, last = [], now
        if step % args.save_every == 0:
            save_state(out, model, ema, opt, step, seconds + time.perf_counter() - t0, log)
    seconds += time.perf_counter() - t0
    save_state(out, model, ema, opt, step, seconds, log)
    info = {
        "steps": step,
        "train_seconds": round(seconds, 1),
        "data": str(args.data),
        "batch": args.batch,
        "lr": args.lr,
        "lr_end": args.lr_end,
        "fps": data.fps,
        "text_encoder": data.text_id,
        "licence": "trained on Bandai Namco motion data (CC BY-NC 4.0): non-commercial use only",
    }
    save_keyjoint_model(ema, out / "export", info)
    print(f"done: {step} steps, {seconds / 60:.1f} min; exported {out / 'export'}", flush=True)
    return out / "export"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m kinema.train.keyjoint", description=__doc__.split("\n")[0])
    p.add_argument("--data", required=True, help="kinema data build folder (e.g. cache/bandai20)")
    p.add_argument("--out", required=True, help="run folder (resumed when it holds a checkpoint)")
    p.add_argument("--minutes", type=float, default=50.0, help="wall-clock budget of this run")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--lr-end", type=float, default=None, help="anneal to this rate (cosine) over --minutes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--log-every", type=int, default=50)
    p.add_argument("--save-every", type=int, default=500)
    p.add_argument("--text-cache", default=str(text_cache_dir()))
    p.add_argument("--text-encoder", default="minilm-l6-v2", help="must be the body model's for generation")
    p.add_argument("--reset-ema", action="store_true", help="on resume, restart the EMA from the current weights")
    run(p.parse_args(argv))


if __name__ == "__main__":
    main()
