"""A skinned-mesh view (viser ``scene.add_mesh_skinned``): the rig's skin posed by a motion, one scene
node per material colour (viser's skinned mesh has one colour), each moved by only the joints that
weigh on it. Vertices are the mesh's rest pose in world metres (kinema.mesh), so the bones start at
the rest pose's global transforms (kinema.io.gltf_writer.rest_world) and are then set to each frame's
global rotations (wxyz) and positions. Same three methods as SkeletonView (kinema.app.views).

viser 1.1.1's browser client crashes (a blank page, "Cannot read properties of null (reading 'remove')")
when a skinned mesh node is removed or replaced, so a view never removes one: ``remove()`` hides its
meshes and they wait in the tab's `SkinPool` for the next view of the same mesh in the same slot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinema.app.views import SELECTED_COLOR
from kinema.io.gltf_writer import rest_world
from kinema.mesh import SkinnedMesh
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton


@dataclass(frozen=True)
class SkinPart:
    """Faces of one colour: its own vertices ``(v, 3)``, faces ``(f, 3)``, the joints ``(b,)`` that move
    it and their dense weights ``(v, b)``; ``rgb`` 0-255."""

    vertices: np.ndarray
    faces: np.ndarray
    bones: np.ndarray
    weights: np.ndarray
    rgb: tuple[int, int, int]


def skin_parts(mesh: SkinnedMesh) -> list[SkinPart]:
    """The mesh split by material colour, each part with only its vertices and joints."""
    parts = []
    for p in np.unique(mesh.face_parts):
        faces = mesh.faces[mesh.face_parts == p]
        used, local = np.unique(faces, return_inverse=True)
        joints, weights = mesh.joints[used], mesh.weights[used]
        bones = np.unique(joints[weights > 0])
        if len(bones) == 0:
            continue
        dense = np.zeros((len(used), len(bones)), dtype=np.float32)
        rows = np.repeat(np.arange(len(used)), joints.shape[1])
        np.add.at(dense, (rows, np.searchsorted(bones, joints.ravel()).clip(0, len(bones) - 1)), weights.ravel())
        rgb = tuple(int(round(255 * c)) for c in mesh.colors[p, :3])
        parts.append(SkinPart(mesh.vertices[used], local.reshape(-1, 3), bones, dense, rgb))
    return parts


class SkinPool:
    """A tab's skinned-mesh nodes, kept for reuse (hidden when unused; see the module docstring):
    one per (slot, mesh, part)."""

    def __init__(self, scene):
        self.scene, self.handles = scene, {}

    def get(self, key: tuple, make):
        """The node for ``key``, made by ``make(name)`` the first time (under /skins)."""
        if key not in self.handles:
            self.handles[key] = make(f"/skins/skin{len(self.handles)}")
        return self.handles[key]


class MeshView:
    """The skin of ``skeleton`` posed frame by frame; ``own_colors`` keeps the file's colours while
    ``color`` is the selected colour (other samples are drawn in ``color``). ``slot`` (a sample's
    number) picks the pooled nodes, so that samples shown side by side have their own."""

    def __init__(
        self,
        pool: SkinPool,
        slot: int,
        skeleton: Skeleton,
        mesh: SkinnedMesh,
        *,
        color=SELECTED_COLOR,
        own_colors=False,
    ):
        self.pool, self.slot, self.mesh, self.color, self.own_colors = pool, slot, mesh, color, own_colors
        self.parts = skin_parts(mesh)
        self.rest = tuple(a.astype(np.float32) for a in rest_world(skeleton))
        self.rotations: np.ndarray | None = None  # (T, J, 4) wxyz
        self.positions: np.ndarray | None = None  # (T, J, 3)
        self.handles: list = []

    def set_motion(self, motion: Motion, offset=(0.0, 0.0, 0.0)) -> None:
        self.rotations = motion.global_rotations.detach().float().numpy()
        self.positions = motion.positions.detach().float().numpy() + np.asarray(offset, dtype=np.float32)

    def _add(self) -> None:
        G, P = self.rest
        for i, part in enumerate(self.parts):
            rgb = part.rgb if self.own_colors and self.color == SELECTED_COLOR else self.color

            def make(name, part=part, rgb=rgb):
                return self.pool.scene.add_mesh_skinned(
                    name,
                    part.vertices,
                    part.faces,
                    bone_wxyzs=G[part.bones],
                    bone_positions=P[part.bones],
                    skin_weights=part.weights,
                    color=rgb,
                    flat_shading=True,
                    side="double",
                )

            handle = self.pool.get((self.slot, self.mesh, i), make)
            handle.color, handle.visible = rgb, True
            self.handles.append(handle)

    def show(self, frame: int) -> None:
        if self.positions is None or self.rotations is None:
            return
        if not self.handles:
            self._add()
        f = int(np.clip(frame, 0, len(self.positions) - 1))
        R, P = self.rotations[f], self.positions[f]
        for part, handle in zip(self.parts, self.handles, strict=True):
            for bone, j in zip(handle.bones, part.bones, strict=True):
                bone.wxyz = R[j]
                bone.position = P[j]

    def remove(self) -> None:
        """Hide the meshes (never removed: see the module docstring)."""
        for h in self.handles:
            h.visible = False
        self.handles = []
