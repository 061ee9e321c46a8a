"""Held-out rigs classified against the training rigs (kinema.evaluate.anyrig.groups), the grouped
table, and caption retrieval per rig (kinema.evaluate.anyrig.suite)."""

from __future__ import annotations

import creature_fixtures
import torch
from rig_fixtures import fish, hexapod, quadruped, walking

from kinema.evaluate.anyrig.groups import (
    CLASSES,
    classify,
    rig_shape,
    similarity_table,
    split_summary,
    training_shapes,
    tree_code,
)
from kinema.evaluate.anyrig.suite import caption_retrieval, evaluate_split, format_row
from kinema.representation.joint import JointRepresentation
from kinema.rig import Rig
from kinema.skeleton import Skeleton

creature_cache, trained = creature_fixtures.creature_cache, creature_fixtures.trained  # module-scoped fixtures


def _renamed(s: Skeleton, suffix: str) -> Skeleton:
    return Skeleton([n + suffix for n in s.names], s.parents, s.offsets, name=s.name + suffix)


def _with_joint(s: Skeleton, parent: str, name: str) -> Skeleton:
    """``s`` with one more joint under ``parent`` (a leaf: a gun, a tail tip)."""
    offsets = torch.cat([s.offsets, torch.tensor([[0.0, 0.05, 0.05]], dtype=s.offsets.dtype)])
    return Skeleton([*s.names, name], [*s.parents, s.index(parent)], offsets, name=s.name + "+")


def test_tree_codes_ignore_names_and_child_order() -> None:
    assert tree_code([-1, 0, 0, 1]) == tree_code([-1, 0, 1, 0]) == "((())())"
    assert tree_code([-1, 0, 1, 2]) != tree_code([-1, 0, 0, 0])
    assert tree_code([-1, 0, 0, 1], drop=3) == tree_code([-1, 0, 0])
    assert tree_code([-1, *range(2000)]).count("(") == 2001  # a long chain: no recursion limit


def test_held_out_rigs_are_classified_against_the_training_rigs() -> None:
    train = [rig_shape("quad", quadruped()), rig_shape("fish", fish())]
    assert train[0].legs == 4 and train[1].legs == 0
    assert classify(rig_shape("dog", _renamed(quadruped(), "_x")), train) == ("same topology", "quad")
    gun = _with_joint(quadruped(), "Chest", "Gun")
    assert classify(rig_shape("gun", gun), train) == ("same topology +-1 joint", "quad")
    assert classify(rig_shape("q2", quadruped()), [rig_shape("gun", gun)]) == ("same topology +-1 joint", "gun")
    q = quadruped()  # the tail tip moved from the tail to the body: another tree, still four legs
    parents = list(q.parents)
    parents[q.index("TailB")] = q.index("Body")
    twotails = Skeleton(q.names, parents, q.offsets)
    assert classify(rig_shape("twotails", twotails), train) == ("new topology", "quad")
    assert classify(rig_shape("insect", hexapod()), train) == ("new limb count", "quad")  # 6 legs: closest is 4
    assert classify(rig_shape("quad", quadruped()), train[:1]) == ("new limb count", None)  # only itself


def test_similarity_table_groups_and_aggregates() -> None:
    rows = [
        {"rig": "a", "similarity": CLASSES[0], "skate_ratio": 2.0, "jerk": 4.0, "jerk_ref": 2.0, "constraint_cm": 0.0,
         "retrieval_hits": 1, "retrieval_n": 2, "retrieval_chance": 0.5},
        {"rig": "b", "similarity": CLASSES[0], "skate_ratio": 4.0, "jerk": 9.0, "jerk_ref": 3.0, "constraint_cm": 1.0,
         "retrieval_hits": 3, "retrieval_n": 3, "retrieval_chance": 1 / 3},
        {"rig": "c", "similarity": CLASSES[3], "skate_ratio": None, "jerk": 1.0, "jerk_ref": 0.0,
         "constraint_cm": None},
    ]  # fmt: skip
    lines = similarity_table(rows).splitlines()
    assert len(lines) == 4 and lines[2] == "| same topology (a, b) | 2 | 3.00 | 2.50 | 0.50 | 0.80 (0.40) |"
    assert lines[3] == "| new limb count (c) | 1 | - | - | - | - |"


def test_split_summary_medians_and_worst_cases() -> None:
    rows = [
        {"rig": "a", "split": "train", "skate_ratio": 1.5, "jerk": 4.0, "jerk_ref": 2.0, "constraint_cm": 0.0,
         "constraint_deg": 0.1, "keyframe_cm": 0.0, "stretch": 1e-12, "retrieval_hits": 1, "retrieval_n": 2},
        {"rig": "b", "split": "train", "skate_ratio": 4.5, "jerk": 9.0, "jerk_ref": 3.0, "constraint_cm": 2.0,
         "constraint_deg": 0.3, "keyframe_cm": 0.5, "stretch": 1e-10, "retrieval_hits": 2, "retrieval_n": 2},
        {"rig": "c", "split": "test", "skate_ratio": None, "jerk": 1.0, "jerk_ref": 0.0, "constraint_cm": None,
         "stretch": 0.0},
    ]  # fmt: skip
    lines = split_summary(rows).splitlines()
    assert len(lines) == 4
    assert lines[2] == "| train | 2 | 3.00 | 1 of 2 | 2.50 | 1.00 / 2.00 | 0.30 | 0.50 | 1.0e-10 | 3 of 4 |"
    assert lines[3] == "| test | 1 | - | 0 of 0 | - | - / - | - | - | 0.0e+00 | 0 of 0 |"


def test_caption_retrieval_finds_the_clip_of_the_caption() -> None:
    rig = Rig.from_skeleton(quadruped())
    rep = JointRepresentation(rig, 20.0)
    still, walk = walking(rig.skeleton, frames=20, speed=0.0), walking(rig.skeleton, frames=20, speed=1.0)
    caps = ["A dog stands.", "A dog walks."]
    assert caption_retrieval([still, walk], [still, walk], caps, rep) == {
        "retrieval_hits": 2,
        "retrieval_n": 2,
        "retrieval_chance": 0.5,
    }
    assert caption_retrieval([walk, still], [still, walk], caps, rep)["retrieval_hits"] == 0
    assert caption_retrieval([still, walk], [still, walk], ["x", "x"], rep) == {}  # one caption: not defined


def test_evaluate_split_classifies_held_out_rigs(trained, creature_cache) -> None:
    model = creature_fixtures.tiny_model(trained)
    shapes = training_shapes(model.loaded.train_rigs)
    rows = []
    for split in ("val", "test"):
        rows += evaluate_split(model, creature_cache, split, clips=2, steps=2, train_shapes=shapes, probe_seconds=1.0,
                               log=lambda s: None)
    assert rows
    for r in rows:  # the held-out rigs are renamed copies of the training shapes
        assert r["similarity"] == "same topology" and r["nearest"] in model.loaded.train_rigs
        assert r["retrieval_n"] == 2 and 0 <= r["retrieval_hits"] <= 2 and r["retrieval_chance"] == 0.5
        assert "same topology (" in format_row(r)
    assert "same topology" in similarity_table(rows)
