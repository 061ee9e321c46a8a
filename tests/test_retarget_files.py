"""Retargeting through files: `kinema retarget` onto GLB/BVH characters, FBX in (ufbx) and out (Blender),
and a walk on a Quaternius character that Blender's glTF importer opens with an animated skinned mesh.

The Blender tests run Debian's Blender 3.4 headless; they skip without it unless
KINEMA_REQUIRE_GLTF_TOOLS is set (.ci/run sets it and installs Blender), as tests/test_gltf_blender.py.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
from pathlib import Path

import pytest
import torch
from blender_gltf import blender_bone_heads, max_head_error
from retarget_rigs import MIXAMO, build_rig, source_walk

from kinema.cli import build_parser, main
from kinema.errors import KinemaError
from kinema.io.gltf import read_gltf
from kinema.motion.core import Motion
from kinema.retarget import fbx_writer, load_character, retarget, save_character_motion
from kinema.retarget.align import rest_frames
from kinema.retarget.fbx import read_fbx
from kinema.skeleton import Skeleton

ROOT = Path(__file__).resolve().parents[1]
QUATERNIUS = Path(os.environ.get("KINEMA_QUATERNIUS", ROOT.parent / "shared/datasets/quaternius"))
REQUIRED = bool(os.environ.get("KINEMA_REQUIRE_GLTF_TOOLS"))
BLENDER = fbx_writer.find_blender()
needs_blender = pytest.mark.skipif(not REQUIRED and BLENDER is None, reason="blender not found")


def _rest_motion(skeleton: Skeleton) -> Motion:
    return Motion(skeleton, 30, skeleton.offsets[0][None], skeleton.rest_rotations[None])


def _mixamo(tmp_path: Path) -> Path:
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.1, name="mixamo")
    return save_character_motion(_rest_motion(rig), tmp_path / "mixamo.glb")


def test_cli_retargets_an_npz_walk_onto_a_glb_and_a_bvh_character(tmp_path, capsys):
    walk = source_walk().save(tmp_path / "walk.npz")
    glb = _mixamo(tmp_path)
    assert main(["retarget", str(walk), "--rig", str(glb), "--out", str(tmp_path / "out.glb")]) == 0
    printed = capsys.readouterr().out
    assert "mapped by humanoid" in printed and "foot skate" in printed
    clip = next(iter(read_gltf(tmp_path / "out.glb").motions.values()))
    assert clip.skeleton.names == load_character(glb).skeleton.names and clip.num_frames == 60
    assert main(["retarget", str(walk), "--rig", str(glb), "--out", str(tmp_path / "out.bvh")]) == 0
    assert (tmp_path / "out.bvh").read_text().count("mixamorig:LeftForeArm") == 1


def test_cli_errors_are_one_line(tmp_path, capsys):
    walk = source_walk().save(tmp_path / "walk.npz")
    odd = Skeleton(["a", "b"], [-1, 0], [[0, 1, 0], [0, 1, 0]], name="stick")
    stick = save_character_motion(
        Motion(odd, 30, torch.zeros(1, 3), torch.tensor([[[1.0, 0, 0, 0]] * 2])), tmp_path / "stick.bvh"
    )
    assert main(["retarget", str(walk), "--rig", str(stick), "--out", str(tmp_path / "o.glb")]) == 2
    err = capsys.readouterr().err
    assert "shares no joint name" in err and err.count("\n") == 1
    assert main(["retarget", str(walk), "--rig", str(tmp_path / "none.fbx"), "--out", str(tmp_path / "o.glb")]) == 2
    assert "no such file" in capsys.readouterr().err
    (tmp_path / "bad.fbx").write_bytes(b"not an fbx")
    with pytest.raises(KinemaError, match="not a readable FBX"):
        load_character(tmp_path / "bad.fbx")


def test_fbx_out_without_blender_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.delenv("KINEMA_BLENDER", raising=False)
    monkeypatch.setattr(shutil, "which", lambda name: None)
    rig = build_rig(MIXAMO, prefix="mixamorig:")
    with pytest.raises(KinemaError, match="apt-get install blender"):
        save_character_motion(_rest_motion(rig), tmp_path / "x.fbx")
    assert not (tmp_path / "x.fbx").exists()


@needs_blender
def test_a_walk_on_an_fbx_character_comes_back_as_fbx_with_the_animation(tmp_path):
    glb_char = load_character(_mixamo(tmp_path))
    fbx = save_character_motion(_rest_motion(glb_char.skeleton), tmp_path / "mixamo.fbx")  # an FBX character
    character = load_character(fbx)
    assert character.kind == "fbx" and character.skeleton.mesh is not None and character.is_humanoid
    _, P_fbx = rest_frames(character.skeleton)
    _, P_glb = rest_frames(glb_char.skeleton)
    for j, name in enumerate(glb_char.skeleton.names):  # ufbx reads Blender's FBX in metres, Y up
        assert float((P_fbx[character.skeleton.names.index(name)] - P_glb[j]).norm()) < 1e-4, name
    out = retarget(source_walk(), character.skeleton)
    written = save_character_motion(out, tmp_path / "walk.fbx", name="walk")
    back = read_fbx(written)
    assert back.motion is not None and back.motion.fps == out.fps and back.motion.num_frames == out.num_frames
    names = back.motion.skeleton.names
    worst = max(
        float((back.motion.positions[:, names.index(n)] - out.positions[:, j]).norm(dim=-1).max())
        for j, n in enumerate(out.skeleton.names)
    )
    assert worst < 1e-3, f"FBX joints differ from the retargeted motion by {worst * 1000:.2f} mm"


@needs_blender
@pytest.mark.skipif(not QUATERNIUS.is_dir(), reason="shared Quaternius GLBs not found")
def test_blender_imports_a_walk_on_a_quaternius_character_with_its_skin(tmp_path):
    character = load_character(QUATERNIUS / "cyberpunk_pack/Character.glb")
    out = retarget(source_walk().crop(0, 24), character.skeleton)
    glb = save_character_motion(out, tmp_path / "walk.glb", name="walk")
    frames = [0, 7, 15, 23]
    report = blender_bone_heads(glb, tmp_path / "heads.json", "walk", [f / out.fps for f in frames], BLENDER)
    assert report["skinned"] and report["vertices"] == character.skeleton.mesh.num_vertices
    assert set(report["bones"]) == set(out.skeleton.names)
    assert max_head_error(report, out, frames) < 1e-4
    moved = [report["heads"][k]["LowerLeg.L"] for k in range(len(frames))]
    assert max(abs(a - b) for a, b in zip(moved[0], moved[-1], strict=True)) > 0.05  # the legs move


def test_commands_in_retarget_docs_parse():
    """Every `kinema` command docs/retarget.md shows is accepted by the real command line."""
    text = (ROOT / "docs/retarget.md").read_text()
    blocks = re.findall(r"^```bash\n(.*?)^```", text, flags=re.M | re.S)
    lines = [line for block in blocks for line in block.splitlines() if line.startswith("kinema ")]
    assert len(lines) >= 4
    parser = build_parser()
    for line in lines:
        args = parser.parse_args(shlex.split(line, comments=True)[1:])
        assert args.command in ("retarget", "inspect", "generate")
