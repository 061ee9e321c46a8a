"""Robot motion files (CSV / npz), the `kinema robot` and `kinema render` commands on them, and an MJCF
humanoid whose body names are not recognised, retargeted through a JSON mapping."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

import kinema
from kinema.cli import main
from kinema.errors import KinemaError
from kinema.robot import BUILTIN_ROBOTS, load_robot, load_robot_motion, replay_report, retarget_to_robot
from kinema.robot.files import ROOT_COLUMNS


@pytest.fixture(scope="module")
def bow_clip(bandai_root):
    """A short captured bow (Bandai Namco, centimetres) as a kinema .bvh.gz path."""
    clips = sorted(bandai_root.glob("*/data/*bow*normal*.bvh.gz")) or sorted(bandai_root.glob("*/data/*.bvh.gz"))
    return clips[0]


@pytest.fixture(scope="module")
def bow(bow_clip):
    human = kinema.load_motion(bow_clip, scale=0.01)
    return human, retarget_to_robot(human, "g1")


def test_csv_and_npz_round_trip(bow, tmp_path):
    _, rm = bow
    csv, npz = rm.save(tmp_path / "bow.csv"), rm.save(tmp_path / "bow.npz")
    header = csv.read_text().splitlines()[0].split(",")
    assert tuple(header[:8]) == ROOT_COLUMNS and tuple(header[8:]) == rm.joint_names
    with np.load(npz) as z:
        assert {"time", "root_position", "root_quaternion", "joint_angles", "joint_names", "fps"} <= set(z.files)
        assert float(z["fps"]) == rm.fps and z["joint_angles"].shape == (rm.num_frames, 29)
    for path in (csv, npz):
        back = load_robot_motion(path)
        assert back.joint_names == rm.joint_names and back.num_frames == rm.num_frames
        assert back.fps == pytest.approx(rm.fps, rel=1e-5)
        np.testing.assert_allclose(back.joint_angles, rm.joint_angles, atol=1e-6)
        np.testing.assert_allclose(back.root_quaternion, rm.root_quaternion, atol=1e-6)
    assert load_robot_motion(npz).sole_planted is not None and load_robot_motion(csv).sole_planted is None


def test_robot_command_writes_and_render_draws(bow_clip, tmp_path, capsys):
    out = tmp_path / "bow.csv"
    assert main(["robot", str(bow_clip), "--scale", "0.01", "--robot", "g1", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "range overshoot 0.000 rad" in said and "lowest sole" in said
    assert main(["render", str(out), "--out", str(tmp_path / "bow.png"), "--frames", "4"]) == 0
    assert (tmp_path / "bow.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--robot", "missing.xml"], "no such robot file"),
        (["--robot", "g1", "--mapping", "nope.json"], "no such mapping file"),
        (["--out-suffix", ".txt"], "--out must end in .csv or .npz"),
    ],
)
def test_robot_command_bad_input(bow_clip, tmp_path, capsys, extra, message):
    out = tmp_path / ("walk.txt" if "--out-suffix" in extra else "walk.csv")
    args = [a for a in extra if a not in ("--out-suffix", ".txt")]
    assert main(["robot", str(bow_clip), "--scale", "0.01", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def _renamed_g1(tmp_path):
    """The G1's MJCF with its limb bodies renamed so that no name says which limb or side it is."""
    text = BUILTIN_ROBOTS["g1"].read_text()
    renames = {}
    for side, code in (("left", "a"), ("right", "b")):
        for part in ("hip_roll", "knee", "ankle_roll", "shoulder_roll", "elbow", "wrist_yaw"):
            renames[f"{side}_{part}_link"] = f"{code}_{part.replace('_', '')}_x"
    for old, new in renames.items():
        text = text.replace(f'<body name="{old}"', f'<body name="{new}"')
    for old in ("left_", "right_"):
        text = text.replace(f'<body name="{old}', f'<body name="{old[0]}q')  # no side word in other bodies
    path = tmp_path / "robot.xml"
    path.write_text(text)
    return path, renames


