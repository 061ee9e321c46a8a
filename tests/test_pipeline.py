"""One pipeline for every model (kinema.pipeline, kinema.generate): one request whose fields every face
derives, one loader that reads the pipeline from checkpoint.json, and both shipped models served by the
server and batch (inline rig, GLB out)."""

from __future__ import annotations

import argparse
import base64
import dataclasses
import json
import shutil
from pathlib import Path

import pytest
import torch

from kinema.cli.request_args import add_request_arguments, request_fields, request_from_args
from kinema.errors import KinemaError
from kinema.generate import GenerationRequest, load_model
from kinema.io.gltf import read_gltf
from kinema.pipeline.request import option
from kinema.pipeline.request_json import request_model
from kinema.server.config import ServerLimits
from kinema.server.schemas import build_request_model
from tests.retarget_rigs import MIXAMO, build_rig
from tests.rig_fixtures import quadruped, walking

SHARED_FOX = Path(__file__).resolve().parents[1].parent / "shared/datasets/quaternius/animals_pack/Fox.glb"


def kinema_motion_file(skeleton, path: Path) -> Path:
    """A one-frame rest-pose motion of ``skeleton`` saved to ``path`` (a character file)."""
    from kinema.motion.core import Motion

    rest = torch.tensor([1.0, 0, 0, 0]).repeat(1, skeleton.num_joints, 1)
    return Motion(skeleton, 20.0, torch.zeros(1, 3), rest).save(path)


def _fox(tmp_path: Path) -> Path:
    """A creature GLB the creatures model never needs to have seen: the shared fox, else a built quadruped."""
    if SHARED_FOX.is_file():
        return SHARED_FOX
    return walking(quadruped()).save(tmp_path / "quadruped.glb")


@dataclasses.dataclass(frozen=True, kw_only=True)
class DummyRequest(GenerationRequest):
    dummy_level: int = option(3, kind="int", low=0, high=9, help="a field added only in this test")


def test_a_new_request_field_reaches_the_cli_the_server_and_batch() -> None:
    parser = argparse.ArgumentParser()
    add_request_arguments(parser, DummyRequest)
    args = parser.parse_args(["A person walks.", "--dummy-level", "7", "--seconds", "2", "--heading", "90"])
    request = request_from_args(args, DummyRequest)
    assert request.dummy_level == 7 and request.seconds == 2 and abs(request.heading - torch.pi / 2) < 1e-9
    with pytest.raises(SystemExit):
        parser.parse_args(["--dummy-level", "-1"])  # bounds come from the field's Option
    with pytest.raises(KinemaError, match=r"dummy_level: expected an integer in \[0, 9\], got 10"):
        request_from_args(parser.parse_args(["--dummy-level", "10"]), DummyRequest)
    server = build_request_model(ServerLimits(), DummyRequest).model_json_schema()
    assert server["properties"]["dummy_level"]["maximum"] == 9
    batch = request_model("Batch", cls=DummyRequest).model_json_schema()
    assert "dummy_level" in batch["properties"]
    assert "dummy_level" in request_fields(DummyRequest) and "dummy_level" not in request_fields()


def test_every_request_field_is_on_every_face_or_says_where_it_is() -> None:
    from kinema.batch.spec import BatchJob
    from kinema.cli import build_parser
    from kinema.pipeline.request import options

    generate = next(a for a in build_parser()._subparsers._group_actions[0].choices.items() if a[0] == "generate")[1]
    dests = {a.dest for a in generate._actions}
    server = build_request_model(ServerLimits()).model_fields
    for f, opt in options(GenerationRequest):
        assert f.name in server and f.name in BatchJob.model_fields, f.name
        assert f.name in dests or (opt.cli is False and opt.cli_note), f.name


def test_request_bounds_and_types_are_one_line_errors(monkeypatch) -> None:
    monkeypatch.setenv("KINEMA_MAX_SECONDS", "1200")
    assert GenerationRequest(prompt="x", seconds=900).seconds == 900  # a process may allow longer motions
    monkeypatch.setenv("KINEMA_MAX_SECONDS", "-3")
    with pytest.raises(KinemaError, match="KINEMA_MAX_SECONDS: expected a positive number"):
        GenerationRequest(prompt="x")
    monkeypatch.delenv("KINEMA_MAX_SECONDS")
    for bad, message in [({"samples": 0}, "samples"), ({"seconds": 1e9}, r"seconds: expected .* \(0, 600\]"),
                         ({"seconds": True}, "expected a finite number"), ({"postprocess": "no"}, "true or false"),
                         ({"heading": float("inf")}, "finite"), ({"prompt": "x", "timeline": [["y", 1]]}, "either"),
                         ({"format": "fbx"}, "one of")]:
        with pytest.raises(KinemaError, match=message):
            GenerationRequest(**bad)
    req = GenerationRequest(prompt="A person waves.", seconds=3, seed=4)
    assert GenerationRequest.from_json(req.to_json()) == req
    with pytest.raises(KinemaError, match="unknown field 'sample'"):
        GenerationRequest.from_json({"sample": 2})


