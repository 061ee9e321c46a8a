"""The shipped model exported once per test session (kinema.portable.cache under pytest's base temp folder),
shared by tests/test_onnx_runtime.py and tests/test_web_runtime.py."""

from __future__ import annotations

from pathlib import Path


def export_once(tmp_path_factory) -> Path:
    from kinema.portable.cache import cached_export

    return cached_export("default", tmp_path_factory.getbasetemp() / "onnx-cache")
