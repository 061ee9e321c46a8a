"""Gallery of the any-rig ("creatures") model: one motion per (rig, prompt), saved as GLB (the rig's
skinned mesh kept) and drawn as a filmstrip PNG with `kinema render`.

    python scripts/anyrig_gallery.py --model runs/creatures --quaternius ../shared/datasets/quaternius \
        --out out/gallery [--seconds 3] [--steps 30]

Prints one line per motion (file, joints, wall time). Look at the PNGs before shipping them.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from kinema.generate import load_model

#: (file under the Quaternius root, prompt, picture name); the alpaca and the apatosaurus are held-out rigs
#: (the T-rex trains since the build keeps the biped dinosaur in train)
CASES = [
    ("cute_fish_pack/Anglerfish.glb", "An anglerfish swims.", "anglerfish_swims"),
    ("fish_pack/Shark.glb", "A shark swims.", "shark_swims"),
    ("animals_pack/Fox.glb", "A fox gallops.", "fox_gallops"),
    ("animals_pack/Fox.glb", "A fox attacks.", "fox_attacks"),
    ("animals_pack/Husky.glb", "A husky dies.", "husky_dies"),
    ("dinosaurs_pack/Trex.glb", "A T-rex attacks.", "trex_attacks"),
    ("dinosaurs_pack/Apatosaurus.glb", "An apatosaurus walks.", "apatosaurus_walks_heldout"),
    ("mech_pack/George.glb", "A robot walks.", "robot_walks"),
    ("single_knight_pack/KnightCharacter.glb", "A knight runs.", "knight_runs"),
    ("cyberpunk_pack/Character.glb", "A person punches with the right hand.", "person_punches"),
    ("animals_pack/Alpaca.glb", "An alpaca walks.", "alpaca_walks_heldout"),
]


def base_parser(description: str, out: str) -> argparse.ArgumentParser:
    """The options every creatures picture script shares (model, data root, output folder, length, steps)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--model", default="creatures")
    ap.add_argument("--quaternius", type=Path, default=Path("../shared/datasets/quaternius"))
    ap.add_argument("--out", type=Path, default=Path(out))
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--steps", type=int)
    return ap


def film(model, rig_file: Path, prompt: str, out: Path, title: str, *, seconds: float, steps, seed: int) -> Path:
    """Generate one motion on ``rig_file``, save it as ``out``.glb and draw its 8-frame filmstrip ``out``.png."""
    res = model.generate(prompt, rig=rig_file, seconds=seconds, steps=steps, seed=seed)
    glb, png = out.with_suffix(".glb"), out.with_suffix(".png")
    res[0].save(glb)
    cmd = [sys.executable, "-m", "kinema", "render", str(glb), "--out", str(png), "--frames", "8", "--title", title]
    subprocess.run(cmd, check=True)
    print(f"{png}: {res[0].num_joints} joints, {res.report.seconds:.1f} s", flush=True)
    return png


def main() -> int:
    ap = base_parser(__doc__.splitlines()[0], "out/gallery")
    ap.add_argument("--only", nargs="+", help="picture names to make")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    model = load_model(args.model, text_cache=Path("cache/text"))
    for file, prompt, name in CASES:
        if args.only and name not in args.only:
            continue
        title = f"{prompt} ({file.split('/')[-1]}, generated)"
        film(
            model,
            args.quaternius / file,
            prompt,
            args.out / name,
            title,
            seconds=args.seconds,
            steps=args.steps,
            seed=0,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
