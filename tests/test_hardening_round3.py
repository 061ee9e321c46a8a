"""Issue 61 (hardening, round 3: characters, robots, streams): inputs that used to end in a traceback, an
unbounded read or a silently wrong result are one-line errors (exit 2 in the CLI) or carry a warning.
Shared helpers: tests/hardening_fixtures.py."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from kinema.cli import main
from kinema.errors import KinemaError
from kinema.input_files import read_json_bounded
from tests import hardening_fixtures as fixtures
from tests.hardening_fixtures import one_line_error

bvh_file = fixtures.bvh_file


# ---------------------------------------------------------------------------- bounded reads
def test_a_bounded_read_stops_at_its_limit(tmp_path):
    big = tmp_path / "big.json"
    big.write_text(json.dumps({"a": "x" * 100}))
    assert read_json_bounded(big, "mapping file", max_bytes=200) == {"a": "x" * 100}
    with pytest.raises(KinemaError, match=r"big\.json: larger than 50 bytes, too large for a mapping file"):
        read_json_bounded(big, "mapping file", max_bytes=50)
    with pytest.raises(KinemaError, match=r"is a folder, not a mapping file"):
        read_json_bounded(tmp_path, "mapping file")


@pytest.mark.parametrize(
    ("args", "what"),
    [
        (["robot", "{bvh}", "--robot", "g1", "--mapping", "/dev/zero"], "mapping file"),
        (["retarget", "{bvh}", "--rig", "{bvh}", "--mapping", "/dev/zero"], "mapping file"),
        (["retarget", "{bvh}", "--rig", "{bvh}", "--overrides", "/dev/zero"], "rig override file"),
        (["generate", "walk", "--robot", "g1", "--robot-mapping", "/dev/zero", "--steps", "2"], "mapping file"),
    ],
)
def test_dev_zero_as_an_input_file_is_refused_after_a_bounded_read(tmp_path, capsys, bvh_file, args, what):
    out = ["--out", str(tmp_path / ("o" if args[0] == "batch" else "o.csv" if "g1" in args else "o.bvh"))]
    assert main([a.format(bvh=bvh_file) for a in args] + out) == 2
    one_line_error(capsys, "/dev/zero: larger than", what)


@pytest.mark.parametrize(
    "args",
    [
        ["robot", "{bvh}", "--robot", "{bad}"],
        ["robot", "{bad}", "--robot", "g1"],
        ["batch", "{bad}"],
        ["stream", "--script", "{bad}", "--seconds", "1"],
        ["generate", "walk", "--constraints", "{bad}"],
        ["generate", "walk", "--rig", "{bad}"],
    ],
)
@pytest.mark.parametrize(("bad", "message"), [("/dev/zero", "is not a regular file"), ("{tmp}", "is a folder")])
def test_an_input_that_is_no_file_says_what_it_is(tmp_path, capsys, bvh_file, args, bad, message):
    """Not "no such file" (nor, for --rig, "the model drives its own skeleton"): what the path is."""
    bad = bad.format(tmp=tmp_path)
    out = tmp_path / ("o.csv" if "robot" in args else "o" if "batch" in args else "o.bvh")
    assert main([a.format(bvh=bvh_file, bad=bad) for a in args] + ["--out", str(out)]) == 2
    one_line_error(capsys, bad, message)


# ---------------------------------------------------------------------------- glTF skins
def _glb_with_skin_joints(tmp_path, joints) -> Path:
    """The synthetic test GLB (tests/gltf_synthetic.py) with its skin's joint list replaced."""
    import pygltflib

    from tests.gltf_synthetic import write_synthetic_glb

    glb = pygltflib.GLTF2().load(str(write_synthetic_glb(tmp_path / "good.glb")))
    glb.skins[0].joints = joints
    path = tmp_path / "skin.glb"
    glb.save(str(path))
    return path


