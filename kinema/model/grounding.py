"""Prompt grounding: condition the denoiser on a blend of the prompt and its nearest training captions.

Why: a small denoiser trained on a fixed set of captions follows those captions, but not a paraphrase
whose text embedding merely lies *near* them (issue 18: "Someone strolls slowly ahead." came out as fast
as a sprint). The nearest training captions of a paraphrase mostly carry its meaning ("Someone strolls
slowly ahead." -> "Someone walks slowly ahead.", cosine 0.93), and the denoiser has learned what those
embeddings mean. Grounding moves the prompt's embedding towards them at inference time:

    e = |e_p| * normalize((1 - a) * e_p + a * sum_i w_i * e_i),   w = softmax(s_i / tau) over the top k

with ``e_p`` the prompt's embedding ``(E,)``, ``e_i`` the unit embeddings of the ``k`` nearest known
captions (kinema.model.vocabulary) *that name the same sides as the prompt*, ``s_i`` their cosine
similarities, ``a`` = ``weight`` and ``tau`` = ``temperature``.

Same sides: MiniLM barely tells left from right ("Somebody lifts the left arm up high." is nearest to
"A person raises their right arm up.", 0.87; "... a wave of the right hand." to "... a wave of their
left hand.", 0.89), so blending the nearest captions as they come would swap sides. A caption is a
candidate only when the set of side words it uses ({left, right}, also as leftward(s) / rightward(s))
equals the prompt's; a prompt that names no side is grounded on captions that name none.

Same directions, likewise: "A man walks forward." was nearest to "A man walks backward while facing
forward." (the masculine style's backward walk), so grounding turned a forward walk into a backward one.
A caption is a candidate only when it names the same directions away from forward ({backward, sideways})
as the prompt: none for "walks forward" or "walks", 'backward' for "walks backwards".

Same manner, likewise: the nearest caption of "A person walks forward." is "A person walks forward
wearily." (an exhausted style), of "A person bows." "A person bows wearily.", so a blend of the nearest
captions as they come would give a user who named no manner a tired walk. When the known prompts list
the phrases that name a manner in their captions (``manner_phrases``: styles such as "wearily" or "An
elderly person" and speed words such as "slowly" or "at full speed"; kinema.data.phrasings.manner_phrases,
written by ``kinema export --known-prompts``), a prompt that names none of them is grounded only on
captions that name none ("A person walks ahead.", the neutral style's "A person walks forward in a
neutral way."), and one that names one only on captions that name one ("Someone strolls slowly ahead."
-> "Someone walks slowly ahead."). When no caption of a prompt's actions names a manner at all ("A man
kicks hard using his left leg.": "A man" is the masculine style's phrase, and no kick caption has a
style), the action wins: the prompt is grounded on its actions' captions whatever their manner, where
it was left alone ('unmatched', conditioned on its own words, and the model made no kick).

Same actions, likewise (kinema.model.actions): MiniLM put "A person walks forward and reaches out with
the right hand." nearest to "A person walks forward and turns to the right." (0.80), so grounding swapped
a reach for a turn. A prompt that names actions is grounded only on captions that name all of them
("Someone strolls ahead." {walk} on a walk, never on a wave; "lifts the right hand to say farewell" {raise}
may go to "raises their right hand and waves goodbye" {raise, wave}); one that names an action the
model has not learned ("A person kicks.", "A person dances.", "A person punches.": too few or no training
clips, KnownPrompts.untrained) is 'unknown', whatever its similarity; one that names none ("Somebody
heads forward.") is grounded as before, on captions of any action.

Four cases are left alone:

- a prompt that *is* a training caption (same text, or cosine >= :data:`EXACT_ABOVE`) of learned actions:
  the model knows it, so its embedding is returned unchanged (grounding is the identity there; tested);
- an unknown prompt (nearest caption below ``UNKNOWN_BELOW``, or an action the model has not learned):
  rewriting it into the nearest known action would silently produce something else; it keeps its own
  embedding and the unknown-prompt warning;
- no caption that names the same sides, manner and actions is near enough (best below
  ``UNKNOWN_BELOW``): 'unmatched' (a prompt whose actions no caption names together also gets a warning);
- ``weight`` 0 (grounding off).

Settings are a small dataclass saved as JSON in a model's ``checkpoint.json`` under ``"grounding"``
(unknown keys rejected, like the guidance settings); a model without it uses :data:`DEFAULT_GROUNDING`.
Measurements behind the defaults: docs/evaluation.md ("Prompt grounding").
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import torch

from kinema.errors import KinemaError
from kinema.model.actions import actions_in
from kinema.model.pace import pace
from kinema.model.sides import sides
from kinema.model.vocabulary import UNKNOWN_BELOW, KnownPrompts

#: cosine at or above which a prompt counts as the training caption itself (float16-stored caption
#: embeddings agree with a fresh encoding to ~1e-6)
EXACT_ABOVE = 0.9999
_KEYS = ("weight", "temperature", "top_k")


_AWAY_FROM_FORWARD = re.compile(
    r"\b(backward|sideways|sideward|(?:walk|step|mov)(?:s|ed|ing|e|es)? back)s?\b", re.IGNORECASE)


def off_forward(text: str) -> frozenset[str]:
    """The directions other than forward a text moves in: a subset of {'backward', 'sideways'}
    ("walks backwards", "steps back" and every other wording of the 'walk back' action, such as "backs up",
    name 'backward'; "sideward" is 'sideways')."""
    named = frozenset("sideways" if m.lower().startswith("side") else "backward"
                      for m in _AWAY_FROM_FORWARD.findall(text))
    return named | {"backward"} if "walk back" in actions_in(text) else named  # "backs up", "retreats"


@dataclass(frozen=True)
class Grounding:
    """How strongly a prompt is pulled towards its nearest training captions.

    ``weight`` a in [0, 1] (0 = off, 1 = the captions alone), ``temperature`` tau > 0 of the softmax over
    the captions' cosine similarities (small = the nearest caption dominates), ``top_k`` >= 1 captions."""

    weight: float = 0.0
    temperature: float = 0.05
    top_k: int = 1

    def __post_init__(self) -> None:
        for name in ("weight", "temperature"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise KinemaError(f"grounding {name} must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        if not 0.0 <= self.weight <= 1.0:
            raise KinemaError(
                f"grounding weight must be in [0, 1] (0 = off, 1 = the nearest captions alone), got {self.weight:g}"
            )
        if self.temperature <= 0.0:
            raise KinemaError(f"grounding temperature must be > 0, got {self.temperature:g}")
        if isinstance(self.top_k, bool) or not isinstance(self.top_k, int) or self.top_k < 1:
            raise KinemaError(f"grounding top_k must be an integer >= 1, got {self.top_k!r}")

    @property
    def off(self) -> bool:
        return self.weight == 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"weight": self.weight, "temperature": self.temperature, "top_k": self.top_k}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "grounding") -> Grounding:
        """Rebuild from :meth:`to_dict`; unknown keys or bad values are a one-line ``KinemaError``."""
        if not isinstance(data, Mapping):
            raise KinemaError(f"{where}: expected an object with keys {list(_KEYS)}, got {type(data).__name__}")
        unknown = sorted(set(data) - set(_KEYS))
        if unknown:
            raise KinemaError(f"{where}: unknown keys {unknown} (expected some of {list(_KEYS)})")
        try:
            return cls(**data)
        except KinemaError as err:
            raise KinemaError(f"{where}: {err}") from None


