"""A TMR-style text-motion retrieval model: the embedding behind kinema's R-precision and FID.

Kimodo (Sec. 6.1) measures text following with R@k and motion quality with FID in the embedding space
of a TMR model (Petrovich et al., ICCV 2023). No such evaluator can be downloaded for our skeleton, so
kinema trains its own (see :mod:`kinema.evaluate.retrieval_train`) and ships the weights in
``kinema/assets/retrieval/``.

* **Motion side**: features ``(B, T, D)`` at the dataset frame rate, *unnormalised* as stored in a
  build or produced by the generator. They are canonicalised (first-frame root over the origin and
  first-frame heading turned to 0, :func:`canonicalize_start`) so the embedding ignores where the
  motion is placed and which way it starts facing, then normalised with the dataset statistics, and
  read by a small pre-norm transformer (two frames per token) with a learned CLS token, sinusoidal
  positions and a padding mask. The CLS output is projected to ``embed_dim`` and L2-normalised.
* **Text side**: the frozen sentence embedding of the text encoder recorded in the config
  (MiniLM, 384-d) goes through a two-layer MLP and is L2-normalised.

A saved model is a folder with ``model.safetensors`` (weights, optionally float16) and
``config.json`` (architecture, feature layout, normalisation stats, fps, text encoder id, a SHA-256 of
the weights file and training notes). Each file is replaced atomically; the hash lets the loader
reject a weights file that does not belong to its config. No pickle.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from safetensors import SafetensorError
from safetensors.torch import load_file
from safetensors.torch import save as save_safetensors_bytes
from torch import nn

from kinema.atomic_files import atomic_write_bytes, atomic_write_text
from kinema.errors import KinemaError
from kinema.model.config import reject_unknown_keys
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.representation.transform import canonicalize_start

FORMAT = "kinema-retrieval-1"
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"


@dataclass
class RetrievalConfig:
    """Architecture and the crop lengths the model was trained for (saved in config.json)."""

    width: int = 128
    layers: int = 3
    heads: int = 4
    ff_mult: int = 2
    dropout: float = 0.1
    embed_dim: int = 256
    text_dim: int = 384
    text_hidden: int = 512
    temperature: float = 0.07
    frames_per_token: int = 2  # consecutive frames concatenated into one token: 10 tokens/s at 20 fps
    min_frames: int = 40  # training crops: 2 s at 20 fps ...
    max_frames: int = 200  # ... to 10 s; evaluation uses a centred crop of at most this length

    @classmethod
    def from_dict(cls, d: dict) -> RetrievalConfig:
        reject_unknown_keys(cls, d, "retrieval model settings")
        return cls(**d)


def sinusoidal_positions(length: int, width: int) -> torch.Tensor:
    """The (length, width) sine/cosine position table of Vaswani et al. (2017)."""
    pos = torch.arange(length, dtype=torch.float32)[:, None]
    freq = torch.exp(torch.arange(0, width, 2, dtype=torch.float32) * (-math.log(10000.0) / width))
    table = torch.zeros(length, width)
    table[:, 0::2] = torch.sin(pos * freq)
    table[:, 1::2] = torch.cos(pos * freq[: width // 2])
    return table


def center_crop(features: torch.Tensor, max_frames: int) -> torch.Tensor:
    """The centred ``max_frames`` window of a (T, D) clip (the clip itself when shorter)."""
    T = features.shape[0]
    if T <= max_frames:
        return features
    start = (T - max_frames) // 2
    return features[start : start + max_frames]


def pad_clips(clips: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Stack (T_i, D) clips into (B, T_max, D) by repeating each clip's last frame; returns lengths (B,)."""
    lengths = torch.tensor([c.shape[0] for c in clips])
    out = torch.empty(len(clips), int(lengths.max()), clips[0].shape[-1], dtype=clips[0].dtype)
    for b, c in enumerate(clips):
        out[b, : c.shape[0]] = c
        out[b, c.shape[0] :] = c[-1]
    return out, lengths


