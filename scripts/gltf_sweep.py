"""Convert every shared Quaternius GLB to BVH and back to GLB, and check the results.

For each file: read every clip (kinema.io.gltf), write each clip as BVH (Motion.save), read the BVH back,
put the rig's skin back on (BVH has no mesh; the rest pose geometry is unchanged), write one GLB with
all clips, then compare every joint's world position in the final GLB with the source GLB at every
frame, using the independent pygltflib forward kinematics of tests/gltf_reference.py. Optionally runs
the Khronos validator over every written GLB (``--validate``; needs node + npm gltf-validator) and
imports each written GLB in Blender (``--blender``: first clip, first/middle/last frame, every bone head
against kinema's forward kinematics; needs ``blender`` with python3-numpy).

    python scripts/gltf_sweep.py --root ../shared/datasets/quaternius --out /tmp/sweep [--validate] [--blender]

Prints one line per file and a summary (files, clips, worst error, failures with their reason); exit
status 1 when any file fails.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pygltflib

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from blender_gltf import blender_bone_heads, max_head_error  # noqa: E402
from gltf_reference import world_positions  # noqa: E402

from kinema.io.bvh import read_bvh  # noqa: E402
from kinema.io.gltf import read_gltf  # noqa: E402
from kinema.io.gltf_writer import write_glb  # noqa: E402
from kinema.skeleton import Skeleton  # noqa: E402


def _with_mesh(skeleton: Skeleton, source: Skeleton) -> Skeleton:
    """``skeleton`` (read from BVH) wearing ``source``'s skin, joints matched by name."""
    mesh = source.mesh.remap_joints([source.names.index(n) for n in skeleton.names]) if source.mesh else None
    return Skeleton(
        skeleton.names,
        skeleton.parents,
        skeleton.offsets,
        skeleton.rest_rotations,
        skeleton.end_sites,
        skeleton.role_overrides,
        skeleton.name,
        mesh,
    )


def sweep_file(src: Path, out: Path) -> tuple[int, float, Path, tuple[str, ...]]:
    """(clips, worst position error in metres, written GLB, reader warnings) for one source file."""
    asset = read_gltf(src)
    back = {}
    for k, (clip, motion) in enumerate(asset.motions.items()):
        bvh = motion.save(out / f"{src.stem}_{k}.bvh")
        again = read_bvh(bvh, root_follows_child=False)  # the root is a real bone here, not Bandai's dummy
        skeleton = _with_mesh(again.skeleton, asset.skeleton)
        back[clip] = type(again)(
            skeleton, again.fps, again.root_translation, again.local_rotations, None, again.local_translations
        )
    glb = write_glb(back, out / f"{src.stem}.glb")
    worst = 0.0
    source, written = pygltflib.GLTF2().load(str(src)), pygltflib.GLTF2().load(str(glb))
    for clip, motion in asset.motions.items():
        anim = next(a for a in source.animations if a.name == clip)
        start = min(source.accessors[s.input].min[0] for s in anim.samplers)  # kinema samples from the first key
        times = np.arange(motion.num_frames) / motion.fps
        a, b = world_positions(source, clip, times + start), world_positions(written, clip, times)
        worst = max(worst, max(float(np.abs(a[n] - b[n]).max()) for n in motion.skeleton.names if n in a))
    return len(asset.motions), worst, glb, asset.warnings


def blender_error(glb: Path, work: Path) -> float:
    """Largest distance (metres) between Blender's bone heads and kinema's joints, first clip of ``glb``."""
    clip, motion = next(iter(read_gltf(glb).motions.items()))
    frames = sorted({0, motion.num_frames // 2, motion.num_frames - 1})
    report = blender_bone_heads(glb, work / f"{glb.stem}.heads.json", clip, [f / motion.fps for f in frames])
    return max_head_error(report, motion, frames)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", type=Path, default=REPO.parent / "shared/datasets/quaternius")
    ap.add_argument("--out", type=Path, required=True, help="folder for the BVH and GLB files")
    ap.add_argument("--validate", action="store_true", help="run the Khronos validator on every GLB")
    ap.add_argument("--blender", action="store_true", help="import every written GLB in Blender and compare")
    ap.add_argument("--tolerance", type=float, default=1e-5, help="largest position error, metres (0.01 mm)")
    args = ap.parse_args()
    files = sorted(args.root.rglob("*.glb"))
    args.out.mkdir(parents=True, exist_ok=True)
    started, clips, worst, failures, written = time.perf_counter(), 0, 0.0, [], []
    for i, src in enumerate(files):
        rel = src.relative_to(args.root)
        folder = args.out / rel.parent.name
        folder.mkdir(exist_ok=True)
        try:
            n, err, glb, warns = sweep_file(src, folder)
        except Exception as exc:  # report and go on: the summary lists every failure
            failures.append(f"{rel}: {type(exc).__name__}: {exc}")
            print(f"[{i + 1}/{len(files)}] {rel}: FAILED {exc}", flush=True)
            continue
        clips, worst, written = clips + n, max(worst, err), written + [glb]
        if err > args.tolerance:
            why = f" (reader warnings: {'; '.join(warns)})" if warns else ""
            failures.append(f"{rel}: joint positions differ by {err * 1000:.4f} mm{why}")
        print(f"[{i + 1}/{len(files)}] {rel}: {n} clips, max error {err * 1000:.5f} mm", flush=True)
    if args.validate and written:
        proc = subprocess.run(
            ["node", str(REPO / "scripts/gltf_validate.js"), *map(str, written)], capture_output=True, text=True
        )
        reports = [json.loads(line) for line in proc.stdout.splitlines()]
        bad = [r for r in reports if r["errors"]]
        failures += [f"{r['file']}: validator errors {r['messages']}" for r in bad]
        print(
            f"validator: {len(reports)} GLBs, {len(bad)} with errors, "
            f"{sum(r['warnings'] for r in reports)} warnings in all"
        )
    if args.blender and written:
        errors = {}
        for glb in written:
            try:
                errors[glb] = blender_error(glb, args.out)
            except Exception as exc:  # report and go on
                failures.append(f"{glb}: {exc}")
        bad = {g: e for g, e in errors.items() if e > args.tolerance}
        failures += [f"{g}: Blender bone heads off by {e * 1000:.4f} mm" for g, e in bad.items()]
        print(
            f"Blender: {len(errors)} GLBs imported, worst bone head error "
            f"{max(errors.values(), default=0) * 1000:.5f} mm, {len(bad)} over tolerance"
        )
    print(
        f"{len(files)} files, {clips} clips, worst joint position error {worst * 1000:.5f} mm, "
        f"{len(failures)} failures, {time.perf_counter() - started:.0f} s"
    )
    for f in failures:
        print("  " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