#: used by models whose checkpoint.json has no "grounding" entry (measured: docs/evaluation.md)
DEFAULT_GROUNDING = Grounding()


def as_grounding(value, base: Grounding) -> Grounding:
    """``generate``'s ``grounding`` argument as settings: None (``base``, the model's default), a
    Grounding, a weight in [0, 1] (``base``'s temperature and top k), False (off) or a dict of some of
    :meth:`Grounding.to_dict`'s keys (the others from ``base``)."""
    if value is None:
        return base
    if isinstance(value, Grounding):
        return value
    if value is False:
        return replace(base, weight=0.0)
    if isinstance(value, Mapping):
        return Grounding.from_dict({**base.to_dict(), **value})
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return replace(base, weight=float(value))
    raise KinemaError(
        f"grounding must be a weight in [0, 1], a Grounding, a dict with some of the keys "
        f"{list(_KEYS)}, False or None (the model's default), got {value!r}"
    )


@dataclass(frozen=True)
class Grounded:
    """A prompt's conditioning embedding ``(1, E)`` and what grounding did: ``status`` is 'grounded',
    'exact' (a training caption), 'unknown' (too far from every caption, or an action the model has not
    learned), 'unmatched' (no caption naming the same sides, manner and actions is near enough) or 'off';
    ``captions`` the
    (caption, weight in the blend) pairs, empty unless grounded; the prompt's own weight is ``1 - sum``."""

    embedding: torch.Tensor
    status: str
    captions: tuple[tuple[str, float], ...] = ()

    def to_dict(self) -> dict:
        return {
            "status": self.status,
            "prompt_weight": round(1.0 - sum(w for _, w in self.captions), 4),
            "captions": [{"caption": c, "weight": round(w, 4)} for c, w in self.captions],
        }


