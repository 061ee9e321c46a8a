"""Evaluation suite, runner, report and `kinema evaluate` (docs/evaluation.md)."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from kinema.constraints import load_constraints
from kinema.evaluate.runner import COLUMNS, run_suite, score_motion
from kinema.evaluate.suite import (
    CASE_KINDS,
    CONSTRAINED_KINDS,
    build_suite,
    case_ground_truth,
    case_targets,
    load_suite,
    save_suite,
)

DOCS = Path(__file__).resolve().parents[1] / "docs" / "evaluation.md"
CONSTRAINT_COLUMNS = ("fullbody_pos_cm", "ee_pos_cm", "ee_rot_deg", "root2d_pos_cm")


def _cli(argv: list[str]) -> int:
    """`kinema ...` through kinema.cli.main once `evaluate` is wired there, else through its own parser."""
    from kinema.cli import build_parser, main
    from kinema.cli import evaluate as evaluate_cli
    from kinema.errors import KinemaError

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    if "evaluate" in sub.choices:
        return main(argv)
    parser = argparse.ArgumentParser(prog="kinema")
    evaluate_cli.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KinemaError as err:
        print(f"kinema: error: {err}")
        return 2


def test_suite_is_deterministic(tiny_data, tmp_path):
    a = build_suite(tiny_data, "train", num_cases=12, seed=0)
    b = build_suite(tiny_data, "train", num_cases=12, seed=0)
    c = build_suite(tiny_data, "train", num_cases=12, seed=1)
    assert json.dumps(a) == json.dumps(b)
    assert json.dumps(a) != json.dumps(c)
    save_suite(a, tmp_path / "suite.json")
    assert json.dumps(load_suite(tmp_path / "suite.json")) == json.dumps(a)


def test_suite_kinds_lengths_and_constraints(tiny_data):
    from kinema.data.dataset import MotionDataset

    ds = MotionDataset(tiny_data, "train")
    cases = build_suite(tiny_data, "train", num_cases=20, seed=0, perturb_fraction=0.5)
    assert {c["kind"] for c in cases} == set(CASE_KINDS) - {"timeline"}  # timeline cases: build_timeline_cases
    assert len({c["id"] for c in cases}) == len(cases)
    constrained = [c for c in cases if c["kind"] != "text"]
    assert {c["with_text"] for c in constrained} == {True, False}
    assert any(c["perturbed"] for c in constrained) and not all(c["perturbed"] for c in constrained)
    for c in cases:
        assert 3.0 <= c["seconds"] <= 9.0
        assert c["num_frames"] == round(c["seconds"] * ds.fps)
        assert (c["prompt"] == "") == (not c["with_text"])
        if c["kind"] == "text":
            assert c["constraints"] == [] and c["prompt"]
            continue
        assert c["kind"] in CONSTRAINED_KINDS and c["constraints"]
        assert c["source"]["frames"] == c["num_frames"]
        assert len(c["parts"]) == (2 if c["kind"] == "mixed" else 1)
        # valid kinema constraints for the case's duration
        load_constraints(c["constraints"], ds.skeleton, ds.fps, c["num_frames"])


def test_ground_truth_scores_its_own_constraints(tiny_data):
    from kinema.data.dataset import MotionDataset

    ds = MotionDataset(tiny_data, "train")
    cases = build_suite(tiny_data, "train", num_cases=20, seed=3, perturb_fraction=0.5)
    seen = set()
    for c in cases:
        gt = case_ground_truth(c, ds)
        assert gt.num_frames == c["source"]["frames"]
        scores, _ = score_motion(gt, case_targets(c, ds.skeleton))
        assert scores["contact_acc"] == 1.0
        for key in CONSTRAINT_COLUMNS:
            if scores[key] is not None:
                seen.add(key)
                limit = 0.05 if key == "ee_rot_deg" else 0.3  # degrees / cm (a few mm at most)
                assert scores[key] < limit, (c["id"], key, scores[key])
    assert seen == set(CONSTRAINT_COLUMNS)


def _documented_keys() -> set[str]:
    return set(re.findall(r"`([a-z0-9_]+)`", DOCS.read_text(encoding="utf-8")))


def test_cli_end_to_end(tiny_checkpoint, tiny_data, tmp_path, capsys):
    out = tmp_path / "eval"
    rc = _cli(["evaluate", "--model", str(tiny_checkpoint), "--data", str(tiny_data), "--split", "train",
               "--cases", "4", "--timeline-cases", "1", "--seed", "0", "--steps", "4", "--out", str(out),
               "--retrieval", str(tmp_path / "no-retrieval"), "--filmstrips", "2", "--no-progress"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "| Ground truth |" in printed and "wall time" in printed
    for name in ("report.md", "report.json", "suite.json", "plots/foot_skate.png", "plots/keyframes.png"):
        assert (out / name).is_file(), name
    data = json.loads((out / "report.json").read_text())
    documented = _documented_keys()
    for key in data:
        assert key in documented, key
    for section in ("meta", "timing", "text", "plots"):
        for key in data[section]:
            assert key in documented, (section, key)
    assert set(data["table"]) == {"ground_truth", "raw", "post"}
    for row in data["table"].values():
        assert tuple(row) == COLUMNS and all(k in documented for k in row)
    for key in data["cases"][0]:
        assert key in documented, key
    assert len(data["cases"]) == 5 and data["meta"]["num_cases"] == 5
    assert data["cases"][-1]["kind"] == "timeline" and set(data["timeline"]) == {"ground_truth", "raw", "post"}
    for row in data["timeline"].values():
        assert all(k in documented for k in row)
    assert data["timeline"]["raw"]["join_acc"] > 0 and data["timeline"]["ground_truth"]["join_acc"] is None
    assert "## Timelines" in (out / "report.md").read_text() and "| Model (raw) | 1 |" in printed.split("Segments")[-1]
    assert any("retrieval" in w for w in data["warnings"]) and data["table"]["raw"]["r3_whole"] is None
    assert len(data["plots"]["filmstrips"]) == 2
    assert all((out / p).is_file() for p in data["plots"]["filmstrips"])
    assert data["table"]["ground_truth"]["contact_acc"] == 1.0
    assert len(load_suite(out / "suite.json")) == 5
    assert "Ground truth" in (out / "report.md").read_text()


def test_text_metrics_with_a_retrieval_model(tiny_checkpoint, tiny_data, tmp_path):
    from kinema.data.dataset import MotionDataset
    from kinema.evaluate.retrieval import RetrievalConfig, RetrievalModel
    from kinema.generate import load_model

    ds = MotionDataset(tiny_data, "train")
    cfg = RetrievalConfig(width=16, layers=1, heads=2, ff_mult=2, embed_dim=8, text_dim=32, text_hidden=16)
    RetrievalModel(cfg, ds.layout, ds.stats, ds.fps, "hash-test-32").save(tmp_path / "ret")
    cases = build_suite(tiny_data, "train", num_cases=3, seed=0, text_fraction=1.0)
    assert [c["kind"] for c in cases] == ["text"] * 3
    res = run_suite(
        load_model(tiny_checkpoint),
        cases,
        postprocess_modes=(False,),
        steps=4,
        progress=False,
        retrieval=tmp_path / "ret",
        mm_prompts=1,
        mm_samples=2,
    )
    table = res.data["table"]
    assert set(table) == {"ground_truth", "raw"}
    for row in table.values():
        assert 0.0 <= row["r1_whole"] <= row["r3_whole"] <= 1.0
        assert row["r3_batch32"] is None and row["diversity"] >= 0.0
    assert table["ground_truth"]["fid"] == pytest.approx(0.0, abs=1e-6)
    assert table["raw"]["multimodality"] >= 0.0 and table["ground_truth"]["multimodality"] is None
    assert any("batch 32" in w for w in res.data["warnings"])


def test_cli_errors(tiny_checkpoint, tiny_data, tmp_path, capsys):
    for argv, name in (
        (["--model", str(tmp_path / "missing-model"), "--data", str(tiny_data)], "missing-model"),
        (["--model", str(tiny_checkpoint), "--data", str(tmp_path / "missing-data")], "missing-data"),
        (["--model", str(tiny_checkpoint), "--suite", str(tmp_path / "bad.json")], "bad.json"),
    ):
        (tmp_path / "bad.json").write_text("[1, 2]")
        rc = _cli(["evaluate", *argv, "--out", str(tmp_path / "out"), "--no-progress"])
        assert rc == 2
        err = capsys.readouterr()
        lines = [ln for ln in (err.out + err.err).strip().splitlines() if ln.strip()]
        assert len(lines) == 1 and name in lines[0], lines


# ----------------------------------------------------------------------------- timeline cases
def test_timeline_cases_are_deterministic_and_scored_per_segment(tiny_checkpoint, tiny_data, tmp_path):
    from kinema.data.dataset import MotionDataset
    from kinema.evaluate.retrieval import RetrievalConfig, RetrievalModel
    from kinema.evaluate.timeline import SEGMENT_SECONDS, build_timeline_cases, segment_bounds
    from kinema.generate import load_model

    ds = MotionDataset(tiny_data, "train")
    cases = build_timeline_cases(ds, tiny_data, "train", 2, seed=3, first_id=7)
    assert cases == build_timeline_cases(ds, tiny_data, "train", 2, seed=3, first_id=7)
    assert [c["id"] for c in cases] == ["0007-timeline", "0008-timeline"]
    for c in cases:
        assert 2 <= len(c["segments"]) <= 4 and len({s["clip_id"] for s in c["segments"]}) == len(c["segments"])
        assert all(SEGMENT_SECONDS[0] - 1e-9 <= s["seconds"] <= SEGMENT_SECONDS[1] + 1e-9 for s in c["segments"])
        assert segment_bounds(c)[-1] == c["num_frames"]
    save_suite(cases, tmp_path / "suite.json")
    assert load_suite(tmp_path / "suite.json") == cases
    cfg = RetrievalConfig(width=16, layers=1, heads=2, ff_mult=2, embed_dim=8, text_dim=32, text_hidden=16)
    RetrievalModel(cfg, ds.layout, ds.stats, ds.fps, "hash-test-32").save(tmp_path / "ret")
    res = run_suite(load_model(tiny_checkpoint), cases, postprocess_modes=(False,), steps=3, progress=False,
                    retrieval=tmp_path / "ret", mm_prompts=0)
    tl = res.data["timeline"]
    n = sum(len(c["segments"]) for c in cases)
    assert tl["raw"]["segments"] == tl["ground_truth"]["segments"] == n and tl["raw"]["cases"] == 2
    for row in tl.values():
        assert 0.0 <= row["r1"] <= row["r3"] <= 1.0 and row["foot_skate_cm_s"] >= 0.0
    assert res.motions["0007-timeline"]["raw"].num_frames == cases[0]["num_frames"]
    assert res.data["by_kind"]["raw"]["timeline"]["cases"] == 2


def test_join_smoothness_sees_a_pop_at_the_join():
    import torch

    from kinema.evaluate.timeline import join_smoothness
    from kinema.motion.core import Motion
    from kinema.skeleton import Skeleton

    skel = Skeleton(["a", "b"], [-1, 0], [[0.0, 0.0, 0.0], [0.0, 0.5, 0.0]], name="two")
    T, fps = 60, 20.0
    root = torch.zeros(T, 3)
    root[:, 2] = torch.arange(T) * 1.0 / fps  # 1 m/s, no acceleration
    quats = torch.zeros(T, 2, 4)
    quats[..., 0] = 1.0
    smooth = join_smoothness(Motion(skel, fps, root, quats), [0, 30, T])
    assert smooth["join_speed"] == pytest.approx(1.0) and smooth["inside_speed"] == pytest.approx(1.0)
    assert smooth["join_acc_peak"] == pytest.approx(0.0, abs=1e-3)  # float32 positions
    root[30:, 0] += 0.2  # a 20-cm jump at the join
    popped = join_smoothness(Motion(skel, fps, root, quats), [0, 30, T])
    assert popped["join_acc_peak"] == pytest.approx(0.2 * fps * fps, rel=1e-4)
    assert popped["inside_acc_p99"] == pytest.approx(0.0, abs=1e-3) and popped["join_speed"] > 1.0
