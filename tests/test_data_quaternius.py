"""`kinema data build quaternius` on a few shared files, and GLB files in the folder build.

The real-data tests read ``../shared/datasets/quaternius`` from the repository (or
``$KINEMA_DATASETS/quaternius``) and skip without it; they read three GLBs (a few seconds).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
import torch
from gltf_synthetic import write_synthetic_glb

from kinema.cli import main
from kinema.data.folder import build_folder
from kinema.data.motion_cache import MotionCache
from kinema.data.quaternius import build_quaternius
from kinema.errors import DataError
from kinema.io.gltf import read_gltf

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("KINEMA_DATASETS") or REPO.parent / "shared/datasets") / "quaternius"


@pytest.fixture(scope="module")
def quaternius_root() -> Path:
    if not (SHARED / "animals_pack" / "Bull.glb").is_file():
        pytest.skip("needs the shared Quaternius data (../shared/datasets/quaternius)")
    return SHARED


def test_build_keeps_the_biped_dinosaur_in_train(quaternius_root, tmp_path) -> None:
    """The default quaternius build never holds the parasaurolophus (biped dinosaur) rig out, whatever
    the hash rule says; ``train_rigs=()`` gives the plain hash split, and with fewer than three rigs
    (clips split inside each rig) a kept rig's clips all train."""
    root = tmp_path / "zoo"
    for rel in ("dinosaurs_pack/Parasaurolophus.glb", "animals_pack/Bull.glb", "easy_enemies_pack/Rat.glb"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).symlink_to(quaternius_root / rel)
    plain, _ = build_quaternius(root, tmp_path / "plain", fps=20, train_rigs=(), progress=False)
    assert "kept in train" not in plain["split_rule"]
    held = {r["rig"] for r in MotionCache(tmp_path / "plain").rigs.values() if r["split"] != "train"}
    assert "parasaurolophus" in held
    meta, _ = build_quaternius(root, tmp_path / "kept", fps=20, progress=False)
    assert meta["split_rule"].endswith("kept in train: parasaurolophus")
    splits = {r["rig"]: r["split"] for r in MotionCache(tmp_path / "kept").rigs.values()}
    assert splits["parasaurolophus"] == "train" and {"val", "test"} & set(splits.values())
    (root / "easy_enemies_pack/Rat.glb").unlink()
    build_quaternius(root, tmp_path / "two", fps=20, progress=False)
    cache = MotionCache(tmp_path / "two")
    assert {r["split"] for r in cache.clips if r["rig"] == "parasaurolophus"} == {"train"}
    assert {r["split"] for r in cache.clips if r["rig"] != "parasaurolophus"} == {"train", "val", "test"}


def test_build_three_files(quaternius_root, tmp_path, capsys) -> None:
    out = tmp_path / "quat"
    # the first three files: Alpaca, Bull and Cow (Bull and Cow share one rig and most clips)
    meta, _ = build_quaternius(quaternius_root, out, fps=20, limit=3, progress=False)
    c = meta["counts"]
    assert (c["files"], c["rigs"], c["source_clips"]) == (3, 2, 37)
    assert c["duplicates_dropped"] == 3  # Cow repeats three of Bull's animations exactly (Attack_Kick, ...)
    cache = MotionCache(out)
    bull = next(r for r in cache.rigs.values() if "animals_pack/Bull.glb" in r["files"])
    assert bull["files"] == ["animals_pack/Bull.glb", "animals_pack/Cow.glb"]
    assert set(bull["file_scales"]) == set(bull["files"]) and all(s > 0 for s in bull["file_scales"].values())
    by_id = {r["clip_id"]: r for r in cache.clips}
    gallop = by_id["animals_pack/Alpaca.glb#AnimalArmature|Gallop"]
    assert gallop["captions"][0] == "An alpaca gallops." and gallop["flags"] == ["travel_recovered"]
    assert gallop["travel"] > 0.5 and gallop["recovered_speed"] > 1.0  # on the spot in the file; feet say it goes
    assert meta["forward_check"]["animals_pack/Alpaca.glb"] > 0.99  # its walk goes along +Z, its forward axis
    walk = by_id["animals_pack/Alpaca.glb#AnimalArmature|Walk"]
    assert 0.1 < walk["recovered_speed"] < gallop["recovered_speed"] / 1.3
    idle = by_id["animals_pack/Alpaca.glb#AnimalArmature|Idle"]
    assert idle["travel"] < 0.01 and "travel_recovered" not in idle["flags"]
    assert gallop["content"] == "gallop" and gallop["style"] == "alpaca" and gallop["fps"] == 20
    kick = by_id["animals_pack/Bull.glb#AnimalArmature|Attack_Kick"]
    assert "animals_pack/Cow.glb#AnimalArmature|Attack_Kick" in kick["duplicates"]
    m = cache.motion(cache.clips.index(gallop))
    assert m.skeleton.names == tuple(cache.rigs[gallop["rig"]]["names"])
    extent = (m.positions[0].max(0).values - m.positions[0].min(0).values).max()
    assert 0.5 < float(extent) < 2.0  # normalised rest size 1; a gallop frame is about that
    # the stored motion is the reader's, scaled by the file's factor (bone translations included)
    source = read_gltf(quaternius_root / "animals_pack" / "Bull.glb", fps=20).motions["AnimalArmature|Attack_Kick"]
    stored = cache.motion(cache.clips.index(kick))
    scale = bull["file_scales"]["animals_pack/Bull.glb"]
    assert torch.allclose(stored.positions.double(), source.positions * scale, atol=1e-5)
    assert main(["data", "stats", str(out)]) == 0
    table = capsys.readouterr().out
    assert "quaternius; 2 rigs" in table and "bull" in table and "flags: travel_recovered" in table


