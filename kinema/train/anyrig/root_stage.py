"""Training the root stage of an any-rig model (kinema.model.anyrig.root_stage) on its multi-rig build.

The data, captions, rig augmentation, clamped root rates and checkpoints are those of the any-rig
trainer (kinema.train.anyrig.trainer); a batch is ``batch_size`` windows drawn from all clips alike
(the stage reads one row per frame, so a 48-joint fox costs what a 6-joint fish does), except that
``content_shares`` may fix the share of each batch drawn from the clips of a content (``{"idle": 0.25}``:
a quarter of every batch stands still, against the 7 % of windows idles are among the creatures' clips),
and the loss
is the masked MSE on the root row's real channels. Constraint masks (probability ``p_constrained``)
are what sampling gives the stage: a prefix of whole frames (window blending, live streams), a few
whole frames (keyframes), or some channels on every frame (a root path's ground velocity, a heading).
The stage belongs to one any-rig model: its config fixes the rig codes (RestPE) the stage reads.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch

from kinema.errors import DataError, KinemaError
from kinema.model.anyrig.loading import load_anyrig
from kinema.model.anyrig.root_stage import RootStageConfig, RootStageDenoiser
from kinema.model.config import reject_unknown_keys
from kinema.model.skeleton_codes import rest_dim
from kinema.train.anyrig.data import GROUND_VELOCITY, Batch, Clip
from kinema.train.anyrig.trainer import AnyRigTrainer

MASK_KINDS = ("prefix", "frames", "channels")


@dataclass
class RootStageTrainConfig:
    """Settings of one root-stage run (saved in every checkpoint; unknown keys are rejected)."""

    steps: int = 6000
    lr: float = 1e-3
    warmup: int = 200
    weight_decay: float = 0.0
    batch_size: int = 64
    variants: int = 2
    seed: int = 0
    ckpt_every: int = 500
    log_every: int = 50
    ema_decay: float = 0.998
    text_drop: float = 0.1
    p_constrained: float = 0.5
    grad_clip: float = 1.0
    velocity_weight: float = 1.0  # x the loss on the root's ground velocity (`root_loss`)
    path_weight: float = 0.0  # of the ground-path term of `root_loss`
    content_shares: dict[str, float] = field(default_factory=dict)  # content -> share of each batch
    width: int = 128
    layers: int = 4
    heads: int = 4
    model: str = ""  # the any-rig model folder the stage belongs to

    @classmethod
    def from_dict(cls, d: dict) -> RootStageTrainConfig:
        reject_unknown_keys(cls, d, "root stage training settings")
        return cls(**d)

    def __post_init__(self) -> None:
        shares = self.content_shares
        if any(not 0.0 < s <= 1.0 for s in shares.values()) or sum(shares.values()) > 1.0:
            raise KinemaError(f"content_shares: expected shares in (0, 1] that add up to at most 1, got {shares}")


def root_rows(batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
    """The batch's root rows ``(B, T, 13)`` and their real channels ``(B, 13)``."""
    root = batch.codes.flags[..., 0].argmax(1)
    b = torch.arange(root.shape[0])
    return batch.x[b, :, root], batch.channel_mask[b, root]


