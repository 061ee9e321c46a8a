"""Skinned geometry of a glTF document, posed in its rest pose in world space (see kinema.mesh).

Each triangle primitive of a skinned node is bound with its own skin's inverse bind matrices and placed
where the file's default (node) pose puts it, so several skins over the same joints end up as one mesh.
Meshes hanging rigidly under a joint node (props in a hand) are bound to that joint with weight 1.
Joint influences are glTF node indices here; kinema.io.gltf maps them to skeleton joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinema.io.gltf_data import GltfBuffers, GltfError, decode_draco

_TRIANGLES = 4


@dataclass
class RawPart:
    """One primitive: world rest-pose vertices, normals, triangles, node-index influences, colour."""

    vertices: np.ndarray  # (V, 3)
    normals: np.ndarray | None  # (V, 3)
    faces: np.ndarray  # (F, 3)
    nodes: np.ndarray  # (V, 4) glTF node index per influence
    weights: np.ndarray  # (V, 4)
    color: tuple[float, float, float, float]


def _attributes(buffers: GltfBuffers, prim, where: str) -> dict[str, np.ndarray]:
    """Attribute arrays of a primitive (Draco-decoded when compressed) plus ``indices``."""
    ext = prim.extensions or {}
    if "KHR_draco_mesh_compression" in ext:
        return decode_draco(buffers, prim, where)
    out = {}
    for name, index in (prim.attributes or {}).items():
        if index is not None and (name in ("POSITION", "NORMAL") or name[:7] in ("JOINTS_", "WEIGHTS")):
            out[name] = buffers.accessor(index)
    if prim.indices is not None:
        out["indices"] = buffers.accessor(prim.indices).reshape(-1).astype(np.int64)
    return out


def _influences(attrs: dict[str, np.ndarray], skin_joints: list[int], where: str, path, warns: list[str]) -> tuple:
    """(V, 4) indices into the skin's joint list and weights: the 4 largest of all JOINTS_n/WEIGHTS_n sets,
    renormalised. Vertices whose weights are all zero or not finite (some Quaternius files have NaN
    weights) are bound to their first listed joint, with a warning."""
    sets = sorted(k[7:] for k in attrs if k.startswith("JOINTS_"))
    if not sets:
        raise GltfError(f"{path}: {where} is skinned but has no JOINTS_0/WEIGHTS_0 attributes")
    idx = np.concatenate([attrs[f"JOINTS_{s}"].astype(np.int64) for s in sets], axis=1)
    w = np.concatenate([attrs[f"WEIGHTS_{s}"].astype(np.float64) for s in sets], axis=1)
    bad = ~np.isfinite(w).all(axis=1) | (np.nan_to_num(w).clip(min=0).sum(axis=1) <= 0)
    w = np.nan_to_num(w, nan=0.0, posinf=0.0, neginf=0.0).clip(min=0)
    if bad.any():
        w[bad] = 0.0
        w[bad, 0] = 1.0
        warns.append(f"{where}: {int(bad.sum())} vertices have no valid skin weights; bound to their first joint")
    if w.max(initial=0) > 1.5:  # unnormalised integer weights stored as raw bytes
        w = w / w.sum(axis=1, keepdims=True).clip(min=1e-12)
    if idx.max(initial=0) >= len(skin_joints) or idx.min(initial=0) < 0:
        raise GltfError(f"{path}: {where} refers to joint {idx.max()} but its skin has {len(skin_joints)} joints")
    order = np.argsort(-w, axis=1)[:, :4]
    idx, w = np.take_along_axis(idx, order, 1), np.take_along_axis(w, order, 1)
    w = w / w.sum(axis=1, keepdims=True).clip(min=1e-12)
    return idx, w


def _color(gltf, prim) -> tuple[float, float, float, float]:
    if prim.material is None or prim.material >= len(gltf.materials):
        return (0.8, 0.8, 0.8, 1.0)
    pbr = gltf.materials[prim.material].pbrMetallicRoughness
    factor = pbr.baseColorFactor if pbr is not None and pbr.baseColorFactor else [1.0, 1.0, 1.0, 1.0]
    return tuple(float(x) for x in factor)


def _inverse_binds(buffers: GltfBuffers, skin, path) -> np.ndarray:
    n = len(skin.joints)
    if skin.inverseBindMatrices is None:
        return np.repeat(np.eye(4)[None], n, axis=0)
    ibm = buffers.accessor(skin.inverseBindMatrices).astype(np.float64)
    if ibm.shape != (n, 16):
        raise GltfError(f"{path}: skin {skin.name!r} has {len(ibm)} inverse bind matrices for {n} joints")
    return ibm.reshape(n, 4, 4).transpose(0, 2, 1)  # column-major storage


def read_parts(
    buffers: GltfBuffers, world: np.ndarray, parent: dict[int, int], joints: set[int], warns: list[str]
) -> list[RawPart]:
    """Every triangle primitive of skinned nodes, and of mesh nodes under a joint, in world rest pose."""
    gltf, path = buffers.gltf, buffers.path
    parts = []
    for n, node in enumerate(gltf.nodes):
        if node.mesh is None:
            continue
        anchor = parent.get(n)
        while anchor is not None and anchor not in joints:
            anchor = parent.get(anchor)
        if node.skin is None and anchor is None:
            continue  # scenery outside the armature
        skin = gltf.skins[node.skin] if node.skin is not None else None
        binds = None
        if skin is not None:
            binds = world[np.asarray(skin.joints)] @ _inverse_binds(buffers, skin, path)
        for k, prim in enumerate(gltf.meshes[node.mesh].primitives):
            where = f"mesh {gltf.meshes[node.mesh].name or node.mesh} primitive {k}"
            if (prim.mode if prim.mode is not None else _TRIANGLES) != _TRIANGLES:
                continue
            attrs = _attributes(buffers, prim, where)
            if "POSITION" not in attrs:
                raise GltfError(f"{path}: {where} has no POSITION attribute")
            v = attrs["POSITION"].astype(np.float64)
            faces = attrs.get("indices", np.arange(len(v), dtype=np.int64)).reshape(-1, 3)
            if len(faces) and (faces.max() >= len(v) or faces.min() < 0):
                raise GltfError(f"{path}: {where} has triangle indices outside its {len(v)} vertices")
            if skin is not None:
                local, w = _influences(attrs, list(skin.joints), where, path, warns)
                nodes = np.asarray(skin.joints, dtype=np.int64)[local]
                m = np.einsum("vk,vkab->vab", w, binds[local])
            else:
                nodes = np.full((len(v), 4), anchor, dtype=np.int64)
                w = np.tile([1.0, 0.0, 0.0, 0.0], (len(v), 1))
                m = np.repeat(world[n][None], len(v), axis=0)
            verts = np.einsum("vab,vb->va", m[:, :3, :3], v) + m[:, :3, 3]
            normals = None
            if "NORMAL" in attrs:
                nr = np.einsum("vab,vb->va", m[:, :3, :3], attrs["NORMAL"].astype(np.float64))
                normals = nr / np.linalg.norm(nr, axis=1, keepdims=True).clip(min=1e-12)
            # keep only the vertices this primitive's triangles use (primitives may share one vertex array)
            used, faces = np.unique(faces, return_inverse=True)
            normals = None if normals is None else normals[used]
            part = RawPart(verts[used], normals, faces.reshape(-1, 3), nodes[used], w[used], _color(gltf, prim))
            parts.append(part)
    return parts