def test_unrecognised_mjcf_needs_and_uses_a_mapping(bow, tmp_path):
    path, renames = _renamed_g1(tmp_path)
    with pytest.raises(KinemaError, match="--mapping"):
        load_robot(path)
    landmarks = {
        "hip": "hip_roll",
        "knee": "knee",
        "foot": "ankle_roll",
        "shoulder": "shoulder_roll",
        "elbow": "elbow",
        "hand": "wrist_yaw",
    }
    mapping = {f"{s}_{k}": renames[f"{s}_{v}_link"] for s in ("left", "right") for k, v in landmarks.items()}
    mapping.update({"pelvis": "pelvis", "torso": "torso_link", "head": {"body": "torso_link", "offset": [0, 0, 0.43]}})
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    robot = load_robot(path, mapping=tmp_path / "map.json")
    human, g1_motion = bow
    rm = retarget_to_robot(human, robot)
    assert rm.joint_names == g1_motion.joint_names  # joints keep their names; the same kinematics
    np.testing.assert_allclose(rm.joint_angles, g1_motion.joint_angles, atol=1e-6)


def test_bad_mapping_file_is_one_clear_error(tmp_path):
    bad = tmp_path / "map.json"
    bad.write_text(json.dumps({"left_knee": {"body": "left_knee_link", "offset": [0, 0]}}))
    with pytest.raises(KinemaError, match="offset must be three finite numbers"):
        load_robot("g1", mapping=bad)
    bad.write_text(json.dumps({"left_kneee": "left_knee_link"}))
    with pytest.raises(KinemaError, match="unknown landmark"):
        load_robot("g1", mapping=bad)
    bad.write_text(json.dumps({"left_knee": "no_such_body"}))
    with pytest.raises(KinemaError, match="does not have"):
        load_robot("g1", mapping=bad)


def test_source_motions_the_robot_cannot_take(bow):
    human, _ = bow
    one = retarget_to_robot(human.crop(0, 1), "g1")  # a single pose is fine
    assert one.num_frames == 1 and np.isfinite(one.joint_angles).all()
    armless = human.prune([n for n in human.skeleton.names if "Arm" in n or "Hand" in n or "Shoulder" in n])
    with pytest.raises(KinemaError, match="left_hand"):
        retarget_to_robot(armless, "g1")
    broken = human.crop(0, 5)
    broken.root_translation = broken.root_translation.clone()  # crop shares memory with the fixture's motion
    broken.root_translation[2, 1] = float("nan")
    with pytest.raises(KinemaError, match="NaN"):
        retarget_to_robot(broken, "g1")


def test_render_refuses_a_csv_of_another_robot(bow, tmp_path, capsys):
    _, rm = bow
    path = rm.save(tmp_path / "bow.csv")
    lines = path.read_text().splitlines()
    path.write_text("\n".join(",".join(line.split(",")[:20]) for line in lines) + "\n")  # 12 joints, not 29
    assert main(["render", str(path), "--out", str(tmp_path / "x.png")]) == 2
    assert "do not match robot g1's 29 hinge joints" in capsys.readouterr().err


def test_landmarks_guessed_from_body_names(bow):
    """The G1 read by path (not by name) goes through the name guess, and the guess works."""
    robot = load_robot(BUILTIN_ROBOTS["g1"])
    assert robot.points["left_knee"].body == "left_knee_link"
    assert robot.points["left_foot"].body == "left_ankle_roll_link"  # the last ankle link: it has the sole
    assert robot.points["right_shoulder"].body == "right_shoulder_pitch_link"
    assert robot.points["left_hand"].body == "left_wrist_yaw_link"
    human, _ = bow
    rep = replay_report(retarget_to_robot(human, robot), robot)
    assert rep.range_overshoot == 0.0 and rep.lowest_sole > -0.02 and rep.planted_slide < 0.15


