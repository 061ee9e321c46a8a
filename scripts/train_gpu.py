"""One command to train a kinema model on a CUDA machine within a time budget and leave it ready to copy.

    python scripts/train_gpu.py --minutes 60                 # on the GPU machine, from the repository
    python scripts/train_gpu.py --minutes 1 --device cpu     # CPU smoke run: tiny preset, same steps

What it does, in order (each step prints one line):

1. picks the device (``--device auto``: CUDA when available);
2. builds the dataset from ``--root`` (default ../shared/datasets/bandai-namco) into ``--data`` unless a
   build is already there (``--limit N`` for a small subset), or rebuilds it from ``--pack`` (a build packed
   small enough to travel with the repository: ``scripts/device_dataset.py``);
3. picks the model: ``--config auto`` times one synthetic training step of each preset on the device,
   widest first (paper, large, medium, small), and takes the first that fits in memory and can do at
   least ``--min-steps`` steps in the budget; on a CPU ``auto`` means ``tiny``;
4. trains with bf16 autocast on CUDA (fp32 on CPU, where it does not pay; docs/training.md):
   ``--calibrate`` real steps (then undone) measure the step time, the run length is set so that it ends
   inside the budget (the learning-rate schedule completes), and the budget is also a hard stop that writes
   a checkpoint (``kinema train --resume --out RUN --data DATA`` continues it);
5. exports the EMA weights (``kinema export``) to ``--models/NAME`` and loads the folder back to prove it.

Fine-tuning (``--init-from FOLDER``, e.g. ``kinema/assets/models/default``) takes that model's
preset, crop length, text encoder and statistics, and the options of ``kinema train`` that a fine-tune
sets (``--lr --warmup --phase1-fraction --high-noise-share --seed``); ``--slim DIR`` copies the last
checkpoint without its optimiser state, in float16 (what a device's file limit lets back) so that
``kinema export DIR/NAME`` works where it lands.

Copy ``models/NAME`` back and use it with ``kinema generate --model models/NAME``. Why a script and not a
CLI sub-command: it strings together commands that exist (data build, train, export) with choices that
only make sense for a rented GPU (preset by budget, bf16), and it must not grow the CLI's surface.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GPU_PRESETS = ("paper", "large", "medium", "small")


def parse_args(argv=None) -> argparse.Namespace:
    """The script's options (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--minutes", type=float, required=True,
                   help="time budget for choosing the preset and training, in minutes (the data build before "
                        "and the export after are not counted)")
    p.add_argument("--name", default=None, help="run / model name (default: <preset>-<minutes>min)")
    p.add_argument("--config", default="auto", help="preset, or 'auto' (widest that fits; tiny on CPU)")
    p.add_argument("--device", default="auto", help="auto (CUDA if present), cuda, cuda:N or cpu")
    p.add_argument("--root", type=Path, default=REPO.parent / "shared/datasets/bandai-namco")
    p.add_argument("--data", type=Path, default=Path("cache/bandai20"), help="dataset folder (built if missing)")
    p.add_argument("--limit", type=int, default=None, help="build only a content-balanced subset of N clips")
    p.add_argument("--runs", type=Path, default=Path("runs"), help="where the run folder goes")
    p.add_argument("--models", type=Path, default=Path("models"), help="where the exported model goes")
    p.add_argument("--batch-size", type=int, default=None, help="default: 128 on CUDA, 32 on CPU")
    p.add_argument("--min-steps", type=int, default=5000, help="auto preset: fewest steps worth training")
    p.add_argument("--calibrate", type=int, default=20, help="real steps timed before fixing the run length")
    p.add_argument("--text-encoder", default=None, help="text encoder id (default: kinema's)")
    p.add_argument("--text-whiten", type=float, default=0.0,
                   help="kinema train --text-whiten: whitened text projection (0 = off; 0.03 deepened bows in the\n"
                        "default model's issue-18 fine-tune, see its model card)")
    p.add_argument("--content-balance", type=float, default=0.0, help="kinema train --content-balance")
    p.add_argument("--foot-contact", type=float, default=0.0, help="kinema train --foot-contact")
    p.add_argument("--cache-dir", type=Path, default=Path("cache/text"), help="text embedding cache")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: kinema.runtime)")
    p.add_argument("--pack", type=Path, default=None,
                   help="rebuild --data from this pack (scripts/device_dataset.py) when it holds no build yet")
    p.add_argument("--init-from", type=Path, default=None,
                   help="fine-tune this model, run or checkpoint folder (kinema train --init-from; the\n"
                        "shipped model is kinema/assets/models/default)")
    p.add_argument("--lr", type=float, default=None, help="peak learning rate (default: TrainConfig's)")
    p.add_argument("--warmup", type=int, default=None, help="warm-up steps (default: a tenth of the run, <= 500)")
    p.add_argument("--phase1-fraction", type=float, default=None, help="kinema train --phase1-fraction")
    p.add_argument("--high-noise-share", type=float, default=0.0, help="kinema train --high-noise-share")
    p.add_argument("--seed", type=int, default=0, help="kinema train --seed")
    p.add_argument("--slim", type=Path, default=None,
                   help="copy the run's last checkpoint (weights, EMA, info), its config and log here")
    return p.parse_args(argv)


