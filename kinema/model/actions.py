"""Action words: which actions a prompt or a training caption names ("Someone strolls ahead." names 'walk').

Why: MiniLM embeddings place a prompt near captions of *another* action when the sentences share their
frame ("A person walks forward and reaches out with the right hand." is nearest to "A person walks forward
and turns to the right.", cosine 0.80), and near captions of a trained action when the asked one is not
learned ("A person kicks." 0.81 from a kick the model cannot make). Prompt grounding
(kinema.model.grounding) and the unknown-prompt warning (kinema.model.vocabulary) therefore compare the
*actions* of prompt and captions, not only their embeddings.

An action is a name and the word forms that say it, synonyms included (walk: walks, strolls, ambles,
saunters, strides, ...; run: runs, jogs, sprints, dashes, races). The actions the Bandai captions use
(kinema.data.captions / kinema.data.phrasings: walk, run, turn, bow, wave, raise, guide, call, kick, spin,
slash, dance) each match the captions of their content labels and nothing else: every training caption
names at least one action, and manner phrases ("with heavy, plodding movements", "with a youthful
bounce", "swaggering like a thug") name none (tests/test_actions.py). The others (punch, jump, sit,
crouch, reach, ...) are what users ask for and the captions lack: a prompt naming one is unknown to the
model. Words that only say how ("limps", "sneaks", "trudges" are not listed as walks) or where
("stands", "leans") name no action, so a prompt made only of them is grounded as before.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

# action -> regular expressions of its word forms (case-insensitive, matched between word boundaries)
ACTION_WORDS: dict[str, tuple[str, ...]] = {
    # the actions of the Bandai captions
    "walk": (r"walk(?:s|ed|ing)?", r"stroll(?:s|ed|ing)?", r"ambl(?:e|es|ed|ing)", r"saunter(?:s|ed|ing)?",
             r"strid(?:e|es|ing)", r"strode", r"march(?:es|ed|ing)?", r"wander(?:s|ed|ing)?",
             r"hik(?:e|es|ed|ing)", r"step(?:s|ped|ping)?", r"on foot"),
    "run": (r"run(?:s|ning)?", r"ran", r"jog(?:s|ged|ging)?", r"sprint(?:s|ed|ing)?", r"dash(?:es|ed|ing)?",
            r"rac(?:e|es|ed|ing)", r"bolt(?:s|ed|ing)?"),
    # walking backwards (walk-back): its own action so that the action expert, which walks backwards where
    # the main weights walk forward (issue 58), can serve it; "falls backward" is not one
    "walk back": (r"(?:walk|step|mov)(?:s|ed|ing|e|es|ped|ping)?(?: \w+ly)? back(?:ward|wards)?",
                  r"back(?:s|ed|ing) (?:up|away)", r"retreat(?:s|ed|ing)?", r"backpedal(?:s|led|ling|ed|ing)?",
                  r"in reverse"),
    "turn": (r"turn(?:s|ed|ing)?", r"veer(?:s|ed|ing)?", r"pivot(?:s|ed|ing)?", r"chang(?:e|es|ed|ing) direction"),
    "bow": (r"bow(?:s|ed|ing)?", r"curts(?:y|ies|ied|eys?)"),
    "wave": (r"wav(?:e|es|ed|ing)", r"flap(?:s|ped|ping)?(?: \w+){0,2} hands?"),
    "raise": (r"rais(?:e|es|ed|ing)", r"lift(?:s|ed|ing)?", r"hoist(?:s|ed|ing)?", r"reach(?:es|ed|ing)? up",
              r"(?:put|puts|putting|hold|holds|holding|held|stick|sticks|sticking)(?: \w+){1,3} up"),
    "guide": (r"guid(?:e|es|ed|ing)", r"gestur(?:e|es|ed|ing)", r"show(?:s|ed|ing)? the way", r"point(?:s|ed|ing)?",
              r"usher(?:s|ed|ing)?", r"direct(?:s|ed|ing)? someone"),
    "call": (r"call(?:s|ed|ing)?", r"shout(?:s|ed|ing)?", r"yell(?:s|ed|ing)?", r"hail(?:s|ed|ing)?",
             r"holler(?:s|ed|ing)?"),
    "kick": (r"kick(?:s|ed|ing)?",
             r"(?:strik(?:e|es|ing)|struck|lash(?:es|ed|ing)?) out with(?: \w+){0,2} (?:foot|leg)"),
    "spin": (r"spin(?:s|ning)?", r"spun", r"twirl(?:s|ed|ing)?", r"whirl(?:s|ed|ing)?", r"pirouett(?:e|es|ed|ing)"),
    "slash": (r"slash(?:es|ed|ing)?", r"swords?", r"blades?", r"chop(?:s|ped|ping)?"),
    "dance": (r"danc(?:e|es|ed|ing)", r"groov(?:e|es|ed|ing)", r"waltz(?:es|ed|ing)?", r"tango(?:s|ed|ing)?",
              r"ballet", r"boogie(?:s|d)?", r"salsa"),
    # what users ask for and the Bandai captions lack
    "punch": (r"punch(?:es|ed|ing)?", r"jab(?:s|bed|bing)?", r"uppercuts?", r"box(?:es|ing)? with"),
    "jump": (r"jump(?:s|ed|ing)?", r"hop(?:s|ped|ping)?", r"leap(?:s|ed|t|ing)?", r"skip(?:s|ped|ping)?"),
    "sit": (r"sit(?:s|ting)?", r"sat", r"seated"),
    "get up": (r"(?:stand|stands|standing|stood|get|gets|getting|got) up",),
    "crouch": (r"crouch(?:es|ed|ing)?", r"squat(?:s|ted|ting)?", r"kneel(?:s|ed|ing)?", r"knelt",
               r"duck(?:s|ed|ing)?"),
    "lie down": (r"(?:lie|lies|lying|lay|lays|laying) down",),
    "reach": (r"reach(?:es|ed|ing)?(?! up\b)",),
    "crawl": (r"crawl(?:s|ed|ing)?",),
    "climb": (r"climb(?:s|ed|ing)?",),
    "swim": (r"swim(?:s|ming)?", r"swam"),
    "roll": (r"roll(?:s|ed|ing)?", r"somersault(?:s|ed|ing)?", r"cartwheel(?:s|ed|ing)?", r"(?:back)?flip(?:s|ped)?"),
    "fall": (r"fall(?:s|ing|en)?", r"fell", r"stumbl(?:e|es|ed|ing)", r"trip(?:s|ped|ping)?",
             r"collaps(?:e|es|ed|ing)", r"toppl(?:e|es|ed|ing)"),
    "throw": (r"(?:throw|throws|throwing|threw|toss|tosses|tossed)(?!(?: \w+){0,3} (?:punch|jab))",),
    "catch": (r"catch(?:es|ing)?", r"caught"),
    "pick up": (r"pick(?:s|ed|ing)?(?: \w+){0,3} up",),
    "carry": (r"carr(?:y|ies|ied|ying)",),
    "push": (r"push(?:es|ed|ing)?",),
    "pull": (r"pull(?:s|ed|ing)?",),
    "clap": (r"clap(?:s|ped|ping)?", r"applaud(?:s|ed|ing)?"),
    "nod": (r"nod(?:s|ded|ding)?", r"shak(?:e|es|ing|ook) (?:\w+ )?head"),
    "salute": (r"salut(?:e|es|ed|ing)",),
    "stretch": (r"stretch(?:es|ed|ing)?",),
    "hug": (r"hug(?:s|ged|ging)?", r"embrac(?:e|es|ed|ing)"),
    "fight": (r"fight(?:s|ing)?", r"fought"),
}

_PATTERNS = {a: re.compile(r"\b(?:" + "|".join(forms) + r")\b", re.IGNORECASE) for a, forms in ACTION_WORDS.items()}

#: per action, the word its one-word synonyms become in :func:`reworded` (the form captions use)
ACTION_VERBS: dict[str, str] = {
    "walk": "walks", "walk back": "walks back", "run": "runs", "turn": "turns", "bow": "bows", "wave": "waves",
    "raise": "raises",
    "guide": "guides", "call": "calls", "kick": "kicks", "spin": "spins", "slash": "slashes", "dance": "dances",
    "punch": "punches", "jump": "jumps", "sit": "sits", "get up": "gets up", "crouch": "crouches",
    "lie down": "lies down", "reach": "reaches", "crawl": "crawls", "climb": "climbs", "swim": "swims",
    "roll": "rolls", "fall": "falls", "throw": "throws", "catch": "catches", "pick up": "picks up",
    "carry": "carries", "push": "pushes", "pull": "pulls", "clap": "claps", "nod": "nods", "salute": "salutes",
    "stretch": "stretches", "hug": "hugs", "fight": "fights",
}


def actions_in(text: str) -> frozenset[str]:
    """The actions ``text`` names (keys of :data:`ACTION_WORDS`); empty when it names none."""
    return frozenset(a for a, pattern in _PATTERNS.items() if pattern.search(text))


def clips_per_action(clip_captions: Iterable[Iterable[str]]) -> dict[str, int]:
    """Per action, the number of clips (each given as its captions) with at least one caption naming it."""
    counts: dict[str, int] = {}
    for captions in clip_captions:
        for action in frozenset().union(*(actions_in(c) for c in captions)):
            counts[action] = counts.get(action, 0) + 1
    return dict(sorted(counts.items()))


def reworded(text: str) -> str:
    """``text`` with every one-word form of an action replaced by that action's verb (:data:`ACTION_VERBS`):
    "Someone jabs with the left hand." -> "Someone punches with the left hand.".

    Why: the unknown-prompt threshold and grounding compare sentence embeddings, and MiniLM puts a synonym
    the action words list far from the captions' own verb ("Someone jabs with the left hand." is 0.63 from
    "A person punches with their left hand.", under the 0.70 threshold, though 'jab' is listed as a punch).
    Only a fallback for prompts that are otherwise unknown (kinema.model.vocabulary, kinema.model.grounding):
    a prompt near enough to the captions in its own words keeps them ("jogs" is not made "runs").
    Multi-word forms ("puts both hands up") are left as written."""
    out = text
    for action, pattern in _PATTERNS.items():
        out = pattern.sub(lambda m, v=ACTION_VERBS[action]: m.group(0) if " " in m.group(0) else v, out)
    return out
