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


def bone_mesh(skeleton, rest: tuple[np.ndarray, np.ndarray], *, color=(0.75, 0.75, 0.78, 1.0)) -> SkinnedMesh:
    """A simple generated skin for rigs without one (the BVH human): a tapered box along every bone.

    ``rest`` is (global rotations (J, 4) wxyz, positions (J, 3)) of the rest pose; each box runs from a
    joint's parent to the joint, is as thick as 12 % of its length (0.5-4 cm) and is bound to the parent
    with weight 1, so it turns exactly like the bone; each leaf joint gets a box along its End Site (or a
    3 cm stub), so every joint carries weight. Faces do not share vertices (flat shading).
    """
    _, P = rest
    tris: list[np.ndarray] = []
    owners: list[int] = []
    for j, p in enumerate(skeleton.parents):
        bone = P[j] - P[p] if p >= 0 else None
        if bone is None or np.linalg.norm(bone) < 1e-6:
            continue
        tris.append(_box(P[p], P[j]))
        owners.append(p)
    G = rest[0]
    for j in range(skeleton.num_joints):  # leaves: a box along the End Site, or a 3 cm stub, bound to the leaf
        if skeleton.children[j]:
            continue
        site = np.asarray(skeleton.end_sites.get(j, (0.0, 0.0, 0.0)), dtype=np.float64)
        if np.linalg.norm(site) < 1e-3:
            site = np.array([0.0, 0.03, 0.0])
        w, x, y, z = G[j]
        rot = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        tris.append(_box(P[j], P[j] + rot @ site))
        owners.append(j)
    verts = np.concatenate(tris).reshape(-1, 3)
    faces = np.arange(len(verts)).reshape(-1, 3)
    joints = np.zeros((len(verts), 4), dtype=np.int64)
    joints[:, 0] = np.repeat(owners, 36)
    weights = np.zeros((len(verts), 4), dtype=np.float32)
    weights[:, 0] = 1.0
    return SkinnedMesh(
        verts.astype(np.float32),
        vertex_normals(verts, faces).astype(np.float32),
        faces,
        joints,
        weights,
        np.zeros(len(faces), dtype=np.int64),
        np.asarray([color], dtype=np.float32),
    )


def _box(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(12, 3, 3) triangles of a box from ``a`` to ``b``, wider at ``a``, outward-facing."""
    d = b - a
    length = float(np.linalg.norm(d))
    axis = d / length
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    w = min(max(0.12 * length, 0.005), 0.04)
    square = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    c = [a + w * (x * u + y * v) for x, y in square] + [b + 0.5 * w * (x * u + y * v) for x, y in square]
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return np.array([[c[q[0]], c[q[k]], c[q[k + 1]]] for q in quads for k in (1, 2)])
