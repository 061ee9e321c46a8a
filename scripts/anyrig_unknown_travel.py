"""Ground measures of the creatures model on the clips whose travel the data does not hold (build flag
``in_place``: swims, flyers, the shin-ended person; kinema.train.anyrig.data.TRAVEL_UNKNOWN), and on two
held-out rigs named like them (the flying skull, the platformer person):

    python scripts/anyrig_unknown_travel.py --model creatures --data cache/quat20rm --out out/unknown.json

Each clip's first caption (or, with ``/in place``, its caption that says "in place") is generated on the
clip's own skeleton, in the build's units (lengths in body sizes), with post-processing, as a user gets it;
printed: ground speed (body sizes/s), forward share and net turn (kinema.evaluate.anyrig.locomotion).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from kinema.data.motion_cache import MotionCache
from kinema.evaluate.anyrig.locomotion import ground_measures
from kinema.generate import load_model
from kinema.representation.joint import JointRepresentation
from kinema.rig import Rig

#: (source file, clip content[/in place])
CASES = (
    ("cute_fish_pack/BlueTang.glb", "swim_normal"),
    ("fish_pack/Shark.glb", "swim"),
    ("fish_pack/Shark.glb", "swim/in place"),
    ("cyberpunk_pack/Character.glb", "run"),
    ("cyberpunk_pack/Character.glb", "run/in place"),
    ("easy_enemies_pack/Snake.glb", "walk"),
    ("cyberpunk_pack/Enemy_Flying_Gun.glb", "walk"),
    ("platformer_game_pack/Skull.glb", "walk"),
    ("platformer_game_pack/Character.glb", "run"),
    ("platformer_game_pack/Character.glb", "walk"),
)


def prompt_for(rec: dict, in_place: bool) -> str:
    if not in_place:
        return rec["captions"][0]
    said = [c for c in rec["captions"] if c.endswith(" in place.")]
    if not said:
        raise SystemExit(f"{rec['path']} {rec['content']}: no caption says 'in place'")
    return said[0]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="creatures")
    p.add_argument("--data", default="cache/quat20rm", help="the multi-rig build (kinema data build quaternius)")
    p.add_argument("--out", required=True, help="JSON file of the measures")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--steps", type=int, default=20)
    args = p.parse_args()
    torch.set_num_threads(1)
    model, cache = load_model(args.model), MotionCache(args.data)
    rows = []
    for path, case in CASES:
        content, _, in_place = case.partition("/")
        found = [i for i, r in enumerate(cache.clips) if r["path"] == path and r["content"] == content]
        if not found:
            print(f"{path} {content}: not in {args.data}; skipped")
            continue
        rec = cache.clips[found[0]]
        rig = Rig.from_skeleton(cache.motion(found[0]).skeleton)
        rep = JointRepresentation(rig, model.fps)
        prompt = prompt_for(rec, bool(in_place))
        for seed in args.seeds:
            m = model.generate(prompt, rig=rig, seconds=args.seconds, steps=args.steps, seed=seed)[0]
            g = ground_measures(m.to(torch.float64), rep)
            rows.append(dict(path=path, split=rec["split"], prompt=prompt, seed=seed,
                             **{k: round(v, 3) for k, v in g.items()}))
            r = rows[-1]
            print(f"{path:38s} {prompt:32s} seed {seed}: {r['speed']:.3f} body sizes/s, forward share "
                  f"{r['forward_share']:+.2f}, net turn {r['net_turn_deg']:.0f} deg", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
