"""Robot demonstrations: kinema's human motions on humanoid robots described in MJCF, checked in MuJoCo.

Entry points::

    from kinema.robot import load_robot, retarget_to_robot
    robot = load_robot("g1")                      # or "path/to/robot.xml", mapping="map.json"
    robot_motion = retarget_to_robot(motion, robot)
    robot_motion.save("walk.csv")                 # or .npz (kinema.robot.files)

``replay_report(robot_motion, robot)`` replays a robot motion with MuJoCo's forward kinematics and
measures what a demonstration must respect (kinema.robot.replay). See docs/robots.md.
"""

from kinema.robot.description import BUILTIN_ROBOTS, Robot, load_robot
from kinema.robot.motion import RobotMotion, load_robot_motion
from kinema.robot.replay import ReplayReport, replay_report
from kinema.robot.retarget import retarget_to_robot

__all__ = [
    "BUILTIN_ROBOTS",
    "ReplayReport",
    "Robot",
    "RobotMotion",
    "load_robot",
    "load_robot_motion",
    "replay_report",
    "retarget_to_robot",
]
