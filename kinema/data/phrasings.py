"""More ways to say a clip: speed words grounded in the measured clip, and held-out phrasings.

Why: the six template captions of `kinema.data.captions` name *what* is done with three verb
phrases per label, so a model trained on them follows the templates but not the user's own words
(issue 18: "Someone strolls slowly ahead." and "A person sprints as fast as possible." both came
out at 2.2 m/s). Two additions, both deterministic:

- **Speed captions** (training): for walk / run / dash clips the clip's mean ground speed of the
  pelvis (m/s, start to end) picks a speed band, and the band's phrases become extra captions
  ("walks slowly ahead", "runs at an easy pace", "runs at high speed"). The bands are quantiles of
  the Bandai captures themselves (walk 0.37-1.87 m/s, median 1.2; run 1.27-3.60, median 2.6;
  dash 2.44-4.09, median 3.1): the slowest ~20 % of walks are "slow", the fastest ~20 % "fast".
- **Held-out phrasings** (evaluation only): other verbs and sentence shapes for every content
  label, and `PROBES`, prompts in a user's words with a measurable expectation (speed order, which
  hand goes up). None of their verb phrases occurs in a training caption (tested), so text
  following is measured on words the model never saw with motion.
"""

from __future__ import annotations

from dataclasses import dataclass

from kinema.data.captions import CONTENT_PHRASES, mirror_content, style_phrases
from kinema.model.sides import mirror_caption

# (slow below, fast above) m/s of mean pelvis ground speed, per locomotion content.
SPEED_BANDS: dict[str, tuple[float, float]] = {"walk": (0.95, 1.40), "run": (2.10, 3.00), "dash": (0.0, 0.0)}

SPEED_PHRASES: dict[tuple[str, str], tuple[str, ...]] = {
    ("walk", "slow"): ("walks forward slowly", "walks slowly ahead", "walks forward at a slow, leisurely pace"),
    ("walk", "medium"): ("walks forward at a normal pace", "walks ahead at an everyday pace"),
    ("walk", "fast"): ("walks forward quickly", "walks briskly ahead", "walks forward at a fast pace"),
    ("run", "slow"): ("runs forward slowly", "runs ahead at an easy pace", "runs forward at a gentle pace"),
    ("run", "medium"): ("runs forward at a steady pace", "runs ahead at a moderate speed"),
    ("run", "fast"): ("runs forward fast", "runs ahead quickly", "runs forward at high speed"),
    ("dash", "fast"): ("runs forward at full speed", "sprints ahead very fast", "runs flat out"),
}

SPEED_SENTENCES = ("A person {vp}.", "Someone {vp}.")

# The words of SPEED_PHRASES (and of the extra dash caption) that say how fast: every speed phrase holds
# one (tested). With the styles' phrases they are the captions' manner phrases (:func:`manner_phrases`).
SPEED_MANNERS: tuple[str, ...] = (
    "slowly", "at a slow, leisurely pace", "at an easy pace", "at a gentle pace", "at a normal pace",
    "at an everyday pace", "quickly", "briskly", "at a fast pace", "at a steady pace", "at a moderate speed",
    "fast", "at high speed", "at full speed", "very fast", "flat out", "at top speed",
)


# More training verb phrases for the labels users ask for most (subject "A person"/"Someone").
EXTRA_PHRASES: dict[str, tuple[str, ...]] = {
    "walk": ("walks ahead", "takes a walk forward"),
    "run": ("runs ahead", "breaks into a run forward"),
    "dash": ("dashes ahead at top speed",),
    "bow": ("bows deeply", "bends forward in a deep bow"),
    "raise-up-left-hand": ("raises their left hand above their head", "reaches up high with their left hand"),
    "raise-up-both-hands": ("raises both hands above their head",),
    "wave-left-hand": ("waves hello with their left hand",),
    "respond": ("raises their left hand high",),
    "bye": ("waves bye with their right hand",),
    "walk-back": ("walks backward",),
    "walk-left": ("walks leftward",),
}
for _label in [k for k in EXTRA_PHRASES if "left" in k.split("-")]:
    EXTRA_PHRASES[mirror_content(_label)] = tuple(mirror_caption(p) for p in EXTRA_PHRASES[_label])


def manner_phrases() -> tuple[str, ...]:
    """Phrases that say *how* something is done in the training captions: the styles' (except the neutral
    one's; kinema.data.captions.style_phrases) and the speed words. Saved with a model's known prompts so
    that prompt grounding keeps a prompt that names no manner off captions that name one."""
    return tuple(sorted(set(style_phrases()) | set(SPEED_MANNERS)))


def extra_captions(content: str, style: str, speed: float | None, mirrored: bool = False) -> list[str]:
    """Captions added after the template ones: extra verb phrases, then the measured speed's words.

    ``content``/``style`` are the source clip's labels; ``mirrored`` swaps sides as
    `kinema.data.captions.captions_for` does. The style is not named (the templates do that)."""
    del style  # the extra captions say what and how fast, not how
    vps = EXTRA_PHRASES.get(content, ())
    out = [SPEED_SENTENCES[i % len(SPEED_SENTENCES)].format(vp=vp) for i, vp in enumerate(vps)]
    out += speed_captions(content, speed)
    return [mirror_caption(c) for c in out] if mirrored else out


