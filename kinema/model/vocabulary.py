"""The captions a model was trained on, kept next to its weights, to tell users when a prompt is unknown.

A small model trained on one dataset only knows that dataset's actions: asked for "A person sits down on
a chair." the shipped human model (no sitting in Bandai Namco) silently raises a hand. ``KnownPrompts``
holds the unique training captions and their text-encoder embeddings (unit length, float16 in the
file ``known_prompts.safetensors`` of a model folder, captions in its metadata); ``match(embedding)``
returns the nearest captions by cosine similarity, and a prompt whose nearest caption is below
``UNKNOWN_BELOW`` is reported as far from everything the model was trained on.

Threshold (MiniLM-L6 embeddings, the 1315 unique train captions of the Bandai Namco build): the 54 test
captions that are not train captions reach 0.745-0.98 (median 0.85), and paraphrases of trained actions
0.75-0.98 ("A man jogs quickly forward." 0.749, "Someone strolls slowly ahead." 0.795, "A woman lifts
her left arm up high." 0.892), while actions the data lacks stay below 0.68 ("A person jumps up in
place." 0.622, "Someone hops on one foot." 0.678, "A person sits down on a chair." 0.337, "A person picks
up a box." 0.369).

Similarity alone misses actions the model does not know when the sentence around them is familiar ("A
person kicks." is 0.81 from a kick caption, "A person dances." 0.87 from a dance caption, yet the default
model makes neither). So the known prompts also compare actions (kinema.model.actions): a prompt that
names an action no training caption names ("A person punches.": 'punch'), or one that the training clips
show too rarely to learn (fewer than ``MIN_ACTION_CLIPS`` clips, counted per action when the file was
written: ``action_clips``), is unknown and its warning names the action; a prompt whose actions are all
learned but never appear together in one caption ("A person walks and waves.") is warned too. Evidence
for the threshold (model card of the default model, train split with mirrors): kick, dance (2 clips each),
call and slash (4) are not produced; bow (22), guide, bye (24 each) are. A file without ``action_clips``
(older exports) counts every action its captions name as learned.

A clip count is a proxy. Where an action was measured on the model itself (``action_probes``: per action,
how many generated samples of held-out phrasings passed a check of the action, e.g. a kick lifts the named
foot above the hips; scripts/humanoid_action_probes.py, saved by ``kinema export --action-probes``), the
measurement decides instead: learned when at least ``PROBE_PASS_SHARE`` of its samples pass, whatever the
count (a fine-tune can teach an action from 6 clips drawn often, and 10 clips do not prove a punch).
"""

from __future__ import annotations

import json
import math
import re
import statistics
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.model.actions import ACTION_WORDS, actions_in, clips_per_action
from kinema.model.pace import pace

FILE_NAME = "known_prompts.safetensors"
#: cosine similarity below which a prompt counts as unknown (see the module docstring for the numbers)
UNKNOWN_BELOW = 0.70
#: nearest captions reported with a match
NEAREST = 3
#: an action shown by fewer training clips (mirrors included) is not learned (see the module docstring)
MIN_ACTION_CLIPS = 10
#: an action measured on the model (``action_probes``) is learned when this share of its samples pass
PROBE_PASS_SHARE = 0.5


@dataclass(frozen=True)
class PromptMatch:
    """How close one prompt is to the training captions: ``nearest`` = [(caption, cosine), ...]."""

    prompt: str
    nearest: list[tuple[str, float]]
    known: bool
    #: the actions the prompt names (kinema.model.actions) and what the model lacks of them, in words
    actions: tuple[str, ...] = ()
    action_notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {
            "prompt": self.prompt,
            "known": self.known,
            "actions": list(self.actions),
            "nearest": [{"caption": c, "similarity": round(s, 4)} for c, s in self.nearest],
        }

    def warning(self) -> str:
        near = "; ".join(f"{c!r} ({s:.2f})" for c, s in self.nearest)
        far = self.nearest[0][1] < UNKNOWN_BELOW
        reasons = [f"best similarity {self.nearest[0][1]:.2f} < {UNKNOWN_BELOW:.2f}"] if far else []
        what = (
            "is far from every caption the model was trained on"
            if far
            else "asks for what the model was not trained on or does not make"
        )
        return (
            f"prompt {self.prompt!r} {what} ({'; '.join(reasons + list(self.action_notes))}); "
            f"the motion may show something else. Nearest known captions: {near}"
        )


