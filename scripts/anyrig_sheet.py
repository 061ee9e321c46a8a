"""Contact sheet of the any-rig ("creatures") model: the issue's five actions (walk, run/gallop, attack,
idle, death) on rigs of different topology, one filmstrip row per action, one PNG per rig.

    python scripts/anyrig_sheet.py --model creatures --quaternius ../shared/datasets/quaternius \
        --out out/sheet [--seconds 3] [--steps 20] [--seed 0] [--only fox knight]

Each motion is generated with the rig's own words (the captions its clips have in the Quaternius build),
saved as GLB (skinned mesh kept), drawn with `kinema render` (8 frames) and the rows stacked into
``<rig>.png``. The parasaurolophus (biped dinosaur, also the T-rex) is a training rig since the build keeps
it in train (`kinema.data.quaternius.DEFAULT_TRAIN_RIGS`); apatosaurus, rat, alpaca and the platformer
character are held out. Look at the sheets before quoting them.
"""

from __future__ import annotations

import sys
from pathlib import Path

from anyrig_gallery import base_parser, film
from PIL import Image

from kinema.generate import load_model

#: rig name -> (file under the Quaternius root, split, [(action, prompt), ...])
SHEETS: dict[str, tuple[str, str, list[tuple[str, str]]]] = {
    "anglerfish": (
        "cute_fish_pack/Anglerfish.glb",
        "train",
        [
            ("swim", "An anglerfish swims."),
            ("swim fast", "A fish swims fast."),
            ("attack", "A fish attacks."),
            ("flop (no idle clip)", "A fish flops about out of the water."),
            ("death", "A fish dies."),
        ],
    ),
    "fox": (
        "animals_pack/Fox.glb",
        "train",
        [
            ("walk", "A fox walks."),
            ("gallop", "A fox gallops."),
            ("attack", "A fox attacks."),
            ("idle", "A fox stands idle."),
            ("death", "A fox dies."),
        ],
    ),
    "knight": (
        "single_knight_pack/KnightCharacter.glb",
        "train",
        [
            ("walk", "A knight walks."),
            ("run", "A knight runs."),
            ("attack", "A knight runs and attacks with a sword."),
            ("idle", "A knight stands idle."),
            ("death", "A knight dies."),
        ],
    ),
    "george": (
        "mech_pack/George.glb",
        "train",
        [
            ("walk", "A robot walks."),
            ("run", "A robot runs."),
            ("attack", "A robot punches."),
            ("idle", "A robot stands idle."),
            ("death", "A robot dies."),
        ],
    ),
    "enemy-2legs": (
        "cyberpunk_pack/Enemy_2Legs.glb",
        "train",
        [
            ("walk", "A robot walks."),
            ("run", "A robot runs."),
            ("attack", "A robot attacks."),
            ("idle", "A robot stands idle."),
            ("death", "A robot dies."),
        ],
    ),
    "parasaurolophus": (
        "dinosaurs_pack/Parasaurolophus.glb",
        "train",
        [
            ("walk", "A parasaurolophus walks."),
            ("run", "A parasaurolophus runs."),
            ("attack", "A parasaurolophus attacks."),
            ("idle", "A parasaurolophus stands idle."),
            ("death", "A parasaurolophus dies."),
        ],
    ),
    "apatosaurus": (
        "dinosaurs_pack/Apatosaurus.glb",
        "held out",
        [
            ("walk", "An apatosaurus walks."),
            ("run", "An apatosaurus runs."),
            ("attack", "An apatosaurus attacks."),
            ("idle", "An apatosaurus stands idle."),
            ("death", "An apatosaurus dies."),
        ],
    ),
    "rat": (
        "easy_enemies_pack/Rat.glb",
        "held out",
        [
            ("walk", "A rat walks."),
            ("run", "A rat runs."),
            ("attack", "A rat attacks."),
            ("idle", "A rat stands idle."),
            ("death", "A rat dies."),
        ],
    ),
    "alpaca": (
        "animals_pack/Alpaca.glb",
        "held out",
        [
            ("walk", "An alpaca walks."),
            ("gallop", "An alpaca gallops."),
            ("attack", "An alpaca attacks with a headbutt."),
            ("idle", "An alpaca stands idle."),
            ("death", "An alpaca dies."),
        ],
    ),
    "character-2": (
        "platformer_game_pack/Character.glb",
        "held out",
        [
            ("walk", "A person walks."),
            ("run", "A person runs."),
            ("attack", "A person punches."),
            ("idle", "A person stands idle."),
            ("death", "A person dies."),
        ],
    ),
}


def stack(pngs: list[Path], out: Path) -> None:
    """Stack filmstrips vertically (white background) into one sheet."""
    images = [Image.open(p).convert("RGB") for p in pngs]
    sheet = Image.new("RGB", (max(i.width for i in images), sum(i.height for i in images)), "white")
    y = 0
    for image in images:
        sheet.paste(image, (0, y))
        y += image.height
    sheet.save(out)


def main() -> int:
    ap = base_parser(__doc__.splitlines()[0], "out/sheet")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="+", choices=sorted(SHEETS), help="rigs to draw")
    args = ap.parse_args()
    (args.out / "rows").mkdir(parents=True, exist_ok=True)
    model = load_model(args.model, text_cache=Path("cache/text"))
    for rig, (file, split, rows) in SHEETS.items():
        if args.only and rig not in args.only:
            continue
        pngs = [
            film(
                model,
                args.quaternius / file,
                prompt,
                args.out / "rows" / f"{rig}_{i}",
                f"{rig} ({split}) {action}: {prompt} ({Path(file).name}, generated, seed {args.seed})",
                seconds=args.seconds,
                steps=args.steps,
                seed=args.seed,
            )
            for i, (action, prompt) in enumerate(rows)
        ]
        stack(pngs, args.out / f"{rig}.png")
        print(f"wrote {args.out / f'{rig}.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
