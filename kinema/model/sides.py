"""The body sides a text names, and the text of its mirror image.

Prompts and captions name sides with the words "left" and "right" (also in "leftward(s)",
"left-hand"). Grounding keeps a prompt on captions that name the same sides
(kinema.model.grounding); the training data builds caption every mirrored clip with the mirrored
caption (kinema.data.captions); a model may generate a prompt that names its weaker side as the mirror
image of the other (kinema.human.mirrored_request).
"""

from __future__ import annotations

import re

#: a side word ("left", "right", also in "leftward(s)" and "left-hand"); group 1 is the side itself
_SIDE_WORD = re.compile(r"\b(left|right)(?=(?:wards?)?\b)", re.IGNORECASE)
#: the side words
SIDES = ("left", "right")


def sides(text: str) -> frozenset[str]:
    """The sides a text names: a subset of {'left', 'right'} ("walks leftward" names 'left')."""
    return frozenset(m.lower() for m in _SIDE_WORD.findall(text))


def mirror_caption(text: str) -> str:
    """Swap the words "left" and "right" (also in "leftward(s)", "left-hand"), keeping case.

    Used on free user text and to build mirrored captions. It is purely lexical: "right" in the
    sense of "correct" or "left" as the past of "leave" would be swapped too.
    """

    def swap(m: re.Match[str]) -> str:
        word = m.group(1)
        new = "right" if word.lower() == "left" else "left"
        if word.isupper():
            return new.upper()
        if word[0].isupper():
            return new.capitalize()
        return new

    return _SIDE_WORD.sub(swap, text)
