"""`kinema convert`, `kinema inspect` and `kinema render` on glTF files (the synthetic rig of
tests/gltf_synthetic.py): every clip converts, names are file-safe, bad input exits 2 with one line."""

from __future__ import annotations

from pathlib import Path

import pytest
from gltf_synthetic import write_synthetic_glb

from kinema.cli import main
from kinema.cli.convert import clip_file_name
from kinema.io import load_motion
from kinema.io.gltf import read_gltf


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Path:
    return write_synthetic_glb(tmp_path_factory.mktemp("glb") / "rig.glb")


def test_convert_glb_to_bvh_npz_and_glb(rig, tmp_path, capsys):
    src = read_gltf(rig, fps=20).motions["Rig|Move"]
    for suffix in (".bvh", ".npz", ".glb"):
        out = tmp_path / f"move{suffix}"
        assert main(["convert", str(rig), str(out), "--animation", "Move", "--fps", "20"]) == 0
        back = load_motion(out)
        assert back.num_frames == src.num_frames and (back.positions - src.positions).abs().max() < 1e-5
    assert "its skinned mesh" in capsys.readouterr().out
    assert read_gltf(tmp_path / "move.glb").skeleton.mesh.num_vertices == 8


def test_convert_all_clips_names_files_per_clip(rig, tmp_path):
    assert main(["convert", str(rig), str(tmp_path / "out.bvh")]) == 0  # one clip: OUT itself
    assert (tmp_path / "out.bvh").is_file()
    assert clip_file_name(Path("x/fox.bvh.gz"), "AnimalArmature|Gallop Jump") == Path("x/fox_Gallop_Jump.bvh.gz")


def test_convert_errors_are_one_line(rig, tmp_path, capsys):
    assert main(["convert", str(rig), str(tmp_path / "o.bvh"), "--animation", "Swim"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no animation named 'Swim'" in err and "\n" not in err
    assert main(["convert", str(rig), str(tmp_path / "o.fbx")]) == 2
    assert "unknown motion format" in capsys.readouterr().err
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00\xff\xff\x00\x00")
    assert main(["convert", str(bad), str(tmp_path / "o.bvh")]) == 2
    assert "bad.glb" in capsys.readouterr().err and not (tmp_path / "o.bvh").exists()


def test_inspect_shows_tree_rig_and_clips(rig, capsys):
    assert main(["inspect", str(rig)]) == 0
    out = capsys.readouterr().out
    assert "armature scale 100 applied" in out and "helper joints dropped (no skin weight): Pole" in out
    assert "  Armature\n  ├─ Body\n  │  ├─ Neck\n  │  │  └─ Head\n  │  └─ Leg\n  └─ Foot" in out
    assert "roles found by name: " in out and "head=Head" in out
    assert "contact joints" in out and "Rig|Move" in out and "5 frames @ 4 fps" in out  # keys every 0.25 s


def test_render_draws_a_glb_rig(rig, tmp_path):
    out = tmp_path / "strip.png"
    assert main(["render", str(rig), "--animation", "Move", "--frames", "4", "--out", str(out)]) == 0
    assert out.stat().st_size > 1000


def test_bench_gltf_reports_throughput(rig, capsys):
    assert main(["bench", "gltf", "--root", str(rig.parent)]) == 0
    out = capsys.readouterr().out
    assert "glTF benchmark: 1 files" in out and "to Motion" in out and "container" in out


def test_glb_bvh_glb_through_the_cli_keeps_a_sliding_part(tmp_path):
    """A root whose only child slides (a Quaternius bouncer, spike trap): --exact-root keeps the root."""
    import torch

    from kinema.io.gltf_writer import write_glb
    from kinema.motion.core import Motion
    from kinema.skeleton import Skeleton

    sk = Skeleton(["Base", "Top"], [-1, 0], [[0, 0, 0], [0, 0.5, 0]])
    trans = sk.offsets.float().expand(8, -1, -1).clone()
    trans[:, 1, 1] += torch.linspace(0, 1.5, 8)
    rots = torch.zeros(8, 2, 4)
    rots[..., 0] = 1
    motion = Motion(sk, 24, torch.zeros(8, 3), rots, None, trans)
    src = write_glb(motion, tmp_path / "bouncer.glb", name="Bounce")
    assert main(["convert", str(src), str(tmp_path / "b.bvh")]) == 0
    assert main(["convert", str(tmp_path / "b.bvh"), str(tmp_path / "back.glb"), "--exact-root"]) == 0
    back = read_gltf(tmp_path / "back.glb").motions
    assert (next(iter(back.values())).positions - motion.positions).abs().max() < 1e-5
