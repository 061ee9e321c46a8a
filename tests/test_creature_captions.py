"""Caption cleaning for creature clips: prefixes, suffixes, misspellings, subjects, prop flags; rig splits."""

from __future__ import annotations

import pytest

from kinema.data.creature_captions import (
    ACTIONS,
    clean_clip_name,
    creature_captions,
    is_prop,
    subject_for,
)
from kinema.data.split import assign_rig_splits
from kinema.errors import DataError


@pytest.mark.parametrize(
    ("name", "key"),
    [
        ("AnimalArmature|Gallop", "gallop"),
        ("Armature|TRex_Walk", "walk"),
        ("Armature|Stegosaurus_Death", "death"),  # another species' prefix, as in Apatosaurus.glb
        ("CharacterArmature|HitRecieve", "hit_receive"),
        ("HitRecieve_2", "hit_receive"),
        ("Armature|Swim.001", "swim"),
        ("CharacterArmature|Attack.001", "attack"),
        ("Fish_Armature|Swimming_Fast", "swim_fast"),
        ("AnimalArmature|Idle_2_HeadLow", "idle_head_low"),
        ("AnimalArmature|Idle_Headlow", "idle_head_low"),
        ("AnimalArmature|Jump_toIdle", "jump_to_idle"),
        ("AnimalArmature|Jump_ToIdle", "jump_to_idle"),
        ("HumanArmature|swordAttackJump", "sword_attack_jump"),
        ("HumanArmature|Walking", "walk"),
        ("CharacterArmature|Dead", "death"),
        ("MonsterArmature|Bite_InPlace", "bite_in_place"),
        ("Hazard_SpikeTrap_Armature|SpikeTrap_Activate", "activate"),
        ("LeverArmature|Lever_On", "on"),
        ("Chest_Open", "open"),
        ("Jump_NoHeight", "jump_no_height"),
    ],
)
def test_clean_clip_name(name: str, key: str) -> None:
    assert clean_clip_name(name) == key
    assert key in ACTIONS  # every shared clip name has hand-written phrases


def test_subjects() -> None:
    assert subject_for("animals_pack/Fox.glb") == "fox"
    assert subject_for("dinosaurs_pack/Trex.glb") == "T-rex"
    assert subject_for("single_knight_pack/KnightCharacter.glb") == "knight"
    assert subject_for("cute_fish_pack/ArmoredCatfish.glb") == "armored catfish"
    assert subject_for("ultimate_space_pack/Astronaut_FinnTheFrog-transformed.glb") == "astronaut"
    assert subject_for("ultimate_space_pack/Enemy_Flying-transformed.glb") == "flying alien"
    assert subject_for("cyberpunk_pack/Enemy_Flying.glb") == "flying drone"
    assert subject_for("my/WeirdCreature.glb") == "weird creature"  # fallback: split the stem


def test_captions_read_as_sentences() -> None:
    assert creature_captions("animals_pack/Fox.glb", "AnimalArmature|Gallop")[0] == "A fox gallops."
    assert creature_captions("dinosaurs_pack/Trex.glb", "Armature|TRex_Attack")[0] == "A T-rex attacks."
    assert creature_captions("single_knight_pack/KnightCharacter.glb", "HumanArmature|Wave")[0] == "A knight waves."
    caps = creature_captions("animals_pack/Alpaca.glb", "AnimalArmature|Eating")
    assert caps[0] == "An alpaca eats." and caps[1].startswith("The alpaca ")
    assert len(set(caps)) == len(caps) >= 2  # several phrasings
    assert all(c[0].isupper() and c.endswith(".") for c in caps)
    hit = creature_captions("cyberpunk_pack/Character.glb", "CharacterArmature|HitRecieve")
    assert "recieve" not in " ".join(hit).lower() and hit[0] == "A person gets hit."


def test_in_place_captions() -> None:
    moving = creature_captions("animals_pack/Fox.glb", "AnimalArmature|Gallop")
    still = creature_captions("animals_pack/Fox.glb", "AnimalArmature|Gallop", in_place=True)
    assert "A fox gallops in place." in still and "A fox gallops in place." not in moving
    assert not any("forward" in c for c in still)  # an in-place clip is not captioned as travelling
    # only locomotion gets the note
    assert creature_captions("animals_pack/Fox.glb", "AnimalArmature|Death", in_place=True) == creature_captions(
        "animals_pack/Fox.glb", "AnimalArmature|Death"
    )


def test_unknown_action_reads_its_words() -> None:
    assert creature_captions("x/Cat.glb", "Armature|Tail_Whip")[0] == "A cat performs a tail whip motion."


def test_prop_flags() -> None:
    assert is_prop("platformer_game_pack/Lever.glb", clean_clip_name("LeverArmature|Lever_On"))
    assert is_prop("platformer_game_pack/Chest.glb", clean_clip_name("Chest_Open"))
    assert is_prop("platformer_game_pack/Hazard_SpikeTrap.glb", "activate")
    assert not is_prop("animals_pack/Fox.glb", clean_clip_name("AnimalArmature|Gallop"))
    assert not is_prop("platformer_game_pack/Crab.glb", clean_clip_name("MonsterArmature|Walk"))


def test_rig_splits_hold_out_whole_rigs() -> None:
    rigs = {f"rig{i}": n for i, n in enumerate([40, 30, 25, 20, 12, 12, 10, 8, 6, 6, 5, 4, 4, 3, 2, 2, 1])}
    out = assign_rig_splits(rigs)
    assert out == assign_rig_splits(dict(reversed(list(rigs.items()))))  # order does not matter
    assert set(out) == set(rigs) and set(out.values()) == {"train", "val", "test"}
    total = sum(rigs.values())
    for split in ("val", "test"):
        share = sum(n for r, n in rigs.items() if out[r] == split) / total
        assert 0.05 <= share <= 0.2, (split, share)
    assert assign_rig_splits({"a": 5, "b": 3}) == {"a": "train", "b": "train"}  # too few rigs to hold out
    three = assign_rig_splits({"a": 5, "b": 3, "c": 100})
    assert sorted(three.values()) == ["test", "train", "val"]  # one rig each, even when large


def test_rig_splits_keep_named_rigs_in_train() -> None:
    """A rig named in ``train`` moves to train and every other rig keeps its split (held-out shares
    shrink instead of another rig being drawn); a name that is not a rig is a one-line error."""
    rigs = {f"rig{i}": n for i, n in enumerate([40, 30, 25, 20, 12, 12, 10, 8, 6, 6, 5, 4, 4, 3, 2, 2, 1])}
    plain = assign_rig_splits(rigs)
    held = sorted(r for r, s in plain.items() if s != "train")
    pinned = assign_rig_splits(rigs, train=frozenset(held[:1]))
    assert pinned[held[0]] == "train"
    assert {r: s for r, s in pinned.items() if r != held[0]} == {r: s for r, s in plain.items() if r != held[0]}
    with pytest.raises(DataError, match=r"train rigs \['dragon'\] are not rigs of this build \(rigs: rig0, rig1,"):
        assign_rig_splits(rigs, train=frozenset({"dragon"}))
