"""Add how many training clips show each action to a model folder's known prompts, keeping its captions,
embeddings and manner phrases bit for bit (what issue 36 did to the default model; a fresh
``kinema export --known-prompts BUILD`` counts the build's train clips itself).

    python scripts/add_action_clips.py kinema/assets/models/default --root ../shared/datasets/bandai-namco

The clips are the Bandai Namco train split of ``kinema data build bandai-namco`` (the same split rule over
the same labels, every clip and its mirror), captioned as the build does (kinema.data.captions /
kinema.data.phrasings; the speed captions, which need the motion, name the clip's own walk or run and are
left out). The script checks that every template caption it makes is one of the file's captions. The counts
let the known prompts tell an action the model saw too rarely to learn (kick, dance) from one it learned
(kinema/model/vocabulary.py, MIN_ACTION_CLIPS).
"""

from __future__ import annotations

import argparse

import torch

from kinema.data.bandai import list_clips
from kinema.data.captions import captions_for
from kinema.data.phrasings import extra_captions
from kinema.data.split import assign_splits, group_of
from kinema.model.actions import clips_per_action
from kinema.model.vocabulary import MIN_ACTION_CLIPS, KnownPrompts


def train_clip_captions(root: str) -> list[list[str]]:
    """The captions of every train clip under ``root`` and of its mirror, without the speed captions."""
    clips = list_clips(root)
    splits = assign_splits([(c.clip_id, group_of(c.clip_id)) for c in clips])
    return [
        captions_for(c.content, c.style, mirrored) + extra_captions(c.content, c.style, None, mirrored)
        for c in clips
        if splits[c.clip_id] == "train"
        for mirrored in (False, True)
    ]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="model folder holding known_prompts.safetensors")
    ap.add_argument("--root", required=True, help="the Bandai Namco datasets folder the model was trained on")
    args = ap.parse_args()
    old = KnownPrompts.load(args.model)
    if old is None:
        raise SystemExit(f"{args.model}: no known_prompts.safetensors")
    clips = train_clip_captions(args.root)
    missing = sorted({c for caps in clips for c in caps} - old.caption_set)
    if missing:
        raise SystemExit(f"{args.model}: {len(missing)} train captions are not in the file, e.g. {missing[0]!r}")
    counts = clips_per_action(clips)
    KnownPrompts(old.captions, old.embeddings, old.encoder_id, old.manner_phrases, counts).save(args.model)
    new = KnownPrompts.load(args.model)
    assert new.captions == old.captions and torch.equal(new.embeddings, old.embeddings)
    assert new.manner_phrases == old.manner_phrases and new.action_clips == counts
    print(f"{args.model}: {len(clips)} train clips (with mirrors); clips per action {counts}")
    print(f"not learned (< {MIN_ACTION_CLIPS} clips): {sorted(new.named_actions - new.learned)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