def speed_band(content: str, speed: float) -> str | None:
    """'slow', 'medium' or 'fast' for a walk/run/dash clip moving at ``speed`` m/s, else None."""
    if content not in SPEED_BANDS:
        return None
    if content == "dash":
        return "fast"
    slow, fast = SPEED_BANDS[content]
    return "slow" if speed < slow else "fast" if speed > fast else "medium"


def speed_captions(content: str, speed: float | None) -> list[str]:
    """Extra captions naming the clip's speed (empty for non-locomotion or unknown speed)."""
    band = None if speed is None else speed_band(content, speed)
    if band is None:
        return []
    vps = SPEED_PHRASES[(content, band)]
    return [SPEED_SENTENCES[i % len(SPEED_SENTENCES)].format(vp=vp) for i, vp in enumerate(vps)]


# Held-out verb phrases: evaluation only, never in training captions (tests/test_phrasings.py).
HELDOUT_PHRASES: dict[str, tuple[str, ...]] = {
    "walk": ("goes for a walk straight ahead", "heads forward on foot"),
    "run": ("jogs ahead", "goes for a run straight ahead"),
    "dash": ("races ahead as fast as possible", "bolts forward at top speed"),
    "walk-back": ("backs up step by step", "retreats backwards on foot"),
    "walk-left": ("heads off to the left on foot", "wanders toward the left"),
    "bow": ("bends over in a polite bow", "gives a respectful bow"),
    "bye": ("bids farewell with a wave of the right hand", "lifts the right hand to say farewell"),
    "byebye": ("bids farewell waving both hands", "lifts both hands to say farewell"),
    "guide": ("points the way with the right arm", "directs someone with the right arm"),
    "respond": ("lifts the left hand high in answer", "answers with the left hand held high"),
    "call": ("shouts to get someone's attention", "hails someone loudly"),
    "punch": ("boxes with the fists", "jabs with the fists"),
    "kick": ("strikes out with the right foot", "lashes out with the right leg"),
    "slash": ("chops downward with a two-handed sword", "cuts the air with a two-handed blade"),
    "dance-long": ("busts out a long series of dance moves", "grooves to the music for a long while"),
    "dance-short": ("busts out a few dance moves", "grooves to the music"),
    "walk-turn-left": ("changes direction to the left while strolling", "veers left in the middle of a walk"),
    "wave-both-hands": ("flaps both hands in greeting", "greets someone with both hands"),
    "wave-left-hand": ("greets someone with the left hand", "flaps the left hand in greeting"),
    "raise-up-both-hands": ("lifts both arms into the air", "holds both arms up high"),
    "raise-up-left-hand": ("lifts the left arm up high", "holds the left hand up in the air"),
}
for _label in [k for k in HELDOUT_PHRASES if "left" in k.split("-")]:
    HELDOUT_PHRASES[mirror_content(_label)] = tuple(mirror_caption(p) for p in HELDOUT_PHRASES[_label])
assert set(HELDOUT_PHRASES) == set(CONTENT_PHRASES), "every content label needs held-out phrasings"

HELDOUT_SUBJECTS = ("Somebody", "A character", "An individual")


def heldout_captions(content: str, mirrored: bool = False) -> list[str]:
    """Held-out captions of a content label (what, not how: styles are left to the template captions)."""
    label = mirror_content(content) if mirrored else content
    phrases = HELDOUT_PHRASES[label]
    return [f"{HELDOUT_SUBJECTS[i % len(HELDOUT_SUBJECTS)]} {vp}." for i, vp in enumerate(phrases)]


@dataclass(frozen=True)
class Probe:
    """A prompt in a user's words and what a motion following it must show.

    ``kind`` is 'speed' (``group`` orders the prompts: slow walk < walk < jog < sprint) or 'hand'
    (``group`` is the hand that must rise above the head: 'left' or 'right')."""

    prompt: str
    kind: str
    group: str


PROBES: tuple[Probe, ...] = (
    Probe("Someone strolls slowly ahead.", "speed", "1 slow walk"),
    Probe("A person ambles along slowly.", "speed", "1 slow walk"),
    Probe("A man saunters forward at a leisurely pace.", "speed", "1 slow walk"),
    Probe("Somebody heads forward on foot.", "speed", "2 walk"),
    Probe("A woman goes for a walk straight ahead.", "speed", "2 walk"),
    Probe("A man jogs quickly forward.", "speed", "3 jog"),
    Probe("Somebody jogs ahead.", "speed", "3 jog"),
    Probe("A person sprints as fast as possible.", "speed", "4 sprint"),
    Probe("Someone races ahead at top speed.", "speed", "4 sprint"),
    Probe("A woman lifts her left arm up high.", "hand", "left"),
    Probe("Somebody holds the left hand up in the air.", "hand", "left"),
    Probe("A man lifts his right arm up high.", "hand", "right"),
    Probe("A character holds the right hand up in the air.", "hand", "right"),
)
