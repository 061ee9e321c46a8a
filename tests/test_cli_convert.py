"""`kinema convert`: BVH -> npz / BVH round trips on real data and one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from kinema.cli import main
from kinema.io import load_motion
from kinema.io.bvh import read_bvh

CLIP = "Bandai-Namco-Research-Motiondataset-2/data/dataset-2_wave-right-hand_normal_002.bvh.gz"


@pytest.fixture(scope="module")
def clip(bandai_root) -> Path:
    """A Bandai clip with its static joint_Root (real, or the synthetic one of the same name: see conftest.py)."""
    return bandai_root / CLIP


def test_bvh_to_npz_follows_the_contract(clip, tmp_path, capsys):
    out = tmp_path / "clip.npz"
    assert main(["convert", str(clip), str(out), "--in-scale", "0.01", "--drop", "joint_Root"]) == 0
    assert "21 joints" in capsys.readouterr().out
    ref = read_bvh(clip, scale=0.01).prune(["joint_Root"])
    with np.load(out, allow_pickle=False) as d:
        assert d["joint_names"].tolist() == list(ref.skeleton.names)
        assert d["parents"].tolist() == list(ref.skeleton.parents)
        assert float(d["fps"]) == 30.0
        assert np.allclose(d["positions"], ref.positions.numpy(), atol=1e-5)
        assert np.allclose(d["root_translation"], ref.root_translation.numpy(), atol=1e-5)
        assert d["local_quats"].shape == (ref.num_frames, 21, 4)


@pytest.mark.parametrize("suffix,scale", [(".bvh", 1.0), (".bvh.gz", 100.0)])
def test_bvh_round_trip_through_cli(clip, tmp_path, suffix, scale):
    out = tmp_path / f"clip{suffix}"
    assert main(["convert", str(clip), str(out), "--in-scale", "0.01", "--out-scale", str(scale)]) == 0
    again = load_motion(out, scale=1.0 / scale)
    ref = read_bvh(clip, scale=0.01)
    assert torch.allclose(again.positions, ref.positions, atol=1e-4)


def test_npz_to_bvh_and_resample(clip, tmp_path):
    npz = tmp_path / "a.npz"
    main(["convert", str(clip), str(npz), "--in-scale", "0.01", "--drop", "joint_Root", "--fps", "20"])
    bvh = tmp_path / "a.bvh"
    assert main(["convert", str(npz), str(bvh)]) == 0
    assert load_motion(bvh).fps == 20
    assert torch.allclose(load_motion(bvh).positions.double(), load_motion(npz).positions.double(), atol=1e-4)


def test_errors_are_one_line_and_exit_2(clip, tmp_path, capsys):
    assert main(["convert", str(tmp_path / "missing.bvh"), str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.bvh" in err[0]
    bad = tmp_path / "bad.bvh"
    bad.write_text(
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.05\n0 0 0\n0 0\n"
    )
    assert main(["convert", str(bad), str(tmp_path / "y.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.bvh:11" in err[0]
    assert not (tmp_path / "y.npz").exists()
    assert main(["convert", str(clip), str(tmp_path / "z.fbx")]) == 2
    assert "unknown motion format" in capsys.readouterr().err
