"""`SkinnedMesh`: a rig's skin, format-neutral, so that a motion can be written back with its mesh.

Vertices are stored in the skeleton's rest pose in world space (metres, Y up), which makes the mesh
independent of the file it came from: the inverse bind matrices of any writer are simply the inverses
of the rest pose's joint transforms. Each vertex has up to 4 joint influences (indices into the
skeleton's joints, weights summing to 1). Faces are grouped into parts, one flat material colour each.

Shapes: vertices/normals ``(V, 3)`` float32, faces ``(F, 3)`` int64, joints ``(V, 4)`` int64,
weights ``(V, 4)`` float32, face_parts ``(F,)`` int64 index into colors ``(P, 4)`` RGBA in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinema.errors import KinemaError


@dataclass(frozen=True, eq=False)
class SkinnedMesh:
    """Triangles skinned to a skeleton's joints (see the module docstring for shapes and units)."""

    vertices: np.ndarray
    normals: np.ndarray | None
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    face_parts: np.ndarray
    colors: np.ndarray

    def __post_init__(self) -> None:
        V = len(self.vertices)
        checks = [
            (self.vertices.shape == (V, 3), "vertices must be (V, 3)"),
            (self.normals is None or self.normals.shape == (V, 3), "normals must be (V, 3)"),
            (self.faces.ndim == 2 and self.faces.shape[1] == 3, "faces must be (F, 3)"),
            (self.joints.shape == (V, 4) and self.weights.shape == (V, 4), "joints and weights must be (V, 4)"),
            (self.face_parts.shape == (len(self.faces),), "face_parts must be (F,)"),
            (self.colors.ndim == 2 and self.colors.shape[1] == 4, "colors must be (P, 4)"),
        ]
        for ok, msg in checks:
            if not ok:
                raise KinemaError(f"bad SkinnedMesh: {msg}")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= V):
            raise KinemaError(f"bad SkinnedMesh: face indices outside [0, {V})")
        if len(self.face_parts) and (self.face_parts.min() < 0 or self.face_parts.max() >= len(self.colors)):
            raise KinemaError("bad SkinnedMesh: face_parts index past the colours")

    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    def max_joint(self) -> int:
        """Largest joint index that carries weight (-1 for an empty mesh)."""
        used = self.joints[self.weights > 0]
        return int(used.max()) if used.size else -1

    def remap_joints(self, keep: list[int]) -> SkinnedMesh | None:
        """The mesh after a skeleton edit that keeps joints ``keep`` (old indices, in new order).

        A removed joint that carries weight would leave vertices without a bone, so then ``None`` is
        returned (callers drop the mesh); weightless influences on removed joints are cleared.
        """
        old_to_new = np.full(max(max(keep, default=0), int(self.joints.max(initial=0))) + 1, -1)
        old_to_new[np.asarray(keep, dtype=np.int64)] = np.arange(len(keep))
        mapped = old_to_new[self.joints]
        if ((mapped < 0) & (self.weights > 0)).any():
            return None
        return SkinnedMesh(
            self.vertices,
            self.normals,
            self.faces,
            np.where(mapped < 0, 0, mapped),
            self.weights,
            self.face_parts,
            self.colors,
        )

    def scaled(self, factor: float) -> SkinnedMesh:
        """The same mesh with every length multiplied by ``factor``."""
        return SkinnedMesh(
            self.vertices * np.float32(factor),
            self.normals,
            self.faces,
            self.joints,
            self.weights,
            self.face_parts,
            self.colors,
        )


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit normals: the area-weighted mean of the adjacent faces' normals (+Y where none)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    face_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    out = np.zeros_like(v)
    for k in range(3):
        np.add.at(out, f[:, k], face_n)
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.where(length > 1e-12, out / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