def test_glb_in_folder_build(quaternius_root, tmp_path) -> None:
    root = tmp_path / "mine"
    root.mkdir()
    shutil.copy(quaternius_root / "animals_pack" / "Fox.glb", root / "Fox.glb")
    lines = [
        {"file": "Fox.glb#AnimalArmature|Gallop", "captions": ["A fox gallops."]},
        {"file": "Fox.glb#AnimalArmature|Walk", "caption": "A fox walks."},
    ]
    (root / "captions.jsonl").write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    meta, messages = build_folder(root, tmp_path / "out", fps=20, skip_uncaptioned=True, progress=False)
    assert meta["counts"]["clips"] == 2 and meta["counts"]["uncaptioned_skipped"] == 10
    assert "skipped (no captions): Fox.glb#AnimalArmature|Death" in messages
    assert not any(m.startswith("detected") for m in messages)  # glTF is metres: nothing to detect


def test_synthetic_glb_sidecar(tmp_path) -> None:
    """A GLB with one animation takes a plain ``<stem>.txt`` sidecar (no real data needed)."""
    root = tmp_path / "d"
    root.mkdir()
    write_synthetic_glb(root / "thing.glb")
    (root / "thing.txt").write_text("A thing moves.\n")
    meta, _ = build_folder(root, tmp_path / "out", fps=20, progress=False)
    cache = MotionCache(tmp_path / "out")
    assert cache.clips[0]["clip_id"] == "thing.glb#Rig|Move" and cache.clips[0]["captions"] == ["A thing moves."]
    assert meta["counts"]["rigs"] == 1 and not meta["trainable"]


def test_refuses_foreign_output_before_reading(tmp_path) -> None:
    out = tmp_path / "notes"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    root = tmp_path / "d"
    root.mkdir()
    write_synthetic_glb(root / "thing.glb")  # uncaptioned: the output check must come first
    for build in (build_folder, build_quaternius):
        with pytest.raises(DataError, match="not empty and is not a kinema dataset build"):
            build(root, out, progress=False)
    assert (out / "mine.txt").read_text() == "keep me" and len(list(out.iterdir())) == 1


def test_cli_errors(tmp_path, capsys) -> None:
    for root, msg in ((tmp_path / "none", "folder does not exist"), (tmp_path, "no .glb files found")):
        assert main(["data", "build", "quaternius", "--root", str(root), "--out", str(tmp_path / "o"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and msg in err


def test_a_rig_whose_walk_goes_against_its_forward_axis_stays_on_the_spot(quaternius_root, tmp_path) -> None:
    """The mech Mike's contact joints (found by the rig layer) are its knees: the walk they imply goes
    backwards along its forward axis, so the build trusts none of its feet and keeps its clips in place;
    the T-rex walks along +Z and travels."""
    root = tmp_path / "two"
    for rel in ("mech_pack/Mike.glb", "dinosaurs_pack/Trex.glb"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).symlink_to(quaternius_root / rel)
    meta, messages = build_quaternius(root, tmp_path / "out", fps=20, progress=False)
    assert (
        meta["forward_check"]["mech_pack/Mike.glb"] < -0.9 and meta["forward_check"]["dinosaurs_pack/Trex.glb"] > 0.99
    )
    assert any(m.startswith("mech_pack/Mike.glb: the walk read from its contact joints") for m in messages)
    clips = MotionCache(tmp_path / "out").clips
    mike = [r for r in clips if r["path"] == "mech_pack/Mike.glb" and r["content"] in ("walk", "run")]
    trex = [r for r in clips if r["path"] == "dinosaurs_pack/Trex.glb" and r["content"] in ("walk", "run")]
    assert mike and all(r["flags"] == ["in_place"] and r["travel"] < 0.1 for r in mike)
    assert trex and all(r["flags"] == ["travel_recovered"] and r["travel"] > 0.3 for r in trex)
