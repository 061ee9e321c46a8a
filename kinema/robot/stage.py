"""The robot stage of a generation: a request that names a robot (``GenerationRequest.robot``) gets its
motions as the robot's joint angles too, each replayed in MuJoCo and measured for the report, with the
inverse dynamics of each (kinema.robot.dynamics: torques, base residual, joint speeds, self-collision).

kinema.pipeline.base imports this module by name only when a request names a robot, since MuJoCo takes
most of a second to import and nothing else needs it.
"""

from __future__ import annotations

import numpy as np

from kinema.robot.description import Robot, load_robot
from kinema.robot.dynamics import dynamics_report
from kinema.robot.motion import RobotMotion
from kinema.robot.replay import replay_report
from kinema.robot.retarget import retarget_to_robot, robot_sizes
from kinema.robot.targets import leg_scale


def robot_motions(motions, robot: str | Robot, mapping=None) -> tuple[list[RobotMotion], list[dict]]:
    """Each motion on the robot (a loaded `Robot`, or ``"g1"`` or an MJCF path; ``mapping``: a JSON file or
    dict naming its bodies) and the measurements of each (robot_measures)."""
    description = robot if isinstance(robot, Robot) else load_robot(robot, mapping=mapping)
    out = [retarget_to_robot(motion, description) for motion in motions]
    return out, [robot_measures(m, rm, description) for m, rm in zip(motions, out, strict=True)]


def robot_measures(motion, robot_motion: RobotMotion, robot: Robot) -> dict:
    """The replay measurements of a human ``motion``'s ``robot_motion``: range overshoot (rad), lowest sole
    and planted-sole slide (m, m/s), travel (m) and its ratio to the human's beside the ratio of leg
    lengths (the travel is scaled by it), leg overlap (m), the steps and the least clearance of a swing (m,
    None without steps) and the slides (moves too short for steps); ``dynamics`` (kinema.robot.dynamics),
    its one-line ``dynamics_summary`` and, for a motion that is not feasible, its one-line ``warning``."""
    rep = replay_report(robot_motion, robot)
    dynamics = dynamics_report(robot_motion, robot)
    return {"robot": robot.name, "range_overshoot_rad": rep.range_overshoot, "lowest_sole_m": rep.lowest_sole,
            "planted_slide_m_s": rep.planted_slide, "travel_m": rep.travel,
            "leg_scale": leg_scale(motion, robot_sizes(robot)), "travel_ratio": _travel_ratio(motion, rep.travel),
            "leg_overlap_m": rep.leg_overlap, "steps": rep.steps, "slides": rep.slides,
            "swing_clearance_m": rep.swing_clearance if rep.steps else None, "feasible": dynamics.feasible,
            "dynamics_summary": dynamics.summary(), "warning": dynamics.warning(), "dynamics": dynamics.as_dict()}


def replay_words(measured: dict) -> str:
    """The replay measurements in one line."""
    m = measured
    ratio = "" if m["travel_ratio"] is None else f" ({m['travel_ratio']:.2f} of the human's; legs {m['leg_scale']:.2f})"
    steps = (f"{m['steps']} steps clearing at least {100 * m['swing_clearance_m']:.1f} cm" if m["steps"]
             else "no steps") + (f", {m['slides']} slides" if m["slides"] else "")
    return (f"range overshoot {m['range_overshoot_rad']:.3f} rad, lowest sole {100 * m['lowest_sole_m']:+.1f} cm, "
            f"planted-sole slide {m['planted_slide_m_s']:.2f} m/s, travel {m['travel_m']:.2f} m{ratio}, {steps}")


def _travel_ratio(motion, robot_travel: float) -> float | None:
    """The robot's root travel over the human's (None when the human stays within 10 cm)."""
    root = motion.positions[:, motion.skeleton.roles["pelvis"]].detach().double().numpy()
    human = float(np.linalg.norm(root[-1, [0, 2]] - root[0, [0, 2]]))  # kinema's ground plane is XZ
    return robot_travel / human if human > 0.1 else None
