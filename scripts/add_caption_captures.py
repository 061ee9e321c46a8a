"""Add how long each known caption's training clips last to a model folder's known prompts, keeping its
captions, embeddings, manner phrases, clips per action and probes bit for bit (what issue 57 did to the
default model; a fresh ``kinema export --known-prompts BUILD`` measures the build's train clips itself).

    python scripts/add_caption_seconds.py kinema/assets/models/default --data cache/bandai20h

The lengths are those of the build's train clips, counted as the export does (each source clip once per
side). They are the windows a longer prompt is continued in (kinema.human.continuation).
"""

from __future__ import annotations

import argparse
import statistics

import torch

from kinema.data.dataset import MotionDataset
from kinema.model.vocabulary import KnownPrompts, median_seconds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="model folder holding known_prompts.safetensors")
    ap.add_argument("--data", required=True, help="the dataset build the model's known prompts were made from")
    args = ap.parse_args()
    old = KnownPrompts.load(args.model)
    if old is None:
        raise SystemExit(f"{args.model}: no known_prompts.safetensors")
    records = MotionDataset(args.data, "train").clips
    once = {(rec.get("source_clip_id", rec["clip_id"]), rec.get("mirrored")): rec for rec in records}
    clips = [[c.strip() for c in rec["captions"]] for rec in once.values()]
    extra = sorted({c for caps in clips for c in caps} - old.caption_set)
    if extra:
        raise SystemExit(f"{args.data}: {len(extra)} train captions are not in the file, e.g. {extra[0]!r}")
    seconds = median_seconds(old.captions, clips, [rec["duration_s"] for rec in once.values()])
    probes = old.action_probes or None
    KnownPrompts(old.captions, old.embeddings, old.encoder_id, old.manner_phrases, old.action_clips, probes,
                 seconds).save(args.model)
    new = KnownPrompts.load(args.model)
    assert new.captions == old.captions and torch.equal(new.embeddings, old.embeddings)
    assert new.manner_phrases == old.manner_phrases and new.action_clips == old.action_clips
    assert new.action_probes == old.action_probes
    print(f"{args.model}: {len(clips)} train clips; caption lengths {min(seconds):.2f}-{max(seconds):.2f} s, "
          f"median {statistics.median(seconds):.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
