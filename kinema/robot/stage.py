"""The robot stage of a generation: a request that names a robot (``GenerationRequest.robot``) gets its
motions as the robot's joint angles too, each replayed in MuJoCo and measured for the report, with the
inverse dynamics of each (kinema.robot.dynamics: torques, base residual, joint speeds, self-collision).

kinema.pipeline.base imports this module by name only when a request names a robot, since MuJoCo takes
most of a second to import and nothing else needs it.
"""

from __future__ import annotations

from kinema.robot.description import Robot, load_robot
from kinema.robot.dynamics import dynamics_report
from kinema.robot.motion import RobotMotion
from kinema.robot.replay import replay_report
from kinema.robot.retarget import retarget_to_robot


def robot_motions(motions, robot: str | Robot, mapping=None) -> tuple[list[RobotMotion], list[dict]]:
    """Each motion on the robot (a loaded `Robot`, or ``"g1"`` or an MJCF path; ``mapping``: a JSON file or
    dict naming its bodies) and the replay measurements of each: range overshoot (rad), lowest sole and
    planted-sole slide (m, m/s), travel (m), leg overlap (m); ``dynamics`` (kinema.robot.dynamics), its
    one-line ``dynamics_summary`` and, for a motion that is not feasible, its one-line ``warning``."""
    description = robot if isinstance(robot, Robot) else load_robot(robot, mapping=mapping)
    out, measured = [], []
    for motion in motions:
        robot_motion = retarget_to_robot(motion, description)
        rep = replay_report(robot_motion, description)
        dynamics = dynamics_report(robot_motion, description)
        out.append(robot_motion)
        measured.append({"robot": description.name, "range_overshoot_rad": rep.range_overshoot,
                         "lowest_sole_m": rep.lowest_sole, "planted_slide_m_s": rep.planted_slide,
                         "travel_m": rep.travel, "leg_overlap_m": rep.leg_overlap, "feasible": dynamics.feasible,
                         "dynamics_summary": dynamics.summary(), "warning": dynamics.warning(),
                         "dynamics": dynamics.as_dict()})
    return out, measured
