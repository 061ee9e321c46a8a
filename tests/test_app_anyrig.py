"""The app with the any-rig model (``kinema app --model creatures``), without a browser: the constraint
panel lists the shown rig's joints, and constraints laid in the scene reach the shipped creatures
model and are met on the motion it returns (a synthetic quadruped GLB, no dataset needed)."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
import torch

pytest.importorskip("viser", reason="pip install 'kinema[app]'")

import kinema  # noqa: E402
from kinema.app import edits  # noqa: E402
from kinema.app.constraint_panel import ConstraintPanel  # noqa: E402
from kinema.app.document import Document, check_timeline  # noqa: E402
from kinema.app.files_panel import FilesPanel  # noqa: E402
from kinema.app.generation import outcome  # noqa: E402
from kinema.app.rig_constraints import planned_root, to_anyrig  # noqa: E402
from kinema.app.rigs import load_rig  # noqa: E402
from kinema.app.views import rest_motion  # noqa: E402
from kinema.constraints.character import JointTarget, Keyframe, RootPath  # noqa: E402
from kinema.rig import Rig  # noqa: E402
from kinema.skeleton import Skeleton  # noqa: E402
from tests.app_rig_data import NAMES, synthetic_rig_glb  # noqa: E402


class _Handle:
    def __init__(self, value=None, options=()):
        self.value, self.options, self.visible, self.disabled = value, options, True, False

    def on_update(self, fn):
        return fn

    on_click = on_upload = on_update


class _Gui:
    """Just what ConstraintPanel builds (records nothing but the values)."""

    def add_folder(self, _label, **_):
        return contextlib.nullcontext()

    def add_dropdown(self, _label, options, initial_value=None, **_):
        return _Handle(initial_value, tuple(options))

    def add_button_group(self, _label, options, **_):
        return _Handle(None, tuple(options))

    def __getattr__(self, name):  # add_checkbox, add_button, add_slider, add_multi_slider, add_markdown
        return lambda *a, **k: _Handle(k.get("initial_value"))


class _Scene:
    def on_click(self):
        return lambda fn: fn


class _Host:
    def __init__(self, model, skeleton):
        self.model, self.skeleton, self.doc = model, skeleton, Document(constraints=[])
        self.shown, self.notes = [], []

    def show_motions(self, motions, *, report, source):
        self.shown.append((list(motions), source))

    def notify(self, title, body, *, error=False):
        self.notes.append(f"{title}: {body}")


@pytest.fixture(scope="module")
def model():
    return kinema.load_model("creatures")


@pytest.fixture(scope="module")
def rig(model, tmp_path_factory):
    return load_rig(synthetic_rig_glb(tmp_path_factory.mktemp("quad") / "quad.glb"), fps=model.fps)


def test_joint_list_is_the_rigs(model, rig):
    panel = ConstraintPanel(_Gui(), _Scene(), _Host(model, rig.skeleton))
    assert list(panel.joint.options) == NAMES and panel.joint.value == "head"  # a role, not the last joint
    other, _ = rig.skeleton.prune(NAMES[5:])  # another rig: the list follows it
    panel.set_skeleton(other)
    assert list(panel.joint.options) == NAMES[:5] and panel.joint.value == "head"
    contact = edits.contacts(0, 3, "left foot planted")
    assert panel._residual(contact, rest_motion(rig.skeleton, model.fps)) == "not used by this model"


def test_what_the_model_cannot_take_is_named(model, rig):
    rest = rest_motion(rig.skeleton, model.fps)
    rotated = edits.target(rest, 0, "fl_foot", position=True, rotation=True)
    root_only = edits.target(rest, 0, "root", position=True, rotation=False)
    scene = [
        edits.waypoint(0, 0.0, 0.0, heading=0.5),
        edits.waypoint(30, 0.0, 1.0),
        rotated,
        root_only,
        edits.keyframe(rest, 0) | {"frame_indices": [10]},
        edits.contacts(0, 4, "both feet planted"),
    ]
    cons, notes = to_anyrig(scene, rig.skeleton, model.fps)
    assert [type(c) for c in cons] == [RootPath, JointTarget, Keyframe]
    assert list(cons[0].frames) == [30] and list(cons[0].xz) == [(0.0, 1.0)] and cons[2].frame == 10
    assert notes == [
        "the any-rig model cannot take a waypoint on frame 0 (the root starts at the origin), waypoint headings "
        "(the root faces where it goes), rotation targets, targets on the root joint (use waypoints), "
        "foot-contact constraints; they were left out"
    ]
    assert planned_root([(20, 1.0, 0.0)], 10) == pytest.approx((0.5, 0.0, torch.pi / 2))


def test_waypoint_and_target_from_the_scene_are_met(model, rig):
    doc = Document(timeline=[{"prompt": "A dog walks.", "seconds": 3.0}], constraints=[])
    doc.constraints.append(edits.waypoint(40, 0.3, 1.2))
    first = outcome(model, rig, check_timeline(doc.timeline), constraints=doc.constraints, samples=1, steps=10,
                    seed=0, progress=None).motions[0]  # fmt: skip
    foot = rig.skeleton.index("fl_foot")
    target = edits.target(first, 30, "fl_foot", position=True, rotation=False)
    target = edits.moved(target, [v + d for v, d in zip(target["positions"][0], (0.0, 0.05, 0.0), strict=True)])
    doc.constraints.append(target)
    steps: list[tuple[int, int]] = []
    out = outcome(model, rig, check_timeline(doc.timeline), constraints=doc.constraints, samples=1, steps=10,
                  seed=0, progress=lambda d, t: steps.append((d, t)))  # fmt: skip
    # two passes on one bar, each the root stage's 10 steps and the body's 10 (the second pass copies the first
    # pass's root up to the foot target's frame, where it pins the root, and samples the root after it)
    assert steps == [(d, 40) for d in range(1, 41)]
    m = out.motions[0].to(torch.float64)
    assert m.num_frames == 60 and out.notes == []
    root = Rig.from_skeleton(rig.skeleton).root
    assert float((m.positions[40, root, [0, 2]] - torch.tensor([0.3, 1.2])).norm()) < 0.03
    assert float((m.positions[30, foot] - torch.tensor(target["positions"][0])).norm()) < 0.03
    assert "joint targets met within" in out.text
    host = _Host(model, rig.skeleton)
    host.doc.constraints, host.result_motion = doc.constraints, lambda: m
    panel = ConstraintPanel(_Gui(), _Scene(), host)
    panel.show_residuals()
    lines = panel.residual_md.content.splitlines()[1:]
    assert len(lines) == 2 and all(float(line.split(": ")[1].split(" cm")[0]) < 3.0 for line in lines), lines


FOX = Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets" / "quaternius" / "animals_pack" / "Fox.glb"


@pytest.mark.skipif(not FOX.is_file(), reason="the Quaternius dataset is not next to the repository")
def test_fox_head_target_is_met_and_ik_bone_targets_are_named(model):
    rig = load_rig(FOX, fps=model.fps)
    panel = ConstraintPanel(_Gui(), _Scene(), _Host(model, rig.skeleton))
    assert list(panel.joint.options) == list(rig.skeleton.names) and "Hand_R" not in panel.joint.options
    timeline = [{"prompt": "A fox walks.", "seconds": 2.0}]
    wp = edits.waypoint(30, 0.2, 1.0)
    first = outcome(model, rig, timeline, constraints=[wp], samples=1, steps=5, seed=0, progress=None).motions[0]
    head = edits.target(first, 20, "Head", position=True, rotation=False)
    head = edits.moved(head, [v + d for v, d in zip(head["positions"][0], (0.0, 0.05, 0.0), strict=True)])
    ik = edits.target(first, 20, "IKFrontLeg.L", position=True, rotation=False)
    toe = edits.target(first, 20, "FFB.R", position=True, rotation=False)  # below an IK bone
    contacts = edits.contacts(0, 5, "both feet planted")
    out = outcome(
        model, rig, timeline, constraints=[wp, head, ik, toe, contacts], samples=1, steps=5, seed=0, progress=None
    )
    m = out.motions[0].to(torch.float64)
    assert float((m.positions[20, rig.skeleton.index("Head")] - torch.tensor(head["positions"][0])).norm()) < 0.03
    assert out.notes == [
        "the any-rig model cannot take foot-contact constraints, targets on bones it moves by translation "
        "(IKFrontLeg.L, FFB.R; target a leg bone instead); they were left out"
    ]


def test_bvh_clip_upload_works_with_the_creatures_model(model, rig, tmp_path):
    """"Upload BVH clip" reads the clip onto the rig's skeleton (the model has none of its own); a clip of
    other joints is a one-line notification."""
    host = _Host(model, rig.skeleton)
    panel = FilesPanel(_Gui(), host)
    walk = rig.clips["Walk"]
    walk.save(tmp_path / "walk.bvh", scale=100.0)  # centimetres: the panel's default units
    panel._guard(lambda: panel._clip("walk.bvh", (tmp_path / "walk.bvh").read_bytes()))
    assert host.notes == [f"Clip loaded: walk.bvh: {walk.num_frames} frames"], host.notes  # the app's own answer
    host.notes.clear()
    (motion,), source = host.shown[-1]
    assert source == "clip walk.bvh" and motion.skeleton.same_topology(rig.skeleton)
    assert motion.num_frames == walk.num_frames
    chain = Skeleton(["a", "b", "c"], [-1, 0, 1], torch.tensor([[0, 1.0, 0], [0, 0.5, 0], [0, 0.5, 0]]))
    rest_motion(chain, model.fps).save(tmp_path / "chain.bvh", scale=100.0)
    panel._guard(lambda: panel._clip("chain.bvh", (tmp_path / "chain.bvh").read_bytes()))
    assert len(host.notes) == 1 and host.notes[0].startswith("Upload failed: ") and "\n" not in host.notes[0]
    assert "Traceback" not in host.notes[0] and "Error:" not in host.notes[0], host.notes