class KnownPrompts:
    """Training captions and their unit-length embeddings ``(N, E)`` from text encoder ``encoder_id``."""

    def __init__(
        self,
        captions: list[str],
        embeddings: torch.Tensor,
        encoder_id: str,
        manner_phrases: tuple[str, ...] = (),
        action_clips: Mapping[str, int] | None = None,
        action_probes: Mapping[str, tuple[int, int]] | None = None,
        caption_seconds: Sequence[float] | None = None,
        caption_speeds: Sequence[float | None] | None = None,
        caption_contents: Sequence[str | None] | None = None,
        content_fidelity: Mapping[str, tuple[int, int, bool]] | None = None,
    ):
        if embeddings.ndim != 2 or embeddings.shape[0] != len(captions) or not captions:
            raise KinemaError(
                f"known prompts: {len(captions)} captions but embeddings of shape {tuple(embeddings.shape)}"
            )
        self.captions = list(captions)
        self.embeddings = torch.nn.functional.normalize(embeddings.float(), dim=-1)
        self.encoder_id = encoder_id
        self.caption_set = frozenset(c.strip() for c in self.captions)
        self._caption_index = {c: i for i, c in enumerate(self.captions)}
        # phrases that say how a caption's action is done ("wearily", "An elderly person", "slowly"); empty = not known
        self.manner_phrases = tuple(manner_phrases)
        longest_first = sorted(self.manner_phrases, key=len, reverse=True)
        self._manner = re.compile(r"\b(?:" + "|".join(map(re.escape, longest_first)) + r")\b", re.IGNORECASE)
        self.mannered = torch.tensor([self.names_manner(c) for c in self.captions], dtype=torch.bool)
        # the actions each caption names; per action the training clips that show it (empty = not known)
        self.caption_actions = [actions_in(c) for c in self.captions]
        self.caption_paces = [pace(c) for c in self.captions]  # kinema.model.pace
        self.action_clips = dict(sorted((action_clips or {}).items()))
        self.action_sets = frozenset(self.caption_actions)
        self.named_actions = frozenset().union(*self.caption_actions)
        # per measured action (passed, samples) of the model's own probes (empty = none measured)
        self.action_probes = {str(a): (int(p), int(n)) for a, (p, n) in sorted((action_probes or {}).items())}
        for a, (passed, total) in self.action_probes.items():
            _check_share(passed, total, f"action {a!r} probes")
        self.learned = frozenset(a for a in self.named_actions if self._learned(a))
        n = len(self.captions)
        # per caption the median length (s) of the training clips that carry it: how long its action was
        # captured at, the window a longer prompt is continued in (kinema.human.continuation); None = not known
        self.caption_seconds = _per_caption(caption_seconds, n, "caption_seconds must hold one positive length",
                                            lambda x: math.isfinite(x) and x > 0, float)
        # per caption the median steady ground speed (m/s) of the training clips that carry it and travel
        # (kinema.data.phases), None for a caption whose clips do not: the speed a continued prompt keeps
        self.caption_speeds = _per_caption(caption_speeds, n, "caption_speeds must hold one speed (m/s, >= 0) or null",
                                           lambda x: x is None or (math.isfinite(x) and x >= 0), _optional(float))
        # per caption the content label of the training clips that carry it (the most common; "wave-right-hand",
        # "kick-left"), and per content the model's caption fidelity on its own captions (samples passed,
        # samples, whether every caption holds: kinema.evaluate.fidelity); None / empty = not known
        self.caption_contents = _per_caption(caption_contents, n, "caption_contents must hold one content label or "
                                             "null", lambda c: True, _optional(str))
        self.content_fidelity = {str(c): (int(p), int(t), bool(h))
                                 for c, (p, t, h) in sorted((content_fidelity or {}).items())}
        for c, (passed, total, _) in self.content_fidelity.items():
            _check_share(passed, total, f"content {c!r} fidelity")
        # per caption: False where its content was measured and does not hold (grounding prefers the others)
        self.made = torch.tensor([self.content_made(c) for c in (self.caption_contents or [None] * n)],
                                 dtype=torch.bool)

    def _learned(self, action: str) -> bool:
        """Whether the model learned ``action``: its probes pass (where measured), else enough clips show it."""
        if action in self.action_probes:
            passed, total = self.action_probes[action]
            return passed >= PROBE_PASS_SHARE * total
        return self.action_clips.get(action, MIN_ACTION_CLIPS) >= MIN_ACTION_CLIPS

    def action_notes(self, actions: frozenset[str]) -> tuple[str, ...]:
        """Why a prompt naming ``actions`` is unknown to the model, one phrase per reason (empty: it is not):
        actions no caption names, actions too few training clips show, or learned actions no one caption
        names all of."""
        notes = [f"the model was not trained on {a!r}" for a in sorted(actions - self.named_actions)]
        notes += [self._unlearned_note(a) for a in sorted((actions & self.named_actions) - self.learned)]
        if not notes and not any(actions <= a for a in self.action_sets):
            notes.append(f"no training caption has {' and '.join(map(repr, sorted(actions)))} together")
        return tuple(notes)

    def _unlearned_note(self, action: str) -> str:
        if action in self.action_probes:
            passed, total = self.action_probes[action]
            return f"the model does not make {action!r}: {passed} of {total} measured samples show it"
        return (f"the model was not trained on {action!r} enough to learn it: only {self.action_clips[action]} "
                "training clips show it")

    def with_probes(self, action_probes: Mapping[str, tuple[int, int]]) -> KnownPrompts:
        """These known prompts with ``action_probes`` (per action: samples passed, samples) measured."""
        return KnownPrompts(self.captions, self.embeddings, self.encoder_id, self.manner_phrases,
                            self.action_clips, action_probes, self.caption_seconds, self.caption_speeds,
                            self.caption_contents, self.content_fidelity)

    def with_content_fidelity(self, content_fidelity: Mapping[str, tuple[int, int, bool]]) -> KnownPrompts:
        """These known prompts with the caption fidelity per content (samples passed, samples, holds)."""
        return KnownPrompts(self.captions, self.embeddings, self.encoder_id, self.manner_phrases,
                            self.action_clips, self.action_probes or None, self.caption_seconds, self.caption_speeds,
                            self.caption_contents, content_fidelity)

    def content_made(self, content: str | None) -> bool:
        """Whether the model makes ``content`` by its caption fidelity (True when not measured)."""
        return content is None or content not in self.content_fidelity or self.content_fidelity[content][2]

    def content_note(self, caption: str) -> str | None:
        """Why the model does not make what a known ``caption`` shows, by the caption-fidelity table of its
        content (None: it does, or it was not measured)."""
        content = self._of(self.caption_contents, caption)
        if self.content_made(content):
            return None
        passed, total, _ = self.content_fidelity[content]
        return (f"the model does not reliably make {content!r}, which its caption {caption!r} shows: "
                f"{passed} of {total} measured samples of that action's captions show it")

    def untrained(self, actions: frozenset[str]) -> frozenset[str]:
        """The ``actions`` the model has not learned (no caption names them, or too few clips show them)."""
        return actions - self.learned

    def names_manner(self, text: str) -> bool:
        """Whether ``text`` contains one of :attr:`manner_phrases` (False when there are none)."""
        return bool(self.manner_phrases) and self._manner.search(text) is not None

    @classmethod
    def build(
        cls, captions, encoder, manner_phrases: tuple[str, ...] = (), action_clips: Mapping[str, int] | None = None
    ) -> KnownPrompts:
        """Embed the unique ``captions`` (sorted) with ``encoder`` (a kinema.text encoder); ``manner_phrases``
        are the words that name a manner in them (kinema.data.phrasings.manner_phrases for kinema's captions;
        those no caption uses are dropped); ``action_clips`` how many training clips show each action
        (kinema.model.actions.clips_per_action of the clips' captions)."""
        unique = sorted({c.strip() for c in captions if c and c.strip()})
        if not unique:
            raise KinemaError("known prompts: no captions to embed")
        phrases = cls.phrases_in(manner_phrases, unique)
        return cls(unique, encoder.encode(unique).float(), encoder.id, phrases, action_clips)

    @classmethod
    def from_clips(cls, clip_captions: list[list[str]], encoder, manner_phrases: tuple[str, ...] = (),
                   clip_seconds: Sequence[float] | None = None,
                   clip_speeds: Sequence[float | None] | None = None,
                   clip_contents: Sequence[str] | None = None) -> KnownPrompts:
        """:meth:`build` from training clips, each given as its captions: all their captions, per action
        the number of clips that show it and, given each clip's length ``clip_seconds`` and steady speed
        ``clip_speeds`` (None: it does not travel), per caption the median length and speed of the clips
        that carry it, and given their content labels ``clip_contents`` each caption's most common one."""
        captions = [c for caps in clip_captions for c in caps]
        known = cls.build(captions, encoder, manner_phrases, clips_per_action(clip_captions))
        if clip_seconds is None and clip_speeds is None and clip_contents is None:
            return known
        return cls(known.captions, known.embeddings, known.encoder_id, known.manner_phrases, known.action_clips,
                   caption_seconds=None if clip_seconds is None else median_seconds(known.captions, clip_captions,
                                                                                   clip_seconds),
                   caption_speeds=None if clip_speeds is None else median_speeds(known.captions, clip_captions,
                                                                                 clip_speeds),
                   caption_contents=None if clip_contents is None else common_contents(known.captions, clip_captions,
                                                                                       clip_contents))

    def seconds_of(self, caption: str) -> float | None:
        """How long the clips of a known ``caption`` last (median, seconds), or None when not known."""
        return self._of(self.caption_seconds, caption)

    def speed_of(self, caption: str) -> float | None:
        """The steady ground speed (m/s, median) of the travelling clips of a known ``caption``, or None when
        not known or its clips do not travel."""
        return self._of(self.caption_speeds, caption)

    def _of(self, values: list | None, caption: str):
        """A known ``caption``'s entry of the per-caption ``values`` (None when either is not known)."""
        i = self._caption_index.get(caption)
        return None if values is None or i is None else values[i]

    @staticmethod
    def phrases_in(phrases, captions) -> tuple[str, ...]:
        """The ``phrases`` that occur (case-insensitively) in at least one of ``captions``, in order."""
        lowered = [c.lower() for c in captions]
        return tuple(p for p in phrases if any(p.lower() in c for c in lowered))

    def save(self, folder: str | Path) -> Path:
        """Write ``folder/known_prompts.safetensors`` atomically (float16 embeddings)."""
        meta = {
            "format": "kinema-known-prompts-1",
            "text_encoder": self.encoder_id,
            "captions": json.dumps(self.captions),
            "manner_phrases": json.dumps(list(self.manner_phrases)),
        }
        if self.action_clips:
            meta["action_clips"] = json.dumps(self.action_clips)
        if self.caption_seconds is not None:
            meta["caption_seconds"] = json.dumps([round(x, 3) for x in self.caption_seconds])
        if self.caption_speeds is not None:
            meta["caption_speeds"] = json.dumps([None if x is None else round(x, 3) for x in self.caption_speeds])
        if self.caption_contents is not None:
            meta["caption_contents"] = json.dumps(self.caption_contents)
        if self.content_fidelity:
            meta["content_fidelity"] = json.dumps({c: list(v) for c, v in self.content_fidelity.items()})
        if self.action_probes:
            meta["action_probes"] = json.dumps({a: list(v) for a, v in self.action_probes.items()})
        path = Path(folder) / FILE_NAME
        atomic_write_bytes(path, save({"embeddings": self.embeddings.half().contiguous()}, metadata=meta))
        return path

    @classmethod
    def load(cls, folder: str | Path) -> KnownPrompts | None:
        """The known prompts saved in a model folder, or None when it has none."""
        path = Path(folder) / FILE_NAME
        if not path.is_file():
            return None
        try:
            with safe_open(str(path), framework="pt") as f:
                meta = f.metadata() or {}
                emb = f.get_tensor("embeddings")
            captions = json.loads(meta["captions"])
            phrases = tuple(json.loads(meta.get("manner_phrases", "[]")))
            clips = {str(a): int(n) for a, n in json.loads(meta.get("action_clips", "{}")).items()}
            probes = {str(a): (int(v[0]), int(v[1])) for a, v in json.loads(meta.get("action_probes", "{}")).items()}
            seconds = json.loads(meta["caption_seconds"]) if "caption_seconds" in meta else None
            speeds = json.loads(meta["caption_speeds"]) if "caption_speeds" in meta else None
            contents = json.loads(meta["caption_contents"]) if "caption_contents" in meta else None
            fidelity = {str(c): (int(v[0]), int(v[1]), bool(v[2]))
                        for c, v in json.loads(meta.get("content_fidelity", "{}")).items()}
            return cls(captions, emb, meta["text_encoder"], phrases, clips, probes, seconds, speeds, contents, fidelity)
        except (OSError, KeyError, TypeError, ValueError, AttributeError, RuntimeError, SafetensorError) as err:
            raise KinemaError(f"{path}: not a known-prompts file ({err})") from None

    def nearest(self, embedding: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Cosine similarities ``(k,)`` (descending) and indices ``(k,)`` of the ``k`` nearest captions
        (fewer when there are fewer) of an embedding ``(E,)`` or ``(1, E)``."""
        e = torch.nn.functional.normalize(embedding.float().reshape(1, -1), dim=-1)
        if e.shape[1] != self.embeddings.shape[1]:
            raise KinemaError(
                f"known prompts: embedding has {e.shape[1]} dimensions, expected "
                f"{self.embeddings.shape[1]} ({self.encoder_id})"
            )
        sims = (self.embeddings @ e[0]).clamp(-1.0, 1.0)
        top = sims.topk(min(k, len(self.captions)))
        return top.values, top.indices

    def nearest_judged(
        self, embedding: torch.Tensor, reworded: torch.Tensor | None, k: int
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """:meth:`nearest` of a prompt's ``embedding``, or of ``reworded`` (the embedding of the prompt with
        its action synonyms in the captions' verbs, kinema.model.actions.reworded; None when that changes
        nothing) where the prompt's own nearest caption is below :data:`UNKNOWN_BELOW` and the reworded
        one's is nearer; and the embedding that decided (``embedding`` itself or ``reworded``)."""
        sims, idx = self.nearest(embedding, k)
        if reworded is not None and float(sims[0]) < UNKNOWN_BELOW:
            r_sims, r_idx = self.nearest(reworded, k)
            if float(r_sims[0]) > float(sims[0]):
                return r_sims, r_idx, reworded
        return sims, idx, embedding

    def match(self, prompt: str, embedding: torch.Tensor, reworded: torch.Tensor | None = None,
              conditioned: str | None = None) -> PromptMatch:
        """Nearest training captions of ``prompt`` given its embedding ``(E,)`` or ``(1, E)``, judged in the
        captions' words where its own are too far (``reworded``, :meth:`nearest_judged`); ``conditioned``,
        the caption the prompt is conditioned on (grounding), is judged by its content's caption fidelity."""
        sims, idx, _ = self.nearest_judged(embedding, reworded, NEAREST)
        nearest = [(self.captions[int(i)], float(v)) for v, i in zip(sims, idx, strict=True)]
        actions = actions_in(prompt)
        notes = self.action_notes(actions)
        content = None if conditioned is None or notes else self.content_note(conditioned)
        notes += () if content is None else (content,)
        return PromptMatch(prompt, nearest, nearest[0][1] >= UNKNOWN_BELOW and not notes, tuple(sorted(actions)), notes)


