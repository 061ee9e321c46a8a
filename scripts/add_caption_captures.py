"""Add how long each known caption's training clips last, how fast they travel and which content they show
to a model folder's known prompts, and the model's caption fidelity per content, keeping its captions,
embeddings, manner phrases, clips per action and probes bit for bit (what issues 57 and 58 did to the
default model; a fresh ``kinema export --known-prompts BUILD [--fidelity JSON ...]`` measures the build's
train clips itself).

    python scripts/add_caption_captures.py kinema/assets/models/default --data cache/bandai20h \
        [--fidelity out/fidelity.json ...]

The lengths and speeds are those of the build's train clips, counted as the export does (each source clip
once per side): the length is the window a longer prompt is continued in, the steady speed
(kinema.data.phases) the speed it keeps (kinema.human.continuation).
"""

from __future__ import annotations

import argparse
import statistics

import torch

from kinema.data.dataset import MotionDataset
from kinema.data.phases import steady_speeds
from kinema.model.vocabulary import (
    KnownPrompts,
    common_contents,
    median_seconds,
    median_speeds,
    read_content_fidelity,
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="model folder holding known_prompts.safetensors")
    ap.add_argument("--data", required=True, help="the dataset build the model's known prompts were made from")
    ap.add_argument("--fidelity", nargs="+", default=[], help="`kinema evaluate fidelity --out` results of the model")
    args = ap.parse_args()
    old = KnownPrompts.load(args.model)
    if old is None:
        raise SystemExit(f"{args.model}: no known_prompts.safetensors")
    dataset = MotionDataset(args.data, "train")
    once = {(rec.get("source_clip_id", rec["clip_id"]), rec.get("mirrored")): rec for rec in dataset.clips}
    clips = [[c.strip() for c in rec["captions"]] for rec in once.values()]
    extra = sorted({c for caps in clips for c in caps} - old.caption_set)
    if extra:
        raise SystemExit(f"{args.data}: {len(extra)} train captions are not in the file, e.g. {extra[0]!r}")
    seconds = median_seconds(old.captions, clips, [rec["duration_s"] for rec in once.values()])
    speeds = median_speeds(old.captions, clips, steady_speeds(dataset, once.values()))
    contents = common_contents(old.captions, clips, [rec["content"] for rec in once.values()])
    fidelity = read_content_fidelity(args.fidelity) if args.fidelity else old.content_fidelity
    probes = old.action_probes or None
    KnownPrompts(old.captions, old.embeddings, old.encoder_id, old.manner_phrases, old.action_clips, probes,
                 seconds, speeds, contents, fidelity).save(args.model)
    new = KnownPrompts.load(args.model)
    assert new.captions == old.captions and torch.equal(new.embeddings, old.embeddings)
    assert new.manner_phrases == old.manner_phrases and new.action_clips == old.action_clips
    assert new.action_probes == old.action_probes
    travel = [s for s in speeds if s is not None]
    print(f"{args.model}: {len(clips)} train clips; caption lengths {min(seconds):.2f}-{max(seconds):.2f} s, "
          f"median {statistics.median(seconds):.2f} s; {len(travel)} travelling captions at "
          f"{min(travel):.2f}-{max(travel):.2f} m/s; {len(set(contents))} contents, "
          f"{sum(not h for _, _, h in fidelity.values())} of {len(fidelity)} measured not holding")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
