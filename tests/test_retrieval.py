"""Retrieval model (kinema.evaluate.retrieval*): learning, persistence, invariance, metrics, CLI, shipped weights."""

from __future__ import annotations

import argparse
import json
import math

import pytest
import torch

from kinema.data.dataset import MotionDataset
from kinema.errors import KinemaError
from kinema.evaluate.retrieval import (
    RetrievalConfig,
    default_retrieval_path,
    load_retrieval,
    pad_clips,
)
from kinema.evaluate.retrieval_train import (
    contrastive_loss,
    evaluate_retrieval,
    format_metrics,
    retrieval_metrics,
    train_retrieval,
)
from kinema.representation.transform import rotate_features, translate_features

TINY = RetrievalConfig(width=32, layers=2, heads=2, embed_dim=32, text_hidden=64, dropout=0.0)


@pytest.fixture(scope="module", autouse=True)
def _one_thread():
    """One torch thread: on a shared, busy 2-core machine two threads made training ~30x slower."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


#: the brief training of the fixture, repeated by the determinism test
TRAIN_SETTINGS = dict(
    steps=80, batch_size=8, lr=3e-3, seed=0, text_encoder="hash-test-32", config=TINY, warmup=5, progress=False,
    log_every=20,
)


@pytest.fixture(scope="module")
def trained(tiny_data, tmp_path_factory):
    """A tiny model trained briefly on the tiny build's train clips (hash text encoder)."""
    out = tmp_path_factory.mktemp("retrieval") / "m"
    torch.manual_seed(0)
    model = train_retrieval(tiny_data, out, **TRAIN_SETTINGS)
    return model, out


def test_beats_chance_on_train_clips(trained, tiny_data):
    model, _ = trained
    res = evaluate_retrieval(model, tiny_data, split="train")
    full = res["full"]
    for kind in ("strict", "label_aware"):
        chance = full[kind]["chance"]
        for d in ("t2m", "m2t"):
            assert full[kind][d]["R@1"] > 2 * chance["R@1"], (kind, d, full)
    assert full["strict"]["t2m"]["R@3"] > 2 * full["strict"]["chance"]["R@3"], full
    curve = model.info["loss_curve"]
    assert curve[-1][1] < curve[0][1]
    assert "| whole train split" in format_metrics(res)


def test_training_is_deterministic(trained, tiny_data, tmp_path):
    model, _ = trained
    again = train_retrieval(tiny_data, tmp_path / "m", **TRAIN_SETTINGS)
    for (k, a), b in zip(model.state_dict().items(), again.state_dict().values(), strict=True):
        assert torch.equal(a, b), k


def _clips(data_dir, split="train"):
    ds = MotionDataset(data_dir, split)
    return [ds[i]["features"] for i in range(len(ds))]


def test_save_load_round_trip(trained, tiny_data, tmp_path):
    model, out = trained
    clips = _clips(tiny_data)
    texts = ["A person bows energetically.", "Someone waves goodbye."]
    loaded = load_retrieval(out)
    assert loaded.text_encoder_id == "hash-test-32" and loaded.config == model.config
    assert torch.equal(loaded.encode_clips(clips), model.encode_clips(clips))
    assert torch.equal(loaded.encode_captions(texts), model.encode_captions(texts))
    meta = json.loads((out / "config.json").read_text())
    assert meta["feature_layout"]["dim"] == 261 and meta["weights_dtype"] == "float32"
    half = load_retrieval(model.save(tmp_path / "half", half=True))
    assert torch.allclose(half.encode_clips(clips), model.encode_clips(clips), atol=2e-2)
    (tmp_path / "half" / "model.safetensors").write_bytes((out / "model.safetensors").read_bytes())
    with pytest.raises(KinemaError, match="SHA-256"):
        load_retrieval(tmp_path / "half")
    with pytest.raises(KinemaError, match="no retrieval model"):
        load_retrieval(tmp_path / "missing")


def test_invariant_to_global_placement(trained, tiny_data):
    model, _ = trained
    clips = _clips(tiny_data)
    feats, lengths = pad_clips(clips)
    g = torch.Generator().manual_seed(1)
    angle = (torch.rand(len(clips), generator=g) * 2 - 1) * math.pi
    offset = torch.randn(len(clips), 2, generator=g) * 5
    moved = translate_features(rotate_features(feats, angle, model.layout), offset, model.layout)
    with torch.no_grad():
        a, b = model.encode_motion(feats, lengths), model.encode_motion(moved, lengths)
    assert torch.allclose(a, b, atol=1e-4), (a - b).abs().max()


