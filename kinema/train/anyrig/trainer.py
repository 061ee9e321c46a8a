"""Training loop of the any-rig model: DDPM x0 prediction on per-joint features of many rigs.

Each step draws one joint-count bucket (kinema.train.anyrig.data), random windows, a random caption
per clip (dropped to the empty condition with probability ``text_drop``), random constraint masks
(kinema.train.anyrig.masks) and a diffusion step; the loss is the masked MSE between the predicted and
the clean normalised features over real frames, joints and channels. AdamW with warm-up and cosine
decay, gradient clipping, an EMA copy. Checkpoints (kinema.train.checkpoint: safetensors, atomic,
``latest`` pointer) hold weights, EMA, optimiser and step; ``resume`` continues the newest, and batches
are a pure function of (seed, step), so an interrupted run continues as if it had not stopped.
Progress: one line every ``log_every`` steps (loss, s/step, ETA) to stdout and ``log.jsonl``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.diffusion.schedule import NoiseSchedule
from kinema.errors import KinemaError
from kinema.model.anyrig.config import AnyRigConfig
from kinema.model.anyrig.denoiser import AnyRigDenoiser
from kinema.model.anyrig.loading import load_anyrig
from kinema.model.config import reject_unknown_keys
from kinema.text import get_text_encoder
from kinema.train.anyrig.data import AnyRigClips, Batch
from kinema.train.anyrig.masks import random_masks
from kinema.train.checkpoint import load_checkpoint, load_optimizer_tensors, save_checkpoint
from kinema.train.optim import lr_at, make_ema, update_ema

DEFAULT_SAMPLER_STEPS = 30


@dataclass
class AnyRigTrainConfig:
    """Settings of one training run (saved in every checkpoint; unknown keys are rejected)."""

    steps: int = 4000
    lr: float = 1e-3
    warmup: int = 200
    weight_decay: float = 0.0
    token_budget: int = 256
    variants: int = 2
    seed: int = 0
    ckpt_every: int = 200
    log_every: int = 20
    ema_decay: float = 0.998
    text_drop: float = 0.1
    p_constrained: float = 0.5
    grad_clip: float = 1.0
    root_weight: float = 1.0
    text_encoder: str = "minilm-l6-v2"
    init_from: str | None = None

    @classmethod
    def from_dict(cls, d: dict) -> AnyRigTrainConfig:
        reject_unknown_keys(cls, d, "any-rig training settings")
        return cls(**d)


class AnyRigTrainer:
    """Train an `AnyRigDenoiser` on a multi-rig build (see the module docstring)."""

    def __init__(
        self,
        model_config: AnyRigConfig,
        cfg: AnyRigTrainConfig,
        data: str | Path,
        out: str | Path,
        *,
        text_cache: Path | None = Path("cache/text"),
        log=print,
    ) -> None:
        self.model_config, self.cfg, self.out, self.log = model_config, cfg, Path(out), log
        self.data_path = str(data)
        self.clips = AnyRigClips(data, model_config, split="train", variants=cfg.variants, seed=cfg.seed, log=log)
        with torch.random.fork_rng():  # the initial weights come from the seed, not the process's random state
            torch.manual_seed(cfg.seed)
            self.model = self.new_model()
        self.set_normalization(*self.clips.stats())
        self.ema = make_ema(self.model)
        self.opt = torch.optim.AdamW(
            self.model.parameters(), lr=cfg.lr, betas=(0.9, 0.99), weight_decay=cfg.weight_decay
        )
        self.schedule = NoiseSchedule()
        encoder = get_text_encoder(self.text_encoder_id(), cache_dir=text_cache)
        if encoder.dim != model_config.text_dim:
            raise KinemaError(
                f"text encoder {self.text_encoder_id()} gives {encoder.dim}-d embeddings; the model "
                f"config expects text_dim {model_config.text_dim}"
            )
        captions = sorted({c for clip in self.clips.clips for c in clip.captions})
        self.text = dict(zip(captions, encoder.encode(captions), strict=True))
        self.text_dim = encoder.dim
        self.step, self.elapsed = 0, 0.0

    # ------------------------------------------------------------------ what is trained (subclasses change it)
    def new_model(self) -> torch.nn.Module:
        """The network this run trains, freshly initialised."""
        return AnyRigDenoiser(self.model_config)

    def set_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Give the network the data's statistics ``(2, 13)`` (root row, other joints)."""
        self.model.set_normalization(mean, std)

    def text_encoder_id(self) -> str:
        return self.cfg.text_encoder

    def config_dict(self) -> dict:
        """The trained network's config as saved (a resumed run must match it)."""
        return self.model_config.to_dict()

    # ------------------------------------------------------------------ checkpoints
    def info(self) -> dict:
        rigs = {rid: rig.to_dict() for rid, rig in self.clips.rigs.items()}
        return {
            "kind": "anyrig",
            "pipeline": "anyrig",  # the MotionPipeline that loads it (kinema.generate.loading)
            "model_config": self.config_dict(),
            "train_config": asdict(self.cfg),
            "fps": self.model_config.fps,
            "text_encoder": self.cfg.text_encoder,
            "sampler": DDIMSampler(self.schedule, num_inference_steps=DEFAULT_SAMPLER_STEPS).to_dict(),
            "guidance": Guidance(w_text=2.0, w_constr=2.0).to_dict(),
            "data": self.data_path,
            "train_rigs": rigs,
            "rig_ties": {rid: t.to_dict(self.clips.rigs[rid].skeleton.names) for rid, t in self.clips.ties.items()},
            "elapsed_s": round(self.elapsed, 1),
        }

    def save(self) -> Path:
        return save_checkpoint(self.out, self.step, self.model, self.ema, self.opt, self.info())

    def resume(self) -> bool:
        """Continue the newest checkpoint in the run folder (False when there is none)."""
        if not (self.out / "latest").exists():
            return False
        ck = load_checkpoint(self.out)
        info = ck["info"]
        if info.get("model_config") != self.config_dict():
            raise KinemaError(f"{self.out}: the checkpoint's model config differs from the requested one")
        self.model.load_state_dict(ck["model"])
        self.ema.load_state_dict(ck["ema"])
        if ck["optimizer"] is not None:
            load_optimizer_tensors(self.opt, ck["optimizer"], info["optimizer_param_groups"])
        self.step, self.elapsed = int(info["step"]), float(info.get("elapsed_s", 0.0))
        self.log(f"resumed {ck['path']} at step {self.step} ({self.elapsed / 60:.1f} min trained)")
        return True

    def init_weights(self, path: str | Path) -> Path:
        """Fine-tuning: start the model and its EMA from a trained any-rig model's (EMA) weights. The
        model config must match; the normalisation statistics stay this run's data's (a rebuilt dataset,
        e.g. with travel recovered, moves the velocity channels' statistics). Returns the checkpoint."""
        loaded = load_anyrig(path)
        if loaded.config != self.model_config:
            raise KinemaError(f"{loaded.path}: its model config differs from this run's ({self.model_config})")
        keep = {"feat_mean", "feat_std"}
        state = {k: v for k, v in loaded.denoiser.state_dict().items() if k not in keep}
        missing, unexpected = self.model.load_state_dict(state, strict=False)
        if set(missing) - keep or unexpected:
            raise KinemaError(f"{loaded.path}: weights do not fit this model ({missing}, {unexpected})")
        self.ema.load_state_dict(self.model.state_dict())
        self.cfg.init_from = str(path)
        return loaded.path

    # ------------------------------------------------------------------ one step
    def loss(self, model: AnyRigDenoiser, batch: Batch, gen: torch.Generator) -> torch.Tensor:
        codes = batch.codes
        x0 = model.normalize(batch.x, codes)
        real = (batch.frame_mask[:, :, None, None] & batch.channel_mask[:, None]).float()
        x0 = x0 * real
        B = x0.shape[0]
        t = torch.randint(0, self.schedule.num_train_steps, (B,), generator=gen)
        noise = torch.randn(x0.shape, generator=gen)
        x_t = self.schedule.q_sample(x0, t, noise) * real
        keep = (torch.rand(B, generator=gen) >= self.cfg.text_drop).float()[:, None]
        text = torch.stack([self.text[c] for c in batch.captions]) * keep
        mask = random_masks(batch.frame_mask, batch.channel_mask, codes.flags[..., 0], gen, self.cfg.p_constrained)
        pred = model(x_t, t, text, codes, batch.frame_mask, x0, mask)
        # the root row (ground velocity, height, heading) counts root_weight times a joint's row
        weight = real * (1.0 + (self.cfg.root_weight - 1.0) * (codes.flags[..., 0] > 0.5).float())[:, None, :, None]
        return ((pred - x0) ** 2 * weight).sum() / weight.sum().clamp_min(1.0)

    def sample_batch(self, gen: torch.Generator) -> Batch:
        return self.clips.sample_batch(gen, self.cfg.token_budget)

    def batch_note(self) -> str:
        return f"token budget {self.cfg.token_budget}"

    def train_step(self) -> float:
        gen = torch.Generator().manual_seed(self.cfg.seed * 1_000_003 + self.step)
        batch = self.sample_batch(gen)
        for g in self.opt.param_groups:
            g["lr"] = lr_at(self.step, self.cfg.lr, self.cfg.warmup, self.cfg.steps)
        self.model.train()
        loss = self.loss(self.model, batch, gen)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.cfg.grad_clip)
        self.opt.step()
        update_ema(self.ema, self.model, self.cfg.ema_decay if self.step > self.cfg.warmup else 0.9)
        self.step += 1
        return loss.item()

    # ------------------------------------------------------------------ loop
    def run(self, *, minutes: float | None = None) -> Path:
        """Train to ``cfg.steps`` (or for ``minutes``), checkpointing every ``ckpt_every`` and at the end."""
        self.out.mkdir(parents=True, exist_ok=True)
        self.log(
            f"model: {self.model.num_parameters()} parameters; {self.cfg.steps} steps, {self.batch_note()}"
        )
        start, t_log, losses = time.time(), time.time(), []
        last = None
        while self.step < self.cfg.steps:
            t0 = time.time()
            losses.append(self.train_step())
            self.elapsed += time.time() - t0
            if self.step % self.cfg.log_every == 0:
                self._log_line(losses, time.time() - t_log)
                t_log, losses = time.time(), []
            if self.step % self.cfg.ckpt_every == 0:
                last = self.save()
            if minutes is not None and time.time() - start > 60 * minutes:
                self.log(f"time budget of {minutes:g} min reached at step {self.step}")
                break
        if last is None or not last.name.endswith(f"{self.step:08d}"):
            last = self.save()
        return last

    def _log_line(self, losses: list[float], dt: float) -> None:
        sps = dt / max(1, len(losses))
        eta = (self.cfg.steps - self.step) * sps / 60
        loss = sum(losses) / max(1, len(losses))
        self.log(f"step {self.step}/{self.cfg.steps}  loss {loss:.4f}  {sps:.2f} s/step  ETA {eta:.0f} min")
        with open(self.out / "log.jsonl", "a", encoding="utf-8") as f:
            f.write(
                json.dumps({"step": self.step, "loss": loss, "s_per_step": sps, "elapsed_s": round(self.elapsed, 1)})
                + "\n"
            )
