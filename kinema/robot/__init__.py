"""Robot demonstrations: kinema's human motions on humanoid robots described in MJCF, checked in MuJoCo.

Entry points::

    from kinema.robot import load_robot, retarget_to_robot
    robot = load_robot("g1")                      # or "path/to/robot.xml", mapping="map.json"
    robot_motion = retarget_to_robot(motion, robot)
    robot_motion.save("walk.csv")                 # or .npz (kinema.robot.files)

``replay_report(robot_motion, robot)`` replays a robot motion with MuJoCo's forward kinematics and
measures what a demonstration must respect (kinema.robot.replay); ``dynamics_report(robot_motion, robot)``
runs MuJoCo's inverse dynamics along it (kinema.robot.dynamics); ``save_for_tracker(robot_motion, robot,
"walk.npz", "beyondmimic")`` (or ``"walk.pkl", "gmr"``) writes it for a tracker (kinema.robot.exports).
See docs/robots.md.
"""

from kinema.robot.description import BUILTIN_ROBOTS, Robot, load_robot
from kinema.robot.dynamics import DynamicsReport, dynamics_report
from kinema.robot.exports import save_for_tracker
from kinema.robot.motion import RobotMotion, load_robot_motion
from kinema.robot.replay import ReplayReport, replay_report
from kinema.robot.retarget import retarget_to_robot

__all__ = [
    "BUILTIN_ROBOTS",
    "DynamicsReport",
    "ReplayReport",
    "Robot",
    "RobotMotion",
    "dynamics_report",
    "load_robot",
    "load_robot_motion",
    "replay_report",
    "retarget_to_robot",
    "save_for_tracker",
]