def ensure_data(args) -> Path:
    """The dataset folder, built from ``args.root`` when it holds no build yet."""
    from kinema.data.build import build_dataset

    if (args.data / "meta.json").exists():
        print(f"[data] using {args.data}")
        return args.data
    if args.pack is not None:
        sys.path.insert(0, str(REPO / "scripts"))
        from device_dataset import unpack

        unpack(args.pack, args.data)
        return args.data
    import os

    t0 = time.time()
    meta = build_dataset(args.root, args.data, fps=20, limit=args.limit, workers=max(1, min(16, os.cpu_count() or 1)),
                         progress=False)
    print(f"[data] built {args.data}: {meta['counts']['clips']} clips in {time.time() - t0:.0f} s")
    return args.data


def synthetic_step_s(preset: str, num_joints: int, batch: int, frames: int, device, bf16: bool) -> float | None:
    """Seconds per training step of ``preset`` on synthetic inputs (worst-case length); None if out of memory."""
    import torch

    from kinema.bench.train import _inputs
    from kinema.model.config import get_config
    from kinema.model.denoiser import Denoiser

    try:
        model = Denoiser(get_config(preset, num_joints, text_dim=384, max_frames=frames)).to(device)
        opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
        inp = {k: v.to(device) if torch.is_tensor(v) else v
               for k, v in _inputs(model.config, batch, frames, torch.Generator().manual_seed(0)).items()}
        times = []
        for _ in range(4):
            t0 = time.perf_counter()
            with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
                out = model(**inp)
            loss = torch.nn.functional.smooth_l1_loss(out.float(), inp["x_t"])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            float(loss)  # waits for the device
            times.append(time.perf_counter() - t0)
        return min(times[1:])
    except torch.cuda.OutOfMemoryError:
        return None
    finally:
        if device.type == "cuda":
            torch.cuda.empty_cache()


def starting_config(init_from: Path) -> dict:
    """The training config saved with the model a fine-tune starts from (its preset, crop length, text
    encoder: what its weights fit)."""
    from kinema.model.loading import find_checkpoint, read_checkpoint_info

    return read_checkpoint_info(find_checkpoint(init_from))["train_config"]


def choose_preset(args, device, num_joints: int, batch: int, frames: int, bf16: bool) -> str:
    """``args.config``, or on 'auto' the widest GPU preset that fits memory and ``--min-steps`` in the budget."""
    if args.config != "auto":
        return args.config
    if device.type != "cuda":
        return "tiny"
    budget_s = 60.0 * args.minutes * 0.8
    for preset in GPU_PRESETS:
        step = synthetic_step_s(preset, num_joints, batch, frames, device, bf16)
        fits = step is not None and budget_s / step >= args.min_steps
        print(f"[preset] {preset}: " + ("out of memory" if step is None else
                                        f"{step:.3f} s/step -> {budget_s / step:.0f} steps in budget"))
        if fits:
            return preset
    return GPU_PRESETS[-1]