def read_content_fidelity(paths: Sequence[str | Path]) -> dict[str, tuple[int, int, bool]]:
    """Per content label, (samples passed, samples, holds) on its own captions, from the JSON files that
    ``kinema evaluate fidelity --out`` writes (``actions`` -> label -> ``own``); a later file's actions
    replace an earlier one's (an action measured again)."""
    out: dict[str, tuple[int, int, bool]] = {}
    for path in paths:
        try:
            actions = json.loads(Path(path).read_text(encoding="utf-8"))["actions"]
            for content, entry in actions.items():
                own = entry["own"]
                out[str(content)] = (int(own["passed"]), int(own["total"]), bool(own["holds"]))
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError) as err:
            raise KinemaError(f"{path}: not a caption-fidelity result of `kinema evaluate fidelity --out` "
                              f"({type(err).__name__}: {err})") from None
    if not out:
        raise KinemaError(f"{', '.join(map(str, paths))}: no action measured")
    return dict(sorted(out.items()))


def read_action_probes(path: str | Path) -> dict[str, tuple[int, int]]:
    """Per action, (samples passed, samples) from the JSON that scripts/humanoid_action_probes.py writes
    (``--json``): its ``rows``, each with a ``content`` (``kick-left``, ``jump``, ...: the action before
    the first ``-``) and, for the actions it checks, a boolean ``pass``."""
    path = Path(path)
    try:
        rows = json.loads(path.read_text())["rows"]
        out: dict[str, list[int]] = {}
        for i, row in enumerate(rows):
            if "pass" not in row:
                continue
            action = str(row["content"]).split("-")[0]
            if action not in ACTION_WORDS:
                raise KinemaError(f"{path}: rows[{i}].content: {row['content']!r} names no known action")
            if not isinstance(row["pass"], bool):
                raise KinemaError(f"{path}: rows[{i}].pass: expected true or false, got {row['pass']!r}")
            counts = out.setdefault(action, [0, 0])
            counts[0] += row["pass"]
            counts[1] += 1
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise KinemaError(f"{path}: not an action-probes file from scripts/humanoid_action_probes.py --json "
                          f"({type(err).__name__}: {err})") from None
    if not out:
        raise KinemaError(f"{path}: no row with a 'pass' (an action-probes file measures kicks, punches, ...)")
    return {a: (p, n) for a, (p, n) in sorted(out.items())}


