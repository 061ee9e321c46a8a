"""Action words (kinema/model/actions.py): the actions of the training captions are read back from them
exactly, synonyms map onto them, and the actions users ask for that the captions lack are recognised."""

from __future__ import annotations

import pytest

from kinema.data.captions import CONTENT_PHRASES, STYLE_PHRASES, captions_for
from kinema.data.phrasings import SPEED_PHRASES, SPEED_SENTENCES, extra_captions, manner_phrases
from kinema.model.actions import ACTION_WORDS, actions_in, clips_per_action

# what each Bandai content label's captions name, all captions of all styles and both sides together
CONTENT_ACTIONS = {
    "walk": {"walk"}, "run": {"run"}, "dash": {"run"}, "walk-back": {"walk", "walk back"}, "walk-left": {"walk"},
    "walk-right": {"walk"}, "walk-turn-left": {"walk", "turn"}, "walk-turn-right": {"walk", "turn"},
    "bow": {"bow"}, "bye": {"wave", "raise"}, "byebye": {"wave", "raise"}, "guide": {"guide"},
    "respond": {"raise"}, "call": {"call"}, "punch": {"punch"}, "kick": {"kick", "spin"},
    "slash": {"slash"}, "dance-long": {"dance"}, "dance-short": {"dance", "spin"},
    "wave-both-hands": {"wave", "raise"}, "wave-left-hand": {"wave", "raise"},
    "wave-right-hand": {"wave", "raise"}, "raise-up-both-hands": {"raise"}, "raise-up-left-hand": {"raise"},
    "raise-up-right-hand": {"raise"},
}


def test_every_training_caption_names_its_contents_actions_and_nothing_else():
    assert set(CONTENT_ACTIONS) == set(CONTENT_PHRASES)
    for content, expected in CONTENT_ACTIONS.items():
        named = set()
        for style in STYLE_PHRASES:
            for mirrored in (False, True):
                for caption in captions_for(content, style, mirrored) + extra_captions(content, style, None, mirrored):
                    assert actions_in(caption), caption  # no training caption is action-free
                    named |= actions_in(caption)
        assert named == expected, content
    for (content, _band), phrases in SPEED_PHRASES.items():
        for phrase in phrases:
            assert actions_in(SPEED_SENTENCES[0].format(vp=phrase)) == CONTENT_ACTIONS[content], phrase


def test_manner_phrases_name_no_action():
    """Styles say how ("with heavy, plodding movements", "with a youthful bounce"), never what."""
    assert [p for p in manner_phrases() if actions_in(p)] == []


@pytest.mark.parametrize(
    "text, actions",
    [
        ("Someone strolls ahead.", {"walk"}),
        ("A man saunters forward at a leisurely pace.", {"walk"}),
        ("A person ambles along and then strides on.", {"walk"}),
        ("Somebody heads forward on foot.", {"walk"}),
        ("A man jogs quickly forward.", {"run"}),
        ("Someone races ahead at top speed.", {"run"}),
        ("A woman lifts her left arm up high.", {"raise"}),
        ("Somebody holds the left hand up in the air.", {"raise"}),
        ("Someone reaches up high with their left hand.", {"raise"}),
        ("A person walks forward and reaches out with the right hand.", {"walk", "reach"}),
        ("A person kicks a ball.", {"kick"}),
        ("Somebody strikes out with the right foot.", {"kick"}),
        ("A person throws a left punch.", {"punch"}),
        ("A person throws a ball.", {"throw"}),
        ("A person picks the box up.", {"pick up"}),
        ("A person jumps up in place.", {"jump"}),
        ("A person sits down on a chair.", {"sit"}),
        ("A person DANCES.", {"dance"}),
        ("A person limps forward, leaning on a cane.", set()),  # how and where, not what: no action
        ("An elbow bends.", set()),  # word boundaries: not a bow
    ],
)
def test_actions_and_their_synonyms(text, actions):
    assert actions_in(text) == actions


def test_clips_are_counted_once_per_action():
    clips = [["A person walks.", "Someone strolls ahead."], ["A person walks and turns."], ["A person bows."]]
    assert clips_per_action(clips) == {"bow": 1, "turn": 1, "walk": 2}
    assert clips_per_action([]) == {} and "kick" in ACTION_WORDS
