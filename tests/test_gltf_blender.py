"""GLB written by kinema imports in Blender (its own glTF importer, headless) with the same joint positions.

Runs scripts/blender_gltf_check.py inside Blender and compares every bone head with kinema's forward
kinematics at several frame times (< 0.01 mm). Skipped when ``blender`` is not on PATH or its Python has
no numpy (Debian: ``apt-get install blender python3-numpy``; .ci/run installs both).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from blender_gltf import blender_bone_heads, max_head_error
from gltf_synthetic import write_synthetic_glb

from kinema.io.bvh import read_bvh
from kinema.io.gltf import read_gltf
from kinema.io.gltf_writer import write_glb

ROOT = Path(__file__).resolve().parents[1]
BLENDER = shutil.which("blender")


def _blender_has_numpy() -> bool:
    if BLENDER is None:
        return False
    probe = [BLENDER, "-b", "--factory-startup", "--python-expr", "import numpy, sys; sys.exit(0)"]
    proc = subprocess.run(probe, capture_output=True, text=True, timeout=120)
    return proc.returncode == 0 and "Error" not in proc.stderr + proc.stdout


REQUIRED = bool(os.environ.get("KINEMA_REQUIRE_GLTF_TOOLS"))  # set by .ci/run: a missing tool is a failure
pytestmark = pytest.mark.skipif(
    not REQUIRED and not _blender_has_numpy(), reason="blender with numpy (python3-numpy) not found"
)


def _check(glb: Path, clip: str, motion, tmp_path: Path) -> None:
    frames = sorted({0, 1, motion.num_frames // 2, motion.num_frames - 1})
    report = blender_bone_heads(glb, tmp_path / "heads.json", clip, [f / motion.fps for f in frames], BLENDER)
    assert set(report["bones"]) == set(motion.skeleton.names)
    assert report["skinned"] and report["vertices"] > 0
    worst = max_head_error(report, motion, frames)
    assert worst < 1e-5, f"Blender bone heads differ from kinema by up to {worst * 1000:.4f} mm"


def test_blender_imports_a_glb_rig(tmp_path):
    src = write_synthetic_glb(tmp_path / "rig.glb")
    motion = read_gltf(src, fps=24).motions["Rig|Move"]
    glb = write_glb(motion, tmp_path / "out.glb", name="Move")
    _check(glb, "Move", motion, tmp_path)


def test_blender_imports_the_bvh_human(walk_clip, tmp_path):
    human = read_bvh(walk_clip, scale=0.01).prune(["joint_Root"]).crop(0, 24).resample(24)
    glb = write_glb(human, tmp_path / "human.glb", name="walk")
    _check(glb, "walk", human, tmp_path)


QUATERNIUS = Path(os.environ.get("KINEMA_QUATERNIUS", ROOT.parent / "shared/datasets/quaternius"))


@pytest.mark.skipif(not QUATERNIUS.is_dir(), reason="shared Quaternius GLBs not found")
def test_blender_imports_a_quaternius_fox(tmp_path):
    asset = read_gltf(QUATERNIUS / "animals_pack/Fox.glb", animations=["Gallop"])
    motion = asset.motions["AnimalArmature|Gallop"]
    glb = write_glb(motion, tmp_path / "fox.glb", name="Gallop")
    _check(glb, "Gallop", motion, tmp_path)
