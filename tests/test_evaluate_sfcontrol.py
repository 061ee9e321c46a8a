"""SFControl protocol cases: targets on the ground truth, their constraint/objective/keyjoint forms."""

from __future__ import annotations

import torch

from kinema.constraints.io import load_constraints
from kinema.evaluate.sfcontrol import (
    as_constraints,
    as_objectives,
    control_error,
    keyjoint_targets,
    sparse_cases,
)
from kinema.evaluate.sfcontrol_tasks import TASKS, uniform_waypoints
from kinema.objectives import bind_objectives, load_objectives
from kinema.representation.keyjoint import keyjoint_indices


def test_sparse_cases_put_half_the_keyjoints_every_1_5_s_on_the_ground_truth(tiny_data) -> None:
    cases = sparse_cases(tiny_data, 2, split="all")
    assert cases
    case = cases[0]
    gt, targets = case["gt"], case["targets"]
    assert gt.num_frames == 100 and {f for f, _, _ in targets} == {0, 30, 60, 90}
    assert len(targets) == 4 * 3 and {j for _, j, _ in targets} <= set(keyjoint_indices(gt.skeleton))
    assert control_error(gt, targets) < 1e-5
    cons = load_constraints(as_constraints(targets, gt.skeleton), gt.skeleton, gt.fps, gt.num_frames)
    assert len(cons) == len(targets)
    objs = bind_objectives(load_objectives(as_objectives(targets, gt.skeleton, gt.fps)), gt.skeleton, gt.fps, 100)
    assert max(float(b.error(gt.positions.float()[None])[0]) for b in objs) < 1e-4
    k, m = keyjoint_targets(targets, gt.skeleton, 100)
    assert int(m.sum()) == 3 * len(targets) and float(m[..., 18:].sum()) == 0


def test_uniform_timing_baseline_spreads_the_path_over_the_window() -> None:
    obj = TASKS["time-agnostic path"][1]
    c = uniform_waypoints(obj, 20.0)
    assert c["frame_indices"][0] == 10 and c["frame_indices"][-1] == 90
    pts = torch.tensor(c["smooth_root_2d"])
    assert torch.allclose(pts[0], torch.tensor(obj["path"][0])) and torch.allclose(
        pts[-1], torch.tensor(obj["path"][-1])
    )
    steps = (pts[1:] - pts[:-1]).norm(dim=-1)
    assert float(steps.max() - steps.min()) < 5e-3  # uniform in arc length (chords cut the corners slightly)


def test_suite_ee_part_runs_the_suites_end_effector_cases_both_ways(tiny_data) -> None:
    import kinema
    from kinema.evaluate.sfcontrol_suite import ee_cases, evaluate_suite_ee, has_ee_positions, summarize_suite
    from kinema.evaluate.suite import build_suite
    from kinema.human.keyjoint_planning import KeyjointPlanner

    cases = build_suite(tiny_data, "all", num_cases=12, seed=0)
    picked = ee_cases(cases)
    assert picked and all(has_ee_positions(c) for _, c in picked)
    assert all(c["kind"] in ("end_effector", "mixed") for _, c in picked)
    first = picked[0][0]
    model = kinema.load_model()
    lines = []
    out = evaluate_suite_ee(
        model, cases[: first + 1], planner=KeyjointPlanner.load("default"), steps=2, progress=lines.append
    )
    assert set(out) == {"direct", "keyjoint-planned"} and len(lines) == 1
    one, two = out["direct"][0], out["keyjoint-planned"][0]
    assert one["id"] == two["id"] == cases[first]["id"] and one["ee_pos_cm"] >= 0 and two["ee_pos_cm"] >= 0
    assert one["ee_pos_cm"] != two["ee_pos_cm"]  # the two rows are different generations
    table = summarize_suite(out)
    assert table["keyjoint-planned"]["cases"] == 1 and table["direct"]["ee_pos_cm"] == one["ee_pos_cm"]


def test_sparse_rows_get_r3_and_fid_from_the_shipped_retrieval_model(tiny_data) -> None:
    import kinema
    from kinema.evaluate.retrieval import default_retrieval_path, load_retrieval
    from kinema.evaluate.sfcontrol import evaluate_sparse, text_scores

    (case,) = sparse_cases(tiny_data, 2, split="all")[:1]  # the tiny build has one clip of 5 s or more
    cases = [case, dict(case, prompt="A person walks forward slowly.")]
    res = evaluate_sparse(kinema.load_model(), cases, rows=["direct"], steps=2, progress=lambda _: None)
    warn: list[str] = []
    out = text_scores(load_retrieval(default_retrieval_path()), cases, res, warn=warn)
    assert set(out) == {"ground_truth", "direct"}
    assert out["ground_truth"]["fid"] < 1e-3 < out["direct"]["fid"]  # FID against the crops themselves
    assert out["ground_truth"]["r3_whole"] == 1.0  # 2 captions: each is in its own top 3
    assert out["direct"]["r3_batch32"] is None and any("R@3 (batch 32) skipped" in w for w in warn)
