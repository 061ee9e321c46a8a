"""Reading and writing motions and rigs: a format registry by filename suffix.

Built-in formats: ``.bvh`` / ``.bvh.gz`` (kinema.io.bvh, kinema.io.bvh_writer), kinema ``.npz``
(kinema.io.npz) and glTF ``.glb`` / ``.gltf`` (kinema.io.gltf reads, kinema.io.gltf_writer writes GLB).
``Motion.save(path)`` and ``kinema.load_motion(path)`` dispatch through this registry;
``Motion`` itself never imports kinema.io (kinema.motion.writer holds the slot this package fills).

Adding a format (e.g. glTF)::

    from kinema.io import register_format
    register_format((".glb", ".gltf"), reader="kinema.io.gltf:read_gltf", writer="kinema.io.gltf:write_gltf")

``reader(path, **options) -> Motion`` and ``writer(motion, path, **options) -> Path`` may be callables
or lazy ``"module:function"`` strings (imported on first use). A suffix already taken is an error unless
``replace=True``. Writers should write atomically (kinema.atomic_files). This package imports no torch.
"""

from __future__ import annotations

from kinema.io.registry import (
    MotionFormat,
    format_for,
    load_motion,
    register_format,
    registered_suffixes,
    save_motion,
)
from kinema.motion.writer import install_writer

__all__ = ["MotionFormat", "format_for", "load_motion", "register_format", "registered_suffixes", "save_motion"]

register_format(
    (".bvh", ".bvh.gz"), name="bvh", reader="kinema.io.bvh:read_bvh", writer="kinema.io.bvh_writer:save_bvh"
)
register_format(".npz", name="npz", reader="kinema.io.npz:load_npz", writer="kinema.io.npz:save_npz")
register_format(
    (".glb", ".gltf"), name="gltf", reader="kinema.io.gltf:load_gltf_motion", writer="kinema.io.gltf_writer:write_glb"
)
install_writer(save_motion)
