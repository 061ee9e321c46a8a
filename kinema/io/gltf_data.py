"""Low-level glTF 2.0 reading: the GLB/JSON container, buffers, accessors (strided, normalised, sparse),
Draco primitives, node matrices and keyframe sampling (LINEAR, STEP, CUBICSPLINE). Used by kinema.io.gltf.

Conventions: glTF quaternions are ``(x, y, z, w)``; everything returned here keeps glTF's layout and
units (the caller converts to kinema's ``(w, x, y, z)`` and metres). Matrices are ``(4, 4)`` float64,
column vectors (``world = parent @ local``).
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from kinema.errors import KinemaError
from kinema.input_files import read_bytes_bounded
from kinema.limits import MAX_ASSET_BYTES

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


class GltfError(KinemaError):
    """A glTF/GLB file kinema cannot read; the message names the file and what is wrong."""


_RAW_KEYS = {"extensions", "extras", "attributes"}  # kept as plain dicts


class GltfObject:
    """A glTF JSON object with attribute access; absent properties read as ``None``."""

    def __init__(self, d: dict):
        for k, v in d.items():
            setattr(self, k, v if k in _RAW_KEYS else _wrap(v))

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        return None


def _wrap(v):
    if isinstance(v, dict):
        return GltfObject(v)
    if isinstance(v, list) and v and isinstance(v[0], dict):
        return [_wrap(x) for x in v]
    return v


class GltfDocument:
    """A parsed glTF: top-level arrays as attributes (``nodes``, ``skins``, ...) and the GLB binary chunk."""

    ARRAYS = ("nodes", "skins", "meshes", "accessors", "bufferViews", "buffers", "animations", "materials", "scenes")

    def __init__(self, data: dict, blob: bytes | None):
        self.json, self.blob = data, blob
        for key in self.ARRAYS:
            setattr(self, key, [GltfObject(x) if isinstance(x, dict) else GltfObject({}) for x in data.get(key, [])])
        self.extensionsUsed = list(data.get("extensionsUsed", []))


def parse_document(raw: bytes, path: Path) -> GltfDocument:
    """Parse GLB bytes (magic ``glTF``) or glTF JSON text; a bad container raises a one-line `GltfError`."""
    blob = None
    if raw[:4] == b"glTF":
        if len(raw) < 20:
            raise GltfError(f"{path}: GLB file is truncated ({len(raw)} bytes)")
        _, version, length = struct.unpack_from("<4sII", raw)
        if version != 2:
            raise GltfError(f"{path}: GLB version {version}; kinema reads glTF 2.0")
        if length > len(raw):
            raise GltfError(f"{path}: GLB header says {length} bytes but the file has {len(raw)} (truncated?)")
        pos, text = 12, None
        while pos + 8 <= length:
            size, kind = struct.unpack_from("<II", raw, pos)
            chunk = raw[pos + 8 : pos + 8 + size]
            if len(chunk) != size:
                raise GltfError(f"{path}: GLB chunk at byte {pos} runs past the end of the file")
            if kind == 0x4E4F534A and text is None:
                text = chunk
            elif kind == 0x004E4942 and blob is None:
                blob = chunk
            pos += 8 + size
        if text is None:
            raise GltfError(f"{path}: GLB file has no JSON chunk")
    else:
        text = raw
    try:
        data = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as err:
        raise GltfError(f"{path}: not a glTF/GLB file (JSON: {err})") from None
    if not isinstance(data, dict) or not str(data.get("asset", {}).get("version", "")).startswith("2"):
        raise GltfError(f"{path}: not a glTF 2.0 file (asset.version must be 2.x)")
    return GltfDocument(data, blob)


class GltfBuffers:
    """Decoded buffers of one glTF document (GLB binary chunk, data URIs or files next to it)."""

    def __init__(self, gltf, path: Path):
        self.gltf, self.path = gltf, path
        self._cache: dict[int, bytes] = {}

    def buffer(self, index: int) -> bytes:
        if index not in self._cache:
            self._cache[index] = self._load(index)
        return self._cache[index]

    def _load(self, index: int) -> bytes:
        try:
            uri = self.gltf.buffers[index].uri
        except IndexError:
            raise GltfError(f"{self.path}: buffer {index} does not exist") from None
        if not uri:
            blob = self.gltf.blob
            if blob is None:
                raise GltfError(f"{self.path}: buffer {index} has no uri and the file has no binary chunk")
            return bytes(blob)
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1])
            except (IndexError, ValueError) as err:
                raise GltfError(f"{self.path}: buffer {index} has a bad data URI ({err})") from None
        try:
            return read_bytes_bounded(self.path.parent / uri, f"buffer {index} of {self.path}", MAX_ASSET_BYTES,
                                      error=GltfError)
        except GltfError as err:
            raise GltfError(f"{self.path}: buffer {index} file {uri}: {err}") from None

    def view(self, index: int) -> tuple[bytes, int, int, int | None]:
        """(buffer bytes, start, length, byte stride) of a bufferView."""
        try:
            bv = self.gltf.bufferViews[index]
        except (IndexError, TypeError):
            raise GltfError(f"{self.path}: bufferView {index} does not exist") from None
        data = self.buffer(bv.buffer)
        start = bv.byteOffset or 0
        if start + bv.byteLength > len(data):
            raise GltfError(f"{self.path}: bufferView {index} runs past the end of buffer {bv.buffer}")
        return data, start, bv.byteLength, bv.byteStride

    def accessor(self, index: int) -> np.ndarray:
        """Accessor ``index`` as a (count, width) array; normalised integers become floats in [0, 1]/[-1, 1]."""
        try:
            acc = self.gltf.accessors[index]
        except (IndexError, TypeError):
            raise GltfError(f"{self.path}: accessor {index} does not exist") from None
        dtype, width = _COMPONENTS.get(acc.componentType), _WIDTH.get(acc.type)
        if dtype is None or width is None:
            raise GltfError(f"{self.path}: accessor {index} has componentType {acc.componentType} / type {acc.type}")
        out = np.zeros((acc.count, width), dtype=dtype)
        if acc.bufferView is not None:
            out = self._dense(index, acc, dtype, width)
        if acc.sparse is not None:
            out = out.copy()
            sp = acc.sparse
            idx_dtype = _COMPONENTS[sp.indices.componentType]
            idx = self._raw(sp.indices.bufferView, sp.indices.byteOffset or 0, idx_dtype, sp.count, 1)[:, 0]
            out[idx.astype(np.int64)] = self._raw(
                sp.values.bufferView, sp.values.byteOffset or 0, dtype, sp.count, width
            )
        if acc.normalized and np.issubdtype(dtype, np.integer):
            return np.maximum(out.astype(np.float64) / np.iinfo(dtype).max, -1.0)
        return out

    def _raw(self, view: int, offset: int, dtype, count: int, width: int, stride: int | None = None) -> np.ndarray:
        data, start, length, view_stride = self.view(view)
        item = np.dtype(dtype).itemsize * width
        stride = stride or view_stride or item
        if count and offset + stride * (count - 1) + item > length:
            raise GltfError(f"{self.path}: accessor data runs past the end of bufferView {view}")
        rows = np.frombuffer(
            data, dtype=np.uint8, count=stride * (count - 1) + item if count else 0, offset=start + offset
        )
        if stride == item:
            return rows.view(dtype).reshape(count, width).copy()
        table = np.lib.stride_tricks.as_strided(rows, shape=(count, item), strides=(stride, 1))
        return np.ascontiguousarray(table).view(dtype).reshape(count, width)

    def _dense(self, index: int, acc, dtype, width: int) -> np.ndarray:
        try:
            return self._raw(acc.bufferView, acc.byteOffset or 0, dtype, acc.count, width)
        except GltfError as err:
            raise GltfError(f"{err} (accessor {index})") from None


def decode_draco(buffers: GltfBuffers, primitive, where: str) -> dict[str, np.ndarray]:
    """Attributes (name -> (N, C) array) and ``"indices"`` of a KHR_draco_mesh_compression primitive."""
    ext = primitive.extensions["KHR_draco_mesh_compression"]
    try:
        import DracoPy  # optional at import time so that a missing wheel is a clear error, not a crash
    except ImportError:
        raise GltfError(
            f"{buffers.path}: {where} is Draco-compressed (KHR_draco_mesh_compression); install DracoPy to read it"
        ) from None
    data, start, length, _ = buffers.view(ext["bufferView"])
    try:
        mesh = DracoPy.decode(data[start : start + length])
    except Exception as err:  # DracoPy raises its own failure types
        raise GltfError(f"{buffers.path}: {where}: Draco data cannot be decoded ({err})") from None
    out = {"indices": np.asarray(mesh.faces, dtype=np.int64).reshape(-1)}
    for name, uid in ext.get("attributes", {}).items():
        attr = mesh.get_attribute_by_unique_id(uid)
        if attr is None:
            raise GltfError(f"{buffers.path}: {where}: Draco attribute {name} (id {uid}) is missing")
        values = np.asarray(attr["data"])
        out[name] = values.reshape(len(values), -1)
    return out


def node_matrix(node) -> np.ndarray:
    """Local (4, 4) matrix of a node: its ``matrix`` or ``T @ R @ S``."""
    if node.matrix is not None and len(node.matrix) == 16:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T  # glTF stores column-major
    return trs_matrix(node.translation, node.rotation, node.scale)


def quat_xyzw_to_matrix(q) -> np.ndarray:
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def trs_matrix(t, r, s) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_xyzw_to_matrix(r if r is not None else (0, 0, 0, 1)) * np.asarray(
        s if s is not None else (1, 1, 1), dtype=np.float64
    )
    m[:3, 3] = t if t is not None else (0, 0, 0)
    return m


def matrix_to_quat_xyzw(m: np.ndarray) -> np.ndarray:
    """Rotation (x, y, z, w) of a 3x3 rotation matrix (Shepperd's method; w >= 0)."""
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
        q[i], q[j], q[k] = 0.25 * s, (m[j, i] + m[i, j]) / s, (m[k, i] + m[i, k]) / s
    q = np.asarray(q)
    return q * (1 if q[3] >= 0 else -1) / np.linalg.norm(q)


def decompose(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(translation, rotation xyzw, scale per axis) of an affine matrix without shear."""
    scale = np.linalg.norm(m[:3, :3], axis=0)
    if np.linalg.det(m[:3, :3]) < 0:
        scale[0] = -scale[0]
    return m[:3, 3].copy(), matrix_to_quat_xyzw(m[:3, :3] / scale), scale


def _slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    small = theta < 1e-6
    sin = np.where(small, 1.0, np.sin(theta))
    a = np.where(small, 1 - u, np.sin((1 - u) * theta) / sin)
    b = np.where(small, u, np.sin(u * theta) / sin)
    out = a * q0 + b * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def sample(times: np.ndarray, values: np.ndarray, interpolation: str, at: np.ndarray, *, rotation: bool) -> np.ndarray:
    """Values of a sampler at times ``at`` (clamped to its key range): (len(at), C) float64.

    ``values`` has one row per key, or three (in-tangent, value, out-tangent) for CUBICSPLINE.
    Rotations (xyzw) are slerped (LINEAR) or normalised (CUBICSPLINE), as the glTF spec asks.
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    values = np.asarray(values, dtype=np.float64)
    n = len(times)
    cubic = interpolation == "CUBICSPLINE"
    tangents = values.reshape(n, 3, -1) if cubic else None
    keys = tangents[:, 1] if cubic else values
    if n == 1:
        out = np.repeat(keys[:1], len(at), axis=0)
        return out / np.linalg.norm(out, axis=-1, keepdims=True) if rotation else out
    i = np.clip(np.searchsorted(times, at, side="right") - 1, 0, n - 2)
    dt = times[i + 1] - times[i]
    u = np.clip((at - times[i]) / np.where(dt > 0, dt, 1.0), 0.0, 1.0)[:, None]
    if interpolation == "STEP":
        return keys[np.where(u[:, 0] >= 1.0, i + 1, i)]
    if cubic:
        u2, u3, d = u * u, u * u * u, dt[:, None]
        out = (
            (2 * u3 - 3 * u2 + 1) * keys[i]
            + d * (u3 - 2 * u2 + u) * tangents[i, 2]
            + (-2 * u3 + 3 * u2) * keys[i + 1]
            + d * (u3 - u2) * tangents[i + 1, 0]
        )
        return out / np.linalg.norm(out, axis=-1, keepdims=True) if rotation else out
    if rotation:
        return _slerp(keys[i], keys[i + 1], u)
    return keys[i] * (1 - u) + keys[i + 1] * u
