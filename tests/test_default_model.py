"""The default human model shipped inside the package (kinema/assets/models/default)."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import pytest
import torch

import kinema
from kinema.cli import main
from kinema.io import load_motion

SHIPPED = Path(str(files("kinema") / "assets" / "models" / "default"))


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


def test_shipped_files_size_and_licence() -> None:
    names = sorted(p.name for p in SHIPPED.iterdir())
    assert names == ["MODEL_CARD.md", "action_expert.safetensors", "checkpoint.json", "ema.safetensors",
                     "known_prompts.safetensors", "walk.png"]
    assert sum(p.stat().st_size for p in SHIPPED.iterdir()) <= 25e6
    card = (SHIPPED / "MODEL_CARD.md").read_text()
    for needed in (
        "CC BY-NC 4.0",
        "non-commercial",
        "Kobayashi",
        "arXiv:2306.08861",
        "kinema train",
        "kinema evaluate",
        "Ground truth",
        "kinema bench",
        "CC0",
        "Quaternius",
        "--action-expert",
    ):
        assert needed in card, needed


def test_default_model_meets_waypoints_after_postprocessing(model) -> None:
    cons = [{"type": "root2d", "times": [1.5, 3.0], "smooth_root_2d": [[0.0, 1.5], [1.0, 3.0]]}]
    m = model.generate("A person walks forward.", seconds=4, constraints=cons, seed=1, steps=20)[0]
    from kinema.representation.kimodo_features import motion_to_features

    root = motion_to_features(m)[:, [0, 2]]  # smoothed root x, z
    for t, xz in ((1.5, (0.0, 1.5)), (3.0, (1.0, 3.0))):
        got = root[round(t * m.fps)]
        assert (got - torch.tensor(xz, dtype=got.dtype)).norm() < 0.01, (t, got)


def test_readme_main_command(tmp_path, capsys) -> None:
    out = tmp_path / "walk.bvh"
    assert (
        main(
            [
                "generate",
                "A person walks forward happily.",
                "--seconds",
                "4",
                "--out",
                str(out),
                "--steps",
                "10",
                "--no-progress",
            ]
        )
        == 0
    )
    assert str(out) in capsys.readouterr().out
    motion = load_motion(out)
    assert motion.num_frames == 80 and motion.skeleton.num_joints == 21


def _root_travel(model, prompt: str) -> torch.Tensor:
    """Pelvis ground-plane displacement (x, z) in metres over a 4-s motion."""
    pelvis = model.generate(prompt, seconds=4, seed=0, steps=20)[0].positions[:, 0]
    return (pelvis[-1] - pelvis[0])[[0, 2]]


def test_default_model_follows_text(model) -> None:
    """Walks travel forward (+Z) at a walking pace, runs travel further, a wave stays in place.

    Ground-truth Bandai Namco walks cover 0.9-1.9 m/s and runs 1.8-3.0 m/s; a lateral drift of about
    10 degrees is within what the data shows, so the direction check allows ~27 degrees.
    """
    walk, run, wave = (
        _root_travel(model, p)
        for p in ("A person walks forward.", "A person runs forward.", "A person waves with the right hand.")
    )
    assert 3.0 < walk[1] < 8.0 and walk[0].abs() < 0.5 * walk[1], walk
    assert run[1] > walk[1] and run[0].abs() < 0.5 * run[1], (run, walk)
    assert wave.norm() < 0.6, wave


def test_new_actions_run_on_the_action_expert_and_old_ones_on_the_main_weights(model) -> None:
    """Issue 38: a kick asked in words no caption uses is made by the action expert (the named foot above
    the pelvis, the other below half the pelvis' height) without a warning; a walk stays on the main
    weights, which are the shipped model's before the expert came."""
    assert model.loaded.expert is not None and "kick" in model.loaded.expert.actions
    res = model.generate("Someone delivers a kick with the left foot.", seconds=3, seed=0)
    P, names = res[0].positions, list(res[0].skeleton.names)
    hips, foot, other = (P[:, names.index(n)] for n in ("Hips", "Foot_L", "Foot_R"))
    assert float((foot[:, 1] - hips[:, 1]).max()) > 0 and float(other[:, 1].max()) < 0.5 * float(hips[0, 1])
    assert res.report.prompts[0]["weights"] == "action expert" and res.report.prompts[0]["known"]
    assert not [w for w in res.report.warnings if w.startswith("prompt ")]  # no unknown-prompt warning
    walk = model.generate("A person walks forward.", seconds=2, seed=0, steps=5)
    assert walk.report.prompts[0]["weights"] == "main"


def test_right_side_actions_are_made_as_the_left_ones_mirror_and_move_the_right_limb(model) -> None:
    """Issue 38, stop 56: the shipped expert does the left side better, so a right kick or punch in words no
    caption uses is made as its left twin's mirror image (the report says so) and moves the right limb: the
    right foot above the pelvis with the left below half the pelvis' height; the right fist 0.25 m or more
    further ahead of the pelvis than at the start (along the body's forward, from the shoulders) and 0.1 m
    more than the left (seed 2: one of the probe's passing seeds). The kick is not warned; the punch is, since
    stop 64, by the caption-fidelity table (punches pass in 3 of 6 samples of their own captions)."""
    assert model.loaded.expert.mirror_side == "right"
    kick = model.generate("A man kicks hard using his right leg.", seconds=3, seed=0)
    P, names = kick[0].positions, list(kick[0].skeleton.names)
    hips, foot, other = (P[:, names.index(n)] for n in ("Hips", "Foot_R", "Foot_L"))
    assert float((foot[:, 1] - hips[:, 1]).max()) > 0 and float(other[:, 1].max()) < 0.5 * float(hips[0, 1])
    punch = model.generate("Someone jabs with the right hand.", seconds=5, seed=2)
    P = punch[0].positions
    across = P[:, names.index("Shoulder_L")] - P[:, names.index("Shoulder_R")]
    forward = torch.nn.functional.normalize(torch.stack([-across[:, 2], torch.zeros_like(across[:, 0]),
                                                         across[:, 0]], dim=-1), dim=-1)  # across x up
    ahead = {h: ((P[:, names.index(h)] - P[:, names.index("Hips")]) * forward).sum(-1) for h in ("Hand_R", "Hand_L")}
    gain = {h: float((a - a[0]).max()) for h, a in ahead.items()}
    assert gain["Hand_R"] >= 0.25 and gain["Hand_R"] >= gain["Hand_L"] + 0.1, gain
    for res, twin in ((kick, "A man kicks hard using his left leg."), (punch, "Someone jabs with the left hand.")):
        assert res.report.prompts[0]["made_as_mirror_of"] == twin
    assert kick.report.prompts[0]["known"] and not [w for w in kick.report.warnings if w.startswith("prompt ")]
    assert not punch.report.prompts[0]["known"]
    assert [w for w in punch.report.warnings if "does not reliably make 'punch-right'" in w]


def test_default_guidance_is_regular_two_branches_and_weights_ask_for_separated(model, monkeypatch) -> None:
    """The shipped model's own guidance is regular CFG (w 2 on text and constraints together): a constrained
    call runs two denoiser rows per step, not separated guidance's three (docs/speed.md, issue 37). Two
    weights in the request ask for separated guidance, three rows, and a different motion; the report
    names the mode that ran."""
    from tests.denoiser_spy import record_forward_rows

    assert model.loaded.guidance.to_dict() == {"mode": "regular", "w_text": 2.0, "w_constr": 2.0}
    cons = [{"type": "root2d", "times": [0.5], "smooth_root_2d": [[0.2, 0.6]]}]
    rows = record_forward_rows(model, monkeypatch)
    kw = {"seconds": 1.0, "constraints": cons, "steps": 3, "seed": 0, "postprocess": False}
    joint = model.generate("A person walks forward.", **kw)
    assert rows == [2] * 3 and joint.report.guidance_mode == "regular"
    rows.clear()
    separated = model.generate("A person walks forward.", guidance=(2.0, 2.0), **kw)
    assert rows == [3] * 3 and separated.report.guidance_mode == "separated"
    assert (joint[0].positions - separated[0].positions).norm(dim=-1).mean() > 1e-3