@pytest.mark.parametrize("joints", [[], [1.5]])
def test_a_skin_without_joints_is_one_line_error(tmp_path, capsys, bvh_file, joints):
    path = _glb_with_skin_joints(tmp_path, joints)
    assert main(["inspect", str(path)]) == 2
    one_line_error(capsys, "skin.glb: skin 0 lists no joints")
    assert main(["retarget", str(bvh_file), "--rig", str(path), "--out", str(tmp_path / "o.glb")]) == 2
    one_line_error(capsys, "skin.glb: skin 0 lists no joints")


# ---------------------------------------------------------------------------- stream scripts
def test_a_stream_script_is_checked_whole_before_the_stream_starts(tmp_path, capsys, monkeypatch):
    """A target naming no joint of the skeleton at line 3 is refused, with its line, before any window."""
    script = tmp_path / "s.jsonl"
    script.write_text('{"t": 0, "prompt": "A person walks."}\n{"t": 1, "clear": true}\n'
                      '{"t": 2, "target": {"joint": "tail", "position": [0, 1, 0]}}\n')
    monkeypatch.setattr("kinema.stream.continuation.MotionStream.next_frames",
                        lambda *a, **k: pytest.fail("a window was generated before the script was checked"))
    assert main(["stream", "--script", str(script), "--seconds", "3", "--out", str(tmp_path / "o.bvh")]) == 2
    one_line_error(capsys, "s.jsonl:3: target: unknown joint 'tail'")
    assert not (tmp_path / "o.bvh").exists()


@pytest.mark.parametrize("fields", [{"seed": 10**400}, {"seconds": 10**400}, {"guidance": (10**400, 1)}])
def test_a_request_number_too_large_for_a_float_is_one_line(fields):
    from kinema.pipeline.request import GenerationRequest

    name = next(iter(fields))
    with pytest.raises(KinemaError, match=rf"^{name}: expected .*, got 1000+\.\.\.0+$"):
        GenerationRequest(prompt="x", **fields)


# ---------------------------------------------------------------------------- the Python API
@pytest.fixture(scope="module")
def human_model():
    import kinema

    return kinema.load_model("default")


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"prompt": "walk", "constraints": "tensor"}, "expected a JSON list of constraint objects"),
        ({"prompt": "walk", "constraints": "array"}, "expected a JSON list of constraint objects"),
        ({"timeline": [("a",)]}, r"timeline: segment 0: expected an object .* got \('a',\)"),
        ({"timeline": ("a", 1.0)}, "timeline: segment 0: expected an object"),
        ({"timeline": [("a", 10**400)]}, "segment 0: field 'seconds' must be a positive number"),
        ({"prompt": "walk", "keyjoint_model": object()}, "keyjoint_model: expected 'default', 'none'"),
    ],
)
def test_python_api_odd_values_are_kinema_errors(human_model, fields, message):
    import numpy as np
    import torch

    values = {"tensor": torch.zeros(3, 3), "array": np.zeros((3, 3))}
    fields = {k: values.get(v, v) if isinstance(v, str) else v for k, v in fields.items()}
    with pytest.raises(KinemaError, match=message):
        human_model.generate(steps=2, **fields)


# ---------------------------------------------------------------------------- robots
@pytest.mark.parametrize(
    ("quat", "message"),
    [("0.7071 0 0.7071 0", r"pelvis to head is 8\d deg from \+Z"), ("0.7071 0 0 0.7071", "right to left hip 90 deg")],
)
def test_a_robot_lying_down_or_turned_at_rest_is_refused(tmp_path, quat, message):
    """The G1 on its back (head above the pelvis by a few cm) or turned 90 deg used to pass the check."""
    from kinema.robot import BUILTIN_ROBOTS, load_robot

    text, pelvis = BUILTIN_ROBOTS["g1"].read_text(), '<body name="pelvis" pos="0 0 0.793"'
    assert text.count(pelvis) == 1
    path = tmp_path / "g1_lying.xml"
    path.write_text(text.replace(pelvis, f'<body name="pelvis" pos="0 0 0.2" quat="{quat}"'))
    with pytest.raises(KinemaError, match=message):
        load_robot(path)


