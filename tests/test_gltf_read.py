"""glTF/GLB reading: the rig, helper bones, the armature scale, every interpolation and the skin.

Joint positions are checked against an independent forward kinematics written for the tests
(tests/gltf_reference.py: pygltflib + numpy). The synthetic rig (tests/gltf_synthetic.py) covers the
cases on any machine; two real Quaternius files are checked when the shared data folder exists.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from gltf_reference import world_positions
from gltf_synthetic import write_synthetic_glb

from kinema.io.gltf import GltfError, read_gltf
from kinema.io.gltf_data import sample
from kinema.kinematics import forward_kinematics

REPO = Path(__file__).resolve().parents[1]
QUATERNIUS = Path(os.environ.get("KINEMA_QUATERNIUS", REPO.parent / "shared/datasets/quaternius"))
needs_quaternius = pytest.mark.skipif(not QUATERNIUS.is_dir(), reason="shared Quaternius GLBs not found")


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    return write_synthetic_glb(tmp_path_factory.mktemp("glb") / "rig.glb")


def _max_error(path: Path, motion, clip: str) -> float:
    ref = world_positions(path, clip, np.arange(motion.num_frames) / motion.fps)
    P = motion.positions.double().numpy()
    names = motion.skeleton.names
    return max(float(np.abs(P[:, names.index(n)] - v).max()) for n, v in ref.items() if n in names)


def test_synthetic_rig_structure(synthetic):
    asset = read_gltf(synthetic)
    sk = asset.skeleton
    # two weighted roots (Body, Foot) -> their armature node becomes joint 0; the weightless Pole is dropped
    assert sk.names[0] == "Armature" and set(sk.names) == {"Armature", "Body", "Neck", "Head", "Leg", "Foot"}
    assert asset.helper_joints == ("Pole",)
    assert asset.scale == pytest.approx(100.0)
    assert all(sk.parents[j] < j for j in range(1, sk.num_joints))
    assert asset.source_fps is not None and list(asset.motions) == ["Rig|Move"]
    # metres: Body sits 0.01 armature units * 100 = 1 m along the armature's +Z, which it turns into world +Y
    body = sk.names.index("Body")
    assert sk.offsets[body].tolist() == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
    _, rest = forward_kinematics(sk.rest_rotations, sk.offsets[0], sk.offsets, sk.parents)
    assert rest[body].tolist() == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)


def test_synthetic_positions_match_independent_fk(synthetic):
    for fps in (None, 30.0, 7.0):
        asset = read_gltf(synthetic, fps=fps)
        motion = asset.motions["Rig|Move"]
        assert _max_error(synthetic, motion, "Rig|Move") < 1e-8
    assert motion.num_frames == 8  # keys span 1 s: frames at 0, 1/7, ..., 1
    assert motion.local_translations is not None  # Foot's translation is animated (STEP)


def test_keep_helpers_and_clip_selection(synthetic):
    asset = read_gltf(synthetic, keep_helpers=True, animations=["Move"], fps=20)
    assert "Pole" in asset.skeleton.names and asset.helper_joints == ("Pole",)
    assert _max_error(synthetic, asset.motions["Rig|Move"], "Rig|Move") < 1e-8
    with pytest.raises(GltfError, match=r"rig\.glb: no animation named 'Walk'"):
        read_gltf(synthetic, animations=["Walk"])


def test_two_skins_become_one_mesh_in_rest_pose(synthetic):
    mesh = read_gltf(synthetic).skeleton.mesh
    assert mesh.num_vertices == 8 and len(mesh.faces) == 4 and len(mesh.colors) == 2
    # the file's bind pose is its node pose, so rest-pose vertices are the stored ones (world units)
    expected_centres = [[0.0, 0.0, 0.012], [0.003, 0.0, 0.0]]
    for k, centre in enumerate(expected_centres):
        assert mesh.vertices[4 * k : 4 * k + 4].mean(axis=0).tolist() == pytest.approx(centre, abs=1e-6)
    assert np.allclose(mesh.weights.sum(axis=1), 1.0)
    names = read_gltf(synthetic).skeleton.names
    assert {names[j] for j in mesh.joints[mesh.weights > 0]} == {"Body", "Leg", "Foot", "Head"}


def test_sampling_interpolations():
    times = np.array([0.0, 1.0])
    values = np.array([[0.0], [2.0]])
    at = np.array([-1.0, 0.25, 1.0, 3.0])
    assert sample(times, values, "LINEAR", at, rotation=False)[:, 0].tolist() == [0.0, 0.5, 2.0, 2.0]
    assert sample(times, values, "STEP", at, rotation=False)[:, 0].tolist() == [0.0, 0.0, 2.0, 2.0]
    cubic = np.array([[0.0], [0.0], [4.0], [0.0], [2.0], [0.0]])  # out-tangent 4 at key 0
    # Hermite at s=0.5, dt=1: 0.5*0 + 0.125*4 + 0.5*2 + (-0.125)*0 = 1.5
    assert sample(times, cubic, "CUBICSPLINE", np.array([0.5]), rotation=False)[0, 0] == pytest.approx(1.5)
    q = sample(times, np.array([[0, 0, 0, 1.0], [0, 0, 1.0, 0]]), "LINEAR", np.array([0.5]), rotation=True)
    assert q[0].tolist() == pytest.approx([0, 0, np.sqrt(0.5), np.sqrt(0.5)])


def test_bad_files_give_one_line_errors(tmp_path, synthetic):
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"not a gltf at all")
    with pytest.raises(GltfError, match=r"junk\.glb: not a glTF/GLB file"):
        read_gltf(junk)
    cut = tmp_path / "cut.glb"
    cut.write_bytes(synthetic.read_bytes()[:300])
    with pytest.raises(GltfError, match=r"cut\.glb: GLB header says \d+ bytes but the file has 300"):
        read_gltf(cut)
    with pytest.raises(GltfError, match=r"missing\.glb: no such glTF/GLB file"):
        read_gltf(tmp_path / "missing.glb")


@needs_quaternius
@pytest.mark.parametrize(
    "rel, clip",
    [("animals_pack/Fox.glb", "AnimalArmature|Gallop"), ("dinosaurs_pack/Trex.glb", "Armature|TRex_Attack")],
)
def test_quaternius_positions_match_independent_fk(rel, clip):
    path = QUATERNIUS / rel
    asset = read_gltf(path, animations=[clip])
    assert asset.scale in (100.0, 300.0)
    assert _max_error(path, asset.motions[clip], clip) < 1e-5  # 0.01 mm


@pytest.mark.parametrize("kind", ["datauri", "binfile"])
def test_gltf_json_with_embedded_or_side_car_buffers(synthetic, tmp_path, kind):
    import pygltflib

    g = pygltflib.GLTF2().load(str(synthetic))
    g.convert_buffers(pygltflib.BufferFormat.DATAURI if kind == "datauri" else pygltflib.BufferFormat.BINFILE)
    path = tmp_path / "rig.gltf"
    if kind == "binfile":
        g.buffers[0].uri = "rig.bin"
        (tmp_path / "rig.bin").write_bytes(pygltflib.GLTF2().load(str(synthetic)).binary_blob())
    g.save_json(str(path))
    glb, gltf = read_gltf(synthetic, fps=10), read_gltf(path, fps=10)
    assert (glb.motions["Rig|Move"].positions - gltf.motions["Rig|Move"].positions).abs().max() == 0
    assert gltf.skeleton.mesh.num_vertices == glb.skeleton.mesh.num_vertices


@needs_quaternius
def test_draco_meshes_decode_or_fail_clearly(monkeypatch):
    path = QUATERNIUS / "ultimate_space_pack/Enemy_Small-transformed.glb"
    mesh = read_gltf(path, animations=[]).skeleton.mesh
    assert mesh.num_vertices > 1000 and np.isfinite(mesh.vertices).all()
    monkeypatch.setitem(__import__("sys").modules, "DracoPy", None)  # as if the wheel were missing
    with pytest.raises(GltfError, match=r"Enemy_Small-transformed\.glb: .* is Draco-compressed .* install DracoPy"):
        read_gltf(path)
