"""Add the training captions' manner phrases to a model folder's known prompts, keeping its captions and
embeddings bit for bit (what stop 30 did to the default model; a fresh ``kinema export --known-prompts``
writes the same phrases, but re-embeds the captions).

    python scripts/add_manner_phrases.py kinema/assets/models/default

The phrases (kinema.data.phrasings.manner_phrases: style and speed words) let prompt grounding keep a
prompt that names no manner off captions that name one (kinema/model/grounding.py).
"""

from __future__ import annotations

import argparse

import torch

from kinema.data.phrasings import manner_phrases
from kinema.model.vocabulary import KnownPrompts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="model folder holding known_prompts.safetensors")
    args = ap.parse_args()
    old = KnownPrompts.load(args.model)
    if old is None:
        raise SystemExit(f"{args.model}: no known_prompts.safetensors")
    used = KnownPrompts.phrases_in(manner_phrases(), old.captions)
    KnownPrompts(old.captions, old.embeddings, old.encoder_id, used).save(args.model)
    new = KnownPrompts.load(args.model)
    assert new.captions == old.captions and torch.equal(new.embeddings, old.embeddings)
    named = int(new.mannered.sum())
    print(f"{args.model}: {len(used)} manner phrases; {named} of {len(new.captions)} captions name one")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
