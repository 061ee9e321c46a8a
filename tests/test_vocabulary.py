"""Known prompts (kinema/model/vocabulary.py): prompts far from every training caption get a warning."""

from __future__ import annotations

import json
import re

import pytest
import torch

import kinema
from kinema.cli import main
from kinema.data.dataset import MotionDataset
from kinema.errors import KinemaError
from kinema.model.actions import actions_in, clips_per_action
from kinema.model.vocabulary import FILE_NAME, MIN_ACTION_CLIPS, UNKNOWN_BELOW, KnownPrompts, read_action_probes
from kinema.text import get_text_encoder

CAPTIONS = ["A person walks forward.", "A person bows.", "A person waves their right hand.", "A person bows."]


def test_round_trip_and_nearest_captions(tmp_path):
    enc = get_text_encoder("hash-test-32")
    known = KnownPrompts.build(CAPTIONS, enc)
    assert known.captions == sorted(set(CAPTIONS))  # unique, sorted
    path = known.save(tmp_path)
    assert path == tmp_path / FILE_NAME
    back = KnownPrompts.load(tmp_path)
    assert back.captions == known.captions and back.encoder_id == enc.id
    torch.testing.assert_close(back.embeddings, known.embeddings, atol=2e-3, rtol=0)  # float16 in the file
    match = back.match("A person bows.", enc.encode(["A person bows."])[0])
    assert match.known and match.nearest[0] == ("A person bows.", pytest.approx(1.0, abs=2e-3))
    assert len(match.nearest) == 3 and match.to_dict()["nearest"][0]["caption"] == "A person bows."
    far = back.match("x", -back.embeddings[0] - back.embeddings[1] - back.embeddings[2])
    assert not far.known and far.nearest[0][1] < UNKNOWN_BELOW
    assert "'x' is far from every caption" in far.warning() and "Nearest known captions" in far.warning()
    assert KnownPrompts.load(tmp_path / "elsewhere") is None


def test_bad_files_and_shapes(tmp_path):
    (tmp_path / FILE_NAME).write_bytes(b"not a safetensors file")
    with pytest.raises(KinemaError, match="not a known-prompts file"):
        KnownPrompts.load(tmp_path)
    with pytest.raises(KinemaError, match="2 captions"):
        KnownPrompts(["a", "b"], torch.zeros(3, 4), "x")
    known = KnownPrompts(["a"], torch.ones(1, 4), "x")
    with pytest.raises(KinemaError, match="5 dimensions"):
        known.match("a", torch.ones(5))


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


@pytest.mark.parametrize("prompt", ["A person sits down on a chair.", "A person climbs a ladder."])
def test_unknown_prompts_warn_with_their_nearest_captions(model, prompt):
    """Issue 18: no sitting or climbing in the training data; the model used to raise a hand silently.
    (Jumping was the second case until stop 53's action expert learned it.)"""
    rep = model.generate(prompt, seconds=1.0, steps=1, postprocess=False).report
    assert len(rep.warnings) == 1 and rep.warnings[0].startswith(f"prompt {prompt!r} is far from every caption")
    (entry,) = rep.prompts
    assert entry["prompt"] == prompt and not entry["known"]
    assert len(entry["nearest"]) == 3 and entry["nearest"][0]["similarity"] < UNKNOWN_BELOW
    assert entry["nearest"][0]["caption"] in rep.warnings[0]


def test_known_prompts_and_paraphrases_do_not_warn(model):
    segments = [
        ("A person walks forward.", 1.0),
        ("Someone strolls slowly ahead.", 1.0),
        ("A woman lifts her left arm up high.", 1.0),
        ("A person walks forward.", 1.0),
    ]
    rep = model.generate(segments, steps=1, postprocess=False).report
    assert rep.warnings == []
    assert [p["prompt"] for p in rep.prompts] == [s for s, _ in segments[:3]]  # each distinct prompt once
    assert all(p["known"] for p in rep.prompts) and rep.prompts[0]["nearest"][0]["similarity"] > 0.9
    assert model.generate("", seconds=1.0, steps=1, postprocess=False).report.prompts == []


