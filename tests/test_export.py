"""Packing a training run as an inference model folder (`kinema export`)."""

from __future__ import annotations

import json

import pytest
import torch
from safetensors.torch import load_file

from kinema.cli import main
from kinema.diffusion.guidance import Guidance
from kinema.errors import KinemaError
from kinema.generate import load_model
from kinema.model.export import export_model
from kinema.model.loading import find_checkpoint, load_denoiser


def test_export_keeps_ema_weights_in_half_precision(tiny_checkpoint, tmp_path) -> None:
    out = export_model(tiny_checkpoint, tmp_path / "model", guidance=Guidance("separated", 1.5, 3.0), sampling_steps=7)
    assert sorted(p.name for p in out.iterdir()) == ["checkpoint.json", "ema.safetensors"]
    src = find_checkpoint(tiny_checkpoint)
    ema = load_file(str(src / "ema.safetensors"))
    packed = load_file(str(out / "ema.safetensors"))
    assert set(packed) == set(ema)
    assert all(v.dtype == torch.float16 for v in packed.values())
    for k, v in ema.items():
        assert torch.allclose(packed[k].float(), v, rtol=1e-3, atol=1e-4), k
    info = json.loads((out / "checkpoint.json").read_text())
    assert "optimizer_param_groups" not in info and info["export"]["dtype"] == "float16"
    loaded = load_denoiser(out)
    assert (loaded.guidance.w_text, loaded.guidance.w_constr) == (1.5, 3.0)
    assert loaded.sampler.num_inference_steps == 7
    assert loaded.info["step"] == json.loads((src / "checkpoint.json").read_text())["step"]


def test_exported_model_generates_like_the_checkpoint(tiny_checkpoint, tmp_path) -> None:
    out = export_model(tiny_checkpoint, tmp_path / "model", dtype="float32")
    a = load_model(tiny_checkpoint).generate("a person walks", seconds=1.0, seed=3, steps=4, postprocess=False)[0]
    b = load_model(out).generate("a person walks", seconds=1.0, seed=3, steps=4, postprocess=False)[0]
    assert torch.allclose(a.positions, b.positions, atol=1e-5)


def test_reexport_keeps_model_card_and_cli_reports_errors(tiny_checkpoint, tmp_path, capsys) -> None:
    out = tmp_path / "model"
    assert main(["export", str(tiny_checkpoint), "--out", str(out), "--steps", "5"]) == 0
    assert "wrote" in capsys.readouterr().out
    (out / "MODEL_CARD.md").write_text("card\n")
    assert main(["export", str(tiny_checkpoint), "--out", str(out)]) == 0
    assert (out / "MODEL_CARD.md").read_text() == "card\n"
    assert main(["export", str(tmp_path / "missing"), "--out", str(tmp_path / "x")]) == 2
    assert "missing: no such model folder" in capsys.readouterr().err
    assert main(["export", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    assert "no checkpoint found" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    with pytest.raises(KinemaError, match="sampling steps"):
        export_model(tiny_checkpoint, tmp_path / "y", sampling_steps=0)
    assert not (tmp_path / "y").exists()


def test_export_raw_weights(tiny_checkpoint, tmp_path, capsys) -> None:
    """``--weights raw`` packs the optimiser weights (they differ from the EMA of the tiny run); an
    exported folder has no raw weights, which is a one-line error, exit 2."""
    src = find_checkpoint(tiny_checkpoint)
    raw = load_file(str(src / "model.safetensors"))
    args = ["export", str(tiny_checkpoint), "--out", str(tmp_path / "raw"), "--weights", "raw", "--dtype", "float32"]
    assert main(args) == 0
    packed = load_file(str(tmp_path / "raw" / "ema.safetensors"))
    assert all(torch.equal(packed[k], v) for k, v in raw.items())
    ema = load_file(str(src / "ema.safetensors"))
    assert any(not torch.equal(ema[k], v) for k, v in raw.items())
    assert main(["export", str(tmp_path / "raw"), "--out", str(tmp_path / "again"), "--weights", "raw"]) == 2
    assert "no model.safetensors" in capsys.readouterr().err


def test_export_mixes_a_fine_tune_with_its_starting_weights(tiny_checkpoint, tmp_path, capsys) -> None:
    """``--mix MODEL SHARE`` packs (1 - SHARE) x the run's weights + SHARE x MODEL's EMA weights, tensor by
    tensor, and says so in checkpoint.json; a model of another network, or a share outside [0, 1], is a
    one-line error that writes nothing."""
    src = find_checkpoint(tiny_checkpoint)
    raw = load_file(str(src / "model.safetensors"))
    ema = load_file(str(src / "ema.safetensors"))
    out = tmp_path / "mixed"
    args = ["export", str(tiny_checkpoint), "--out", str(out), "--weights", "raw", "--dtype", "float32",
            "--mix", str(tiny_checkpoint), "0.25"]
    assert main(args) == 0
    packed = load_file(str(out / "ema.safetensors"))
    for k, v in raw.items():
        assert torch.allclose(packed[k], 0.75 * v + 0.25 * ema[k], atol=1e-6), k
    assert any(not torch.allclose(packed[k], v) for k, v in raw.items())
    mixed = json.loads((out / "checkpoint.json").read_text())["export"]["mixed_with"]
    assert mixed["share"] == 0.25 and mixed["source"] == str(src)
    assert main(["export", str(tiny_checkpoint), "--out", str(tmp_path / "x"), "--mix", "default", "0.5"]) == 2
    assert "another model_config" in capsys.readouterr().err
    assert main(["export", str(tiny_checkpoint), "--out", str(tmp_path / "x"), "--mix", str(src), "1.5"]) == 2
    assert "[0, 1]" in capsys.readouterr().err
    assert main(["export", str(tiny_checkpoint), "--out", str(tmp_path / "x"), "--mix", str(src), "half"]) == 2
    assert "SHARE must be a number" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_export_guidance_mode(tiny_checkpoint, tmp_path, capsys) -> None:
    """``--guidance-mode regular`` saves regular CFG as the model's own guidance (a call without weights runs
    it, two branches; weights ask for separated guidance); without ``--guidance`` it is a one-line error."""
    out = tmp_path / "regular"
    assert main(["export", str(tiny_checkpoint), "--out", str(out), "--guidance", "2", "2",
                 "--guidance-mode", "regular"]) == 0
    assert "regular guidance 2/2" in capsys.readouterr().out
    model = load_model(out)
    assert model.loaded.guidance.to_dict() == {"mode": "regular", "w_text": 2.0, "w_constr": 2.0}
    cons = [{"type": "root2d", "times": [0.5], "smooth_root_2d": [[0.2, 0.6]]}]
    kw = {"seconds": 1.0, "constraints": cons, "steps": 2, "postprocess": False}
    assert model.generate("a person walks", **kw).report.guidance_mode == "regular"
    assert model.generate("a person walks", guidance=(2.0, 2.0), **kw).report.guidance_mode == "separated"
    assert main(["export", str(tiny_checkpoint), "--out", str(tmp_path / "x"), "--guidance-mode", "regular"]) == 2
    assert "--guidance-mode: give --guidance" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