def test_a_robot_without_hinge_joints_is_refused(tmp_path):
    from kinema.robot import load_robot

    path = tmp_path / "stone.xml"
    path.write_text("<mujoco><worldbody><body name='pelvis'><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
    with pytest.raises(KinemaError, match="stone.xml: the robot has no hinge joints below its base"):
        load_robot(path)


# ---------------------------------------------------------------------------- characters
def test_a_glb_scaled_a_millionfold_is_refused(tmp_path, capsys, bvh_file):
    """The synthetic GLB's armature scale (100) made 1e8: 1.7e6 m across, as a BVH of that size is refused."""
    import pygltflib

    from kinema.io.gltf import read_gltf
    from tests.gltf_synthetic import write_synthetic_glb

    good = write_synthetic_glb(tmp_path / "good.glb")
    assert read_gltf(good).skeleton.reach() == pytest.approx(1.7, rel=0.01)
    glb = pygltflib.GLTF2().load(str(good))
    glb.nodes[0].scale = [1e8, 1e8, 1e8]
    huge = tmp_path / "huge.glb"
    glb.save(str(huge))
    assert main(["retarget", str(bvh_file), "--rig", str(huge), "--out", str(tmp_path / "o.glb")]) == 2
    one_line_error(capsys, "huge.glb: the rig reaches 1.7e+06 m from its root (armature scale 1e+08 applied)")


def test_a_glb_with_two_joints_of_one_name_is_refused(tmp_path, capsys, bvh_file):
    """A left foot also named like the right one was read as the right foot (renamed 'Foot.1')."""
    import pygltflib

    from tests.gltf_synthetic import write_synthetic_glb

    glb = pygltflib.GLTF2().load(str(write_synthetic_glb(tmp_path / "good.glb")))
    names = [n.name for n in glb.nodes]
    glb.nodes[names.index("Neck")].name = "Leg"
    glb.save(str(tmp_path / "dup.glb"))
    assert main(["retarget", str(bvh_file), "--rig", str(tmp_path / "dup.glb"), "--out", str(tmp_path / "o.glb")]) == 2
    one_line_error(capsys, "dup.glb: duplicate joint names ['Leg']")


def test_a_humanoid_missing_a_leg_gets_no_arm_or_spine_as_that_leg(tmp_path, bandai_root, capsys):
    """The rest-pose geometry used to take the spine, chest, shoulder and upper arm for the missing right leg."""
    from kinema.io import load_motion
    from kinema.retarget import find_humanoid

    clip = sorted(bandai_root.glob("*/data/*.bvh.gz"))[0]
    out = tmp_path / "one_leg.bvh"
    assert main(["convert", str(clip), str(out), "--in-scale", "0.01",
                 "--drop", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"]) == 0
    found = find_humanoid(load_motion(out).skeleton)
    names = found.skeleton.names
    assert names[found.slots["left_foot"]] == "Foot_L"
    assert not any(slot.startswith("right_") and slot.endswith(("_leg", "_foot", "_toes")) for slot in found.slots)
    assert not found.is_humanoid and "right_upper_leg" in found.missing


@pytest.mark.parametrize("drop", [0.0, 1.0, -0.5])
def test_a_character_stands_on_the_world_floor_whatever_its_rest_height(drop):
    """A Mixamo-style A-pose rig whose rest pose has its hips at the origin (feet 0.93 m below, as CMU-derived
    and some FBX rigs have) was animated under the floor: the floor was taken from the rest pose."""
    from kinema.retarget import retarget
    from kinema.skeleton import Skeleton
    from tests.retarget_rigs import MIXAMO, build_rig, source_walk

    rig = build_rig(MIXAMO, a_pose=True, prefix="mixamorig:")
    offsets = rig.offsets.clone()
    offsets[0, 1] -= drop
    moved = Skeleton(rig.names, rig.parents, offsets, rig.rest_rotations, name="moved")
    height = 1.78
    P = retarget(source_walk(), moved).positions
    lowest = float(P[..., 1].min())
    assert -0.02 * height <= lowest <= 0.08 * height, lowest


# ---------------------------------------------------------------------------- the server
def test_the_server_takes_numbers_as_numbers_only():
    """"seconds": "5" was taken while "samples": "2" was refused; both are 422 naming the field."""
    from fastapi.testclient import TestClient

    from kinema.server.app import create_app
    from kinema.server.config import ServerConfig, ServerLimits
    from kinema.server.models import ModelRegistry

    client = TestClient(create_app(ServerConfig(limits=ServerLimits(max_steps=4)), ModelRegistry.load(["default"])))
    for body, path in (({"prompt": "walk", "seconds": "5"}, "$.seconds"),
                       ({"prompt": "walk", "samples": "2"}, "$.samples"),
                       ({"timeline": [{"prompt": "walk", "seconds": "1"}]}, "$.timeline[0].seconds")):
        answer = client.post("/v1/generate", json=body | {"steps": 2})
        assert answer.status_code == 422 and answer.json()["detail"][0]["path"] == path, answer.text


@pytest.mark.parametrize(("field", "value"), [("translation", [1.5, 0.25, 0.25]), ("rotation", [0, 0, 0, 0]),
                                              ("scale", [1, "x", 1])])
def test_a_glb_node_with_a_bad_transform_is_one_line_naming_the_file(tmp_path, capsys, field, value):
    import warnings

    import pygltflib

    from tests.gltf_synthetic import write_synthetic_glb

    glb = pygltflib.GLTF2().load(str(write_synthetic_glb(tmp_path / "good.glb")))
    names = [n.name for n in glb.nodes]
    setattr(glb.nodes[names.index("Neck")], field, value)
    glb.save(str(tmp_path / "bad.glb"))
    if field == "translation":  # JSON's NaN, which pygltflib does not write: the same length in place
        data = (tmp_path / "bad.glb").read_bytes()
        assert data.count(b"[1.5,0.25,0.25]") == 1
        (tmp_path / "bad.glb").write_bytes(data.replace(b"[1.5,0.25,0.25]", b"[NaN,0.25,0.25]"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning before the error
        assert main(["inspect", str(tmp_path / "bad.glb")]) == 2
    one_line_error(capsys, f"bad.glb: node {names.index('Neck')} (Neck) has a bad {field}")


def test_checking_an_inline_rig_does_not_hold_up_the_server(monkeypatch):
    """/healthz took 1.6-3.5 s while a 909 KB inline BVH was checked on the event loop."""
    import threading

    from fastapi.testclient import TestClient

    import kinema.server.app as server_app
    from kinema.server.config import ServerConfig, ServerLimits
    from kinema.server.errors import RequestError
    from kinema.server.models import ModelRegistry

    checking, answered = threading.Event(), threading.Event()

    def slow_prepare(*args):
        checking.set()
        assert answered.wait(20), "/healthz did not answer while a request was being checked"
        raise RequestError.at(["body", "rig"], "checked")

    monkeypatch.setattr(server_app, "prepare", slow_prepare)
    client = TestClient(server_app.create_app(ServerConfig(limits=ServerLimits(max_steps=4)),
                                              ModelRegistry.load(["default"])))
    with client:
        posted = []
        poster = threading.Thread(target=lambda: posted.append(client.post("/v1/generate", json={"prompt": "x"})))
        poster.start()
        assert checking.wait(20)
        assert client.get("/healthz").status_code == 200
        answered.set()
        poster.join(30)
    assert posted and posted[0].status_code == 422 and "checked" in posted[0].text
