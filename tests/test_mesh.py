"""`SkinnedMesh` on a `Skeleton`: validation, scaling and pruning carry or drop the skin sensibly."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kinema.errors import KinemaError, SkeletonError
from kinema.mesh import SkinnedMesh, bone_mesh, vertex_normals
from kinema.skeleton import Skeleton


def _mesh(joints: list[int]) -> SkinnedMesh:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    j = np.array([[x, 0, 0, 0] for x in joints], dtype=np.int64)
    w = np.tile(np.array([1, 0, 0, 0], dtype=np.float32), (3, 1))
    return SkinnedMesh(v, None, np.array([[0, 1, 2]]), j, w, np.zeros(1, dtype=np.int64), np.ones((1, 4), np.float32))


def _skeleton(mesh=None) -> Skeleton:
    return Skeleton(["a", "b", "c"], [-1, 0, 1], [[0, 1, 0], [0, 1, 0], [0, 1, 0]], mesh=mesh)


def test_mesh_is_validated_against_the_skeleton():
    with pytest.raises(SkeletonError, match="skinned to joint 5"):
        _skeleton(_mesh([0, 1, 5]))
    with pytest.raises(KinemaError, match="face indices"):
        SkinnedMesh(
            np.zeros((2, 3)),
            None,
            np.array([[0, 1, 2]]),
            np.zeros((2, 4), int),
            np.ones((2, 4)),
            np.zeros(1, int),
            np.ones((1, 4)),
        )


def test_scaled_and_pruned_skeletons_carry_or_drop_the_mesh():
    sk = _skeleton(_mesh([0, 2, 2]))
    big = sk.scaled(2.0)
    assert np.allclose(big.mesh.vertices, 2 * sk.mesh.vertices)
    kept, _ = sk.prune(["b"])  # b carries no weight: the skin stays, c is now joint 1
    assert kept.mesh is not None and kept.mesh.joints[:, 0].tolist() == [0, 1, 1]
    gone, _ = _skeleton(_mesh([0, 1, 1])).prune(["b"])  # b is weighted: its vertices would lose their bone
    assert gone.mesh is None
    assert "mesh" not in sk.to_dict()


def test_bone_mesh_binds_a_box_per_bone_and_leaf():
    sk = _skeleton()
    rest = (torch.tensor([[1.0, 0, 0, 0]] * 3).numpy(), np.array([[0, 1, 0], [0, 2, 0], [0, 3, 0.0]]))
    mesh = bone_mesh(sk, rest)
    assert mesh.num_vertices == 36 * 3 and set(mesh.joints[:, 0].tolist()) == {0, 1, 2}
    assert mesh.vertices[:, 1].min() >= 1 - 1e-6 and mesh.vertices[:, 1].max() <= 3.03 + 1e-6
    n = vertex_normals(mesh.vertices, mesh.faces)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
