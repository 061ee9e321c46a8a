"""kinema.io's format registry: Motion.save / load_motion dispatch, plug-in formats, clear errors."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import torch

import kinema
from kinema.errors import KinemaError
from kinema.io import format_for, load_motion, register_format, registered_suffixes, registry
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

KINEMA = Path(kinema.__file__).parent


def _motion() -> Motion:
    skel = Skeleton(["a", "b"], [-1, 0], torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 0.5]]))
    rots = torch.zeros(3, 2, 4)
    rots[..., 0] = 1
    return Motion(skel, 20, torch.zeros(3, 3), rots, torch.ones(3, 6))


@pytest.fixture
def clean_registry(monkeypatch):
    monkeypatch.setattr(registry, "_FORMATS", dict(registry._FORMATS))


def test_builtin_formats_round_trip(tmp_path) -> None:
    assert {".bvh", ".bvh.gz", ".npz"} <= set(registered_suffixes(readable=True, writable=True))
    m = _motion()
    for name in ("m.npz", "m.BVH", "m.bvh.gz"):
        back = load_motion(m.save(tmp_path / name))
        assert torch.allclose(back.positions.float(), m.positions.float(), atol=1e-5), name
    assert load_motion(tmp_path / "m.npz").foot_contacts.shape == (3, 6)  # any number of contact channels
    assert kinema.load_motion is load_motion


def test_plugin_format_and_errors(tmp_path, clean_registry) -> None:
    written = []
    register_format((".fake", ".fake.gz"), writer=lambda motion, path, **kw: written.append((path, kw)) or path)
    assert format_for("x.FAKE.gz").name == "fake"
    _motion().save(tmp_path / "a.fake.gz", level=3)
    assert written == [(tmp_path / "a.fake.gz", {"level": 3})]
    with pytest.raises(KinemaError, match=r"a\.fake: unknown motion format; kinema can read .*\.npz"):
        load_motion(tmp_path / "a.fake")
    with pytest.raises(KinemaError, match="unknown motion format; kinema can write"):
        _motion().save(tmp_path / "a.xyz")
    with pytest.raises(ValueError, match="already registered"):
        register_format(".npz", reader=lambda p: None)
    with pytest.raises(ValueError, match="starts with a dot"):
        register_format("glb", reader=lambda p: None)
    register_format(".npz", reader="kinema.io.npz:load_npz", replace=True)  # lazy "module:function"
    assert format_for("x.npz").writer is None


def test_npz_reader_scales_lengths(tmp_path) -> None:
    m = _motion()
    back = load_motion(m.save(tmp_path / "m.npz"), scale=0.5)
    assert torch.allclose(back.positions, 0.5 * m.positions.float(), atol=1e-6)
    with pytest.raises(KinemaError, match="scale must be a positive number"):
        load_motion(tmp_path / "m.npz", scale=0)


def _imports(path: Path) -> set[str]:
    mods = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            mods.add(node.module)
        elif isinstance(node, ast.Import):
            mods.update(a.name for a in node.names)
    return mods


def test_motion_knows_no_file_format() -> None:
    """The motion layer never imports kinema.io (at module level or inside functions)."""
    for path in sorted((KINEMA / "motion").glob("*.py")):
        bad = sorted(m for m in _imports(path) if m == "kinema.io" or m.startswith("kinema.io."))
        assert not bad, f"{path.name} imports {bad}"
