"""kinema.rig: parts found from names (human) and geometry (creatures), overrides, round trips."""

from __future__ import annotations

import json

import pytest
import torch
from rig_fixtures import fish, hexapod, human, quadruped, snake2

from kinema.errors import SkeletonError
from kinema.motion.contacts import contact_joints
from kinema.postprocess.footlock import leg_locks
from kinema.rig import Rig
from kinema.rig.find import rest_positions
from kinema.skeleton import Skeleton


def test_human_rig_from_names() -> None:
    skel = human()
    rig = Rig.from_skeleton(skel)
    assert rig.root == skel.index("Hips") == 0
    assert rig.contacts == tuple(contact_joints(skel)) and rig.num_contacts == 4
    assert rig.joint_names(rig.contacts) == ["Foot_L", "Toes_L", "Foot_R", "Toes_R"]
    assert rig.joint_names(rig.limbs["left_leg"]) == ["UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L"]
    assert rig.joint_names(rig.limbs["right_arm"])[-1] == "Hand_R"
    assert set(rig.end_effectors) == {"head", "left_hand", "right_hand", "left_foot", "right_foot"}
    assert rig.contact_mirror == [2, 3, 0, 1]
    assert set(rig.legs()) == {"left_leg", "right_leg"}
    assert rig.up == (0.0, 1.0, 0.0) and rig.forward == (0.0, 0.0, 1.0)


@pytest.mark.parametrize(
    ("make", "legs", "contacts"),
    [(hexapod, 6, 6), (quadruped, 4, 8), (fish, 0, 0), (snake2, 0, 0)],
)
def test_creature_rigs_from_geometry(make, legs, contacts) -> None:
    skel = make()
    rig = Rig.from_skeleton(skel)
    assert len(rig.legs()) == legs and rig.num_contacts == contacts
    P = rest_positions(skel)
    for j in rig.contacts:  # every contact is in the lowest band
        assert P[j, 1] < P[:, 1].min() + 0.2 * (P[rig.root, 1] - P[:, 1].min())
    for chain in rig.limbs.values():  # chains run root side -> end
        assert all(skel.parents[b] == a for a, b in zip(chain, chain[1:], strict=False))
    if legs:  # feet ordered front to back
        z = [float(P[c[-1], 2]) for c in rig.legs().values()]
        assert z == sorted(z, reverse=True)


def test_overrides_from_file_and_mapping(tmp_path) -> None:
    skel = fish()
    path = tmp_path / "rig.json"
    path.write_text(
        json.dumps(
            {
                "comment": "a fish that rests on its fins",
                "contacts": ["Fin_L", "Fin_R"],
                "limbs": {"tail": ["Tail_1", "Tail_2", "Tail_3"]},
                "up": [0, 2, 0],
            }
        )
    )
    rig = Rig.from_skeleton(skel, overrides=path)
    assert rig.joint_names(rig.contacts) == ["Fin_L", "Fin_R"] and list(rig.limbs) == ["tail"]
    assert rig.up == (0.0, 1.0, 0.0)
    again = Rig.from_dict(json.loads(json.dumps(rig.to_dict())))
    assert again.to_dict() == rig.to_dict()
    assert Rig.from_skeleton(skel, overrides={"root": "Tail_1"}).root == skel.index("Tail_1")


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"contact": ["Fin_L"]}, "unknown rig override key 'contact' (did you mean 'contacts'?)"),
        ({"contacts": ["Nope"]}, "'contacts[0]' names unknown joint 'Nope'"),
        ({"limbs": {"x": ["Fin_L", "Tail_3"]}}, "is not a parent-to-child chain"),
        ({"up": [0, 0, 0]}, "'up' must be a non-zero finite vector"),
        ({"forward": [0, 1, 0]}, "must be perpendicular"),
        ([1, 2], "must be a JSON object"),
    ],
)
def test_bad_overrides_are_clear(overrides, message) -> None:
    with pytest.raises(SkeletonError) as err:
        Rig.from_skeleton(fish(), overrides=overrides)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_bad_override_file(tmp_path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    with pytest.raises(SkeletonError, match="bad.json:1: not valid JSON"):
        Rig.from_skeleton(fish(), overrides=bad)
    with pytest.raises(SkeletonError, match="no such rig override file"):
        Rig.from_skeleton(fish(), overrides=tmp_path / "missing.json")
    with pytest.raises(SkeletonError, match="unknown keys"):
        Rig.from_dict({"skeleton": fish().to_dict(), "legs": 4})


def test_two_joint_and_single_joint_skeletons() -> None:
    two = Skeleton(["a", "b"], [-1, 0], torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert Rig.from_skeleton(two).contacts == () and Rig.from_skeleton(two).end_effectors == {"b": 1}
    one = Skeleton(["a"], [-1], torch.zeros(1, 3))
    assert Rig.from_skeleton(one).limbs == {}


def test_ik_helper_rig_like_the_quaternius_animals() -> None:
    """An armature at the origin, a low control bone, pole targets and IK-driven feet outside the legs:
    the root is not the armature, pole targets are never contacts, the feet are, and foot locking
    (tested in test_footlock_rigs) has no three-joint leg chain to bend there."""
    rows = [
        ("Armature", None, (0.0, 0.0, 0.0)),
        ("Body", "Armature", (0.0, 0.07, 0.0)),
        ("Back", "Body", (0.0, 0.24, 0.0)),
        ("Head", "Back", (0.0, 0.05, 0.3)),
        ("PoleTarget.L", "Body", (0.05, 0.06, 0.5)),
        ("PoleTarget.R", "Body", (-0.05, 0.06, 0.5)),
    ]
    for k, (x, z) in enumerate(((0.05, 0.15), (-0.05, 0.15), (0.05, -0.15), (-0.05, -0.15))):
        rows += [
            (f"Upper{k}", "Back", (x, -0.05, z)),
            (f"Lower{k}", f"Upper{k}", (0.0, -0.08, 0.0)),
            (f"IKLeg{k}", "Armature", (x, 0.03, z)),
            (f"Foot{k}", f"IKLeg{k}", (0.0, -0.02, 0.02)),
        ]
    names = [r[0] for r in rows]
    skel = Skeleton(
        names,
        [-1 if r[1] is None else names.index(r[1]) for r in rows],
        torch.tensor([r[2] for r in rows], dtype=torch.float64),
    )
    rig = Rig.from_skeleton(skel)
    assert skel.names[rig.root] == "Body"
    contacts = rig.joint_names(rig.contacts)
    assert sorted(contacts) == sorted([f"IKLeg{k}" for k in range(4)] + [f"Foot{k}" for k in range(4)])
    assert not any("Pole" in n for n in [*contacts, *rig.end_effectors])
    assert len(rig.legs()) == 4
    assert leg_locks(rig) == []  # IK would have to bend the armature: foot locking leaves these feet alone
