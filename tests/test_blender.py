"""BVH written by kinema imports in Blender with the same joint positions (to well under 1 mm).

Runs Blender's own BVH importer through scripts/blender_import_check.py (see its docstring for the
import settings, the Y-up -> Z-up axis conversion and why no root or frame correction is needed) and
compares every bone head with kinema's forward kinematics on a handful of frames. Skipped when
``blender`` is not on PATH. Uses the Bandai walk (real, or the synthetic one: see conftest.py).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from kinema.io.bvh import read_bvh
from kinema.io.bvh_writer import write_bvh

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts/blender_import_check.py"
BLENDER = shutil.which("blender")

pytestmark = pytest.mark.skipif(BLENDER is None, reason="blender is not on PATH")

#: Blender world (Z up) from kinema world (Y up): x -> x, y -> z, z -> -y.
KINEMA_TO_BLENDER = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])


def _blender_heads(bvh: Path, out: Path, frames: list[int]) -> dict:
    cmd = [
        BLENDER,
        "-b",
        "--factory-startup",
        "--python",
        str(SCRIPT),
        "--",
        str(bvh),
        str(out),
        ",".join(map(str, frames)),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and out.exists(), proc.stdout[-2000:] + proc.stderr[-2000:]
    return json.loads(out.read_text())


@pytest.mark.parametrize("order", ["ZXY", "XYZ"])
def test_blender_import_matches_kinema_fk(walk_clip, tmp_path, order):
    motion = read_bvh(walk_clip, scale=0.01).prune(["joint_Root"])
    bvh = write_bvh(motion, tmp_path / "walk.bvh", order=order)  # metres, Y up
    T = motion.num_frames
    frames = [0, 1, 37, T // 2, T - 2, T - 1]
    report = _blender_heads(bvh, tmp_path / "heads.json", frames)

    assert report["num_frames"] == T
    assert report["bones"] == list(motion.skeleton.names)
    axis = np.array(report["axis_matrix"])[:3, :3]
    assert np.allclose(axis, KINEMA_TO_BLENDER)
    heads = np.array(report["heads"])  # (F, J, 3) Blender world, Z up
    back = heads @ axis  # row vectors: axis^T @ h, the inverse rotation -> kinema Y up
    want = motion.positions.numpy()[frames]
    err = np.linalg.norm(back - want, axis=-1)  # (F, J) metres
    worst = np.unravel_index(err.argmax(), err.shape)
    assert err.max() < 1e-3, (
        f"joint {motion.skeleton.names[worst[1]]} at frame {frames[worst[0]]} is off by {err.max() * 1000:.3f} mm"
    )
    # the check is not vacuous: the character walks several metres and, relative to the hips, some limb
    # moves over 10 cm between the compared frames (real walk: the left toes 0.43 m; synthetic: 0.25 m)
    limbs = want - want[:, :1]
    assert np.ptp(want[:, 0, 2]) > 5 and np.ptp(limbs, axis=0).max() > 0.1
