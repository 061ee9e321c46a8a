"""The side words of a text and its mirror (kinema.model.sides)."""

from kinema.model.sides import mirror_caption, sides


def test_mirror_caption() -> None:
    assert mirror_caption("A person waves with their left hand.") == "A person waves with their right hand."
    assert mirror_caption("Left then RIGHT, then right.") == "Right then LEFT, then left."
    assert mirror_caption("He turns leftwards; a left-hand wave.") == "He turns rightwards; a right-hand wave."
    assert mirror_caption("A bright, leftover rightful kick.") == "A bright, leftover rightful kick."
    text = "Someone turns Left, then waves the right hand."
    assert mirror_caption(mirror_caption(text)) == text


def test_sides_of_a_text_and_of_its_mirror() -> None:
    assert sides("A person kicks with the right foot.") == {"right"}
    assert sides(mirror_caption("A person kicks with the right foot.")) == {"left"}
    assert sides("Left, then rightwards.") == {"left", "right"}
    assert sides("A bright, leftover kick.") == frozenset()
