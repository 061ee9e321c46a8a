"""The app's rigs without a browser: loading GLB/BVH rigs, splitting a skin by colour for viser, the
skinned view posing its bones, and what the app says when a model cannot generate for a rig."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("viser", reason="pip install 'kinema[app]'")

from kinema.anyrig.pipeline import AnyRigModel, AnyRigReport, AnyRigResult  # noqa: E402
from kinema.app.generation import cannot_generate, outcome  # noqa: E402
from kinema.app.mesh_view import MeshView, SkinPool, skin_parts  # noqa: E402
from kinema.app.rigs import load_rig, load_rig_bytes, model_rig  # noqa: E402
from kinema.cli import build_parser, main  # noqa: E402
from kinema.errors import KinemaError  # noqa: E402
from kinema.io.gltf_writer import rest_world  # noqa: E402
from kinema.skeleton import Skeleton  # noqa: E402
from tests.app_rig_data import NAMES, quad_motion, synthetic_rig_glb  # noqa: E402


def test_glb_rig_loads_with_skin_clip_and_contacts(tmp_path):
    rig = load_rig(synthetic_rig_glb(tmp_path / "quad.glb"), fps=20.0)
    assert rig.name == "quad.glb" and list(rig.skeleton.names) == NAMES
    assert list(rig.clips) == ["Walk"] and rig.clips["Walk"].fps == 20.0
    assert rig.mesh.num_vertices > 0 and rig.own_colors
    assert len(rig.contacts) == 4 and all(rig.skeleton.names[j].endswith("foot") for j in rig.contacts)
    flags = rig.clips["Walk"].foot_contacts
    assert flags is not None and flags.shape == (rig.clips["Walk"].num_frames, 4)


def test_bvh_rig_and_bad_uploads(tmp_path):
    path = tmp_path / "quad.bvh"
    quad_motion().save(path, scale=100.0)
    rig = load_rig(path, fps=20.0, scale=0.01)
    assert list(rig.skeleton.names) == NAMES and not rig.own_colors  # the generated bone skin
    clip = next(iter(rig.clips.values()))
    assert abs(float(clip.positions[0, 4, 1]) - 0.05) < 1e-4  # a foot 5 cm up: centimetres were read as such
    with pytest.raises(KinemaError, match=r"^notes.txt: upload a rig as \.glb, \.gltf or \.bvh"):
        load_rig_bytes("notes.txt", b"hello", fps=20.0)
    with pytest.raises(KinemaError, match=r"^broken\.glb"):
        load_rig_bytes("broken.glb", b"glTF not really", fps=20.0)


def test_skin_parts_keep_every_face_and_weights(tmp_path):
    rig = load_rig(synthetic_rig_glb(tmp_path / "quad.glb"), fps=20.0)
    parts = skin_parts(rig.mesh)
    assert sum(len(p.faces) for p in parts) == len(rig.mesh.faces)
    for p in parts:
        assert np.allclose(p.weights.sum(1), 1.0, atol=1e-5) and p.faces.max() < len(p.vertices)


class _Bone:
    wxyz = position = None


class _Scene:
    def __init__(self):
        self.added = []

    def add_mesh_skinned(self, name, vertices, faces, *, bone_wxyzs, bone_positions, skin_weights, **_):
        handle = type("H", (), {"bones": tuple(_Bone() for _ in bone_wxyzs), "removed": False})()
        self.added.append((name, vertices, bone_positions, handle))
        return handle


def test_mesh_view_starts_at_rest_poses_bones_and_reuses_its_nodes(tmp_path):
    rig = load_rig(synthetic_rig_glb(tmp_path / "quad.glb"), fps=20.0)
    scene, motion = _Scene(), rig.clips["Walk"]
    pool = SkinPool(scene)
    view = MeshView(pool, 0, rig.skeleton, rig.mesh, own_colors=True)
    view.set_motion(motion, offset=(1.0, 0.0, 0.0))
    view.show(3)
    part, (_, _, rest_positions, handle) = view.parts[0], scene.added[0]
    assert np.allclose(rest_positions, rest_world(rig.skeleton)[1][part.bones], atol=1e-6)  # the skin's own pose
    j = int(part.bones[0])
    assert np.allclose(handle.bones[0].position, motion.positions[3, j].numpy() + [1.0, 0.0, 0.0], atol=1e-6)
    assert np.allclose(handle.bones[0].wxyz, motion.global_rotations[3, j].numpy(), atol=1e-6)
    view.remove()  # hidden, never removed (viser 1.1.1's client crashes on removing a skinned mesh)
    assert handle.visible is False and not handle.removed
    again = MeshView(pool, 0, rig.skeleton, rig.mesh, own_colors=True)
    again.set_motion(motion)
    again.show(0)
    assert len(scene.added) == len(view.parts) and handle.visible is True


def test_human_model_cannot_generate_for_another_rig(tmp_path):
    quad = load_rig(synthetic_rig_glb(tmp_path / "quad.glb"), fps=20.0)
    human = model_rig(quad_motion().skeleton, name="quad-model")

    class Model:  # a model with its own skeleton (kinema.pipeline.base.MotionPipeline's properties)
        skeleton = human.skeleton
        needs_rig = False

    assert cannot_generate(Model(), human, "m") is None
    assert cannot_generate(Model(), quad, "m") is None  # the same joints from a GLB file: fine
    chain = Skeleton(["a", "b", "c"], [-1, 0, 1], torch.tensor([[0, 1.0, 0], [0, 0.5, 0], [0, 0.5, 0]]))
    other = model_rig(chain, name="chain")
    why = cannot_generate(Model(), other, "default")
    assert why is not None and "'default' model generates for its own 11-joint skeleton" in why and "chain" in why


def test_cli_rig_arguments(capsys, tmp_path):
    args = build_parser().parse_args(["app", "--rig", "Fox.glb", "--rig-units", "metres"])
    assert str(args.rig) == "Fox.glb" and args.rig_units == "metres"
    assert main(["app", "--rig", str(tmp_path / "missing.glb")]) == 2
    assert capsys.readouterr().err.strip().endswith("missing.glb: no such rig file")


class _FakeAnyRig(AnyRigModel):
    """Stands in for a trained any-rig model: records the call, returns the rig's clip."""

    fps = 20.0
    path = Path("fake-creatures")

    def __init__(self, clip):
        self.clip, self.calls = clip, []

    def frames(self, prompt, seconds=4.0) -> int:
        return self.clip.num_frames

    def sample_on_rig(self, request, *, rig, **_):
        r = request
        self.calls.append((r.prompt if r.timeline is None else r.timeline, rig.skeleton, r.samples, r.steps, r.seed))
        return AnyRigResult([self.clip] * r.samples, AnyRigReport(seconds=0.1, steps=r.steps))


def test_any_rig_model_gets_the_timeline_and_the_shown_rig(tmp_path):
    rig = load_rig(synthetic_rig_glb(tmp_path / "quad.glb"), fps=20.0)
    clip = rig.clips["Walk"]
    bare = type(clip)(clip.skeleton, clip.fps, clip.root_translation, clip.local_rotations)
    model = _FakeAnyRig(bare)
    timeline = [{"prompt": "A dog walks.", "seconds": 2.0}, {"prompt": "A dog sits.", "seconds": 1.5}]
    contacts = {"type": "foot-contact", "frame_indices": [0, 1], "contacts": [[1, 1, 0, 0]] * 2}
    out = outcome(model, rig, timeline, constraints=[contacts], samples=2, steps=3, seed=4, progress=None)
    assert model.calls == [(timeline, rig.skeleton, 2, 3, 4)]  # every segment (kinema.anyrig.windows)
    assert len(out.motions) == 2 and out.motions[0].foot_contacts.shape == (clip.num_frames, 4)
    assert out.notes == ["the any-rig model cannot take foot-contact constraints; they were left out"]
    assert out.text.startswith("2 sample(s) on quad.glb")
    assert cannot_generate(model, rig, "creatures") is None