def median_seconds(captions: list[str], clip_captions: list[list[str]], clip_seconds: Sequence[float]) -> list[float]:
    """Per caption of ``captions`` the median of ``clip_seconds`` over the clips (given as their captions)
    that carry it; a caption no clip carries is an error."""
    return _medians(captions, clip_captions, clip_seconds, "clip lengths")


def _per_caption(values, n: int, what: str, ok: Callable[[Any], bool], convert: Callable[[Any], Any]) -> list | None:
    """``values`` converted, one per caption (None: not known), or a one-line error saying ``what`` they must be."""
    if values is None:
        return None
    out = [convert(v) for v in values]
    if len(out) != n or not all(ok(v) for v in out):
        raise KinemaError(f"known prompts: {what} per caption ({n})")
    return out


def _optional(convert: Callable[[Any], Any]) -> Callable[[Any], Any]:
    """``convert`` that leaves None alone."""
    return lambda v: None if v is None else convert(v)


def _check_share(passed: int, total: int, what: str) -> None:
    if not 0 <= passed <= total or total < 1:
        raise KinemaError(f"known prompts: {what} {passed}/{total} is not a share of samples")


def common_contents(captions: list[str], clip_captions: list[list[str]], clip_contents: Sequence[str]) -> list[str]:
    """Per caption of ``captions`` the most common content label of the clips that carry it (ties: the first
    in sorted order); a caption no clip carries is an error."""
    if len(clip_captions) != len(clip_contents):
        raise KinemaError(f"known prompts: {len(clip_captions)} clips but {len(clip_contents)} clip contents")
    per: dict[str, Counter] = {}
    for caps, content in zip(clip_captions, clip_contents, strict=True):
        for c in {c.strip() for c in caps}:
            per.setdefault(c, Counter())[str(content)] += 1
    missing = [c for c in captions if c not in per]
    if missing:
        raise KinemaError(f"known prompts: no clip carries the caption {missing[0]!r}")
    return [min(per[c].items(), key=lambda kv: (-kv[1], kv[0]))[0] for c in captions]


def median_speeds(captions: list[str], clip_captions: list[list[str]],
                  clip_speeds: Sequence[float | None]) -> list[float | None]:
    """Per caption of ``captions`` the median of ``clip_speeds`` over the clips that carry it and travel
    (speed not None), None where none does; a caption no clip carries is an error."""
    return _medians(captions, clip_captions, clip_speeds, "clip speeds")


def _medians(captions, clip_captions, values, what: str) -> list:
    if len(clip_captions) != len(values):
        raise KinemaError(f"known prompts: {len(clip_captions)} clips but {len(values)} {what}")
    per: dict[str, list[float]] = {}
    for caps, value in zip(clip_captions, values, strict=True):
        for c in {c.strip() for c in caps}:
            per.setdefault(c, [])
            if value is not None:
                per[c].append(float(value))
    missing = [c for c in captions if c not in per]
    if missing:
        raise KinemaError(f"known prompts: no clip carries the caption {missing[0]!r}")
    return [statistics.median(per[c]) if per[c] else None for c in captions]
