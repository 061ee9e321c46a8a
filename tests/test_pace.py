"""Pace words (kinema/model/pace.py) and grounding on them: a jog is grounded on a slow run, a stroll on a slow
walk, a plain run never on a sprint (issue 57)."""

from __future__ import annotations

import pytest

import kinema
from kinema.model.grounding import Grounding, ground
from kinema.model.pace import pace
from kinema.model.vocabulary import KnownPrompts
from kinema.text import get_text_encoder


@pytest.mark.parametrize("text, want", [
    ("Someone jogs forward.", "jog"),
    ("A runner is jogging along.", "jog"),
    ("A person runs ahead at an easy pace.", "jog"),
    ("Someone runs forward slowly.", "jog"),
    ("A woman strolls along at her leisure.", "stroll"),
    ("A man ambles ahead.", "stroll"),
    ("Someone walks slowly ahead.", "stroll"),
    ("A person walks forward at a slow, leisurely pace.", "stroll"),
    ("A person sprints forward.", "sprint"),
    ("Someone dashes forward.", "sprint"),
    ("Someone races ahead at top speed.", "sprint"),
    ("A person runs flat out.", "sprint"),
    ("A person runs forward.", None),
    ("A person runs forward fast.", None),
    ("A person walks ahead.", None),
    ("A person bows slowly.", None),
    ("Someone embraces a friend.", None),
])
def test_pace_of_words(text, want):
    assert pace(text) == want


def test_grounding_keeps_a_prompt_on_captions_of_its_pace():
    captions = ["A person runs forward.", "A person sprints forward.", "A person runs forward slowly.",
                "A person walks forward.", "A person walks forward slowly."]
    enc = get_text_encoder("minilm-l6-v2")
    known = KnownPrompts.build(captions, enc)
    settings = Grounding(weight=1.0, top_k=3)

    def grounded_on(prompt):
        out = ground(prompt, enc.encode([prompt]), known, settings)
        return {c for c, _ in out.captions}, out.status

    on, status = grounded_on("Someone jogs ahead.")
    assert status == "grounded" and on == {"A person runs forward slowly."}
    on, _ = grounded_on("Someone strolls forward.")
    assert on == {"A person walks forward slowly."}
    on, _ = grounded_on("Somebody runs ahead.")
    assert on and on <= {"A person runs forward."}


def test_shipped_model_grounds_jogs_and_strolls_on_their_pace():
    model = kinema.load_model()
    for prompt, want in [("Someone jogs forward.", "jog"), ("Someone is jogging straight ahead.", "jog"),
                         ("A woman strolls along at her leisure.", "stroll"),
                         ("A man runs quickly down the road.", None)]:
        grounded = model.ground_prompts([prompt])[prompt]
        assert grounded.status == "grounded", prompt
        assert [pace(c) for c, _ in grounded.captions] == [want] * len(grounded.captions), (prompt, grounded.captions)
