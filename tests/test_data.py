"""Dataset build (kinema.data.bandai/build/dataset) and the `kinema data` CLI, on a 12-clip subset.

One build of 12 Bandai Namco clips (plus mirrors) is shared by the module; it takes a few seconds. The clips
are the real ones, or the synthetic ones of kinema.data.synthetic without the shared data (see conftest.py).
"""

from __future__ import annotations

import gzip
import json
import re
import shutil
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from kinema.cli import main
from kinema.data.bandai import ClipInfo, list_clips, load_clip, min_toe_height
from kinema.data.build import FILES, select_subset
from kinema.data.captions import captions_for, mirror_content
from kinema.data.dataset import MotionDataset
from kinema.data.phrasings import speed_band, speed_captions
from kinema.data.split import assign_splits, group_of
from kinema.errors import DataError
from kinema.representation.kimodo_features import motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats

LIMIT = 12


@pytest.fixture(scope="module")
def build(bandai_root, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("data") / "bandai20"
    argv = [
        "data",
        "build",
        "bandai-namco",
        "--root",
        str(bandai_root),
        "--fps",
        "20",
        "--out",
        str(out),
        "--limit",
        str(LIMIT),
        "--workers",
        "2",
        "--quiet",
    ]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def records(build) -> list[dict]:
    return json.loads((build / "clips.json").read_text())


@pytest.fixture(scope="module")
def clips_by_id(bandai_root) -> dict[str, ClipInfo]:
    return {c.clip_id: c for c in list_clips(bandai_root)}


def test_build_writes_every_file_and_features_match_layout(build, records, bandai_root):
    assert sorted(p.name for p in build.iterdir()) == sorted(FILES)
    meta = json.loads((build / "meta.json").read_text())
    layout = FeatureLayout(21)
    assert meta["layout"] == layout.to_dict() and meta["fps"] == 20.0
    assert json.loads((build / "skeleton.json").read_text())["names"][0] == "Hips"
    feats = load_file(str(build / "features.safetensors"))["features"]
    assert feats.dtype == torch.float32 and feats.shape == (sum(r["length"] for r in records), layout.dim)
    assert torch.isfinite(feats).all()
    starts = [r["start"] for r in records]
    assert starts == sorted(starts) and starts[0] == 0
    assert meta["counts"]["source_clips"] == LIMIT and len(records) == 2 * LIMIT
    for r in records:
        assert r["length"] > 0 and r["duration_s"] == pytest.approx(r["length"] / 20)
        assert 0.0 < r["min_toe_height"] < 0.08  # toes touch the floor (joint ~2-5 cm above it)
        assert (bandai_root / r["path"]).is_file() and r["captions"]
    # no temporary folders left next to the output
    assert [p.name for p in build.parent.iterdir()] == [build.name]


def test_limit_is_deterministic_and_spread_over_contents(clips_by_id):
    clips = list(clips_by_id.values())
    a, b = select_subset(clips, LIMIT), select_subset(list(reversed(clips)), LIMIT)
    assert [c.clip_id for c in a] == [c.clip_id for c in b]
    assert len({(c.dataset, c.content) for c in a}) == LIMIT
    assert {c.dataset for c in a} == {"dataset-1", "dataset-2"}


def test_mirrored_copies_have_mirrored_labels_and_captions(records):
    originals = {r["clip_id"]: r for r in records if not r["mirrored"]}
    mirrors = [r for r in records if r["mirrored"]]
    assert len(mirrors) == len(originals)
    sided = 0
    for m in mirrors:
        o = originals[m["source_clip_id"]]
        assert m["clip_id"] != o["clip_id"] and m["content"] == mirror_content(o["content"])
        same = ("style", "take", "length", "split", "source_clip_id")
        assert [m[k] for k in same] == [o[k] if k != "source_clip_id" else o["clip_id"] for k in same]
        for co, cm in zip(o["captions"], m["captions"], strict=True):
            assert cm == co.replace("left", "@").replace("right", "left").replace("@", "right")
        if "left" in o["content"].split("-"):
            sided += 1
            assert "right" in m["content"] and all("left" not in c for c in m["captions"])
    assert sided >= 1  # the subset holds e.g. raise-up-left-hand and walk-turn-left
    bye = [m for m in mirrors if m["content"] == "bye"]
    assert bye and all("left hand" in c for c in bye[0]["captions"] if "hand" in c)


def test_speed_captions_follow_the_templates_of_locomotion_clips(records, clips_by_id):
    """Walk/run/dash clips get the words of their measured speed band after the unchanged template captions."""
    seen = set()
    for r in records:
        info = clips_by_id[r["source_clip_id"]]
        templates = captions_for(info.content, info.style, mirrored=r["mirrored"])
        assert r["captions"][: len(templates)] == templates  # captions[0] is still the evaluation prompt
        motion = load_clip(info, 20)
        travel = (motion.root_translation[-1] - motion.root_translation[0])[[0, 2]].norm()
        speed = float(travel) * 20 / (motion.num_frames - 1)
        tail = r["captions"][len(templates) :]
        if info.content in ("walk", "run", "dash"):
            seen.add(info.content)
            words = speed_captions(info.content, speed)
            assert words and tail[-len(words) :] == words, (r["clip_id"], speed_band(info.content, speed))
        else:
            assert not any(w in c for c in tail for w in ("slowly", "pace", "speed", "fast")), tail
    assert {"walk", "run"} <= seen  # (the synthetic data has no dash among the 12)


def test_mirrored_features_are_those_of_the_mirrored_motion(build, records, clips_by_id):
    ds = MotionDataset(build, split="all")
    i = next(k for k, r in enumerate(ds.clips) if r["mirrored"] and r["content"] == "raise-up-right-hand")
    motion = load_clip(clips_by_id[ds.clips[i]["source_clip_id"]], 20).mirror()
    torch.testing.assert_close(ds[i]["features"], motion_to_features(motion).float(), atol=1e-5, rtol=1e-5)


def test_splits_are_by_take_and_independent_of_limit(records, clips_by_id):
    split_of: dict[str, set[str]] = {}
    for r in records:
        split_of.setdefault(r["source_clip_id"], set()).add(r["split"])
    assert all(len(s) == 1 for s in split_of.values())  # a clip and its mirror share a split
    assert len({r["clip_id"] for r in records}) == len(records)  # no clip id twice
    full = assign_splits([(c, group_of(c)) for c in clips_by_id])
    assert all(r["split"] == full[r["source_clip_id"]] for r in records)


def test_stats_cover_the_train_split_only(build, records):
    stats = NormStats.from_dict(json.loads((build / "stats.json").read_text()))
    D = FeatureLayout(21).dim
    assert stats.mean.shape == stats.std.shape == (D,)
    assert torch.isfinite(stats.std).all() and (stats.std > 0).all() and torch.isfinite(stats.mean).all()
    feats = load_file(str(build / "features.safetensors"))["features"]
    train = [feats[r["start"] : r["start"] + r["length"]] for r in records if r["split"] == "train"]
    from kinema.representation.transform import canonicalize_start

    layout = FeatureLayout(21)
    expect = NormStats.compute((canonicalize_start(f, layout) for f in train), xz_pairs=layout.xz_pairs())
    torch.testing.assert_close(stats.mean, expect.mean)
    assert stats.mean[layout.slices["heading"]].abs().max() == 0  # isotropic: any heading is equally likely
    torch.testing.assert_close(stats.std, expect.std)


def test_data_stats_prints_labels_splits_and_totals(build, records, capsys):
    assert main(["data", "stats", str(build)]) == 0
    out = capsys.readouterr().out
    for word in {r["content"] for r in records} | {r["style"] for r in records} | {"train", "val", "test", "total"}:
        assert word in out
    assert f"{len(records)} clips" in out


@pytest.mark.parametrize("command", ["build", "stats"])
def test_missing_paths_exit_2_with_one_line(tmp_path, capsys, command):
    missing = tmp_path / "nowhere"
    if command == "build":
        argv = ["data", "build", "bandai-namco", "--root", str(missing), "--out", str(tmp_path / "o")]
    else:
        argv = ["data", "stats", str(missing)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("kinema: error:") and str(missing) in err
    assert not (tmp_path / "o").exists()


def test_dataset_round_trip_matches_direct_features(build, clips_by_id):
    ds = MotionDataset(build, split="train")
    assert len(ds) > 0 and ds.fps == 20.0 and ds.layout.dim == 261 and ds.skeleton.num_joints == 21
    assert all(r["split"] == "train" for r in ds.clips)
    item = ds[0]
    assert item["captions"] == item["clip"]["captions"] and not item["clip"]["mirrored"]
    motion = load_clip(clips_by_id[item["clip"]["clip_id"]], 20)
    assert item["clip"]["min_toe_height"] == pytest.approx(min_toe_height(motion), abs=1e-5)
    torch.testing.assert_close(item["features"], motion_to_features(motion).float(), atol=1e-5, rtol=1e-5)
    sizes = [len(MotionDataset(build, s)) for s in ("train", "val", "test")]
    assert sum(sizes) == len(MotionDataset(build, "all")) == 2 * LIMIT


def _copy(build: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(build, dst)
    return dst


@pytest.mark.parametrize("damage", ["missing_stats", "corrupt_features", "layout", "bad_json", "no_dir"])
def test_dataset_errors_name_the_path(build, tmp_path, damage):
    d = _copy(build, tmp_path)
    target = d
    if damage == "missing_stats":
        target = d / "stats.json"
        target.unlink()
    elif damage == "corrupt_features":
        target = d / "features.safetensors"
        target.write_bytes(b"not a safetensors file")
    elif damage == "layout":
        target = d / "meta.json"
        meta = json.loads(target.read_text())
        meta["layout"]["dim"] += 1
        target.write_text(json.dumps(meta))
    elif damage == "bad_json":
        target = d / "clips.json"
        target.write_text("[{")
    else:
        target = tmp_path / "absent"
    with pytest.raises(DataError, match=re.escape(str(target))):
        MotionDataset(target if damage == "no_dir" else d)


def test_existing_output_is_kept_unless_replaceable(build, tmp_path, monkeypatch, bandai_root):
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "notes.txt").write_text("keep me")
    with pytest.raises(DataError, match="not a kinema dataset build"):
        from kinema.data.build import build_dataset

        build_dataset(bandai_root, precious, limit=1, workers=1, progress=False)
    assert (precious / "notes.txt").read_text() == "keep me"

    # a failing rebuild leaves the earlier build untouched
    d = _copy(build, tmp_path)
    before = (d / "meta.json").read_text()

    def boom(info, fps):
        raise DataError(f"{info.path}: simulated failure")

    monkeypatch.setattr("kinema.data.build.load_clip", boom)
    with pytest.raises(DataError, match="simulated failure"):
        build_dataset(bandai_root, d, limit=2, workers=1, progress=False)
    assert (d / "meta.json").read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy", "precious"]


def _fake_root(data: Path, tmp_path: Path, twin: dict | None) -> Path:
    """A one-clip copy of dataset 1 under ``data`` with a chosen JSON twin (None: no twin)."""
    src = data / "Bandai-Namco-Research-Motiondataset-1"
    dst = tmp_path / "Bandai-Namco-Research-Motiondataset-1"
    shutil.copytree(src / "cfg", dst / "cfg")
    (dst / "data").mkdir()
    name = "dataset-1_walk_happy_001"
    with gzip.open(src / "data" / f"{name}.bvh.gz") as f:  # a dataset file, recompressed
        (dst / "data" / f"{name}.bvh.gz").write_bytes(gzip.compress(f.read()))
    if twin is not None:
        (dst / "data" / f"{name}.json").write_text(json.dumps(twin))
    return tmp_path


def test_list_clips_checks_the_json_twin(tmp_path, bandai_root):
    root = _fake_root(bandai_root, tmp_path / "ok", {"content": 0, "style": 1})  # walk, happy
    (info,) = list_clips(root)
    assert (info.content, info.style, info.take) == ("walk", "happy", 1)
    assert info.relpath == "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_happy_001.bvh.gz"
    assert list_clips(root / "Bandai-Namco-Research-Motiondataset-1")[0].clip_id == info.clip_id
    bad = _fake_root(bandai_root, tmp_path / "bad", {"content": 1, "style": 1})  # run != walk
    with pytest.raises(DataError, match=r"dataset-1_walk_happy_001\.json.*disagree"):
        list_clips(bad)
    missing = _fake_root(bandai_root, tmp_path / "missing", None)
    with pytest.raises(DataError, match=r"dataset-1_walk_happy_001\.json.*missing"):
        list_clips(missing)
    with pytest.raises(DataError, match="no Bandai-Namco"):
        list_clips(tmp_path)


def test_load_clip_prunes_the_static_root_and_moves_the_pelvis(clips_by_id):
    info = clips_by_id["dataset-1_walk_normal_001"]
    motion = load_clip(info, 20)
    assert motion.fps == 20 and motion.skeleton.num_joints == 21 and motion.skeleton.names[0] == "Hips"
    travel = (motion.root_translation[-1] - motion.root_translation[0])[[0, 2]].norm()
    assert travel > 2.0  # metres walked
    assert 0.0 < min_toe_height(motion) < 0.08


def test_rebuild_replaces_an_earlier_build_in_process_without_mirrors(build, tmp_path, bandai_root):
    d = _copy(build, tmp_path)
    argv = ["data", "build", "bandai-namco", "--root", str(bandai_root), "--out", str(d), "--limit", "2"]
    assert main(argv + ["--workers", "1", "--no-mirror", "--quiet"]) == 0
    meta = json.loads((d / "meta.json").read_text())
    assert meta["limit"] == 2 and meta["mirror"] is False and meta["counts"]["clips"] == 2
    recs = json.loads((d / "clips.json").read_text())
    assert not any(r["mirrored"] for r in recs)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy"]
