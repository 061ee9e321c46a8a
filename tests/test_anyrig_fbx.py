"""The creatures model on a rig given as an FBX file (ufbx in, Blender out): the rig it reads is the one
the same character's GLB gives (helper bones dropped alike), the walk goes forward on it, and the FBX it
writes carries the motion with the skin. Writing the FBX fixture needs Blender: these tests skip without
it unless KINEMA_REQUIRE_GLTF_TOOLS is set (.ci/run sets it and installs Blender)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from kinema.cli import main
from kinema.evaluate.anyrig.locomotion import ground_measures
from kinema.generate import load_model
from kinema.motion.core import Motion
from kinema.representation.joint import JointRepresentation
from kinema.retarget import fbx_writer, load_character, save_character_motion
from kinema.retarget.align import rest_frames
from kinema.retarget.fbx import read_fbx

ROOT = Path(__file__).resolve().parents[1]
QUATERNIUS = Path(os.environ.get("KINEMA_QUATERNIUS", ROOT.parent / "shared/datasets/quaternius"))
ALPACA = QUATERNIUS / "animals_pack/Alpaca.glb"  # held out of the creatures model's training
REQUIRED = bool(os.environ.get("KINEMA_REQUIRE_GLTF_TOOLS"))
pytestmark = [
    pytest.mark.skipif(not REQUIRED and fbx_writer.find_blender() is None, reason="blender not found"),
    pytest.mark.skipif(not ALPACA.is_file(), reason="shared Quaternius GLBs not found"),
]


@pytest.fixture(scope="module")
def alpaca_fbx(tmp_path_factory) -> Path:
    """The alpaca character (every bone, its skin) written as FBX by Blender, as a user's FBX would be."""
    sk = load_character(ALPACA).skeleton
    rest = Motion(sk, 30, sk.offsets[0][None], sk.rest_rotations[None])
    return save_character_motion(rest, tmp_path_factory.mktemp("fbx") / "alpaca.fbx")


def test_an_fbx_rig_is_read_as_its_glb_is_and_walks_forward(alpaca_fbx) -> None:
    model = load_model("creatures")
    from_fbx, from_glb = model.resolve_rig(alpaca_fbx), model.resolve_rig(ALPACA)
    assert read_fbx(alpaca_fbx).skeleton.num_joints > from_fbx.skeleton.num_joints  # pole targets dropped
    assert from_fbx.skeleton.names == from_glb.skeleton.names
    (_, P_fbx), (_, P_glb) = rest_frames(from_fbx.skeleton), rest_frames(from_glb.skeleton)
    assert float((P_fbx - P_glb).norm(dim=-1).max()) < 1e-3  # the same rest pose, in metres, Y up
    walk = model.generate("An alpaca walks forward.", rig=alpaca_fbx, seconds=3, steps=10, seed=0)[0]
    assert walk.skeleton.names == from_fbx.skeleton.names
    g = ground_measures(walk.to(torch.float64), JointRepresentation(from_fbx, model.fps))
    assert g["forward_share"] > 0.9 and g["travel"] > 0.3, g


def test_the_cli_writes_a_creature_motion_on_an_fbx_rig_as_fbx(alpaca_fbx, tmp_path, capsys) -> None:
    out = tmp_path / "walk.fbx"
    args = ["generate", "An alpaca walks forward.", "--model", "creatures", "--rig", str(alpaca_fbx), "--seconds",
            "2", "--steps", "5", "--out", str(out)]
    assert main(args) == 0
    back = read_fbx(out)
    assert back.motion is not None and back.motion.num_frames == 40
    assert back.skeleton.mesh is not None
    assert back.skeleton.mesh.num_vertices == read_fbx(alpaca_fbx).skeleton.mesh.num_vertices
    travel = float((back.motion.positions[-1, 0] - back.motion.positions[0, 0]).norm())
    assert travel > 0.1  # the motion is in the file, not the rest pose
