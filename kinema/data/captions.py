"""English captions for Bandai Namco clips, built from their (content, style) labels.

The Bandai Namco motion datasets label every clip with a *content* (what is done) and a *style*
(how it is done) but carry no text. To train and evaluate a text-conditioned model we turn each
label pair into several short, grammatical sentences in the style of Kimodo's prompts: each one
opens with its subject ("A person", "Someone", "A tired person", "A woman", ...), is in the
present tense and ends with a period. Several phrasings per clip keep the text encoder from
latching onto one fixed string; all of them are deterministic, so caches and tests are stable.

What each label means (from the dataset READMEs plus a look at the motion itself: sides are
the character's own, taken from the `_L`/`_R` joints, which agree with e.g. `wave-left-hand`):

=================== ============================================================================
content             reading used here
=================== ============================================================================
walk, run, dash     straight-line locomotion forward; dash is a full-speed sprint.
walk-back           walks backwards while still facing forward.
walk-left / -right  walks off towards the character's left / right. Not a pure sidestep: the
                    body turns most of the way (about 45-75 degrees) towards the travel direction.
bow                 bends forward from the waist in a bow, standing in place.
bye                 waves goodbye with the right hand only (the left arm stays down).
byebye              waves goodbye with both hands raised.
guide               extends the right arm to show someone the way (usher-like gesture).
respond             raises the left hand high, as when answering "yes" or "here".
call                leans forward and calls out to someone (the two takes differ in hand use,
                    so no hand is named).
punch               throws punches (no clip of it is published, so no side is named).
kick                from a fighting stance, kicks with the right leg and spins round with it.
slash               overhead sword strikes with both hands on the hilt.
dance-long/-short   a dance routine with many spins (dance-long has no published motion).
walk-turn-left/-r.  walks forward, then turns about 90 degrees to the left / right.
wave-*-hand(s)      waves the named hand (or both) in place.
raise-up-*-hand(s)  raises the named hand (or both) in place.
=================== ============================================================================

Styles: normal, happy, sad, angry, proud, not-confident (timid), masculinity/masculine (a man),
feminine (a woman), childish (child-like; the README calls it "children"), old/elderly, tired/
exhausted, active (energetic), musical (theatrical, like a stage musical), giant (huge and
heavy), chimpira (Japanese slang for a small-time thug: a punk's swagger), youthful (young and
lively). Style phrases never name a side, so mirroring only ever touches the content part.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from kinema.errors import DataError
from kinema.model.sides import mirror_caption

# --------------------------------------------------------------------------------------------
# Content -> verb phrases (present tense, third person). "{their}" becomes his/her/their to
# agree with the subject. Right-hand variants are generated from the left ones further below.
# --------------------------------------------------------------------------------------------
CONTENT_PHRASES: dict[str, tuple[str, ...]] = {
    "walk": ("walks forward", "walks straight ahead", "walks forward in a straight line"),
    "run": ("runs forward", "runs straight ahead", "runs forward in a straight line"),
    "dash": ("dashes forward", "sprints forward", "sprints straight ahead at full speed"),
    "walk-back": ("walks backwards", "walks backward while facing forward", "steps backwards"),
    "walk-left": ("walks to the left", "walks off toward the left", "walks over to the left"),
    "bow": ("bows", "bows forward from the waist", "takes a bow"),
    "bye": (
        "waves goodbye with {their} right hand",
        "says goodbye with a wave of {their} right hand",
        "raises {their} right hand and waves goodbye",
    ),
    "byebye": (
        "waves goodbye with both hands",
        "waves both hands to say bye-bye",
        "raises both hands and waves goodbye",
    ),
    "guide": (
        "gestures with {their} right hand to show the way",
        "extends {their} right arm to guide someone",
        "shows the way with {their} right hand",
    ),
    "respond": (
        "raises {their} left hand to answer",
        "responds by raising {their} left hand",
        "puts {their} left hand up high in reply",
    ),
    "call": (
        "calls out to someone",
        "leans forward and calls out to someone",
        "calls out loudly to get someone's attention",
    ),
    "punch": ("throws punches", "punches forward", "throws a series of punches"),
    "kick": (
        "kicks with {their} right leg",
        "does a roundhouse kick with {their} right leg",
        "kicks with {their} right leg and spins all the way around",
    ),
    "slash": (
        "swings a sword down with both hands",
        "slashes with a sword held in both hands",
        "makes overhead sword strikes with both hands",
    ),
    "dance-long": ("dances", "performs a long dance routine", "dances for a long time"),
    "dance-short": ("dances", "performs a short dance routine", "dances and spins around"),
    "walk-turn-left": (
        "turns left while walking",
        "walks forward and turns to the left",
        "makes a left turn while walking",
    ),
    "wave-both-hands": ("waves both hands", "waves with both hands", "raises both hands and waves them"),
    "wave-left-hand": (
        "waves with {their} left hand",
        "waves {their} left hand",
        "raises {their} left hand and waves",
    ),
    "raise-up-both-hands": ("raises both hands", "raises both arms up", "puts both hands up"),
    "raise-up-left-hand": (
        "raises {their} left hand",
        "raises {their} left arm up",
        "puts {their} left hand up",
    ),
}


@dataclass(frozen=True)
class StyleWords:
    """How one style is said: sentence subjects, phrases after the verb, clauses after a comma."""

    subjects: tuple[str, ...]
    manners: tuple[str, ...]
    clauses: tuple[str, ...]


# --------------------------------------------------------------------------------------------
# Style -> subjects / manner phrases / participle clauses. Gendered subjects ("A man", "A woman")
# appear only for the masculine and feminine styles.
# --------------------------------------------------------------------------------------------
STYLE_PHRASES: dict[str, StyleWords] = {
    "normal": StyleWords(
        ("A person", "Someone"),
        ("in a calm, natural way", "in a neutral way", "in an ordinary way"),
        ("looking calm", "showing no particular emotion"),
    ),
    "happy": StyleWords(
        ("A happy person", "A cheerful person"),
        ("happily", "in a joyful mood", "cheerfully"),
        ("looking happy", "full of joy"),
    ),
    "sad": StyleWords(
        ("A sad person", "A gloomy person"),
        ("sadly", "with a heavy heart", "gloomily"),
        ("looking sad", "looking downcast"),
    ),
    "angry": StyleWords(
        ("An angry person", "A furious person"),
        ("angrily", "in a fit of anger", "furiously"),
        ("looking angry", "clearly annoyed"),
    ),
    "proud": StyleWords(
        ("A proud person", "A self-assured person"),
        ("proudly", "in a proud manner", "with {their} chest puffed out"),
        ("looking proud", "full of pride"),
    ),
    "not-confident": StyleWords(
        ("A timid person", "An insecure person"),
        ("timidly", "hesitantly", "without any confidence"),
        ("looking unsure", "lacking confidence"),
    ),
    "masculinity": StyleWords(
        ("A man",),
        ("in a masculine way", "with a manly swagger", "in a strong, masculine manner"),
        ("moving in a masculine way", "with a masculine air"),
    ),
    "feminine": StyleWords(
        ("A woman", "A graceful woman"),
        ("in a feminine way", "in a soft, feminine manner", "with feminine grace"),
        ("moving in a feminine way", "with a feminine air"),
    ),
    "childish": StyleWords(
        ("A child-like person", "A childish person"),
        ("in a childish way", "playfully, like a small child", "like a little kid"),
        ("acting like a child", "full of childish energy"),
    ),
    "old": StyleWords(
        ("An elderly person", "An old person"),
        ("slowly and stiffly", "with the frail movements of old age", "in an elderly way"),
        ("moving like an old person", "stiff with age"),
    ),
    "tired": StyleWords(
        ("A tired person", "A weary person"),
        ("wearily", "sluggishly", "with tired, heavy movements"),
        ("looking exhausted", "worn out"),
    ),
    "active": StyleWords(
        ("An energetic person", "A lively person"),
        ("energetically", "actively", "with lots of energy"),
        ("full of energy", "looking lively"),
    ),
    "musical": StyleWords(
        ("A theatrical performer", "A stage performer"),
        ("theatrically", "with exaggerated, showy movements", "like a performer in a musical"),
        ("as if performing in a musical", "moving with theatrical flair"),
    ),
    "giant": StyleWords(
        ("A giant", "A huge, lumbering person"),
        ("like a giant", "in a big, heavy way", "with heavy, plodding movements"),
        ("moving like a giant", "lumbering heavily"),
    ),
    "chimpira": StyleWords(
        ("A street punk", "A small-time thug"),
        ("like a thug", "with a cocky swagger", "like a small-time punk"),
        ("acting tough like a street punk", "swaggering like a thug"),
    ),
    "elderly": StyleWords(
        ("An elderly person", "An old person"),
        ("slowly, like an elderly person", "with the stiff movements of old age", "slowly and carefully"),
        ("moving like an elderly person", "showing {their} age"),
    ),
    "exhausted": StyleWords(
        ("An exhausted person", "A worn-out person"),
        ("wearily", "with exhausted, heavy movements", "as if completely drained"),
        ("looking exhausted", "out of energy"),
    ),
    "masculine": StyleWords(
        ("A man",),
        ("in a masculine way", "with a manly swagger", "in a strong, masculine manner"),
        ("moving in a masculine way", "with a masculine air"),
    ),
    "youthful": StyleWords(
        ("A young person", "A spirited young person"),
        ("with youthful energy", "in a lively, youthful way", "with a youthful bounce"),
        ("full of youthful energy", "looking young and lively"),
    ),
}

# Sentence shapes. Each placeholder takes the next entry of its list (cyclically), so the six
# captions of a clip mix different verb phrases, subjects and manner phrases.
TEMPLATES: tuple[str, ...] = (
    "A person {vp} {manner}.",
    "{subject} {vp}.",
    "Someone {vp}, {clause}.",
    "{subject} {vp} {manner}.",
    "A person {vp}, {clause}.",
    "Someone {vp} {manner}.",
)

# Possessive that agrees with a subject; anything not listed is singular "their".
_POSSESSIVE = {"A man": "his", "A woman": "her", "A graceful woman": "her"}

_LABEL_PREFIX = re.compile(r"^dataset-\d+_")


def mirror_content(content: str) -> str:
    """Content label of the left/right mirrored motion (`walk-left` <-> `walk-right`, ...)."""
    swap = {"left": "right", "right": "left"}
    return "-".join(swap.get(part, part) for part in content.split("-"))


# Right-side contents are the exact mirror of the left ones, so both sides read alike.
for _label in [k for k in CONTENT_PHRASES if "left" in k.split("-")]:
    CONTENT_PHRASES[mirror_content(_label)] = tuple(mirror_caption(p) for p in CONTENT_PHRASES[_label])


def _compose(vps: tuple[str, ...], words: StyleWords) -> list[str]:
    """Fill TEMPLATES with cycling phrases; drop repeats but keep the first order."""
    pools = {"vp": vps, "subject": words.subjects, "manner": words.manners, "clause": words.clauses}
    used = dict.fromkeys(pools, 0)
    out: list[str] = []
    for template in TEMPLATES:
        fill = {}
        for key in pools:
            if "{" + key + "}" in template:
                fill[key] = pools[key][used[key] % len(pools[key])]
                used[key] += 1
        sentence = template.format(**fill)
        subject = fill.get("subject", sentence.split(" ")[0])
        sentence = sentence.replace("{their}", _POSSESSIVE.get(subject, "their"))
        if sentence not in out:
            out.append(sentence)
    return out


def style_phrases(neutral: tuple[str, ...] = ("normal",)) -> tuple[str, ...]:
    """Every phrase that names a manner in these captions (subjects other than "A person" / "Someone",
    manner phrases, clauses; each possessive spelled out), except the ``neutral`` styles' own: a caption
    with none of them says what is done and not how (kinema.model.grounding grounds a prompt that names
    no manner only on such captions)."""
    out: set[str] = set()
    for style, words in STYLE_PHRASES.items():
        if style in neutral:
            continue
        out.update(s for s in words.subjects if s not in ("A person", "Someone"))
        for phrase in words.manners + words.clauses:
            out.update(phrase.replace("{their}", p) for p in ("their", "his", "her"))
    return tuple(sorted(out))


def captions_for(content: str, style: str, mirrored: bool = False) -> list[str]:
    """Deterministic English captions for one clip's (content, style) labels.

    With `mirrored=True` the captions describe the left/right mirrored motion: every side word
    is swapped, which equals `captions_for(mirror_content(content), style)` for labels naming a
    side and also fixes sides implied by the label (`bye` is done with the right hand).
    Raises `DataError` naming the label when content or style is unknown.
    """
    if content not in CONTENT_PHRASES:
        raise DataError(f"unknown content label {content!r}; known: {', '.join(sorted(CONTENT_PHRASES))}")
    if style not in STYLE_PHRASES:
        raise DataError(f"unknown style label {style!r}; known: {', '.join(sorted(STYLE_PHRASES))}")
    captions = _compose(CONTENT_PHRASES[content], STYLE_PHRASES[style])
    if mirrored:
        captions = [mirror_caption(c) for c in captions]
    return captions


def _read_label_file(path: Path) -> list[str]:
    """Bare labels from one cfg file (one `dataset-N_<label>` per line)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise DataError(f"{path.name}: cannot read label file {path}: {exc.strerror or exc}") from exc
    labels: list[str] = []
    for number, line in enumerate(text.splitlines(), start=1):
        raw = line.strip()
        if not raw:
            continue
        if not _LABEL_PREFIX.match(raw):
            raise DataError(f"{path.name}:{number}: expected 'dataset-N_<label>', got {raw!r}")
        label = _LABEL_PREFIX.sub("", raw)
        if not label or "_" in label or label in labels:
            raise DataError(f"{path.name}:{number}: bad or repeated label {raw!r}")
        labels.append(label)
    if not labels:
        raise DataError(f"{path.name}: label file {path} is empty")
    return labels


def load_labels(dataset_dir: Path) -> tuple[list[str], list[str]]:
    """(content labels, style labels) of one dataset directory, in file order (= JSON indices).

    `dataset_dir` is e.g. `.../Bandai-Namco-Research-Motiondataset-2`, holding
    `cfg/content_label.txt` and `cfg/style_label.txt`; the `dataset-N_` prefixes are stripped.
    """
    cfg = Path(dataset_dir) / "cfg"
    return _read_label_file(cfg / "content_label.txt"), _read_label_file(cfg / "style_label.txt")