def test_name_guess_prefers_the_exact_word():
    """MuJoCo's own humanoid.xml lists 'waist_lower' before 'pelvis': the body called pelvis is the pelvis
    (the first match of any pelvis word used to win, putting the robot's root 16 cm too high)."""
    from kinema.robot.mapping import resolve_mapping

    names = ["world", "torso", "head", "waist_lower", "pelvis", "thigh_right", "shin_right", "foot_right",
             "thigh_left", "shin_left", "foot_left", "upper_arm_right", "lower_arm_right", "hand_right",
             "upper_arm_left", "lower_arm_left", "hand_left"]  # fmt: skip
    points = {key: p.body for key, p in resolve_mapping(names, None, None, "humanoid.xml").items()}
    assert points["pelvis"] == "pelvis" and points["torso"] == "torso" and points["head"] == "head"
    assert points["left_hip"] == "thigh_left" and points["right_foot"] == "foot_right"
    assert points["left_shoulder"] == "upper_arm_left" and points["right_hand"] == "hand_right"


@pytest.mark.parametrize(
    ("xml", "message"),
    [
        ("<mujoco><worldbody><body name='pelvis'><geom size='0.1'/></body></worldbody></mujoco>", "freejoint"),
        (
            "<mujoco><worldbody><body name='pelvis'><freejoint/><geom size='0.1'/>"
            "<body name='arm'><joint type='ball'/><geom size='0.1'/></body></body></worldbody></mujoco>",
            "only hinge joints",
        ),
        ("<mujoco><worldbody><body", "not a valid MJCF robot"),
    ],
)
def test_robots_kinema_cannot_use(tmp_path, xml, message):
    path = tmp_path / "robot.xml"
    path.write_text(xml)
    with pytest.raises(KinemaError, match=message):
        load_robot(path)


def test_commands_in_robot_docs_parse():
    """Every `kinema` command docs/robots.md shows is accepted by the real command line."""
    from kinema.cli import build_parser

    text = (Path(__file__).resolve().parents[1] / "docs" / "robots.md").read_text()
    blocks = re.findall(r"^```bash\n(.*?)^```", text, flags=re.M | re.S)
    lines = [line for block in blocks for line in block.splitlines() if line.startswith("kinema ")]
    commands = [shlex.split(line, comments=True) for line in lines]
    assert len(commands) >= 4
    parser = build_parser()
    for words in commands:
        args = parser.parse_args(words[1:])
        assert args.command in ("generate", "robot", "render")


def test_render_of_an_npz_whose_robot_file_is_not_here(bow, tmp_path, capsys):
    """A robot npz names its MJCF as it was given (a relative path): from elsewhere, render says to pass --robot."""
    import dataclasses

    _, rm = bow
    path = dataclasses.replace(rm, robot="elsewhere/robot.xml").save(tmp_path / "bow.npz")
    assert main(["render", str(path), "--out", str(tmp_path / "x.png"), "--frames", "2"]) == 2
    err = capsys.readouterr().err
    assert "names robot 'elsewhere/robot.xml'" in err and "--robot" in err and len(err.strip().splitlines()) == 1
    assert main(["render", str(path), "--robot", "g1", "--out", str(tmp_path / "x.png"), "--frames", "2"]) == 0


def test_generate_and_app_take_mapping_like_robot(tmp_path, capsys):
    """`--mapping` wherever `--robot` is taken (issue 62): the error of an unrecognised MJCF names it, and
    `kinema generate --robot X.xml --mapping map.json` then works."""
    from kinema.cli import build_parser

    path, renames = _renamed_g1(tmp_path)
    parts = {"hip": "hip_roll", "knee": "knee", "foot": "ankle_roll", "shoulder": "shoulder_roll", "elbow": "elbow",
             "hand": "wrist_yaw"}
    mapping = {f"{s}_{k}": renames[f"{s}_{v}_link"] for s in ("left", "right") for k, v in parts.items()}
    (tmp_path / "map.json").write_text(json.dumps(mapping | {"pelvis": "pelvis", "torso": "torso_link"}))
    out = tmp_path / "walk.csv"
    args = ["generate", "A person walks.", "--seconds", "1", "--steps", "2", "--robot", str(path), "--out", str(out)]
    assert main(args) == 2
    assert "--mapping FILE with --robot on any command" in capsys.readouterr().err
    assert main([*args, "--mapping", str(tmp_path / "map.json")]) == 0
    assert load_robot_motion(out, str(path)).num_frames == 20
    parsed = build_parser().parse_args(["app", "--robot", str(path), "--mapping", str(tmp_path / "map.json")])
    assert parsed.mapping == tmp_path / "map.json"
