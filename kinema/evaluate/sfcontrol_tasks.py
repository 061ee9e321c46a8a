"""SFControl's goal-reaching and implicit-task protocols (paper Sec. 4.1.1, 4.2; Tables 2-3), small.

Goal reaching: the first frame of a 3-s test crop is the start pose (full-body keyframe) and the crop's
right-hand position on its last frame is the goal. Rows: ``explicit goal`` (end-effector keyframe on
the last frame: timing fixed by the user) and ``goal objective`` (reach within the last 0.5 s: timing
left to the model). Metrics: distance to goal (closest approach in the last 0.5 s), distance to start
(mean joint distance on frame 0), foot skate.

Implicit tasks (prompts fixed, ``cases`` seeds each): ``hand-to-head`` (right hand within 10 cm of the
head some time in 1-4 s), ``corridor`` (pelvis x inside [0.6, 1.0] m from 2.5 s on: the walker must
move 0.8 m left), ``time-agnostic path`` (pelvis along a curved ground path between 0.5 and 4.5 s).
Rows: ``none`` (the objective ignored), ``noise opt`` (kinema.objectives), and for the path the paper's
``explicit, uniform timing`` baseline (the path resampled at uniform times as root waypoints). Metrics:
constraint error (the objective's own error: cm), foot skate, jerk; raw output (post-processing would
hide the differences).
"""

from __future__ import annotations

import random
import statistics
import time

import torch

from kinema.data.dataset import MotionDataset
from kinema.evaluate.metrics import foot_skate, jerk
from kinema.evaluate.suite import ground_truth_motion
from kinema.objectives import bind_objectives, load_objectives
from kinema.objectives.goal import goal_reach, start_pose
from kinema.objectives.snap import point_at_fraction

GOAL_SECONDS, HOLD = 3.0, 0.5
TASKS = {
    "hand-to-head": (
        "A person stands still.",
        {"type": "hand-to-head", "hand": "right", "distance": 0.1, "window": [1.0, 4.0]},
    ),
    "corridor": (
        "A person walks forward.",
        {
            "type": "stay-within",
            "joints": ["Hips"],
            "min": [0.6, None, None],
            "max": [1.0, None, None],
            "window": [2.5, 4.95],
        },
    ),
    "time-agnostic path": (
        "A person walks forward.",
        {
            "type": "path-time-agnostic",
            "joint": "Hips",
            "window": [0.5, 4.5],
            "path": [[0.0, 0.5], [0.2, 2.0], [1.2, 3.0], [2.4, 3.3]],
        },
    ),
}


def _objective_error(model, obj: dict, motion) -> float:
    b = bind_objectives(load_objectives([obj]), model.skeleton, model.fps, motion.num_frames)[0]
    return float(b.error(motion.positions.float()[None])[0])


def uniform_waypoints(obj: dict, fps: float) -> dict:
    """The paper's 'w/o time-agnostic' baseline: the path at uniform times as dense root2d targets."""
    f0, f1 = (round(t * fps) for t in obj["window"])
    u = torch.linspace(0, 1, f1 - f0 + 1)
    pts = point_at_fraction(torch.tensor(obj["path"], dtype=torch.float32), u)
    return {"type": "root2d", "frame_indices": list(range(f0, f1 + 1)), "smooth_root_2d": pts.tolist()}


def evaluate_tasks(model, *, cases: int, objective_steps: int, seed: int = 0, progress=print) -> dict:
    """Per task, per row: mean constraint error (cm), skate, jerk, seconds."""
    out = {}
    for task, (prompt, obj) in TASKS.items():
        rows = ["none", "noise opt"] + (["explicit, uniform timing"] if "path" in task else [])
        res = {r: [] for r in rows}
        for s in range(seed, seed + cases):
            for row in rows:
                t0 = time.perf_counter()
                kw = {"objectives": [obj], "objective_steps": objective_steps} if row == "noise opt" else {}
                cons = [uniform_waypoints(obj, model.fps)] if row.startswith("explicit") else None
                m = model.generate(prompt, seconds=5.0, seed=s, postprocess=False, constraints=cons, **kw)[0]
                res[row].append(
                    {
                        "error_cm": 100 * _objective_error(model, obj, m),
                        "skate": foot_skate(m),
                        "jerk": jerk(m),
                        "seconds": time.perf_counter() - t0,
                    }
                )
        out[task] = {r: {k: statistics.fmean(v[k] for v in vals) for k in vals[0]} for r, vals in res.items()}
        progress(f"{task}: " + ", ".join(f"{r} {v['error_cm']:.1f} cm" for r, v in out[task].items()))
    return out


def goal_cases(data_dir, num_cases: int, seed: int = 0, split: str = "test") -> list[dict]:
    """``{"prompt", "gt", "goal"}``: 3-s test crops, the right hand's last position as the goal."""
    ds = MotionDataset(data_dir, split)
    T = round(GOAL_SECONDS * ds.fps)
    rng = random.Random(seed + 1)
    pool = [i for i, r in enumerate(ds.clips) if r["length"] >= T and not r["mirrored"]]
    out = []
    hand = ds.skeleton.names.index("Hand_R")
    for i in sorted(rng.sample(pool, min(num_cases, len(pool)))):
        item = ds[i]
        start = rng.randrange(item["features"].shape[0] - T + 1)
        gt = ground_truth_motion(item["features"][start : start + T], ds)
        out.append({"prompt": item["captions"][0], "gt": gt, "goal": [float(v) for v in gt.positions[-1, hand]]})
    return out


def evaluate_goal(model, cases: list[dict], *, objective_steps: int, seed: int = 0, progress=print) -> dict:
    hand = model.skeleton.names.index("Hand_R")
    T = round(GOAL_SECONDS * model.fps)
    res = {"explicit goal": [], "goal objective": []}
    for case in cases:
        start = start_pose(case["gt"], 0)
        for row in res:
            t0 = time.perf_counter()
            if row == "explicit goal":
                kw = {
                    "constraints": [
                        start,
                        {
                            "type": "end-effector",
                            "joint": "Hand_R",
                            "frame_indices": [T - 1],
                            "positions": [case["goal"]],
                        },
                    ]
                }
            else:
                kw = {
                    "constraints": [start],
                    "objective_steps": objective_steps,
                    "objectives": [goal_reach("Hand_R", case["goal"], seconds=GOAL_SECONDS, fps=model.fps, hold=HOLD)],
                }
            m = model.generate(case["prompt"], seconds=GOAL_SECONDS, seed=seed, postprocess=False, **kw)[0]
            lo = T - round(HOLD * model.fps) - 1
            goal = (m.positions[lo:, hand] - torch.tensor(case["goal"], dtype=m.positions.dtype)).norm(dim=-1)
            st = (m.positions[0] - case["gt"].positions[0].to(m.positions.dtype)).norm(dim=-1).mean()
            res[row].append(
                {
                    "goal_cm": 100 * float(goal.min()),
                    "start_cm": 100 * float(st),
                    "skate": foot_skate(m),
                    "seconds": time.perf_counter() - t0,
                }
            )
        progress(
            f"goal case {len(res['explicit goal'])}/{len(cases)}: "
            + ", ".join(f"{r} {v[-1]['goal_cm']:.1f} cm" for r, v in res.items())
        )
    return {r: {k: statistics.fmean(v[k] for v in vals) for k in vals[0]} for r, vals in res.items() if vals}
