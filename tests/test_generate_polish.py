"""Issue 13: `kinema generate` polish (--constraints-fps, Kimodo meta.json defaults, --no-progress,
sample suffixes, --fps keeping the duration), checked against a fake model that records the call.
Shared helpers: tests/hardening_fixtures.py."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from kinema.cli import main
from kinema.errors import KinemaError
from kinema.io import load_motion
from kinema.motion.core import Motion
from tests import hardening_fixtures as fixtures
from tests.hardening_fixtures import Stop, one_line_error
from tests.test_motion import random_motion

fake_model = fixtures.fake_model  # fixture shared with the other hardening tests


# ---------------------------------------------------------------------------- generate polish
def test_constraints_fps_is_passed_to_the_api(tmp_path, fake_model):
    c = tmp_path / "c.json"
    c.write_text("[]")
    with pytest.raises(Stop):
        main(["generate", "walk", "--constraints", str(c), "--constraints-fps", "30", "--out", str(tmp_path / "o.bvh")])
    assert fake_model[-1]["constraints_fps"] == 30.0
    with pytest.raises(Stop):
        main(["generate", "walk", "--out", str(tmp_path / "o.bvh")])
    call = fake_model[-1]
    assert "constraints_fps" not in call or call["constraints_fps"] is None
    # the request's defaults without a Kimodo meta.json (seconds None: the model's default, 5 s for the human)
    assert (call["what"], call["seconds"], call["seed"], call["samples"], call["steps"], call["guidance"]) == (
        "walk",
        None,
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
    with pytest.raises(Stop):
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
    with pytest.raises(Stop):
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
    with pytest.raises(Stop):
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
