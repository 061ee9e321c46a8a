"""Prompt grounding from the runtime JSON alone: the rule of kinema.model.grounding, in numpy.

The JSON's grounding table holds the captions, their unit embeddings and their words as the rule reads
them (sides, directions away from forward, pace, whether a manner phrase is named, actions), and the
regular expressions that read the same from a prompt; this module is the reference a runtime without
Python follows (docs/onnx_runtime.md, "Grounding"), and the tests check it against kinema.model.grounding.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from kinema.portable.manifest import decode_array


@dataclass(frozen=True)
class PromptWords:
    """What the grounding rule reads from a text."""

    sides: frozenset[str]
    away: frozenset[str]
    pace: str | None
    manner: bool
    actions: frozenset[str]


class GroundingTable:
    """The JSON's ``grounding`` entry, compiled."""

    def __init__(self, entry: dict):
        s = entry["settings"]
        self.weight, self.temperature, self.top_k = float(s["weight"]), float(s["temperature"]), int(s["top_k"])
        self.unknown_below, self.exact_above = float(entry["unknown_below"]), float(entry["exact_above"])
        self.captions = list(entry["captions"])
        self.caption_set = frozenset(c.strip() for c in self.captions)
        e = decode_array(entry["embeddings"]).astype(np.float32)
        self.embeddings = e / np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-12)
        self.caption_words = [
            PromptWords(frozenset(sd), frozenset(aw), pc, bool(mn), frozenset(ac))
            for sd, aw, pc, mn, ac in zip(entry["caption_sides"], entry["caption_away"], entry["caption_pace"],
                                          entry["caption_manner"], entry["caption_actions"], strict=True)
        ]
        self.made = np.array(entry["caption_made"], dtype=bool)
        self.learned = frozenset(entry["learned_actions"])
        self.has_manner = bool(entry["manner_phrases"])
        p = entry["patterns"]
        flags = re.IGNORECASE
        self._side = re.compile(p["side"], flags)
        self._away = re.compile(p["away"], flags)
        self._actions = {a: re.compile(r, flags) for a, r in p["actions"].items()}
        self._verbs = p["action_verbs"]
        self._pace = {k: re.compile(r, flags) for k, r in p["pace"].items()}
        phrases = entry["manner_phrases"]
        self._manner = re.compile(r"\b(?:" + "|".join(map(re.escape, phrases)) + r")\b", flags) if phrases else None

    # ------------------------------------------------------------------ words
    def actions(self, text: str) -> frozenset[str]:
        return frozenset(a for a, r in self._actions.items() if r.search(text))

    def pace(self, text: str) -> str | None:
        for name in ("sprint", "jog", "stroll"):
            if self._pace[name].search(text):
                return name
        if self._pace["slow"].search(text):
            acts = self.actions(text)
            return "jog" if "run" in acts else "stroll" if "walk" in acts else None
        return None

    def words(self, text: str) -> PromptWords:
        acts = self.actions(text)
        away = frozenset("sideways" if m.lower().startswith("side") else "backward" for m in self._away.findall(text))
        away = away | {"backward"} if "walk back" in acts else away
        sides = frozenset(m.lower() for m in self._side.findall(text))
        manner = self._manner is not None and self._manner.search(text) is not None
        return PromptWords(sides, away, self.pace(text), manner, acts)

    def reworded(self, text: str) -> str:
        """The text with every one-word action form replaced by its action's verb."""
        out = text
        for action, pattern in self._actions.items():
            verb = self._verbs[action]
            out = pattern.sub(lambda m, v=verb: m.group(0) if " " in m.group(0) else v, out)
        return out

    # ------------------------------------------------------------------ rule
    def _candidates(self, w: PromptWords, manner: bool = True, paced: bool = True) -> np.ndarray:
        out = []
        for c in self.caption_words:
            ok = c.sides == w.sides and c.away == w.away
            ok = ok and (not paced or c.pace == w.pace)
            if manner and self.has_manner and not (paced and w.pace):
                ok = ok and c.manner == w.manner
            ok = ok and (not w.actions or w.actions <= c.actions)
            out.append(ok)
        return np.array(out, dtype=bool)

    def _nearest(self, same: np.ndarray, ref_unit: np.ndarray, floor: float):
        """Among the captions whose action is made when one is near enough, else among all."""
        made = self._top(same & self.made, ref_unit, floor)
        return made if made is not None else self._top(same, ref_unit, floor)

    def _top(self, same: np.ndarray, ref_unit: np.ndarray, floor: float):
        if not same.any():
            return None
        sims = np.where(same, self.embeddings @ ref_unit, -np.inf)
        order = np.argsort(-sims, kind="stable")[: min(self.top_k, int(same.sum()))]
        return None if sims[order[0]] < floor else (sims[order], order)

    def ground(self, prompt: str, e: np.ndarray, reworded: np.ndarray | None) -> tuple[np.ndarray, str, list[str]]:
        """``(embedding (E,), status, captions blended)`` for a prompt of embedding ``e (E,)``; ``reworded``:
        the embedding of :meth:`reworded` (None when it equals the prompt)."""
        if self.weight == 0.0:
            return e, "off", []
        unit = e / np.linalg.norm(e)
        sims = self.embeddings @ unit
        best, ref = float(sims.max()), e
        if reworded is not None and best < self.unknown_below:
            r_best = float((self.embeddings @ (reworded / np.linalg.norm(reworded))).max())
            if r_best > best:
                best, ref = r_best, reworded
        w = self.words(prompt)
        if w.actions - self.learned:
            return e, "unknown", []
        if prompt.strip() in self.caption_set or (ref is e and best >= self.exact_above):
            return e, "exact", []
        if best < self.unknown_below:
            return e, "unknown", []
        ref_unit = ref / np.linalg.norm(ref)
        top = self._nearest(self._candidates(w), ref_unit, -1.0 if w.pace else self.unknown_below)
        if top is None and w.pace:
            top = self._nearest(self._candidates(w, paced=False), ref_unit, self.unknown_below)
        if top is None and w.actions and self.has_manner and w.manner:
            top = self._nearest(self._candidates(w, manner=False), ref_unit, self.unknown_below)
        if top is None:
            return e, "unmatched", []
        vals, idx = top
        z = (vals - vals.max()) / self.temperature
        soft = np.exp(z) / np.exp(z).sum()
        target = (soft[:, None] * self.embeddings[idx]).sum(0)
        blend = (1.0 - self.weight) * unit + self.weight * target
        blend = blend / np.linalg.norm(blend) * np.linalg.norm(e)
        return blend.astype(np.float32), "grounded", [self.captions[i] for i in idx]