def test_load_model_reads_the_pipeline_key_and_old_checkpoints(tmp_path) -> None:
    from kinema.generate.loading import resolve_model_path

    for name, pipeline in (("default", "human"), ("creatures", "anyrig")):
        src = resolve_model_path(name)
        assert json.loads((src / "checkpoint.json").read_text())["pipeline"] == pipeline
        old = tmp_path / name
        shutil.copytree(src, old)
        info = json.loads((old / "checkpoint.json").read_text())
        del info["pipeline"]
        (old / "checkpoint.json").write_text(json.dumps(info))
        assert type(load_model(old)).pipeline_name == pipeline
        info["pipeline"] = "teleport"
        (old / "checkpoint.json").write_text(json.dumps(info))
        with pytest.raises(KinemaError, match="unknown pipeline 'teleport'"):
            load_model(old)


def test_both_models_take_the_same_request_and_refuse_what_they_cannot_do(tmp_path) -> None:
    human, creatures = load_model("default"), load_model("creatures")
    fox = _fox(tmp_path)
    req = GenerationRequest(prompt="A person walks forward.", seconds=1.5, steps=3, seed=2)
    a = human.generate(req)
    b = creatures.generate(req.replace(prompt="A fox walks.", rig=str(fox)))
    for res, joints in ((a, 21), (b, read_gltf(fox).skeleton.num_joints)):
        assert res[0].num_frames == 30 and res[0].num_joints == joints
        assert res.report.steps == 3 and res.report.seed == 2 and set(res.report.timings) == {"sampling", "postprocess"}
    assert torch.equal(human.generate(req)[0].positions, a[0].positions)  # a seed fixes the result
    with pytest.raises(KinemaError, match="keeps no training captions"):
        creatures.generate(req.replace(rig=str(fox), grounding=0.5))
    with pytest.raises(KinemaError, match="needs a rig"):
        creatures.generate(req)
    with pytest.raises(KinemaError, match="not a humanoid"):
        human.generate(req.replace(rig=str(fox)))  # a character file: the human model retargets humanoids only
    with pytest.raises(KinemaError, match="drives its own skeleton"):
        human.generate(req.replace(rig="fox0"))  # a rig id it does not have


def test_server_serves_both_models_with_an_inline_rig_and_glb_out(tmp_path) -> None:
    from fastapi.testclient import TestClient

    from kinema.server.app import create_app
    from kinema.server.config import ServerConfig
    from kinema.server.models import ModelRegistry

    registry = ModelRegistry.load(["default", "creatures=creatures"])
    client = TestClient(create_app(ServerConfig(limits=ServerLimits(max_steps=4)), registry))
    models = {m["name"]: m for m in client.get("/v1/models").json()["models"]}
    assert models["default"]["rig"]["name"] == "bandai-namco" and not models["default"]["needs_rig"]
    assert models["creatures"]["needs_rig"] and len(models["creatures"]["rigs"]) > 10
    fox = _fox(tmp_path)
    rig = {"format": "glb", "data": base64.b64encode(fox.read_bytes()).decode()}
    body = {"prompt": "A fox walks.", "seconds": 1.0, "steps": 2, "rig": rig, "format": "glb"}
    answer = client.post("/v1/generate", json=body)
    assert answer.status_code == 200, answer.text
    out = answer.json()
    assert out["model"] == "creatures" and out["format"] == "glb" and out["report"]["joints"] > 0
    glb = tmp_path / "out.glb"
    glb.write_bytes(base64.b64decode(out["motions"][0]["data"]))
    clip = read_gltf(glb)
    assert clip.skeleton.names == read_gltf(fox).skeleton.names and clip.motions
    human = client.post("/v1/generate", json={"prompt": "A person waves.", "seconds": 1.0, "steps": 2})
    assert human.status_code == 200 and human.json()["model"] == "default"
    bad = client.post("/v1/generate", json={"model": "default", "prompt": "x", "rig": rig})
    assert bad.status_code == 422 and "not a humanoid" in bad.text
    broken = client.post("/v1/generate", json=body | {"rig": {"format": "bvh", "data": "HIERARCHY\nnonsense"}})
    assert broken.status_code == 422 and "kinema-serve-" not in broken.text  # no server temp path leaks
    person = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.2, arms=0.9)
    glb = kinema_motion_file(person, tmp_path / "person.glb")
    inline = {"format": "glb", "data": base64.b64encode(glb.read_bytes()).decode()}
    answer = client.post("/v1/generate", json={"prompt": "A person waves.", "seconds": 1.0, "steps": 2, "rig": inline,
                                               "format": "glb"})
    assert answer.status_code == 200 and answer.json()["model"] == "default", answer.text  # humanoid: retargeted
    assert answer.json()["report"]["character"][0]["bone_drift_mm"] < 0.1