def root_masks(frame_mask: torch.Tensor, channels: torch.Tensor, gen: torch.Generator, p: float) -> torch.Tensor:
    """{0, 1} masks ``(B, T, 13)`` of the kinds in the module docstring, on real frames and channels."""
    B, T = frame_mask.shape
    out = torch.zeros(B, T, channels.shape[1])
    for i in range(B):
        if float(torch.rand(1, generator=gen)) >= p:
            continue
        n = int(frame_mask[i].sum())
        kind = MASK_KINDS[int(torch.randint(len(MASK_KINDS), (1,), generator=gen))]
        if kind == "prefix":
            out[i, : int(torch.randint(1, max(2, n // 2 + 1), (1,), generator=gen))] = 1.0
        elif kind == "frames":
            k = int(torch.randint(1, 4, (1,), generator=gen))
            out[i, torch.randperm(n, generator=gen)[:k]] = 1.0
        else:
            real = channels[i].nonzero().flatten()
            pick = real[torch.rand(len(real), generator=gen) < 0.5]
            out[i, :n, pick if len(pick) else real[:1]] = 1.0
    return out * frame_mask[:, :, None] * channels[:, None]


class RootStageTrainer(AnyRigTrainer):
    """Train a `RootStageDenoiser` for the any-rig model ``cfg.model`` (see the module docstring)."""

    def __init__(
        self,
        cfg: RootStageTrainConfig,
        data: str | Path,
        out: str | Path,
        *,
        text_cache: Path | None = Path("cache/text"),
        log=print,
    ) -> None:
        base = load_anyrig(cfg.model)
        self.base_text_encoder = base.text_encoder_id
        self.stage_config = RootStageConfig(
            code_dim=2 + rest_dim(base.config), width=cfg.width, layers=cfg.layers, heads=cfg.heads,
            text_dim=base.config.text_dim,
        )
        super().__init__(base.config, cfg, data, out, text_cache=text_cache, log=log)
        self.by_content = content_pools(self.clips.clips, cfg.content_shares, data)

    def new_model(self) -> RootStageDenoiser:
        return RootStageDenoiser(self.stage_config)

    def set_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        self.model.set_normalization(mean[0], std[0])  # the root row's

    def text_encoder_id(self) -> str:
        return self.base_text_encoder

    def config_dict(self) -> dict:
        return self.stage_config.to_dict()

    def info(self) -> dict:
        return {
            "kind": "anyrig-root-stage",
            "model_config": self.config_dict(),
            "anyrig_config": self.model_config.to_dict(),
            "train_config": asdict(self.cfg),
            "data": self.data_path,
            "elapsed_s": round(self.elapsed, 1),
        }

    def init_weights(self, path: str | Path) -> Path:
        raise KinemaError("a root stage trains from scratch (it is small); --init-from does not apply")

    def sample_batch(self, gen: torch.Generator) -> Batch:
        B, picks = self.cfg.batch_size, []
        for content, share in sorted(self.cfg.content_shares.items()):
            pool = self.by_content[content]
            picks += [pool[int(i)] for i in torch.randint(len(pool), (round(share * B),), generator=gen)]
        picks += [int(i) for i in torch.randint(len(self.clips.clips), (B - len(picks),), generator=gen)]
        return self.clips.window_batch([self.clips.clips[i] for i in picks], gen)

    def batch_note(self) -> str:
        shares = ", ".join(f"{s:.0%} {c}" for c, s in sorted(self.cfg.content_shares.items()))
        return f"{self.cfg.batch_size} windows a batch" + (f" ({shares})" if shares else "")

    def loss(self, model: RootStageDenoiser, batch: Batch, gen: torch.Generator) -> torch.Tensor:
        x, channels = root_rows(batch)
        real = (batch.frame_mask[:, :, None] & channels[:, None]).float()
        x0 = model.normalize(x) * real
        B = x0.shape[0]
        t = torch.randint(0, self.schedule.num_train_steps, (B,), generator=gen)
        x_t = self.schedule.q_sample(x0, t, torch.randn(x0.shape, generator=gen)) * real
        keep = (torch.rand(B, generator=gen) >= self.cfg.text_drop).float()[:, None]
        text = torch.stack([self.text[c] for c in batch.captions]) * keep
        mask = root_masks(batch.frame_mask, channels, gen, self.cfg.p_constrained)
        pred = model(x_t, t, text, batch.codes, batch.frame_mask, x0, mask)
        return root_loss(pred, x0, real, velocity_weight=self.cfg.velocity_weight, path_weight=self.cfg.path_weight)


def content_pools(clips: list[Clip], shares: dict[str, float], data: str | Path) -> dict[str, list[int]]:
    """The indices of the clips of each content named in ``shares``; a content no clip has is an error."""
    pools = {c: [i for i, clip in enumerate(clips) if clip.content == c] for c in shares}
    missing = sorted(c for c, idx in pools.items() if not idx)
    if missing:
        have = sorted({clip.content for clip in clips})
        raise DataError(f"{data}: content_shares: no clips of content {', '.join(missing)} (the build has: "
                        f"{', '.join(have)})")
    return pools


def root_loss(pred: torch.Tensor, x0: torch.Tensor, real: torch.Tensor, *, velocity_weight: float = 1.0,
              path_weight: float = 0.0) -> torch.Tensor:
    """The masked MSE of normalised root rows ``(B, T, 13)`` (``real``: {0, 1} of the same shape), the
    ground velocity's squared error times ``velocity_weight``, plus ``path_weight`` times the ground path's:
    the running sum of the ground velocity's error (the displacement it adds up to) squared over the
    window's frames. A steady error of e a frame adds up to n e over n frames (the shipped stage's idles
    creep so: a steady 0.03 body sizes/s on held-out rigs) and costs about n / 3 times its per-frame square
    there; uncorrelated per-frame errors cost about half theirs."""
    vel = list(GROUND_VELOCITY)
    err = (pred - x0) * real
    w = torch.ones(err.shape[-1], dtype=err.dtype)
    w[vel] = velocity_weight
    total = (err**2 * w).sum()
    if path_weight:
        n = real[..., vel].amax(-1).sum(1).clamp_min(1.0)  # (B,) frames with a real velocity
        path = err[..., vel].cumsum(1)
        total = total + path_weight * (path**2 / n[:, None, None]).sum()
    return total / real.sum().clamp_min(1.0)
