"""Issue 13, sections 3-4, input files: deeply nested JSON, damaged model folders and non-finite motion
data are one-line errors (exit 2, nothing written), never a traceback or a silently wrong result.
Shared helpers: tests/hardening_fixtures.py; the CLI side is tests/test_hardening_cli.py."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from safetensors.torch import load_file, save

from kinema.cli import main
from kinema.errors import BVHError, KinemaError
from kinema.io import load_motion
from kinema.motion.core import Motion
from tests import hardening_fixtures as fixtures
from tests.hardening_fixtures import DEEP, FAST, SHIPPED, one_line_error
from tests.test_bvh_errors import GOOD
from tests.test_motion import random_motion

bvh_file, no_model = fixtures.bvh_file, fixtures.no_model  # fixtures shared with the other hardening tests


# ---------------------------------------------------------------------------- deeply nested JSON
def test_deep_constraints_json_is_one_line_error(tmp_path, capsys):
    deep = tmp_path / "deep.json"
    deep.write_text(DEEP)
    out = tmp_path / "o.bvh"
    assert main(["generate", "walk", *FAST, "--constraints", str(deep), "--out", str(out)]) == 2
    one_line_error(capsys, "deep.json", "nested too deeply")
    assert not out.exists()


def test_deep_json_in_timeline_meta_and_render_constraints(tmp_path, bvh_file, capsys, no_model):
    from kinema.constraints import find_kimodo_meta, read_kimodo_meta
    from kinema.pipeline.timeline import parse_timeline

    deep = tmp_path / "deep.json"
    deep.write_text(DEEP)
    with pytest.raises(KinemaError, match="nested too deeply"):
        parse_timeline(deep)
    assert main(["generate", "--timeline", str(deep), "--out", str(tmp_path / "o.bvh")]) == 2
    one_line_error(capsys, "deep.json", "nested too deeply")
    meta = tmp_path / "meta.json"
    meta.write_text(DEEP)
    assert find_kimodo_meta(tmp_path / "c.json") is None
    with pytest.raises(KinemaError, match="nested too deeply"):
        read_kimodo_meta(meta)
    png = tmp_path / "o.png"
    assert main(["render", str(bvh_file), "--out", str(png), "--constraints", str(deep)]) == 2
    one_line_error(capsys, "nested too deeply")
    assert not png.exists()


# ---------------------------------------------------------------------------- damaged model folders
def _damaged_copy(tmp_path: Path, name: str, weights: bytes | None = None, info: str | None = None) -> Path:
    folder = tmp_path / name
    shutil.copytree(SHIPPED, folder)
    if weights is not None:
        (folder / "ema.safetensors").write_bytes(weights)
    if info is not None:
        (folder / "checkpoint.json").write_text(info)
    return folder


def _nan_weights() -> bytes:
    state = load_file(str(SHIPPED / "ema.safetensors"))
    key = next(iter(state))
    state[key] = state[key].clone()
    state[key].view(-1)[0] = float("nan")
    return save(state)


WEIGHTS = SHIPPED / "ema.safetensors"


@pytest.mark.parametrize("case", ["empty", "truncated", "garbled", "nan"])
def test_damaged_weights_are_one_line_errors(tmp_path, capsys, case):
    from kinema.model.export import export_model
    from kinema.model.loading import load_denoiser

    data = WEIGHTS.read_bytes()
    blob = {
        "empty": b"",
        "truncated": data[: len(data) // 2],
        "garbled": data[:8] + b"\xff" * 64 + data[72:],
        "nan": _nan_weights() if case == "nan" else b"",
    }[case]
    folder = _damaged_copy(tmp_path, case, weights=blob)
    with pytest.raises(KinemaError, match="ema.safetensors"):
        load_denoiser(folder)
    out = tmp_path / "o.bvh"
    assert main(["generate", "walk", *FAST, "--model", str(folder), "--out", str(out)]) == 2
    one_line_error(capsys, "ema.safetensors")
    assert not out.exists()
    exported = tmp_path / "exported"
    assert main(["export", str(folder), "--out", str(exported)]) == 2
    one_line_error(capsys, "ema.safetensors")
    assert not exported.exists()
    with pytest.raises(KinemaError):
        export_model(folder, exported)


@pytest.mark.parametrize(
    "text", ["", '{"fps": 20, "model_con', "[1, 2]", "null", DEEP, '{"model_config": [1], "fps": 20}']
)
def test_garbled_checkpoint_json_is_one_line_error(tmp_path, capsys, text):
    from kinema.model.loading import load_denoiser

    folder = _damaged_copy(tmp_path, "m", info=text)
    with pytest.raises(KinemaError, match="checkpoint|cannot load model"):
        load_denoiser(folder)
    out = tmp_path / "o.bvh"
    assert main(["generate", "walk", *FAST, "--model", str(folder), "--out", str(out)]) == 2
    one_line_error(capsys, str(folder))
    assert not out.exists()


def test_export_never_replaces_a_model_with_one_that_does_not_load(tmp_path):
    from kinema.model.export import export_model

    info = json.loads((SHIPPED / "checkpoint.json").read_text())
    info["skeleton"] = {"broken": True}
    folder = _damaged_copy(tmp_path, "bad", info=json.dumps(info))
    out = _damaged_copy(tmp_path, "out")
    before = (out / "checkpoint.json").read_bytes()
    with pytest.raises(KinemaError):
        export_model(folder, out)
    assert (out / "checkpoint.json").read_bytes() == before


def test_damaged_retrieval_weights_are_one_line_errors(tmp_path):
    from kinema.evaluate.retrieval import default_retrieval_path, load_retrieval

    folder = tmp_path / "retrieval"
    shutil.copytree(default_retrieval_path(), folder)
    meta = json.loads((folder / "config.json").read_text())
    meta.pop("weights_sha256", None)  # without the recorded hash, the weights file itself must be checked
    (folder / "config.json").write_text(json.dumps(meta))
    (folder / "model.safetensors").write_bytes(b"")
    with pytest.raises(KinemaError, match="unreadable retrieval model"):
        load_retrieval(folder)


# ---------------------------------------------------------------------------- non-finite motion data
@pytest.mark.parametrize(
    "row,where",
    [
        ("1e300 90 0 0 0 0 10 0 0", "Hips Xposition in frame 2"),
        ("0 1e300 0 0 0 0 10 0 0", "Hips Yposition in frame 2"),
        ("0 90 0 1e300 0 0 10 0 0", ":20: rotation out of range: 1e+300 in frame 2 (Hips Zrotation)"),
        ("0 90 0 0 0 0 10 0 1e308", ":20: rotation out of range: 1e+308 in frame 2 (Chest Yrotation)"),
    ],
)
def test_bvh_with_huge_values_is_rejected(tmp_path, capsys, row, where):
    src = tmp_path / "huge.bvh"
    src.write_text(GOOD.replace("1 90 0 0 5 0 20 0 0", row))
    with pytest.raises(BVHError, match="huge.bvh"):
        load_motion(src)
    out, png = tmp_path / "huge.npz", tmp_path / "huge.png"
    assert main(["convert", str(src), str(out)]) == 2
    one_line_error(capsys, "huge.bvh", where)
    assert main(["render", str(src), "--out", str(png)]) == 2
    one_line_error(capsys, "huge.bvh")
    assert not out.exists() and not png.exists()


def test_bvh_huge_offset_and_scale_are_rejected(tmp_path):
    src = tmp_path / "off.bvh"
    src.write_text(GOOD.replace("OFFSET 0 10 0", "OFFSET 0 1e300 0"))
    with pytest.raises(BVHError, match="OFFSET of joint Chest"):
        load_motion(src)
    ok = tmp_path / "ok.bvh"
    ok.write_text(GOOD)
    load_motion(ok, scale=1e4)  # 90 file units x 1e4 = 900 km: large, but a length
    with pytest.raises(BVHError, match="Hips Yposition in frame 1 is 90 x scale 100000"):
        load_motion(ok, scale=1e5)


def test_npz_with_non_finite_values_names_file_and_key(tmp_path, bvh_file, capsys):
    good = tmp_path / "good.npz"
    load_motion(bvh_file).save(good)
    for key, value in [
        ("root_translation", np.inf),
        ("local_quats", np.nan),
        ("offsets", np.inf),
        ("fps", np.nan),
        ("fps", -3.0),
    ]:
        d = dict(np.load(good))
        if d[key].ndim:
            d[key] = d[key].copy()
            d[key].reshape(-1)[1] = value
        else:
            d[key] = np.array(value)
        bad = tmp_path / f"bad_{key}.npz"
        np.savez(bad, **d)
        with pytest.raises(KinemaError, match=f"bad_{key}.npz: 'fps'|bad_{key}.npz: '{key}'"):
            load_motion(bad)
        out = tmp_path / "o.bvh"
        assert main(["convert", str(bad), str(out)]) == 2
        one_line_error(capsys, f"bad_{key}.npz")
        assert not out.exists()


def test_npz_save_refuses_values_beyond_float32(tmp_path):
    m = random_motion(T=5)
    big = Motion(m.skeleton, m.fps, m.root_translation * 1e300, m.local_rotations)
    with pytest.raises(KinemaError, match="float32"):
        big.save(tmp_path / "big.npz")
    assert not list(tmp_path.iterdir())