def train(args, data: Path, device, preset: str, batch: int, deadline: float, start: dict | None) -> Path:
    """Train ``preset`` until the run length fitted to the budget (or the hard stop); returns the run folder.
    ``start``: the training config of the model a fine-tune starts from (:func:`starting_config`), or None."""
    from kinema.train.trainer import TrainConfig, Trainer

    name = args.name or f"{preset}-{args.minutes:g}min"
    run_dir = args.runs / name
    if (run_dir / "latest").exists():
        raise SystemExit(f"{run_dir} already holds a run: choose another --name, or continue it with "
                         f"`kinema train --resume --out {run_dir} --data {data}`")
    cfg = TrainConfig(model=preset, batch_size=batch, steps=10**9, ckpt_every=2000, log_every=50,
                      text_whiten=args.text_whiten, content_balance=args.content_balance,
                      foot_contact=args.foot_contact, high_noise_share=args.high_noise_share, seed=args.seed)
    for key in ("lr", "phase1_fraction"):
        if getattr(args, key) is not None:
            setattr(cfg, key, getattr(args, key))
    if start is not None:  # a fine-tune: what the starting model's weights fit
        cfg.init_from, cfg.max_seconds, cfg.text_encoder = str(args.init_from.resolve()), start["max_seconds"], \
            start["text_encoder"]
    if args.text_encoder:
        cfg.text_encoder = args.text_encoder
    trainer = Trainer(cfg, data, run_dir, cache_dir=args.cache_dir, device=device, bf16=device.type == "cuda")
    if cfg.init_from:
        print(f"[train] fine-tuning from {trainer.init_weights(cfg.init_from)}")
    step_s = trainer.time_steps(max(1, args.calibrate))
    left = deadline - time.monotonic()
    steps = max(1, int(0.95 * left / step_s))
    cfg.warmup = args.warmup if args.warmup is not None else min(cfg.warmup, max(1, steps // 10))
    cfg.ckpt_every = min(cfg.ckpt_every, max(1, steps // 4))
    trainer.set_total_steps(steps)
    print(f"[train] {preset} ({trainer.model.num_parameters() / 1e6:.1f} M parameters) on {device}, "
          f"batch {batch}, {'bf16' if trainer.bf16 else 'fp32'}: {step_s:.3f} s/step -> {steps} steps")
    trainer.run(progress=sys.stderr.isatty(), minutes=max(0.05, left / 60.0))
    how = "time budget spent" if trainer.stopped_by_budget else "schedule complete"
    print(f"[train] stopped at step {trainer.step} of {steps} ({how}); run folder {run_dir}")
    return run_dir


def slim_copy(run_dir: Path, dest: Path) -> None:
    """The run's last checkpoint without its optimiser state, weights and EMA in float16 (the precision
    models ship in), with the run's config and log, as a run folder (under half the checkpoint's size)."""
    import shutil

    from safetensors.torch import load_file, save_file

    last = (run_dir / "latest").read_text().strip()
    (dest / last).mkdir(parents=True, exist_ok=True)
    for name in ("model.safetensors", "ema.safetensors"):
        state = load_file(str(run_dir / last / name))
        save_file({k: v.half() if v.is_floating_point() else v for k, v in state.items()}, str(dest / last / name))
    shutil.copy2(run_dir / last / "checkpoint.json", dest / last / "checkpoint.json")
    for name in ("latest", "train_config.json", "log.jsonl"):
        shutil.copy2(run_dir / name, dest / name)
    print(f"[slim] {dest}")


def main(argv=None) -> int:
    """Data, preset, budgeted training, export: the whole GPU run; returns the exit status."""
    args = parse_args(argv)
    start = time.monotonic()
    from kinema.runtime import configure_threads, resolve_device

    configure_threads(args.threads, cap=None)
    device = resolve_device(args.device)
    if args.minutes <= 0:
        raise SystemExit("--minutes must be positive")
    data = ensure_data(args)
    deadline = time.monotonic() + 60.0 * args.minutes  # the budget is for choosing the preset and training
    batch = args.batch_size or (128 if device.type == "cuda" else 32)
    num_joints = int(json.loads((data / "meta.json").read_text())["layout"]["num_joints"])
    init = starting_config(args.init_from) if args.init_from else None
    preset = init["model"] if init else choose_preset(args, device, num_joints, batch, 200, device.type == "cuda")
    run_dir = train(args, data, device, preset, batch, deadline, init)
    if args.slim is not None:
        slim_copy(run_dir, args.slim / run_dir.name)
    from kinema.model.export import export_model
    from kinema.model.loading import load_denoiser

    out = export_model(run_dir, args.models / run_dir.name)
    loaded = load_denoiser(out)
    size = sum(p.stat().st_size for p in out.iterdir() if p.is_file()) / 1e6
    print(f"[export] {out} ({size:.1f} MB, step {loaded.info.get('step')}); copy it back and run "
          f"`kinema generate \"A person walks forward.\" --model {out}`")
    print(f"[done] {(time.monotonic() - start) / 60:.1f} min in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
