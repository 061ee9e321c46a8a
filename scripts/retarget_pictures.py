"""The pictures and the per-rig table of docs/retarget.md.

    python scripts/retarget_pictures.py [--out docs/images] [--quaternius DIR]

Generates the default model's 'A person walks forward.' (3 s, 10 steps) and retargets it onto the
characters below. Draws the source and two Quaternius characters as kinema render filmstrips stacked
into one PNG (``retarget_walk.png``; pole-target helpers left out of the stick figures) and, with
Blender, as skinned renders side by side (``retarget_skinned.png``: rows source, cyberpunk
character, knight; columns frames 10-40). Prints a Markdown table per rig: limb-direction error vs
the source, foot skate vs the source (source centimetres per second), lowest joint against where the
rest pose puts it, bone-length drift. A Quaternius fox gallop onto the wolf and the husky too.

The Mixamo-, UE5- and CMU-named rigs are the test rigs of tests/retarget_rigs.py (built, not files).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the test rigs (tests/retarget_rigs.py)

from retarget_rigs import CMU, MIXAMO, UE5, build_rig, source_walk  # noqa: E402

from kinema.io import load_motion  # noqa: E402
from kinema.render import render_filmstrip  # noqa: E402
from kinema.retarget import build_joint_map, load_character, retarget_report, save_character_motion  # noqa: E402
from kinema.retarget.core import retarget_with_map  # noqa: E402
from kinema.rig.find import helpers  # noqa: E402


def _stack(pngs: list[Path], out: Path) -> None:
    images = [mpimg.imread(p)[..., :3] for p in pngs]
    width = max(im.shape[1] for im in images)
    padded = [np.pad(im, ((0, 0), (0, width - im.shape[1]), (0, 0)), constant_values=1.0) for im in images]
    mpimg.imsave(out, np.concatenate(padded, axis=0))


def _skinned_grid(motions: list, frames: list[int], out: Path, tmp: Path) -> bool:
    """One row per motion of Blender renders (scripts/blender_render_frames.py) at ``frames``; False
    without Blender."""
    blender = shutil.which("blender")
    if blender is None:
        return False
    rows = []
    for k, motion in enumerate(motions):
        glb = save_character_motion(motion, tmp / f"m{k}.glb")
        script = ROOT / "scripts/blender_render_frames.py"
        cmd = [
            blender,
            "-b",
            "--factory-startup",
            "--python",
            str(script),
            "--",
            str(glb),
            str(tmp / f"r{k}"),
            f"{motion.fps:g}",
            ",".join(map(str, frames)),
        ]
        subprocess.run(cmd, check=True, capture_output=True)
        rows.append(np.concatenate([mpimg.imread(tmp / f"r{k}_{f:03d}.png")[..., :3] for f in frames], axis=1))
    mpimg.imsave(out, np.concatenate(rows, axis=0))
    return True


def _no_poles(motion):
    """The motion without pole-target helpers (leaves under the root), for stick figures only."""
    skeleton = motion.skeleton
    return motion.prune([skeleton.names[j] for j in helpers(skeleton) if not skeleton.children[j]])


def _ankles(r: dict) -> str:
    if "ankle_cm" not in r:
        return "n/a (no legs)"
    return f"{r['ankle_source_cm']:.2f} / {r['ankle_cm']:.2f}"


def _row(name: str, r: dict) -> str:
    skate = (
        f"{r['skate_source_cm_s']:.2f} / {r['skate_target_cm_s']:.2f}" if "skate_source_cm_s" in r else "n/a (no legs)"
    )
    return (
        f"| {name} | {r['scale']:.3g} | {r['direction_deg_mean']:.1f} / {r['direction_deg_max']:.1f} | {skate} "
        f"| {r['lowest']:.4g} / {r['lowest_rest']:.4g} | {_ankles(r)} | {r['bone_drift_mm']:.2g} "
        f"| {r.get('twist_deg', 0.0):.0f} ({r.get('twist_bone', '-')}) |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs/images")
    parser.add_argument("--quaternius", type=Path, default=ROOT.parent / "shared/datasets/quaternius")
    args = parser.parse_args()
    q = args.quaternius
    source = source_walk()
    targets = {
        "Mixamo-named, A-pose, legs x1.2, arms x0.9 (GLB-style, bones along +Y)": build_rig(
            MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.2, arms=0.9
        ),
        "UE5-named, T-pose, bones along +X, root + ik_foot helpers, x1.1": build_rig(
            UE5, axis="x", root="root", legs=0.85, scale=1.1
        ),
        "CMU-named BVH, centimetres, arms x1.1": build_rig(CMU, axis=None, scale=100.0, arms=1.1),
    }
    for name in (
        "cyberpunk_pack/Character.glb",
        "platformer_game_pack/Character.glb",
        "single_knight_pack/KnightCharacter.glb",
        "mech_pack/George.glb",
    ):
        targets[f"Quaternius {name}"] = load_character(q / name).skeleton
    print(
        "| rig | body scale | direction error, deg (mean / max) | skate, cm/s (source / character) "
        "| lowest joint (clip / rest) | planted feet above rest, cm (source / character) | bone drift, mm "
        "| largest bone turn about itself, deg (bone) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    results = {}
    for name, skeleton in targets.items():
        jm = build_joint_map(source.skeleton, skeleton)
        results[name] = retarget_with_map(source, jm)
        print(_row(name, retarget_report(source, results[name], jm)))
    fox = load_motion(q / "animals_pack/Fox.glb", animation="Gallop")
    trex = load_motion(q / "dinosaurs_pack/Trex.glb", animation="TRex_Attack")
    creatures = [(fox, "Fox Gallop", "animals_pack", a) for a in ("Wolf", "Husky")]
    for clip, what, pack, animal in [*creatures, (trex, "Trex Attack", "dinosaurs_pack", "Parasaurolophus")]:
        jm = build_joint_map(clip.skeleton, load_character(q / f"{pack}/{animal}.glb").skeleton)
        print(
            _row(f"Quaternius {what} -> {animal} (same names)", retarget_report(clip, retarget_with_map(clip, jm), jm))
        )
    with tempfile.TemporaryDirectory() as tmp:
        pair = [
            results["Quaternius cyberpunk_pack/Character.glb"],
            results["Quaternius single_knight_pack/KnightCharacter.glb"],
        ]
        if _skinned_grid([source, *pair], [10, 20, 30, 40], args.out / "retarget_skinned.png", Path(tmp)):
            print(f"wrote {args.out / 'retarget_skinned.png'}")
        strips = [
            render_filmstrip(source, Path(tmp) / "src.png", frames=6, title="source: default model (Bandai skeleton)")
        ]
        for k, name in enumerate(
            ["Quaternius cyberpunk_pack/Character.glb", "Quaternius single_knight_pack/KnightCharacter.glb"]
        ):
            strips.append(render_filmstrip(_no_poles(results[name]), Path(tmp) / f"{k}.png", frames=6, title=name))
        args.out.mkdir(parents=True, exist_ok=True)
        _stack(strips, args.out / "retarget_walk.png")
    print(f"wrote {args.out / 'retarget_walk.png'}")


if __name__ == "__main__":
    main()