def test_a_batch_line_names_the_creatures_model_and_a_rig_file(tmp_path) -> None:
    from kinema.batch.runner import run_batch

    fox = _fox(tmp_path)
    jobs = tmp_path / "jobs.jsonl"
    jobs.write_text("\n".join(json.dumps(j) for j in [
        {"id": "fox", "model": "creatures", "rig": str(fox), "prompt": "A fox walks.", "seconds": 1.0, "steps": 2,
         "format": "glb"},
        {"id": "person", "prompt": "A person walks.", "seconds": 1.0, "steps": 2},
        {"id": "nope", "model": "creatures", "prompt": "A fox walks.", "seconds": 1.0, "steps": 2},
    ]) + "\n")
    summary = run_batch(jobs, tmp_path / "out", workers=1, progress=False)
    assert summary.done == 2 and summary.failed == 1 and "needs a rig" in summary.errors[0]
    clip = read_gltf(tmp_path / "out" / "fox.glb")
    assert clip.skeleton.num_joints == read_gltf(fox).skeleton.num_joints
    assert (tmp_path / "out" / "person.bvh").read_text().startswith("HIERARCHY")


def test_a_robot_through_the_request_on_every_face(tmp_path) -> None:
    """issue 39 through the one request: Python, the server (a built-in robot by name only) and batch; an
    inline robot_mapping is read as a mapping file is on all three (issue 61: it used to be a 500)."""
    from fastapi.testclient import TestClient

    from kinema.batch.runner import run_batch
    from kinema.robot import load_robot_motion
    from kinema.server.app import create_app
    from kinema.server.config import ServerConfig
    from kinema.server.models import ModelRegistry

    res = load_model("default").generate(GenerationRequest(prompt="A person walks.", seconds=1.0, steps=2, robot="g1",
                                                           robot_mapping={"pelvis": "pelvis"}))
    (rm,) = res.robot_motions
    assert rm.num_frames == res[0].num_frames and res.report.robot[0]["range_overshoot_rad"] == 0.0
    with pytest.raises(KinemaError, match="csv is a robot's joint angles"):
        GenerationRequest(prompt="x", format="csv")
    client = TestClient(create_app(ServerConfig(limits=ServerLimits(max_steps=4)), ModelRegistry.load(["default"])))
    body = {"prompt": "A person waves.", "seconds": 1.0, "steps": 2, "robot": "g1", "format": "csv"}
    answer = client.post("/v1/generate", json=body | {"robot_mapping": {"head": {"body": "torso_link",
                                                                               "offset": [0, 0, 0.43]}}})
    assert answer.status_code == 200, answer.text
    for mapping, message in (({"tail": "pelvis"}, "robot_mapping: unknown landmark(s) ['tail']"),
                             ({"left_hip": "pelvis"}, "puts 'pelvis' and 'left_hip' at the same point")):
        refused = client.post("/v1/generate", json=body | {"robot_mapping": mapping})
        assert refused.status_code == 422 and message in refused.text, refused.text
    csv = answer.json()["motions"][0]["data"]
    assert csv.startswith("time,root_x,root_y,root_z,root_qw") and len(csv.splitlines()) == 21
    assert client.post("/v1/generate", json=body | {"robot": "../g1.xml"}).status_code == 422  # names only
    jobs = tmp_path / "jobs.jsonl"
    jobs.write_text(json.dumps({"id": "g1walk", "prompt": "A person walks.", "seconds": 1.0, "steps": 2,
                                "robot": "g1", "robot_mapping": {"pelvis": "pelvis"}, "format": "csv"}) + "\n")
    assert run_batch(jobs, tmp_path / "out", workers=1, progress=False).done == 1
    assert load_robot_motion(tmp_path / "out" / "g1walk.csv", "g1").num_frames == 20
