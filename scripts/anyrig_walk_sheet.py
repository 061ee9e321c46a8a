"""Held-out rigs walking, next to the same rigs' own walk clips (issue 34's gallery).

    python scripts/anyrig_walk_sheet.py --model creatures --quaternius ../shared/datasets/quaternius \
        --out out/walk_sheet [--also OTHER_MODEL] [--seconds 3] [--steps 20] [--seed 0] [--only Rat Alpaca]

One sheet per file: row 1 the file's own walk clip with the travel its planted feet imply (the build's
root-motion recovery, kinema.data.quaternius.with_travel), looped to ``--seconds``; row 2 the model's
"<subject> walks forward." on the same file (skinned mesh kept); row 3 the same from ``--also`` (e.g. the
previous model) when given. Each row is an 8-frame `kinema render` filmstrip. Look at the sheets before
quoting them.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import torch
from anyrig_gallery import base_parser, film
from anyrig_sheet import stack

from kinema.data.creature_captions import clean_clip_name, creature_captions
from kinema.data.quaternius import with_travel
from kinema.generate import load_model
from kinema.io.gltf import read_gltf
from kinema.motion.core import Motion
from kinema.rig import Rig

#: held-out legged files (the build's val and test rigs with a walk clip)
FILES = [
    "animals_pack/Alpaca.glb",
    "animals_pack/Deer.glb",
    "dinosaurs_pack/Apatosaurus.glb",
    "dinosaurs_pack/Stegosaurus.glb",
    "dinosaurs_pack/Triceratops.glb",
    "easy_enemies_pack/Rat.glb",
    "cyberpunk_pack/Enemy_2Legs_Gun.glb",
    "cyberpunk_pack/Enemy_Large.glb",
    "platformer_game_pack/Character.glb",
]


def looped(m: Motion, frames: int) -> Motion:
    """A looping clip (last frame = first) repeated to ``frames`` frames, each lap starting where the last ended."""
    lap = m.num_frames - 1
    step = m.root_translation[-1] - m.root_translation[0]
    laps = -(-frames // lap)
    root = torch.cat([m.root_translation[:-1] + k * step for k in range(laps)])[:frames]
    rots = m.local_rotations[:-1].repeat(laps, 1, 1)[:frames]
    lt = None if m.local_translations is None else m.local_translations[:-1].repeat(laps, 1, 1)[:frames]
    return Motion(m.skeleton, m.fps, root, rots, None, lt)


def own_walk(path: Path, fps: float, seconds: float, out: Path, title: str) -> Path | None:
    """The file's walk clip with recovered travel, looped, saved as ``out``.glb and drawn to ``out``.png."""
    asset = read_gltf(path, fps=fps)
    name = next((n for n in asset.motions if clean_clip_name(n) == "walk"), None)
    if name is None:
        return None
    clip = asset.motions[name]
    got = with_travel(clip, Rig.from_skeleton(clip.skeleton))
    moved = got[0] if got is not None else clip
    m = looped(moved, round(seconds * fps))
    glb, png = out.with_suffix(".glb"), out.with_suffix(".png")
    m.save(glb)
    cmd = [sys.executable, "-m", "kinema", "render", str(glb), "--out", str(png), "--frames", "8", "--title", title]
    subprocess.run(cmd, check=True)
    return png


def main() -> int:
    ap = base_parser(__doc__.splitlines()[0], "out/walk_sheet")
    ap.add_argument("--also", help="a second model to draw below the first (e.g. the previous one)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="+", help="file stems to draw")
    args = ap.parse_args()
    (args.out / "rows").mkdir(parents=True, exist_ok=True)
    models = [(args.model, load_model(args.model, text_cache=Path("cache/text")))]
    if args.also:
        models.append((args.also, load_model(args.also, text_cache=Path("cache/text"))))
    fps = models[0][1].fps
    for rel in FILES:
        stem = Path(rel).stem
        if args.only and stem not in args.only:
            continue
        path = args.quaternius / rel
        prompt = next(c for c in creature_captions(rel, "Walk") if c.endswith(" walks."))[: -len(".")] + " forward."
        rows = [
            own_walk(
                path,
                fps,
                args.seconds,
                args.out / "rows" / f"{stem}_own",
                f"{stem}: its own walk clip, travel recovered from its feet (looped)",
            )
        ]
        for k, (name, model) in enumerate(models):
            rows.append(
                film(
                    model,
                    path,
                    prompt,
                    args.out / "rows" / f"{stem}_gen{k}",
                    f"{stem} (held out): {prompt} ({Path(name).name}, generated, seed {args.seed})",
                    seconds=args.seconds,
                    steps=args.steps,
                    seed=args.seed,
                )
            )
        stack([r for r in rows if r is not None], args.out / f"{stem}.png")
        print(f"wrote {args.out / f'{stem}.png'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