def test_cli_prints_the_warning_on_stderr(tmp_path, capsys):
    out = tmp_path / "m.bvh"
    assert (
        main(
            [
                "generate",
                "A person sits down on a chair.",
                "--seconds",
                "1",
                "--steps",
                "1",
                "--no-postprocess",
                "--no-progress",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "kinema: warning: prompt 'A person sits down on a chair.' is far from every caption" in err
    assert out.is_file()


def test_export_writes_known_prompts(tiny_checkpoint, tiny_data, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "model"
    assert main(["export", str(tiny_checkpoint), "--out", str(out), "--known-prompts", str(tiny_data)]) == 0
    assert (out / FILE_NAME).is_file() and "known captions" in capsys.readouterr().out
    loaded = kinema.load_model(out)
    assert loaded.known_prompts is not None and loaded.known_prompts.encoder_id == "hash-test-32"
    train = [rec["captions"] for rec in MotionDataset(tiny_data, "train").clips]
    assert loaded.known_prompts.action_clips == clips_per_action(train) and loaded.known_prompts.action_clips
    assert (
        main(
            [
                "export",
                str(tiny_checkpoint),
                "--out",
                str(tmp_path / "m2"),
                "--known-prompts",
                str(tmp_path / "nothing"),
            ]
        )
        == 2
    )
    assert "not a dataset build" in capsys.readouterr().err and not (tmp_path / "m2").exists()
    # measured actions (issue 38): written with the known prompts; refused alone or malformed, before writing
    probes = tmp_path / "probes.json"
    probes.write_text(json.dumps({"rows": [{"content": "walk", "pass": False}, {"content": "walk", "pass": True}]}))
    assert main(["export", str(tiny_checkpoint), "--out", str(out), "--known-prompts", str(tiny_data),
                 "--action-probes", str(probes)]) == 0
    assert "measured: walk 1/2" in capsys.readouterr().out
    assert kinema.load_model(out).known_prompts.action_probes == {"walk": (1, 2)}
    assert main(["export", str(tiny_checkpoint), "--out", str(tmp_path / "m3"), "--action-probes", str(probes)]) == 2
    assert "--action-probes: give --known-prompts DATA too" in capsys.readouterr().err
    probes.write_text("{}")
    assert main(["export", str(tiny_checkpoint), "--out", str(tmp_path / "m3"), "--known-prompts", str(tiny_data),
                 "--action-probes", str(probes)]) == 2
    assert "not an action-probes file" in capsys.readouterr().err and not (tmp_path / "m3").exists()


# ----------------------------------------------------------------------------- actions (issues 36, 38)
def test_action_counts_round_trip_and_older_files_still_load(tmp_path):
    enc = get_text_encoder("hash-test-32")
    clips = [["A person walks forward."], ["A person walks forward.", "A person bows."], ["A person kicks."]]
    known = KnownPrompts.from_clips(clips, enc)
    assert known.action_clips == {"bow": 1, "kick": 1, "walk": 2} and known.learned == frozenset()  # all < 10
    known.save(tmp_path)
    assert KnownPrompts.load(tmp_path).action_clips == known.action_clips
    older = KnownPrompts(known.captions, known.embeddings, known.encoder_id)  # written before action_clips
    older.save(tmp_path / "old")
    back = KnownPrompts.load(tmp_path / "old")
    assert back.action_clips == {} and back.learned == {"bow", "kick", "walk"}  # every named action counts
    assert back.match("A person kicks.", enc.encode(["A person kicks."])[0]).known
    assert not back.match("A person punches.", enc.encode(["A person kicks."])[0]).known  # never named


def test_measured_actions_decide_over_clip_counts(tmp_path):
    """Issue 38: a probe file (scripts/humanoid_action_probes.py --json) measured on the model decides
    whether an action is learned, both ways: kick (6 clips) learned when its samples pass, punch (12 clips)
    not when they fail; unmeasured actions keep the count rule."""
    enc = get_text_encoder("hash-test-32")
    clips = [["A person kicks."]] * 6 + [["A person punches."]] * 12 + [["A person jumps."]] * 3
    known = KnownPrompts.from_clips(clips, enc)
    assert known.learned == {"punch"}
    rows = ([{"content": "kick-left", "pass": True}] * 3 + [{"content": "kick-right", "pass": False}]
            + [{"content": "punch-right", "pass": False}] * 4 + [{"content": "dance", "travel_m": 0.3}])
    probes_file = tmp_path / "probes.json"
    probes_file.write_text(json.dumps({"rows": rows}))
    probes = read_action_probes(probes_file)
    assert probes == {"kick": (3, 4), "punch": (0, 4)}
    measured = known.with_probes(probes)
    assert measured.learned == {"kick"}
    (note,) = measured.action_notes(frozenset({"punch"}))
    assert note == "the model does not make 'punch': 0 of 4 measured samples show it"
    assert "only 3 training clips show it" in measured.action_notes(frozenset({"jump"}))[0]
    measured.save(tmp_path / "m")
    back = KnownPrompts.load(tmp_path / "m")
    assert back.action_probes == probes and back.learned == {"kick"}
    for text, says in ((json.dumps({"rows": [{"content": "moonwalk", "pass": True}]}), "names no known action"),
                       (json.dumps({"rows": [{"content": "kick", "pass": 1}]}), "rows[0].pass: expected true or false"),
                       (json.dumps({"rows": [{"content": "dance"}]}), "no row with a 'pass'"),
                       ("[1, 2]", "not an action-probes file")):
        probes_file.write_text(text)
        with pytest.raises(KinemaError, match=re.escape(says)):
            read_action_probes(probes_file)


def test_the_default_model_knows_which_actions_its_clips_show():
    """Stops 53-56: the known prompts are the Bandai + Quaternius humanoid build's (an animation counted once
    at its two idle lengths); the actions its action expert was measured to make (kick, jump, roll, fall,
    punch: scripts/humanoid_action_probes.py) are learned whatever their clip count, the one it was measured
    not to make (nod) is not, and the unmeasured rare ones keep the count rule."""
    known = kinema.load_model().known_prompts
    clips = known.action_clips
    assert clips["kick"] == 6 and clips["dance"] == 8 and clips["call"] == clips["slash"] == 4  # mirrored
    assert clips["punch"] == 10 and clips["nod"] == 12 and clips["roll"] == 4
    assert min(clips[a] for a in ("walk", "run", "turn", "bow", "wave", "raise", "guide")) >= 2 * MIN_ACTION_CLIPS
    assert {"kick", "jump", "roll", "fall", "punch"} <= known.learned
    assert known.action_probes["punch"] == (8, 12) and known.action_probes["nod"] == (0, 12)
    unlearned = {"nod", "dance", "crouch", "pick up", "call", "slash", "spin"}
    assert known.named_actions - known.learned == unlearned


@pytest.mark.parametrize(
    "prompt, says",
    [
        ("A person walks forward and reaches out with the right hand.", "the model was not trained on 'reach'"),
        ("A person dances.", "the model was not trained on 'dance' enough to learn it"),
        ("Someone nods yes.", "the model does not make 'nod': 0 of 12 measured samples show it"),
        ("A person picks up a box.", "only 2 training clips show it"),
    ],
)
def test_a_prompt_whose_action_the_model_does_not_know_is_warned(model, prompt, says):
    """Issue 36: these were grounded on other captions without a word (the reach on a walk-and-turn)."""
    (match,) = model.match_prompts([prompt])
    assert not match.known and says in match.warning() and "\n" not in match.warning()
    assert match.to_dict()["actions"] == sorted(actions_in(prompt))
    grounded = model.ground_prompts([prompt])[prompt]
    assert grounded.status == "unknown" and grounded.captions == ()
    assert torch.equal(grounded.embedding, model.encode_text(prompt))  # conditioned on its own words


def test_actions_no_caption_names_together_are_warned(model):
    (match,) = model.match_prompts(["A person walks forward and waves."])
    assert not match.known and "no training caption has 'walk' and 'wave' together" in match.warning()
    assert match.warning().startswith("prompt 'A person walks forward and waves.' asks for what the model was not")


def test_the_warning_reaches_the_report(model):
    rep = model.generate("A person dances.", seconds=1.0, steps=1, postprocess=False).report
    assert len(rep.warnings) == 1 and "'dance'" in rep.warnings[0]
    assert rep.prompts[0]["grounding"]["status"] == "unknown" and rep.prompts[0]["actions"] == ["dance"]
