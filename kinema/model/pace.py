"""Pace words: how fast a prompt or a training caption travels ("strolls" < "walks" < "jogs" < "runs" < "sprints").

Why (issue 57): grounding chose captions by embedding, sides, directions, manner and actions, and all of
those treat "jogs" as a run and "strolls" as a walk. "Someone jogs forward." names no manner phrase, so it
was grounded on the nearest caption that names none: "A person sprints forward." (a dash, 2.6-4 m/s in
the captures); "A woman strolls along at her leisure." on a plain walk. The speed words the captions do
carry (kinema.data.phrasings: a walk or run clip's measured speed band, "walks slowly ahead", "runs ahead
at an easy pace", "runs flat out") were never reached by the words users type. Here a text's *pace* is
read from its words, and grounding (kinema.model.grounding) keeps a prompt on captions of its own pace:

=========== =================================================================== ==========================
pace        a prompt says it with                                              a caption says it with
=========== =================================================================== ==========================
stroll      stroll, amble, saunter, mosey, leisurely, unhurried; a walk + slow  a walk + a slow speed word
jog         jog; a run + slow / easy / gentle / relaxed                         a run + a slow speed word
sprint      sprint, dash, race, bolt; full / top speed, flat out, as fast as    the dash captions
=========== =================================================================== ==========================

Anything else has no pace (None): "walks", "runs", "runs fast" (a run's fast band is still a run).
"""

from __future__ import annotations

import re

from kinema.model.actions import actions_in

PACES = ("stroll", "jog", "sprint")

_WORD = re.IGNORECASE
_STROLL = re.compile(r"\b(?:stroll\w*|ambl\w*|saunter\w*|mosey\w*|leisurely|unhurried\w*)\b", _WORD)
_JOG = re.compile(r"\bjog(?:s|ged|ging|ger|gers)?\b", _WORD)
_SPRINT = re.compile(r"\b(?:sprint\w*|dash(?:es|ed|ing)?|rac(?:e|es|ed|ing)|bolt(?:s|ed|ing)?|full speed|"
                     r"top speed|flat out|as fast as)\b", _WORD)
_SLOW = re.compile(r"\b(?:slow\w*|easy pace|gentle pace|relaxed pace|easy|gently|leisurely)\b", _WORD)


def pace(text: str) -> str | None:
    """'stroll', 'jog', 'sprint' or None (no pace of its own) for a prompt or caption."""
    if _SPRINT.search(text):
        return "sprint"
    if _JOG.search(text):
        return "jog"
    if _STROLL.search(text):
        return "stroll"
    if _SLOW.search(text):
        actions = actions_in(text)
        if "run" in actions:
            return "jog"
        if "walk" in actions:
            return "stroll"
    return None