class RetrievalModel(nn.Module):
    """Motion and text encoders into one L2-normalised space of dimension ``config.embed_dim``.

    Besides the weights it carries what using it correctly needs: the feature ``layout`` and
    normalisation ``stats`` of the data it was trained on, the ``fps`` and the ``text_encoder_id`` whose
    sentence embeddings :meth:`encode_text` expects.
    """

    def __init__(self, config: RetrievalConfig, layout: FeatureLayout, stats: NormStats, fps: float,
                 text_encoder_id: str, info: dict | None = None):
        super().__init__()
        c = self.config = config
        self.layout, self.fps, self.text_encoder_id = layout, float(fps), text_encoder_id
        self.info: dict[str, Any] = dict(info or {})
        self.register_buffer("mean", stats.mean.clone().float(), persistent=False)
        self.register_buffer("std", stats.std.clone().float(), persistent=False)
        self.input = nn.Linear(c.frames_per_token * layout.dim, c.width)
        self.cls = nn.Parameter(torch.randn(c.width) * 0.02)
        layer = nn.TransformerEncoderLayer(c.width, c.heads, c.ff_mult * c.width, c.dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, c.layers, enable_nested_tensor=False)
        self.motion_head = nn.Sequential(nn.LayerNorm(c.width), nn.Linear(c.width, c.embed_dim))
        self.text_head = nn.Sequential(nn.Linear(c.text_dim, c.text_hidden), nn.GELU(), nn.Dropout(c.dropout),
                                       nn.Linear(c.text_hidden, c.embed_dim))

    @property
    def stats(self) -> NormStats:
        return NormStats(self.mean.clone(), self.std.clone())

    def prepare(self, features: torch.Tensor) -> torch.Tensor:
        """Canonicalise (root at the origin, heading 0 at frame 0) and normalise (B, T, D) features."""
        x = canonicalize_start(features.float(), self.layout, angle=0.0)
        return (x - self.mean) / self.std

    def encode_motion(self, features: torch.Tensor, lengths: torch.Tensor | None = None,
                      chunk: int = 32) -> torch.Tensor:
        """(B, E) unit embeddings of unnormalised features (B, T, D); ``lengths`` (B,) marks real frames.

        Frames past a clip's length are ignored (masked). For speed the batch is sorted by length and
        encoded in chunks of ``chunk`` clips, each trimmed to its own longest clip, which spends little
        time on padding without changing the result beyond float rounding."""
        if features.ndim != 3 or features.shape[-1] != self.layout.dim:
            raise KinemaError(f"expected features (B, T, {self.layout.dim}), got {tuple(features.shape)}")
        B, T, _ = features.shape
        lengths = torch.full((B,), T) if lengths is None else torch.as_tensor(lengths).cpu()
        if int(lengths.min()) < 1 or int(lengths.max()) > T:
            raise KinemaError(f"lengths must lie in [1, {T}], got {lengths.tolist()}")
        x = self.prepare(features)
        if B <= chunk:
            return self._encode(x[:, : int(lengths.max())], lengths)
        order = torch.argsort(lengths, stable=True)
        parts = []
        for k in range(0, B, chunk):
            idx = order[k : k + chunk]
            parts.append(self._encode(x[idx, : int(lengths[idx].max())], lengths[idx]))
        return torch.cat(parts)[torch.argsort(order)]

    def _encode(self, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """Transformer pass over normalised (B, T, D) frames: tokens of ``frames_per_token`` frames."""
        B, T, D = x.shape
        f = self.config.frames_per_token
        last = x[torch.arange(B), lengths.to(x.device) - 1]  # frames past the end repeat the last real one,
        x = torch.where(torch.arange(T, device=x.device)[None, :, None] < lengths.to(x.device)[:, None, None],
                        x, last[:, None])  # so what padding holds never matters
        if T % f:  # whole tokens only
            x = torch.cat([x, x[:, -1:].expand(B, f - T % f, D)], dim=1)
        x = x.reshape(B, -1, f * D)
        n = x.shape[1]
        h = self.input(x) + sinusoidal_positions(n, self.config.width).to(x.device)
        h = torch.cat([self.cls.expand(B, 1, -1), h], dim=1)
        tokens = (lengths.to(x.device) + f - 1) // f
        pad = torch.arange(n + 1, device=x.device)[None, :] > tokens[:, None]  # CLS at 0 never masked
        h = self.encoder(h, src_key_padding_mask=pad)
        return F.normalize(self.motion_head(h[:, 0]), dim=-1)

    def encode_text(self, text_emb: torch.Tensor) -> torch.Tensor:
        """(B, E) unit embeddings of frozen sentence embeddings (B, text_dim)."""
        if text_emb.ndim != 2 or text_emb.shape[-1] != self.config.text_dim:
            raise KinemaError(f"expected text embeddings (B, {self.config.text_dim}), got {tuple(text_emb.shape)}")
        return F.normalize(self.text_head(text_emb.float()), dim=-1)

    @torch.no_grad()
    def encode_clips(self, clips: list[torch.Tensor], batch_size: int = 64) -> torch.Tensor:
        """(N, E) embeddings of whole (T_i, D) clips, each centred-cropped to ``config.max_frames``.

        Clips are batched in order of length so that little time is spent on padding."""
        was_training = self.training
        self.eval()
        crops = [center_crop(c, self.config.max_frames) for c in clips]
        order = sorted(range(len(crops)), key=lambda i: crops[i].shape[0])
        out = torch.empty(len(crops), self.config.embed_dim)
        for k in range(0, len(order), batch_size):
            idx = order[k : k + batch_size]
            feats, lengths = pad_clips([crops[i] for i in idx])
            out[idx] = self.encode_motion(feats, lengths)
        self.train(was_training)
        return out

    @torch.no_grad()
    def encode_captions(self, texts: list[str], cache_dir: str | Path | None = None) -> torch.Tensor:
        """(N, E) embeddings of raw captions through this model's text encoder (optionally cached).

        The encoder is built once per (id, cache_dir) and kept, since MiniLM loads its weights on first use."""
        was_training = self.training
        self.eval()
        out = self.encode_text(_text_encoder(self.text_encoder_id, None if cache_dir is None else str(cache_dir))
                               .encode(texts))
        self.train(was_training)
        return out

    # ------------------------------------------------------------------ persistence
    def config_dict(self) -> dict:
        return {
            "format": FORMAT,
            "config": asdict(self.config),
            "feature_layout": self.layout.to_dict(),
            "fps": self.fps,
            "stats": self.stats.to_dict(),
            "text_encoder": self.text_encoder_id,
            "info": self.info,
        }

    def save(self, path: str | Path, half: bool = False) -> Path:
        """Write ``model.safetensors`` (float16 when ``half``) and ``config.json`` into folder ``path``."""
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        dtype = torch.float16 if half else torch.float32
        state = {k: v.detach().cpu().to(dtype).contiguous() for k, v in self.state_dict().items()}
        data = save_safetensors_bytes(state, metadata={"format": FORMAT})
        digest = hashlib.sha256(data).hexdigest()
        atomic_write_bytes(path / WEIGHTS_FILE, data)
        payload = self.config_dict() | {"weights_dtype": str(dtype).removeprefix("torch."), "weights_sha256": digest}
        atomic_write_text(path / CONFIG_FILE, json.dumps(payload, indent=1) + "\n")
        return path


@functools.lru_cache(maxsize=4)
def _text_encoder(name: str, cache_dir: str | None):
    from kinema.text import get_text_encoder

    return get_text_encoder(name, cache_dir=cache_dir)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def default_retrieval_path() -> Path:
    """The folder of the retrieval weights shipped with kinema (``kinema/assets/retrieval``)."""
    return Path(str(resources.files("kinema").joinpath("assets", "retrieval")))


def load_retrieval(path: str | Path | None = None) -> RetrievalModel:
    """Load a saved retrieval model (default: the shipped one) in eval mode, float32 on the CPU."""
    path = Path(path) if path is not None else default_retrieval_path()
    cfg_path, weights = path / CONFIG_FILE, path / WEIGHTS_FILE
    if not cfg_path.is_file() or not weights.is_file():
        raise KinemaError(f"{path}: no retrieval model (expected {CONFIG_FILE} and {WEIGHTS_FILE}); "
                          "train one with `kinema retrieval train`")
    try:
        meta = json.loads(cfg_path.read_text(encoding="utf-8"))
        if meta.get("format") != FORMAT:
            raise KinemaError(f"{cfg_path}: format {meta.get('format')!r}, this kinema reads {FORMAT!r}")
        expected = meta.get("weights_sha256")
        if expected and _sha256(weights) != expected:
            raise KinemaError(f"{weights}: does not match the SHA-256 recorded in {cfg_path} (half-written save?)")
        config = RetrievalConfig.from_dict(meta["config"])
        layout = FeatureLayout(int(meta["feature_layout"]["num_joints"]))
        if layout.to_dict() != meta["feature_layout"]:
            raise KinemaError(f"{cfg_path}: feature layout does not match this kinema version")
        model = RetrievalModel(config, layout, NormStats.from_dict(meta["stats"]), meta["fps"],
                               meta["text_encoder"], meta.get("info"))
        state = load_file(str(weights))
        model.load_state_dict({k: v.float() for k, v in state.items()})
    except KinemaError:
        raise
    except (OSError, ValueError, KeyError, TypeError, RuntimeError, SafetensorError) as err:
        raise KinemaError(f"{path}: unreadable retrieval model ({err})") from None
    return model.eval()
