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
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError

FILE_NAME = "known_prompts.safetensors"
#: cosine similarity below which a prompt counts as unknown (see the module docstring for the numbers)
UNKNOWN_BELOW = 0.70
#: nearest captions reported with a match
NEAREST = 3


@dataclass(frozen=True)
class PromptMatch:
    """How close one prompt is to the training captions: ``nearest`` = [(caption, cosine), ...]."""

    prompt: str
    nearest: list[tuple[str, float]]
    known: bool

    def to_dict(self) -> dict:
        return {
            "prompt": self.prompt,
            "known": self.known,
            "nearest": [{"caption": c, "similarity": round(s, 4)} for c, s in self.nearest],
        }

    def warning(self) -> str:
        near = "; ".join(f"{c!r} ({s:.2f})" for c, s in self.nearest)
        return (
            f"prompt {self.prompt!r} is far from every caption the model was trained on (best similarity "
            f"{self.nearest[0][1]:.2f} < {UNKNOWN_BELOW:.2f}); the motion may show something else. "
            f"Nearest known captions: {near}"
        )


class KnownPrompts:
    """Training captions and their unit-length embeddings ``(N, E)`` from text encoder ``encoder_id``."""

    def __init__(
        self, captions: list[str], embeddings: torch.Tensor, encoder_id: str, manner_phrases: tuple[str, ...] = ()
    ):
        if embeddings.ndim != 2 or embeddings.shape[0] != len(captions) or not captions:
            raise KinemaError(
                f"known prompts: {len(captions)} captions but embeddings of shape {tuple(embeddings.shape)}"
            )
        self.captions = list(captions)
        self.embeddings = torch.nn.functional.normalize(embeddings.float(), dim=-1)
        self.encoder_id = encoder_id
        self.caption_set = frozenset(c.strip() for c in self.captions)
        # phrases that say how a caption's action is done ("wearily", "An elderly person", "slowly"); empty = not known
        self.manner_phrases = tuple(manner_phrases)
        longest_first = sorted(self.manner_phrases, key=len, reverse=True)
        self._manner = re.compile(r"\b(?:" + "|".join(map(re.escape, longest_first)) + r")\b", re.IGNORECASE)
        self.mannered = torch.tensor([self.names_manner(c) for c in self.captions], dtype=torch.bool)

    def names_manner(self, text: str) -> bool:
        """Whether ``text`` contains one of :attr:`manner_phrases` (False when there are none)."""
        return bool(self.manner_phrases) and self._manner.search(text) is not None

    @classmethod
    def build(cls, captions, encoder, manner_phrases: tuple[str, ...] = ()) -> KnownPrompts:
        """Embed the unique ``captions`` (sorted) with ``encoder`` (a kinema.text encoder); ``manner_phrases``
        are the words that name a manner in them (kinema.data.phrasings.manner_phrases for kinema's captions;
        those no caption uses are dropped)."""
        unique = sorted({c.strip() for c in captions if c and c.strip()})
        if not unique:
            raise KinemaError("known prompts: no captions to embed")
        return cls(unique, encoder.encode(unique).float(), encoder.id, cls.phrases_in(manner_phrases, unique))

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
            return cls(captions, emb, meta["text_encoder"], tuple(json.loads(meta.get("manner_phrases", "[]"))))
        except (OSError, KeyError, TypeError, ValueError, RuntimeError, SafetensorError) as err:
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

    def match(self, prompt: str, embedding: torch.Tensor) -> PromptMatch:
        """Nearest training captions of ``prompt`` given its embedding ``(E,)`` or ``(1, E)``."""
        sims, idx = self.nearest(embedding, NEAREST)
        nearest = [(self.captions[int(i)], float(v)) for v, i in zip(sims, idx, strict=True)]
        return PromptMatch(prompt, nearest, nearest[0][1] >= UNKNOWN_BELOW)
