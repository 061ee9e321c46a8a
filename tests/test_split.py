"""Clip-name parsing and the deterministic, stratified train/val/test split."""

from __future__ import annotations

import random
from collections import Counter, defaultdict
from pathlib import Path

import pytest

from kinema.data.split import assign_splits, group_of, parse_clip_name, split_for
from kinema.errors import DataError


def _clips(root: Path) -> list[dict]:
    """Every clip under ``root`` that has motion (a .bvh.gz), parsed from its file name."""
    dirs = [root / f"Bandai-Namco-Research-Motiondataset-{n}" for n in (1, 2)]
    return [parse_clip_name(p.name) for d in dirs for p in sorted((d / "data").glob("*.bvh.gz"))]


def test_parse_clip_name() -> None:
    got = parse_clip_name("dataset-2_wave-left-hand_normal_012.bvh.gz")
    assert got == {
        "dataset": "dataset-2",
        "content": "wave-left-hand",
        "style": "normal",
        "take": 12,
        "clip_id": "dataset-2_wave-left-hand_normal_012",
    }
    assert parse_clip_name("some/dir/dataset-1_walk-back_not-confident_001.json")["style"] == "not-confident"
    assert parse_clip_name("dataset-1_walk_old_002")["take"] == 2
    assert parse_clip_name("dataset-1_walk_old_002.bvh")["clip_id"] == "dataset-1_walk_old_002"
    assert group_of("dataset-2_raise-up-both-hands_active_001") == "dataset-2_raise-up-both-hands"


@pytest.mark.parametrize(
    "bad",
    [
        "walk_normal_001.bvh.gz",
        "dataset-2_wave_left_hand_normal_012.bvh.gz",
        "dataset-2_walk_normal.bvh.gz",
        "dataset-2_walk_normal_01a.bvh.gz",
        "dataset-2_walk_normal_001.txt",
        "dataset-x_walk_normal_001.bvh.gz",
        "",
    ],
)
def test_parse_clip_name_rejects(bad: str) -> None:
    with pytest.raises(DataError):
        parse_clip_name(bad)


def test_split_for_is_pinned_and_deterministic() -> None:
    # Pinned values: a change here means every cached split on every machine changes.
    cid = "dataset-2_wave-left-hand_normal_012"
    assert split_for(cid, group_of(cid)) == "test"
    assert split_for("dataset-1_walk_happy_001", "dataset-1_walk") == "train"
    assert all(split_for(cid, "g") == split_for(cid, "g") for _ in range(3))
    assert split_for(cid, group_of(cid), fractions=(1.0, 0.0, 0.0)) == "train"
    assert split_for(cid, group_of(cid), fractions=(0.0, 0.0, 1.0)) == "test"
    with pytest.raises(ValueError):
        split_for(cid, "g", fractions=(0.5, 0.5, 0.5))


def test_assign_splits_small_groups_and_order() -> None:
    clips = [(f"dataset-9_hop_normal_{i:03d}", "hop") for i in range(10)]
    clips += [
        ("dataset-9_solo_normal_001", "solo"),
        ("dataset-9_pair_a_001", "pair"),
        ("dataset-9_pair_b_001", "pair"),
    ]
    clips += [(f"dataset-9_tri_normal_{i:03d}", "tri") for i in range(3)]
    out = assign_splits(clips)
    assert set(out) == {c for c, _ in clips}
    hop = Counter(out[c] for c, g in clips if g == "hop")
    assert hop == {"train": 8, "val": 1, "test": 1}
    assert Counter(out[c] for c, g in clips if g == "tri") == {"train": 1, "val": 1, "test": 1}
    assert {out[c] for c, g in clips if g in ("solo", "pair")} == {"train"}
    shuffled = clips[:]
    random.Random(0).shuffle(shuffled)
    assert assign_splits(shuffled + clips[:3]) == out  # order and repeats do not matter
    with pytest.raises(DataError, match="two groups"):
        assign_splits([("x", "a"), ("x", "b")])
    assert set(assign_splits(clips, fractions=(1.0, 0.0, 0.0)).values()) == {"train"}


def test_real_data_split(real_bandai_root) -> None:
    """The real data's size and split fractions: facts of the real data (skips without it)."""
    clips = _clips(real_bandai_root)
    assert len(clips) > 2500
    pairs = [(c["clip_id"], group_of(c["clip_id"])) for c in clips]
    out = assign_splits(pairs)
    assert out == assign_splits(list(reversed(pairs)))

    per_dataset: dict[str, Counter] = defaultdict(Counter)
    per_group: dict[str, Counter] = defaultdict(Counter)
    for clip_id, group in pairs:
        per_dataset[clip_id.split("_")[0]][out[clip_id]] += 1
        per_group[group][out[clip_id]] += 1

    for counts in per_dataset.values():  # fractions roughly respected
        total = sum(counts.values())
        assert abs(counts["train"] / total - 0.8) < 0.06, counts
        assert abs(counts["test"] / total - 0.1) < 0.04, counts
        assert abs(counts["val"] / total - 0.1) < 0.04, counts
    for group, counts in per_group.items():  # stratified: every big enough group is covered
        if sum(counts.values()) >= 3:
            assert counts["test"] >= 1 and counts["val"] >= 1 and counts["train"] >= 1, group
    d2_contents = {c["content"] for c in clips if c["dataset"] == "dataset-2"}
    assert len(d2_contents) == 10
    assert all(per_group[f"dataset-2_{c}"]["test"] >= 1 for c in d2_contents)

    # the stateless rule and the ranked rule agree for almost every clip
    agree = sum(split_for(c, g) == out[c] for c, g in pairs) / len(pairs)
    assert agree > 0.9


def test_split_of_the_data_in_use_covers_every_group(bandai_root) -> None:
    """On the real or synthetic data alike: every group of 3 or more takes has train, val and test clips,
    and the split does not depend on the order of the clips."""
    pairs = [(c["clip_id"], group_of(c["clip_id"])) for c in _clips(bandai_root)]
    out = assign_splits(pairs)
    assert out == assign_splits(list(reversed(pairs))) and set(out) == {c for c, _ in pairs}
    per_group: dict[str, Counter] = defaultdict(Counter)
    for clip_id, group in pairs:
        per_group[group][out[clip_id]] += 1
    for group, counts in per_group.items():
        if sum(counts.values()) >= 3:
            assert counts["test"] >= 1 and counts["val"] >= 1 and counts["train"] >= 1, group