def _candidates(prompt: str, actions: frozenset[str], known: KnownPrompts, manner: bool = True,
                paced: bool = True) -> torch.Tensor:
    """Which captions ``(N,)`` bool a prompt may be grounded on: same sides, same directions away from
    forward, same pace (kinema.model.pace, when ``paced``), same manner (when the known prompts list manner
    phrases, ``manner`` and the prompt names no pace: a pace word is the manner a caption says it with) and,
    when the prompt names actions, all of them."""
    want, away, speed = sides(prompt), off_forward(prompt), pace(prompt)
    same = torch.tensor([sides(c) == want and off_forward(c) == away for c in known.captions])
    if paced:
        same &= torch.tensor([p == speed for p in known.caption_paces])
    if manner and known.manner_phrases and not (paced and speed):
        # a prompt that names no manner is grounded on captions that name none
        same &= known.mannered == known.names_manner(prompt)
    if actions:
        same &= torch.tensor([actions <= a for a in known.caption_actions])
    return same


def _nearest(same: torch.Tensor, ref_unit: torch.Tensor, known: KnownPrompts, settings: Grounding,
             floor: float = UNKNOWN_BELOW):
    """The top-k (values, indices) of the candidate captions ``same (N,)`` by cosine to ``ref_unit (1, E)``,
    among those whose action the model makes (``KnownPrompts.made``, by its caption fidelity) when one of them
    is near enough, else among all; None when there is none or the nearest is below ``floor``.

    Why (issue 58): "Someone delivers a kick with the right leg." was grounded on the Bandai Namco kick's
    caption, which the model does not make (0 of 6 samples of its own captions kick), while the CC0 humanoid
    kick captions of the same side, a little farther, are made in 5 of 6."""
    made = _top(same & known.made, ref_unit, known, settings, floor)
    return made if made is not None else _top(same, ref_unit, known, settings, floor)


def _top(same: torch.Tensor, ref_unit: torch.Tensor, known: KnownPrompts, settings: Grounding, floor: float):
    sims = torch.where(same, known.embeddings @ ref_unit[0], -math.inf)
    top = sims.topk(min(settings.top_k, int(same.sum())))
    if top.values.numel() == 0 or float(top.values[0]) < floor:
        return None
    return top


def ground(prompt: str, embedding: torch.Tensor, known: KnownPrompts | None, settings: Grounding,
           reworded: torch.Tensor | None = None) -> Grounded:
    """The embedding ``(1, E)`` to condition on for ``prompt`` (its own ``embedding`` ``(1, E)`` or ``(E,)``).

    ``reworded``: the embedding of the prompt with its action synonyms replaced by the captions' verbs
    (kinema.model.actions.reworded; None when that changes nothing). It stands in for the prompt's own, to
    judge whether the prompt is known and to pick the captions, only where the prompt's own embedding is
    below the unknown threshold and the reworded one is nearer ("Someone jabs with the left hand.")."""
    e = embedding.float().reshape(1, -1)
    if settings.off or known is None:
        return Grounded(e, "off")
    best, _, ref = known.nearest_judged(e, reworded, 1)
    actions = actions_in(prompt)
    if known.untrained(actions):  # even a training caption ("A person dances.": 8 clips, not learned)
        return Grounded(e, "unknown")
    # a reworded prompt was below the unknown threshold in its own words, so never a caption's twin
    if prompt.strip() in known.caption_set or (ref is e and float(best[0]) >= EXACT_ABOVE):
        return Grounded(e, "exact")
    if float(best[0]) < UNKNOWN_BELOW:
        return Grounded(e, "unknown")
    unit = torch.nn.functional.normalize(e, dim=-1)
    ref_unit = torch.nn.functional.normalize(ref.float().reshape(1, -1), dim=-1)
    # a prompt known as a whole (checked above) that names a pace is grounded on its pace's nearest captions
    # however near: "A woman strolls along at her leisure." is 0.63 from "Someone walks slowly ahead." and
    # 0.72 from "A woman walks straight ahead.", a walk at full pace
    floor = -1.0 if pace(prompt) else UNKNOWN_BELOW
    top = _nearest(_candidates(prompt, actions, known), ref_unit, known, settings, floor)
    if top is None and pace(prompt):
        # no caption of these actions and directions says this pace ("strolls backwards"): ground as before
        top = _nearest(_candidates(prompt, actions, known, paced=False), ref_unit, known, settings)
    if top is None and actions and known.manner_phrases and known.names_manner(prompt):
        # no caption of these actions says it in this manner ("A man kicks hard using his left leg.": the
        # kicks have no style words): the action matters more than the manner, so ground on the action's own
        top = _nearest(_candidates(prompt, actions, known, manner=False), ref_unit, known, settings)
    if top is None:
        return Grounded(e, "unmatched")
    w = torch.softmax(top.values.double() / settings.temperature, dim=0).float()
    target = (w[:, None] * known.embeddings[top.indices]).sum(dim=0, keepdim=True)  # (1, E)
    blend = torch.nn.functional.normalize((1.0 - settings.weight) * unit + settings.weight * target, dim=-1)
    captions = tuple(
        (known.captions[int(i)], settings.weight * float(wi)) for i, wi in zip(top.indices, w, strict=True)
    )
    return Grounded(blend * e.norm(dim=-1, keepdim=True), "grounded", captions)
