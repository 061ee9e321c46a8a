"""The training loop (Kimodo Sec. 4.3): DDPM x0-prediction, Eq. 1 loss, two-phase curriculum, EMA.

Runs on one CPU process or, under ``torchrun --nproc_per_node N``, as DistributedDataParallel (gloo on
CPU, nccl on GPU) with rank-0-only checkpoints and logs. Resuming restores weights, EMA, optimizer and
step; batches and noise are a pure function of (seed, rank, step) (see kinema.train.batching), so a
resumed run continues exactly as the uninterrupted one would have.

Runtime options that do not change what a run *is* (so they are not part of TrainConfig and a resumed run
may change them): ``device`` (batches are drawn on the CPU, bit-identically, then moved), ``bf16``
(autocast of the forward pass to bfloat16; the loss stays float32), ``compile`` (torch.compile of the
training forward) and the time budget of :meth:`Trainer.run` (``minutes``: stop cleanly with a checkpoint
when it is spent). docs/training.md has the measurements behind their defaults.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch

from kinema.data.dataset import MotionDataset
from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.diffusion.schedule import NoiseSchedule
from kinema.errors import KinemaError
from kinema.model.config import get_config, reject_unknown_keys
from kinema.model.denoiser import Denoiser, local_root_stats
from kinema.representation.stats import NormStats
from kinema.text import get_text_encoder
from kinema.train.anchor import Anchor, anchored_clips
from kinema.train.batching import BatchSampler, step_generator
from kinema.train.checkpoint import load_checkpoint, load_init_weights, load_optimizer_tensors, save_checkpoint
from kinema.train.constraints import max_keyframes_at, sample_batch_masks
from kinema.train.losses import LossWeights, motion_loss
from kinema.train.noise_levels import high_noise_timesteps
from kinema.train.optim import build_optimizer, lr_at, make_ema, update_ema
from kinema.train.text_whitening import whiten_text_projections


@dataclass
class TrainConfig:
    """Everything that defines a run (saved in every checkpoint)."""

    model: str = "small"
    steps: int = 20000
    batch_size: int = 32
    lr: float = 2e-4
    warmup: int = 500
    weight_decay: float = 0.01
    optimizer: str = "adamw"
    grad_clip: float = 1.0
    phase1_fraction: float = 0.5  # Kimodo: 500k text-only steps, then 500k with constraints
    phase1_dropout: float = 0.1
    max_keyframes: int = 20
    ema_decay: float = 0.995
    ema_every: int = 10
    text_dropout: float = 0.1
    random_heading: bool = True  # Kimodo's first-frame heading augmentation
    max_seconds: float = 10.0
    text_encoder: str = "minilm-l6-v2"
    seed: int = 0
    log_every: int = 20
    ckpt_every: int = 1000
    sampling_steps: int = 50  # saved with the model as the sampler default
    # clip sampling weight = (train clips sharing its content label) ** -content_balance: 0 draws clips
    # uniformly (common contents dominate), 0.5 square-root balances, 1 gives every content equal time
    content_balance: float = 0.0
    # multiply the sampling weight of the clips of these contents (clips.json 'content') by these factors,
    # after content_balance: a fine-tune can spend more of its steps on a few rare actions (issue 38: punches)
    content_weight: dict[str, float] = field(default_factory=dict)
    # train only on the clips of these datasets of the build (clips.json 'dataset'; all when empty): an
    # action expert (kinema.model.action_expert) serves only its actions' prompts, so its fine-tune need not
    # rehearse the rest
    datasets: list[str] = field(default_factory=list)
    # fine-tuning: start from the weights of this model or checkpoint folder (its EMA copy when present)
    # instead of random ones; the optimiser, step counter and schedule start fresh
    init_from: str = ""
    # weight of the foot-contact consistency term (kinema.train.losses.foot_contact_term, MDM's foot
    # loss); 0 trains with Eq. 1 (+ the constraint term) only, as every run before issue 18 did
    foot_contact: float = 0.0
    # > 0: train the text projection in whitened caption coordinates with this eigenvalue shrinkage
    # (kinema.train.text_whitening; a reparametrisation, saved folded, so models stay plain)
    text_whiten: float = 0.0
    # training windows are uniform in [crop_min_fraction, 1] x the longest clip of the batch's length
    # bucket: 0.5 as before issue 18; smaller lets a run's speed be learned apart from its clip's length
    # (docs/training.md: the captured runs all cover the ~8 m capture room, so slow runs are long clips)
    crop_min_fraction: float = 0.5
    # > 0: rows whose clip reaches beyond high_noise_min_std normalised units get, with this probability,
    # a training step where the noise hides that clip's largest value (kinema.train.noise_levels): clips far
    # outside the normalisation are otherwise read from the noisy input, never made from the text
    high_noise_share: float = 0.0
    high_noise_min_std: float = 8.0
    # those rows' steps: where sqrt(alpha_bar_t) * the clip's largest value <= this (1: at the noise's level)
    high_noise_visible: float = 1.0
    # fine-tuning: pull the predictions on the rows of these datasets' clips (all when empty) towards those
    # of this frozen model (kinema.train.anchor: learning without forgetting), with this weight
    anchor: str = ""
    anchor_weight: float = 1.0
    anchor_datasets: list[str] = field(default_factory=list)

    @classmethod
    def from_dict(cls, d: dict) -> TrainConfig:
        reject_unknown_keys(cls, d, "training settings")
        return cls(**d)


def content_weights(records: list[dict], power: float, scale: dict[str, float] | None = None,
                    source: str = "the training clips") -> list[float] | None:
    """Per-clip sampling weights ``count(content) ** -power``, times ``scale[content]`` for the contents
    it names (None for ``power == 0`` without a scale); a clip without a ``content`` label counts as its
    own content. Every content ``scale`` names must have a clip in ``records`` (``source`` names them in
    the error)."""
    if not math.isfinite(power) or power < 0:
        raise KinemaError(f"content_balance must be a finite number >= 0, got {power}")
    scale = scale or {}
    keys = [str(r.get("content") or r.get("clip_id", i)) for i, r in enumerate(records)]
    counts = Counter(keys)
    for content, factor in scale.items():
        if content not in counts:
            raise KinemaError(f"content_weight: no clip of {source} has the content {content!r} "
                              f"(contents: {', '.join(sorted(counts))})")
        if not (math.isfinite(factor) and factor > 0):
            raise KinemaError(f"content_weight: the factor of {content!r} must be a finite number > 0, got {factor}")
    if power == 0 and not scale:
        return None
    return [counts[k] ** -power * scale.get(k, 1.0) for k in keys]


def _dist_info() -> tuple[int, int]:
    if "WORLD_SIZE" in os.environ and int(os.environ["WORLD_SIZE"]) > 1:
        import torch.distributed as dist

        if not dist.is_initialized():
            dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


class Trainer:
    """Builds data, model, optimizer and EMA from a TrainConfig and runs the loop."""

    def __init__(self, cfg: TrainConfig, data_dir: str | Path, out_dir: str | Path, cache_dir: Path | None = None,
                 device: str | torch.device | None = None, bf16: bool = False, compile: bool = False):
        self.cfg, self.out_dir = cfg, Path(out_dir)
        self.rank, self.world = _dist_info()
        self.device = torch.device(device if device is not None else "cpu")
        if self.device.type == "cuda" and self.device.index is None and self.world > 1:
            self.device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))  # one GPU per rank
        if self.device.type == "cuda":  # a bare "cuda" means the current device (set_device wants an index)
            self.device = torch.device("cuda", self.device.index if self.device.index is not None
                                       else torch.cuda.current_device())
            torch.cuda.set_device(self.device)
        self.bf16, self.compile = bool(bf16), bool(compile)
        self.stopped_by_budget = False  # set by run(): whether its time budget ended it
        ds = MotionDataset(data_dir, "train")
        if cfg.datasets:
            ds.keep_datasets(cfg.datasets)
        if len(ds) == 0:
            raise KinemaError(f"{data_dir}: the train split is empty")
        self.dataset = ds
        self.layout, self.skeleton, self.stats, self.fps = ds.layout, ds.skeleton, ds.stats, ds.fps
        clips = [ds[i]["features"] for i in range(len(ds))]
        captions: list[str] = []
        ranges = []
        for rec in ds.clips:
            ranges.append((len(captions), len(captions) + len(rec["captions"])))
            captions.extend(rec["captions"])
        encoder = get_text_encoder(cfg.text_encoder, cache_dir=cache_dir)
        self.text_encoder_id = encoder.id
        self.text_table = encoder.encode(captions).float()
        max_frames = int(round(cfg.max_seconds * self.fps))
        if not 0.0 < cfg.crop_min_fraction <= 1.0:
            raise KinemaError(f"crop_min_fraction must be in (0, 1], got {cfg.crop_min_fraction}")
        self.batches = BatchSampler(
            clips, ranges, self.layout, self.stats, cfg.batch_size, max_frames,
            text_dropout=cfg.text_dropout, random_heading=cfg.random_heading, rank=self.rank, world_size=self.world,
            clip_weights=content_weights(ds.clips, cfg.content_balance, cfg.content_weight,
                                         f"{Path(data_dir) / 'clips.json'} (train split)"),
            crop_min_fraction=cfg.crop_min_fraction,
        )
        self.model_config = get_config(
            cfg.model, num_joints=self.skeleton.num_joints, text_dim=encoder.dim, fps=self.fps,
            max_frames=max_frames, dropout=cfg.phase1_dropout,
        )
        torch.manual_seed(cfg.seed)
        self.model = Denoiser(self.model_config)
        self.model.set_normalization(self.stats.mean, self.stats.std)
        lr_stats = local_root_stats(clips, self.fps)
        self.model.set_local_root_normalization(lr_stats.mean, lr_stats.std)
        if cfg.text_whiten:
            whiten_text_projections(self.model, self.text_table, cfg.text_whiten)
        self.model.to(self.device)
        self.ema = make_ema(self.model)
        self.optimizer = build_optimizer(cfg.optimizer, self.model.parameters(), cfg.lr, cfg.weight_decay)
        self.schedule = NoiseSchedule()
        if not math.isfinite(cfg.foot_contact) or cfg.foot_contact < 0:
            raise KinemaError(f"foot_contact must be a finite weight >= 0, got {cfg.foot_contact}")
        self.weights = LossWeights(foot_contact=cfg.foot_contact)
        self.step = 0
        self.phase1_steps = int(round(cfg.steps * cfg.phase1_fraction))
        self.anchor = self._anchor(ds.clips) if cfg.anchor else None

    def _anchor(self, records: list[dict]) -> Anchor:
        """The frozen teacher of ``cfg.anchor`` and which of the train clips ``records`` it anchors."""
        cfg = self.cfg
        _, state, stats = load_init_weights(cfg.anchor, self.model_config, self.layout, self.skeleton, self.fps)
        teacher = Denoiser(self.model_config)
        teacher.load_state_dict(state)
        return Anchor(teacher.to(self.device), stats, anchored_clips(records, cfg.anchor_datasets), cfg.anchor_weight)

    # ------------------------------------------------------------------ state
    def info(self) -> dict:
        """JSON saved with every checkpoint: what a loader needs to rebuild and use the model."""
        sampler = DDIMSampler(self.schedule, num_inference_steps=self.cfg.sampling_steps)
        return {
            "format": "kinema-checkpoint-1",
            "model_config": self.model_config.to_dict(),
            "feature_layout": self.layout.to_dict(),
            "fps": self.fps,
            "skeleton": self.skeleton.to_dict(),
            "stats": self.stats.to_dict(),
            "text_encoder": self.text_encoder_id,
            "pipeline": "human",  # the MotionPipeline that loads it (kinema.generate.loading)
            "sampler": sampler.to_dict(),
            "guidance": Guidance().to_dict(),
            "train_config": asdict(self.cfg),
            "loss_weights": self.weights.to_dict(),
            "phase": 1 if self.step < self.phase1_steps else 2,
            "world_size": self.world,
        }

    def resume(self) -> bool:
        """Load the newest checkpoint of ``out_dir``; False when there is none.

        The run continues in the normalisation statistics it saved, not the dataset's: a fine-tune
        (``init_from``) trains in its starting model's statistics, and before this a resumed fine-tune
        went on in the dataset's own (issue 38's run h38i switched at step 1250 of 4000, unnoticed, while
        the model's buffers and so generation kept the starting model's)."""
        if not (self.out_dir / "latest").exists():
            return False
        ck = load_checkpoint(self.out_dir)
        if ck["info"]["stats"] != self.stats.to_dict():  # a fine-tune: its starting model's statistics
            self.stats = self.batches.stats = NormStats.from_dict(ck["info"]["stats"])
        self.model.load_state_dict(ck["model"])
        if ck["ema"] is not None:
            self.ema.load_state_dict(ck["ema"])
        if ck["optimizer"] is not None:
            load_optimizer_tensors(self.optimizer, ck["optimizer"], ck["info"]["optimizer_param_groups"])
        self.step = int(ck["info"]["step"])
        return True

    def init_weights(self, path: str | Path) -> Path:
        """Fine-tuning: copy a trained model's weights (EMA copy preferred) into the model and its EMA.

        The model must have this run's architecture, skeleton, fps and feature layout; its normalisation
        statistics replace the dataset's (the weights were trained in them). Returns the checkpoint used.
        """
        ckpt, state, stats = load_init_weights(path, self.model_config, self.layout, self.skeleton, self.fps)
        self.model.load_state_dict(state)
        self.ema.load_state_dict(state)
        self.stats = self.batches.stats = stats
        return ckpt

    def keyframe_cap(self, step: int) -> int:
        """Most keyframes a phase-2 training mask may hold at ``step``: the curriculum ramp, except in a
        fine-tune that starts in phase 2 (its model already went through the ramp)."""
        cfg = self.cfg
        if cfg.init_from and self.phase1_steps == 0:
            return cfg.max_keyframes
        return max_keyframes_at(step, self.phase1_steps, cfg.steps - self.phase1_steps, 1, cfg.max_keyframes)

    def set_total_steps(self, steps: int) -> None:
        """Change the run's length (and with it the phase boundary) before the steps it affects.

        Why: a time-budgeted run (scripts/train_gpu.py) knows how many steps fit only once it has timed
        real steps (:meth:`time_steps`, then this at step 0). The schedule reads ``cfg.steps`` at every
        step, so this is exactly the run that had been started with ``steps``, as long as the steps done
        so far fall in the learning-rate warm-up and in phase 1 of both schedules (which is checked);
        `--resume` changes ``--steps`` the same way between invocations.
        """
        new_phase1 = int(round(steps * self.cfg.phase1_fraction))
        if steps <= self.step or self.step > min(self.cfg.warmup, self.phase1_steps, new_phase1):
            raise KinemaError(f"cannot change the run length to {steps} steps at step {self.step}: only during "
                              "the warm-up of phase 1 and before the end")
        self.cfg.steps = steps
        self.phase1_steps = new_phase1

    def time_steps(self, n: int) -> float:
        """Seconds per training step over ``n`` real steps, which are then undone (weights, EMA, optimizer
        state and step counter restored), so the run starts from where it was.

        Why: a time-budgeted run (scripts/train_gpu.py) needs its real step time (data drawing, device,
        precision) to fit the run length to the budget before the schedule starts."""
        import copy

        saved = (copy.deepcopy(self.model.state_dict()), copy.deepcopy(self.ema.state_dict()),
                 copy.deepcopy(self.optimizer.state_dict()), self.step)
        model = torch.compile(self.model) if self.compile else self.model
        self.train_step(model)  # warm-up: allocator, kernels, compilation
        t0 = time.perf_counter()
        for _ in range(n):
            self.train_step(model)
        seconds = (time.perf_counter() - t0) / n
        self.model.load_state_dict(saved[0])
        self.ema.load_state_dict(saved[1])
        self.optimizer.load_state_dict(saved[2])
        self.step = saved[3]
        return seconds

    def save(self) -> Path | None:
        if self.rank != 0:
            return None
        return save_checkpoint(self.out_dir, self.step, self.model, self.ema, self.optimizer, self.info())

    # ------------------------------------------------------------------ one step
    def train_step(self, model: torch.nn.Module) -> dict[str, float]:
        """One optimisation step with ``model`` (``self.model``, or it wrapped by DDP / torch.compile).

        Batch, mask, timesteps and noise are drawn on the CPU from the step's own generator (so runs are
        reproducible and resumable), then moved to ``self.device``; the forward runs under bf16 autocast
        when ``self.bf16``, the loss in float32. Returns the logged values of the step."""
        cfg, step = self.cfg, self.step
        g = step_generator(cfg.seed, self.rank, step)
        torch.manual_seed(int(torch.randint(0, 2**62, (1,), generator=g)))  # dropout masks
        phase = 1 if step < self.phase1_steps else 2
        self.model.set_dropout(cfg.phase1_dropout if phase == 1 else 0.0)
        batch = self.batches.sample(g)
        x0 = batch.features
        B = x0.shape[0]
        if phase == 2:
            kmax = self.keyframe_cap(step)
            mask = sample_batch_masks(batch.raw_features, batch.lengths, self.layout, self.skeleton, kmax, g)
        else:
            mask = torch.zeros_like(x0)
        t = self.schedule.sample_timesteps(B, g)
        t = high_noise_timesteps(t, x0, self.schedule, cfg.high_noise_share, cfg.high_noise_min_std, g,
                                 visible=cfg.high_noise_visible)
        noise = torch.randn(x0.shape, generator=g)
        x_t = self.schedule.q_sample(x0, t, noise)
        text = self.text_table[batch.caption_index]
        inputs = [x_t, t, text, batch.text_keep, batch.c_dir, x0, mask, batch.pad_mask]
        if self.device.type != "cpu":
            inputs = [x.to(self.device, non_blocking=True) for x in inputs]
        x0, mask, pad_mask = inputs[5], inputs[6], inputs[7]
        with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.bf16):
            pred = model(*inputs)
        loss, terms = motion_loss(pred.float(), x0, pad_mask, self.layout, self.skeleton, self.stats, self.weights,
                                  constraint_mask=mask if phase == 2 else None, fps=self.fps)
        if self.anchor is not None:
            with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.bf16):
                anchor = self.anchor.term(pred.float(), inputs, batch.clip_index, pad_mask)
            loss, terms["anchor"] = loss + anchor, anchor.detach()
        lr = lr_at(step, cfg.lr, cfg.warmup, cfg.steps)
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(self.model.parameters(), cfg.grad_clip)
        self.optimizer.step()
        self.step += 1
        if self.step % cfg.ema_every == 0:
            update_ema(self.ema, self.model, cfg.ema_decay)
        out = {k: float(v) for k, v in terms.items()}
        out.update(loss=float(loss.detach()), lr=lr, grad_norm=float(grad_norm), phase=phase,
                   frames=int(batch.lengths.sum()))
        return out

    # ------------------------------------------------------------------ loop
    def _out_of_time(self, deadline: float | None) -> bool:
        """Whether the time budget is spent; under DDP every rank gets rank 0's answer (they must agree)."""
        if deadline is None:
            return False
        late = time.monotonic() >= deadline
        if self.world > 1:
            import torch.distributed as dist

            flag = torch.tensor([1.0 if late else 0.0], device=self.device)
            dist.broadcast(flag, src=0)
            late = bool(flag.item())
        return late

    def run(self, progress: bool = True, stop_after: int | None = None, minutes: float | None = None) -> Path | None:
        """Train until ``cfg.steps`` (or ``stop_after`` more steps); returns the last checkpoint.

        ``minutes``: a wall-clock budget from this call (compilation included); when it is spent the loop
        stops after the current step, logs it and writes a checkpoint, so `--resume` continues from there.
        ``self.stopped_by_budget`` tells the caller which way the loop ended.
        """
        from tqdm.auto import tqdm

        deadline = None if minutes is None else time.monotonic() + 60.0 * minutes
        if self.anchor is not None:
            self.anchor.check_stats(self.stats, self.cfg.anchor)
        self.stopped_by_budget = False
        model: torch.nn.Module = self.model
        if self.world > 1:
            model = torch.nn.parallel.DistributedDataParallel(self.model)
        if self.compile:
            model = torch.compile(model)
        end = self.cfg.steps if stop_after is None else min(self.cfg.steps, self.step + stop_after)
        log_path = self.out_dir / "log.jsonl"
        if self.rank == 0:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            (self.out_dir / "train_config.json").write_text(json.dumps(asdict(self.cfg), indent=1))
        bar = tqdm(total=end, initial=self.step, disable=not progress or self.rank != 0, desc="train",
                   dynamic_ncols=True)
        last = None
        t0, ema_loss = time.time(), None
        while self.step < end:
            rec = self.train_step(model)
            ema_loss = rec["loss"] if ema_loss is None else 0.95 * ema_loss + 0.05 * rec["loss"]
            bar.update(1)
            bar.set_postfix(loss=f"{ema_loss:.4f}", phase=rec["phase"])
            stop = self.step < end and self._out_of_time(deadline)
            if self.rank == 0 and (self.step % self.cfg.log_every == 0 or self.step == end or stop):
                rec.update(step=self.step, time=round(time.time() - t0, 2))
                with open(log_path, "a") as fh:
                    fh.write(json.dumps(rec) + "\n")
            if self.step % self.cfg.ckpt_every == 0 or self.step == end or stop:
                last = self.save() or last
            if stop:
                self.stopped_by_budget = True
                break
        bar.close()
        return last
