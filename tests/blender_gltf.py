"""Blender's own glTF importer as an independent check, shared by tests/test_gltf_blender.py and
scripts/gltf_sweep.py: import a GLB headless (scripts/blender_gltf_check.py), read its bone heads at given
times, and compare them with a motion's joint positions (kinema: Y up; Blender: Z up)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[1] / "scripts/blender_gltf_check.py"


def blender_bone_heads(glb: Path, out: Path, clip: str, times, blender: str = "blender") -> dict:
    """Blender's report for ``clip`` of ``glb`` at ``times`` (seconds): bones, skinned, vertices, heads."""
    cmd = [
        blender,
        "-b",
        "--factory-startup",
        "--python",
        str(SCRIPT),
        "--",
        str(glb),
        str(out),
        clip,
        ",".join(f"{t:.9f}" for t in times),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if proc.returncode != 0 or not out.exists():
        raise RuntimeError(f"Blender import of {glb} failed: {proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return json.loads(out.read_text())


def max_head_error(report: dict, motion, frames) -> float:
    """Largest distance (metres) between Blender's bone heads and the motion's joints at ``frames``."""
    P = motion.positions.double().numpy()
    worst = 0.0
    for k, f in enumerate(frames):
        for name, (x, y, z) in report["heads"][k].items():
            # Blender is Z up: (x, y, z)_blender = (x, -z, y)_gltf
            want = P[f, motion.skeleton.names.index(name)]
            worst = max(worst, float(np.linalg.norm([x - want[0], z - want[1], -y - want[2]])))
    return worst