def test_padding_and_chunking_do_not_matter(trained, tiny_data):
    model, _ = trained
    feats, lengths = pad_clips(_clips(tiny_data))
    garbage = feats.clone()
    for b, n in enumerate(lengths.tolist()):
        garbage[b, n:] = torch.randn_like(garbage[b, n:]) * 10
    with torch.no_grad():
        ref = model.encode_motion(feats, lengths)
        assert torch.allclose(model.encode_motion(garbage, lengths), ref, atol=1e-5)
        assert torch.allclose(model.encode_motion(feats, lengths, chunk=3), ref, atol=1e-5)
        assert ref.shape == (len(lengths), TINY.embed_dim)
        assert torch.allclose(ref.norm(dim=-1), torch.ones(len(lengths)), atol=1e-5)


def test_metrics_on_known_rankings():
    labels = torch.tensor([0, 0, 1, 2])
    motion = torch.eye(4)
    motion[1] = torch.tensor([1.0, 1.0, 0, 0]) / math.sqrt(2)  # closer to clip 0's text than to nothing
    text = torch.eye(4)
    text[1] = text[0]  # clips 0 and 1 share a caption, so their texts are identical
    res = retrieval_metrics(motion, text, labels, ks=(1, 3))
    assert res["strict"]["t2m"]["R@1"] == pytest.approx((1 + 0 + 1 + 1) / 4)  # text 1 retrieves clip 0 first
    assert res["strict"]["t2m"]["R@3"] == 1.0
    assert res["strict"]["m2t"]["R@1"] == pytest.approx((0.5 + 0.5 + 1 + 1) / 4)  # ties broken at random
    assert res["label_aware"]["t2m"]["R@1"] == 1.0 and res["label_aware"]["m2t"]["R@1"] == 1.0
    assert res["strict"]["chance"]["R@1"] == pytest.approx(0.25)
    assert res["strict"]["ceiling"]["R@1"] == pytest.approx(0.75) and res["strict"]["ceiling"]["R@3"] == 1.0
    assert res["label_aware"]["chance"]["R@1"] == pytest.approx((0.5 + 0.5 + 0.25 + 0.25) / 4)
    assert res["label_aware"]["chance"]["R@3"] == pytest.approx((1 + 1 + 0.75 + 0.75) / 4)


def test_loss_masks_same_caption_pairs():
    m = torch.nn.functional.normalize(torch.tensor([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), dim=-1)
    t = m.clone()
    masked = contrastive_loss(m, t, torch.tensor([0, 0, 1]), 0.07)
    plain = contrastive_loss(m, t, torch.tensor([0, 1, 2]), 0.07)
    assert masked < 1e-3 < plain  # identical twins are no longer punished as negatives


def test_cli_train_and_eval(tiny_data, tmp_path, capsys):
    from kinema.cli import evaluate_retrieval as cli

    parser = argparse.ArgumentParser(prog="kinema")
    cli.register(parser.add_subparsers(dest="command", required=True))
    out = tmp_path / "cli"
    args = parser.parse_args(
        [
            "retrieval",
            "train",
            "--data",
            str(tiny_data),
            "--out",
            str(out),
            "--steps",
            "3",
            "--batch-size",
            "4",
            "--text-encoder",
            "hash-test-32",
            "--cache-dir",
            str(tmp_path / "c"),
            "--eval-split",
            "none",
            "--no-progress",
        ]
    )
    assert args.func(args) == 0
    args = parser.parse_args(
        [
            "retrieval",
            "eval",
            "--data",
            str(tiny_data),
            "--model",
            str(out),
            "--split",
            "train",
            "--cache-dir",
            str(tmp_path / "c"),
            "--json",
            str(tmp_path / "m.json"),
        ]
    )
    assert args.func(args) == 0
    assert "text->motion" in capsys.readouterr().out
    assert json.loads((tmp_path / "m.json").read_text())["split"] == "train"


def test_shipped_weights():
    path = default_retrieval_path()
    if not (path / "config.json").exists():
        pytest.skip("no shipped retrieval weights")
    assert (path / "model.safetensors").stat().st_size < 5 * 2**20
    model = load_retrieval()
    assert model.text_encoder_id == "minilm-l6-v2" and model.config.text_dim == 384
    assert model.config.embed_dim == 256 and model.layout.dim == 261 and model.fps == 20.0
    assert (path / "MODEL_CARD.md").exists()
    with torch.no_grad():
        z = model.encode_motion(torch.zeros(2, 30, 261) + model.mean, torch.tensor([30, 12]))
        t = model.encode_text(torch.nn.functional.normalize(torch.ones(1, 384), dim=-1))
    assert z.shape == (2, 256) and t.shape == (1, 256) and torch.isfinite(z).all()
