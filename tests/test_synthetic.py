"""kinema.data.synthetic: the procedurally animated stand-in for the Bandai Namco data used by the tests
when the shared data is absent. These tests always use the synthetic folder (fixture ``synthetic_bandai``)."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
import torch

from kinema.data.bandai import list_clips, load_clip, min_toe_height
from kinema.data.captions import captions_for
from kinema.data.split import assign_splits, group_of
from kinema.data.synthetic import CLIPS, PINNED_DURATION_S, animate, clip_ids, write_synthetic_bandai
from kinema.io.bvh import parse_bvh, read_bvh
from kinema.motion.contacts import foot_contacts
from kinema.representation.kimodo_features import heading_from_positions, motion_to_features

D2 = "Bandai-Namco-Research-Motiondataset-2/data"


def _clip(root, clip_id: str):
    """The 21-joint motion (metres, 30 fps) of a synthetic clip."""
    folder = f"Bandai-Namco-Research-Motiondataset-{clip_id[8]}/data"
    return read_bvh(root / folder / f"{clip_id}.bvh.gz", scale=0.01).prune(["joint_Root"])


def test_layout_labels_and_twins(synthetic_bandai):
    clips = list_clips(synthetic_bandai)  # also checks every JSON twin against its file name
    assert len(clips) == len(clip_ids()) == sum(len(c) * len(s) * k for c, s, k in CLIPS.values()) == 63
    assert {c.dataset for c in clips} == {"dataset-1", "dataset-2"}
    assert len({(c.dataset, c.content) for c in clips}) == 13  # more groups than test_data's subset of 12
    assert all(captions_for(c.content, c.style) for c in clips)
    for name in (
        "dataset-2_walk_normal_001",
        "dataset-2_wave-right-hand_normal_002",
        "dataset-2_wave-left-hand_elderly_003",
        "dataset-1_dance-short_normal_001",
        "dataset-1_walk_happy_001",
    ):  # clips that tests name
        assert any(c.clip_id == name for c in clips), name
    splits = assign_splits([(c.clip_id, group_of(c.clip_id)) for c in clips])
    per_group: dict[str, Counter] = {}
    for c in clips:
        per_group.setdefault(group_of(c.clip_id), Counter())[splits[c.clip_id]] += 1
    assert all(set(n) == {"train", "val", "test"} for n in per_group.values())  # split by take, all non-empty


def test_files_look_like_bandai_and_are_reproducible(synthetic_bandai, tmp_path):
    path = synthetic_bandai / D2 / "dataset-2_run_normal_001.bvh.gz"
    data = parse_bvh(path)
    assert data.num_joints == 22 and data.names[:2] == ["joint_Root", "Hips"] and len(data.end_sites) == 5
    assert all(
        c == ["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"] for c in data.channels
    )
    assert data.frame_time == pytest.approx(1 / 30, rel=1e-4) and np.isfinite(data.values).all()
    assert (data.values[:, :6] == 0).all()  # the static joint_Root
    x_angles = data.values[:, 4::6]
    assert np.abs(x_angles).max() < 89.0  # no ZXY gimbal lock anywhere, so Euler curves stay smooth
    assert np.abs(np.diff(data.values[:, 6:], axis=0)).max() < 30.0  # cm or degrees per frame: no flips
    again = write_synthetic_bandai(tmp_path / "again")
    assert (again / D2 / path.name).read_bytes() == path.read_bytes()


@pytest.mark.parametrize(
    "content", ["walk", "run", "bow", "bye", "dance-short", "wave-both-hands", "raise-up-left-hand"]
)
def test_every_content_loads_on_the_floor_with_finite_features(synthetic_bandai, content):
    info = next(c for c in list_clips(synthetic_bandai) if c.content == content)
    motion = load_clip(info, 20)  # also checks that walks and runs travel
    seconds = motion.num_frames / 20
    pinned = PINNED_DURATION_S.get(info.clip_id)  # the first dance is pinned at 5.5 s
    assert motion.skeleton.num_joints == 21
    assert abs(seconds - pinned) < 0.1 if pinned else 2.5 < seconds < 5.0
    assert 0.03 < min_toe_height(motion) < 0.06  # toes on the floor, as on Bandai (about 4 cm)
    assert torch.isfinite(motion_to_features(motion)).all()


def test_walk_travels_forward_on_planted_feet(synthetic_bandai):
    walk = _clip(synthetic_bandai, "dataset-2_walk_normal_001")
    assert walk.fps == 30 and walk.num_frames == 271  # 9 s, as tests of the real clip expect
    travel = walk.root_translation[-1] - walk.root_translation[0]
    assert 9.0 < travel[2] < 14.0 and abs(travel[0]) < 0.2  # about 1.35 m/s along +Z
    heading = heading_from_positions(walk.positions, walk.skeleton)
    assert torch.atan2(heading[:, 1], heading[:, 0]).abs().max() < 0.15  # facing +Z all along
    contacts = foot_contacts(walk.positions, walk.fps, walk.skeleton)
    assert 0.3 < contacts.mean() < 0.8
    toes = walk.positions[:, [walk.skeleton.index("left_toe"), walk.skeleton.index("right_toe")]][..., [0, 2]]
    speed = (toes[1:] - toes[:-1]).norm(dim=-1) * walk.fps
    both = (contacts[1:, [1, 3]] > 0) & (contacts[:-1, [1, 3]] > 0)
    assert speed[both].max() < 0.02  # planted toes do not slide (m/s)
    hands = walk.positions[:, [walk.skeleton.index("left_hand"), walk.skeleton.index("right_hand")], 2]
    swing = hands - walk.root_translation[:, None, 2]
    assert torch.corrcoef(swing.T)[0, 1] < -0.9  # the arms counter-swing


def test_gestures_move_the_named_arm(synthetic_bandai):
    def hand_above_head(clip_id: str) -> tuple[float, float]:
        m = _clip(synthetic_bandai, clip_id)
        P, s = m.positions, m.skeleton
        head = P[:, s.index("head"), 1]
        return tuple(float((P[:, s.index(f"{side}_hand"), 1] - head).max()) for side in ("left", "right"))

    left, right = hand_above_head("dataset-2_wave-left-hand_normal_001")
    assert left > 0.1 and right < -0.3
    left, right = hand_above_head("dataset-1_bye_normal_001")  # bye is a right-hand wave
    assert right > 0.1 and left < -0.3
    assert min(hand_above_head("dataset-2_raise-up-both-hands_normal_001")) > 0.2
    bow = _clip(synthetic_bandai, "dataset-1_bow_normal_001")
    head = bow.positions[:, bow.skeleton.index("head")] - bow.root_translation[:1]
    assert head[0, 1] - head[:, 1].min() > 0.1 and head[:, 2].max() - head[0, 2] > 0.2  # bends forward
    dance = _clip(synthetic_bandai, "dataset-1_dance-short_normal_001")
    h = heading_from_positions(dance.positions, dance.skeleton)
    turned = np.unwrap(torch.atan2(h[:, 1], h[:, 0]).numpy())
    assert abs(turned[-1] - turned[0]) > 1.8 * math.pi  # about a full turn


def test_unknown_content_or_style_raises():
    rng = np.random.default_rng(0)
    with pytest.raises(KeyError):
        animate("kick", "normal", 1.0, rng)
    with pytest.raises(KeyError):
        animate("walk", "giant", 1.0, rng)
