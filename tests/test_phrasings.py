"""Training phrasings and held-out phrasings (kinema.data.phrasings): held-out words never reach training."""

from __future__ import annotations

import re

import pytest

from kinema.data.captions import CONTENT_PHRASES, STYLE_PHRASES, captions_for, mirror_content
from kinema.data.phrasings import (
    EXTRA_PHRASES,
    HELDOUT_PHRASES,
    PROBES,
    SPEED_BANDS,
    SPEED_PHRASES,
    extra_captions,
    heldout_captions,
    speed_band,
    speed_captions,
)

#: speeds (m/s) that fall in every band of walk, run and dash, plus "not measured"
SPEEDS = (None, 0.3, 0.9, 1.2, 1.6, 2.0, 2.5, 3.2, 4.0)
SUBJECT = re.compile(r"^(?:(?:A|An)\s+\w+|\w+)\s+")


def _training_captions() -> set[str]:
    """Every caption `kinema data build` can write: templates and extra captions, both sides, all speeds."""
    out: set[str] = set()
    for content in CONTENT_PHRASES:
        for style in STYLE_PHRASES:
            for mirrored in (False, True):
                out.update(captions_for(content, style, mirrored=mirrored))
                for speed in SPEEDS:
                    out.update(extra_captions(content, style, speed, mirrored=mirrored))
    return {c.lower() for c in out}


def _predicate(prompt: str) -> str:
    """The words after the subject, without the final period ("Someone jogs ahead." -> "jogs ahead")."""
    return SUBJECT.sub("", prompt).rstrip(".").lower()


@pytest.fixture(scope="module")
def training() -> set[str]:
    return _training_captions()


def test_training_captions_include_the_extra_and_speed_phrases(training):
    # the check below is only meaningful if the extra captions are part of the training set it scans
    assert "a person walks forward slowly." in training and "someone sprints ahead very fast." in training
    assert "a person raises their right hand above their head." in training  # a mirrored extra phrase


def test_no_heldout_phrase_or_probe_occurs_in_training_captions(training):
    phrases = {vp.lower() for vps in HELDOUT_PHRASES.values() for vp in vps}
    phrases |= {_predicate(p.prompt) for p in PROBES} | {p.prompt.rstrip(".").lower() for p in PROBES}
    leaks = sorted((p, c) for p in phrases for c in training if p in c)
    assert not leaks, leaks[:5]


def test_heldout_captions_cover_every_content_label_and_swap_sides():
    assert set(HELDOUT_PHRASES) == set(CONTENT_PHRASES)
    for content in CONTENT_PHRASES:
        caps = heldout_captions(content)
        assert len(caps) >= 2 and len(set(caps)) == len(caps), content
        for text in caps:
            assert re.match(r"^(Somebody|A character|An individual) [a-z]", text) and text.endswith("."), text
            assert text.count(".") == 1 and "{" not in text, text
        assert heldout_captions(content, mirrored=True) == heldout_captions(mirror_content(content))
        side = next((s for s in ("left", "right") if s in content.split("-")), None)
        if side is not None:
            other = "right" if side == "left" else "left"
            assert all(side in c and other not in c for c in caps), caps
            assert all(other in c and side not in c for c in heldout_captions(content, mirrored=True))
    with pytest.raises(KeyError):
        heldout_captions("juggle")


@pytest.mark.parametrize(
    ("content", "speed", "band"),
    [
        ("walk", 0.5, "slow"),
        ("walk", 1.2, "medium"),
        ("walk", 1.7, "fast"),
        ("run", 1.5, "slow"),
        ("run", 2.6, "medium"),
        ("run", 3.4, "fast"),
        ("dash", 1.0, "fast"),
        ("dash", 4.0, "fast"),
        ("bow", 1.2, None),
        ("walk-back", 1.2, None),
    ],
)
def test_speed_band(content, speed, band):
    assert speed_band(content, speed) == band
    caps = speed_captions(content, speed)
    if band is None:
        assert caps == []
    else:
        assert [re.sub(r"^(A person|Someone) ", "", c).rstrip(".") for c in caps] == list(
            SPEED_PHRASES[(content, band)]
        )


def test_speed_band_edges_follow_the_thresholds():
    for content, (slow, fast) in SPEED_BANDS.items():
        if content == "dash":
            continue
        assert speed_band(content, slow - 1e-6) == "slow" and speed_band(content, slow) == "medium"
        assert speed_band(content, fast) == "medium" and speed_band(content, fast + 1e-6) == "fast"
    assert speed_captions("walk", None) == []


def test_extra_captions_order_and_mirroring():
    caps = extra_captions("walk", "normal", 0.5)
    n = len(EXTRA_PHRASES["walk"])
    assert caps[n:] == speed_captions("walk", 0.5) and "slowly" in caps[n]
    assert extra_captions("walk", "sad", 0.5) == caps  # the style is not named
    assert extra_captions("bow", "normal", 3.0) == ["A person bows deeply.", "Someone bends forward in a deep bow."]
    for content in ("raise-up-left-hand", "wave-left-hand", "respond", "bye", "walk-left"):
        plain = extra_captions(content, "normal", None)
        mirrored = extra_captions(content, "normal", None, mirrored=True)
        assert plain and len(plain) == len(mirrored)
        for a, b in zip(plain, mirrored, strict=True):
            side = "left" if "left" in a else "right"
            other = "right" if side == "left" else "left"
            assert side in a and other not in a and other in b and side not in b, (a, b)
        if mirror_content(content) != content:  # a sided label: its mirror is the other side's label
            assert mirrored == extra_captions(mirror_content(content), "normal", None)


def test_probes_are_well_formed():
    groups = {p.kind: set() for p in PROBES}
    for p in PROBES:
        groups[p.kind].add(p.group)
        assert p.prompt.endswith(".") and p.prompt[0].isupper()
    assert groups == {"speed": {"1 slow walk", "2 walk", "3 jog", "4 sprint"}, "hand": {"left", "right"}}
    for p in PROBES:
        if p.kind == "hand":
            other = "right" if p.group == "left" else "left"
            assert p.group in p.prompt and other not in p.prompt


def test_every_speed_phrase_names_a_speed_manner():
    from kinema.data.phrasings import SPEED_MANNERS, manner_phrases

    for vp in [vp for vps in SPEED_PHRASES.values() for vp in vps] + list(EXTRA_PHRASES["dash"]):
        assert any(re.search(rf"\b{re.escape(m)}\b", vp) for m in SPEED_MANNERS), vp
    assert set(SPEED_MANNERS) < set(manner_phrases()) and "wearily" in manner_phrases()
    # the plain verb phrases of walks and runs name no manner: grounding may put a plain prompt on them
    for vp in EXTRA_PHRASES["walk"] + EXTRA_PHRASES["run"]:
        assert not any(re.search(rf"\b{re.escape(m)}\b", vp) for m in manner_phrases()), vp
