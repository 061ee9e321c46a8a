"""Caption fidelity (kinema.evaluate.fidelity, issue 58): the detectors pass what the action shows and fail
what it does not, on real motions (the shipped model's, the captures' when cache/ has them)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
import torch

import kinema
from kinema.cli import main
from kinema.data.captions import STYLE_PHRASES, captions_for
from kinema.data.humanoid_actions import HUMANOID_ACTIONS, humanoid_captions
from kinema.data.phrasings import extra_captions
from kinema.evaluate import fidelity as F
from kinema.motion.core import Motion

REPO = Path(__file__).resolve().parents[1]
BUILD = REPO / "cache/bandai20h"


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


@pytest.fixture(scope="module")
def walk(model) -> Motion:
    """The shipped model's "A person walks forward." (4 s, seed 0; at its own step count: with 10 steps it
    hurries past the fastest captured walk)."""
    return model.generate("A person walks forward.", seconds=4.0, seed=0)[0]


def _reversed(m: Motion) -> Motion:
    """The motion played backwards: a forward walk becomes a backward one, still facing forward."""
    return replace(m, root_translation=m.root_translation.flip(0), local_rotations=m.local_rotations.flip(0),
                   foot_contacts=None)


def _still(m: Motion) -> Motion:
    """The motion's first pose held for as long: standing still."""
    T = m.num_frames
    return replace(m, root_translation=m.root_translation[:1].expand(T, 3).clone(),
                   local_rotations=m.local_rotations[:1].expand(T, -1, -1).clone(), foot_contacts=None)


def test_walk_forward_passes_walk_and_fails_backward_until_reversed(walk):
    fwd = F.DETECTORS["walk"](walk)
    assert fwd.passed and fwd.value > F.WALK_MIN_SPEED
    back = F.DETECTORS["walk-back"](walk)
    assert not back.passed and back.value < 0  # it goes forward: negative backward speed
    rev = _reversed(walk)
    assert F.DETECTORS["walk-back"](rev).passed
    assert not F.DETECTORS["walk"](rev).passed
    assert math.isclose(F.DETECTORS["walk-back"](rev).value, fwd.value, rel_tol=0.05)


def test_standing_still_fails_every_detector(walk):
    still = _still(walk)
    failed = {a: d(still) for a, d in F.DETECTORS.items()}
    assert not [a for a, c in failed.items() if c.passed], failed


def test_hand_swings_count_a_wave_not_a_held_hand(walk):
    b = F.body(_still(walk))
    hand, shoulder = b.roles["right_hand"], b.roles["right_shoulder"]
    t = torch.arange(len(b.P), dtype=b.P.dtype) / b.fps
    held = b.P.clone()
    held[:, hand] = b.P[:, shoulder] + torch.tensor([0.0, 0.4, 0.0], dtype=b.P.dtype)
    assert F.hand_swings(replace(b, P=held), "right") == 0
    waving = held.clone()
    waving[:, hand, 0] += 0.15 * torch.sin(2 * math.pi * 1.5 * t)  # 1.5 Hz across the body (facing +Z)
    swings = F.hand_swings(replace(b, P=waving), "right")
    assert swings >= 2 * 1.5 * 4.0 - 2
    assert F.hand_swings(replace(b, P=waving), "left") == 0


def test_captured_clips_pass_their_own_detector():
    """Real captures (cache/bandai20h, skipped without it): an unmirrored clip of each clear-cut action passes
    its detector, and fails the opposite one."""
    if not (BUILD / "clips.json").is_file():
        pytest.skip("no cache/bandai20h build")
    from kinema.data.dataset import MotionDataset
    from kinema.representation.kimodo_features import features_to_motion

    ds = MotionDataset(BUILD, "train")
    opposite = {"walk-back": "walk", "walk-turn-left": "walk-turn-right", "kick-right": "kick-left",
                "fall-forward": "fall-backward", "jump": "roll", "nod-yes": "shake-head-no", "pick-up": "jump"}
    for content, other in opposite.items():
        i = next(i for i, r in enumerate(ds.clips) if r["content"] == content and not r["mirrored"])
        m = features_to_motion(ds[i]["features"].double(), ds.skeleton, ds.fps)
        assert F.DETECTORS[content](m).passed, content
        assert not F.DETECTORS[other](m).passed, (content, other)


def _training_captions() -> set[str]:
    """Every training caption: of the build when cache/ has it, else from the caption functions."""
    if (BUILD / "clips.json").is_file():
        return {c for r in json.loads((BUILD / "clips.json").read_text()) for c in r["captions"]}
    out: set[str] = set()
    for content in F.BANDAI_DETECTORS:
        for style in STYLE_PHRASES:
            for mirrored in (False, True):
                out.update(captions_for(content, style, mirrored))
                out.update(extra_captions(content, style, 1.2, mirrored) + extra_captions(content, style, 3.0))
    for action, _ in HUMANOID_ACTIONS.values():
        for side in ((None,) if action.sided is None else ("left", "right", "forward", "backward")):
            out.update(humanoid_captions(action, side))
    return out


def test_prompts_cover_every_action_and_heldout_ones_are_no_training_caption():
    captions = _training_captions()
    clips = BUILD / "clips.json"
    built = {r["content"] for r in json.loads(clips.read_text())} if clips.is_file() else set()
    for action in F.DETECTORS:
        own, held = F.own_captions(action), F.heldout_prompts(action)
        assert len(own) == len(held) == F.PROMPTS_PER_KIND
        assert not set(held) & captions, action
        if action in built:  # punch and dance-long have no published Bandai clip
            assert set(own) <= captions, action


def test_runner_and_table(model):
    res = F.run_fidelity(model, seeds=(0,), seconds=2.0, actions=["walk-back"], steps=4)
    entry = res["actions"]["walk-back"]
    assert len(entry["prompts"]) == 2 * F.PROMPTS_PER_KIND
    for kind in ("own", "heldout"):
        s = entry[kind]
        assert s["total"] == F.PROMPTS_PER_KIND and 0 <= s["passed"] <= s["total"]
        assert s["holds"] == (s["passed"] == s["total"])  # one seed: a prompt holds when it passes
    table = F.format_fidelity(res)
    assert "| walk-back | m/s backward |" in table


def test_actions_resolve_by_family_and_bad_input_is_one_line(capsys):
    assert F.resolve_actions(["wave"]) == ["wave-left-hand", "wave-right-hand", "wave-both-hands"]
    assert F.resolve_actions(None) == list(F.DETECTORS)
    assert F.holds(2, 3) and not F.holds(1, 3)
    assert main(["evaluate", "fidelity", "--model", "default", "--actions", "backflip"]) == 2
    assert "unknown action 'backflip'" in capsys.readouterr().err
    assert main(["evaluate", "fidelity", "--model", "default", "--seconds", "0"]) == 2
    assert main(["evaluate", "sfcontrol", "--protocol", "fidelity", "--model", "default"]) == 2
