"""Issue 13, sections 3-4: bad input is a one-line error (exit 2, nothing written), never a traceback
or a silently wrong result; and `kinema generate` polish (--constraints-fps, Kimodo meta.json
defaults, --no-progress, sample suffixes, --fps keeping the duration)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file, save

from kinema.cli import main
from kinema.errors import BVHError, KinemaError
from kinema.io import load_motion
from kinema.io.atomic import check_output_path
from kinema.motion.core import Motion
from tests.test_bvh import GOOD
from tests.test_motion import random_motion

SHIPPED = Path(__file__).resolve().parents[1] / "kinema/assets/models/default"
DEEP = "[" * 100000 + "]" * 100000
FAST = ["--steps", "2", "--seconds", "1", "--no-progress"]


def one_line_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err
    assert err.startswith("kinema: error:") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err
    return err


class _Stop(Exception):
    """Raised by the fake model: the CLI got as far as calling generate."""


class _FakeModel:
    """Stands in for `load_model(...)`: records the generate call, generates nothing."""

    def __init__(self, calls: list):
        self.calls = calls

        class _Sampler:
            num_train_steps = 1000

        class _Loaded:
            sampler = _Sampler()

        self.loaded = _Loaded()

    def generate(self, what, **kwargs):
        self.calls.append({"what": what, **kwargs})
        raise _Stop


@pytest.fixture
def fake_model(monkeypatch):
    calls: list = []
    monkeypatch.setattr("kinema.generate.api.load_model", lambda *a, **k: _FakeModel(calls))
    return calls


@pytest.fixture
def no_model(monkeypatch):
    """Loading the model is a failure: the error must come before any heavy work."""

    def boom(*a, **k):
        raise AssertionError("the model was loaded before the bad input was reported")

    monkeypatch.setattr("kinema.generate.api.load_model", boom)


@pytest.fixture
def bvh_file(tmp_path) -> Path:
    path = tmp_path / "good.bvh"
    path.write_text(GOOD)
    return path


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
    from kinema.generate.timeline import parse_timeline

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


# ---------------------------------------------------------------------------- output paths
def test_check_output_path(tmp_path):
    assert check_output_path(tmp_path / "new/deeper/x.bvh") == tmp_path / "new/deeper/x.bvh"
    assert not (tmp_path / "new").exists()  # only checked; the writer creates folders
    assert not list(tmp_path.iterdir())  # the write probe leaves nothing behind
    (tmp_path / "folder.bvh").mkdir()
    with pytest.raises(KinemaError, match="is a folder"):
        check_output_path(tmp_path / "folder.bvh")
    (tmp_path / "file").write_text("x")
    with pytest.raises(KinemaError, match="is a file, not a folder"):
        check_output_path(tmp_path / "file/sub/x.bvh")


def _unwritable_folder() -> Path | None:
    """A folder nobody can write to, root included (sysfs is read-only), or None."""
    import tempfile

    sys_dir = Path("/sys")
    if not sys_dir.is_dir():
        return None
    try:
        fd, probe = tempfile.mkstemp(dir=sys_dir)
    except OSError:
        return sys_dir
    import os

    os.close(fd)
    os.unlink(probe)
    return None


def _bad_outputs(tmp_path: Path, name: str) -> list[tuple[Path, str]]:
    (tmp_path / f"dir{name}").mkdir()
    (tmp_path / "plain").write_text("x")
    cases = [(tmp_path / f"dir{name}", "is a folder"), (tmp_path / "plain" / name, "not a folder")]
    ro = _unwritable_folder()
    if ro is not None:
        cases.append((ro / "kinema-test" / name, "cannot write"))
    return cases


def test_generate_checks_output_path_before_loading_the_model(tmp_path, capsys, no_model):
    for out, msg in _bad_outputs(tmp_path, "m.bvh"):
        assert main(["generate", "walk", *FAST, "--out", str(out)]) == 2, out
        one_line_error(capsys, msg)
    assert main(["generate", "walk", *FAST, "--samples", "2", "--out", str(tmp_path / "plain/m.npz")]) == 2
    one_line_error(capsys, "m_00.npz")


def test_convert_and_render_check_output_path_first(tmp_path, bvh_file, capsys, monkeypatch):
    import kinema.io as kio

    def boom(*a, **k):
        raise AssertionError("the input was read before the bad output was reported")

    monkeypatch.setattr(kio, "load_motion", boom)
    for out, msg in _bad_outputs(tmp_path, "m.npz"):
        assert main(["convert", str(bvh_file), str(out)]) == 2, out
        one_line_error(capsys, msg)
    for out, msg in _bad_outputs(tmp_path, "m.png"):
        assert main(["render", str(bvh_file), "--out", str(out)]) == 2, out
        one_line_error(capsys, msg)
    assert main(["convert", str(bvh_file), str(tmp_path / "x.fbx")]) == 2
    one_line_error(capsys, "unknown motion format")


# ---------------------------------------------------------------------------- argument checks
@pytest.mark.parametrize(
    "args,what",
    [
        (["--fps", "-30"], "--fps"),
        (["--fps", "0"], "--fps"),
        (["--fps", "nan"], "--fps"),
        (["--guidance", "nan", "1"], "--guidance"),
        (["--guidance", "-5", "-5"], "--guidance"),
        (["--guidance", "1", "inf"], "--guidance"),
        (["--seed", "99999999999999999999999"], "--seed"),
        (["--seed", "-1"], "--seed"),
        (["--samples", "0"], "--samples"),
        (["--steps", "0"], "--steps"),
        (["--seconds", "-1"], "--seconds"),
        (["--seconds", "inf"], "--seconds"),
        (["--heading", "nan"], "--heading"),
        (["--constraints-fps", "0"], "--constraints-fps"),
        (["--constraints-fps", "-30"], "--constraints-fps"),
    ],
)
def test_generate_rejects_bad_numbers(tmp_path, capsys, no_model, args, what):
    with pytest.raises(SystemExit) as exc:
        main(["generate", "walk", "--out", str(tmp_path / "o.bvh"), *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {what}:" in err and "Traceback" not in err, err
    assert not (tmp_path / "o.bvh").exists()


@pytest.mark.parametrize(
    "cmd",
    [
        ["convert", "IN", "OUT.npz", "--fps", "0"],
        ["convert", "IN", "OUT.npz", "--fps", "-30"],
        ["convert", "IN", "OUT.npz", "--in-scale", "0"],
        ["export", "M", "--out", "O", "--guidance", "nan", "1"],
        ["evaluate", "--model", "M", "--seed", "-1"],
    ],
)
def test_other_commands_reject_bad_numbers(capsys, cmd):
    with pytest.raises(SystemExit) as exc:
        main(cmd)
    assert exc.value.code == 2
    assert "argument --" in capsys.readouterr().err


def test_largest_seed_is_accepted_by_torch():
    from kinema.cli._args import MAX_SEED, seed

    assert seed(str(MAX_SEED)) == MAX_SEED
    torch.Generator().manual_seed(MAX_SEED)


def test_steps_above_the_trained_length_is_an_error(tmp_path, capsys):
    out = tmp_path / "o.bvh"
    assert main(["generate", "walk", "--steps", "5000", "--seconds", "1", "--no-progress", "--out", str(out)]) == 2
    one_line_error(capsys, "5000", "1000")
    assert not out.exists()


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


# ---------------------------------------------------------------------------- timelines
def test_timeline_unknown_key_is_an_error_with_a_suggestion(tmp_path, capsys, no_model):
    from kinema.generate.timeline import parse_timeline

    with pytest.raises(KinemaError, match=r"segment 1: unknown key 'promt' \(did you mean 'prompt'\?\)"):
        parse_timeline([{"prompt": "a", "seconds": 1}, {"prompt": "b", "seconds": 4, "promt": "c"}])
    with pytest.raises(KinemaError, match=r"segment 0: unknown key 'speed';"):
        parse_timeline([{"prompt": "a", "seconds": 1, "speed": 2}])
    ok = parse_timeline([{"prompt": "a", "seconds": 1, "comment": "x", "_note": 1}])
    assert [(s.prompt, s.seconds) for s in ok] == [("a", 1.0)]
    path = tmp_path / "t.json"
    path.write_text(json.dumps([{"prompt": "walk", "seconds": 4, "secnds": 2}]))
    assert main(["generate", "--timeline", str(path), "--out", str(tmp_path / "o.bvh")]) == 2
    one_line_error(capsys, "t.json: segment 0: unknown key 'secnds' (did you mean 'seconds'?)")
    txt = tmp_path / "t.txt"
    txt.write_text("[]")
    assert main(["generate", "--timeline", str(txt), "--out", str(tmp_path / "o.bvh")]) == 2
    one_line_error(capsys, "must be a .json file")


# ---------------------------------------------------------------------------- generate polish
def test_constraints_fps_is_passed_to_the_api(tmp_path, fake_model):
    c = tmp_path / "c.json"
    c.write_text("[]")
    with pytest.raises(_Stop):
        main(["generate", "walk", "--constraints", str(c), "--constraints-fps", "30", "--out", str(tmp_path / "o.bvh")])
    assert fake_model[-1]["constraints_fps"] == 30.0
    with pytest.raises(_Stop):
        main(["generate", "walk", "--out", str(tmp_path / "o.bvh")])
    call = fake_model[-1]
    assert "constraints_fps" not in call or call["constraints_fps"] is None
    # the effective defaults without a Kimodo meta.json
    assert (call["what"], call["seconds"], call["seed"], call["samples"], call["steps"], call["guidance"]) == (
        "walk",
        5.0,
        0,
        1,
        None,
        None,
    )


def _kimodo_folder(tmp_path: Path, **texts) -> Path:
    folder = tmp_path / "kimodo"
    folder.mkdir()
    meta = {
        "num_samples": 2,
        "seed": 7,
        "diffusion_steps": 3,
        "cfg": {"enabled": True, "text_weight": 2.5, "constraint_weight": 1.5},
    }
    (folder / "meta.json").write_text(json.dumps({**meta, **(texts or {"text": "A person walks", "duration": 1.5})}))
    (folder / "constraints.json").write_text("[]")
    return folder / "constraints.json"


def test_kimodo_meta_fills_what_the_user_left_out(tmp_path, capsys, fake_model):
    c = _kimodo_folder(tmp_path)
    out = str(tmp_path / "o.bvh")
    with pytest.raises(_Stop):
        main(["generate", "--constraints", str(c), "--out", out])
    call = fake_model[-1]
    assert (call["what"], call["seconds"], call["seed"], call["steps"], call["samples"]) == (
        "A person walks",
        1.5,
        7,
        3,
        2,
    )
    g = call["guidance"]
    assert (g.w_text, g.w_constr) == (2.5, 1.5)
    line = capsys.readouterr().out.strip()
    assert line.count("\n") == 0 and "prompt, seconds, seed, steps, samples, guidance" in line
    assert "meta.json" in line
    with pytest.raises(_Stop):
        main(
            [
                "generate",
                "run",
                "--constraints",
                str(c),
                "--out",
                out,
                "--seed",
                "1",
                "--steps",
                "2",
                "--samples",
                "1",
                "--guidance",
                "1",
                "1",
                "--seconds",
                "2",
            ]
        )
    call = fake_model[-1]
    assert (call["what"], call["seconds"], call["seed"], call["steps"], call["samples"], call["guidance"]) == (
        "run",
        2.0,
        1,
        2,
        1,
        (1.0, 1.0),
    )
    assert "Kimodo" not in capsys.readouterr().out


def test_kimodo_meta_timeline(tmp_path, capsys, fake_model):
    c = _kimodo_folder(tmp_path, texts=["walk", "wave"], durations=[1.0, 2.0])
    out = str(tmp_path / "o.bvh")
    with pytest.raises(_Stop):
        main(["generate", "--constraints", str(c), "--out", out])
    call = fake_model[-1]
    assert call["what"] == [{"prompt": "walk", "seconds": 1.0}, {"prompt": "wave", "seconds": 2.0}]
    assert call["seconds"] is None
    assert "timeline" in capsys.readouterr().out
    assert main(["generate", "--constraints", str(c), "--seconds", "3", "--out", out]) == 2
    one_line_error(capsys, "--seconds", "meta.json")


def test_generate_no_progress_sample_suffixes_and_fps_keep_duration(tmp_path, capfd, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a fresh text cache: the text encoder really loads
    out = tmp_path / "m.bvh"
    assert (
        main(
            [
                "generate",
                "A person jumps.",
                "--steps",
                "2",
                "--seconds",
                "1",
                "--no-progress",
                "--samples",
                "2",
                "--fps",
                "30",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    err = capfd.readouterr().err
    assert "Loading" not in err and "%|" not in err and "it/s" not in err, err
    assert not out.exists()
    for name in ("m_00.bvh", "m_01.bvh"):
        m = load_motion(tmp_path / name)
        assert m.fps == 30 and m.num_frames == 30  # round(1 s x 30 fps)


def test_resample_keep_duration():
    m = random_motion(T=20)  # 30 fps in random_motion; re-label as 20 fps, 1 s
    m = Motion(m.skeleton, 20, m.root_translation, m.local_rotations)
    up = m.resample(30, keep_duration=True)
    assert up.num_frames == 30 and up.duration == pytest.approx(m.duration)
    assert torch.allclose(up.positions[::3], m.positions[::2], atol=1e-9)  # the common time grid
    assert torch.allclose(up.positions[-1], m.positions[-1], atol=1e-9)  # past the end: last pose held
    down = m.resample(7, keep_duration=True)
    assert down.num_frames == 7
    assert m.resample(30).num_frames == 29  # default: same span [0, (T-1)/fps]
    for bad in (0, -30, float("nan"), float("inf")):
        with pytest.raises(KinemaError, match="fps"):
            m.resample(bad)
