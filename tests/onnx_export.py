"""What tests/test_onnx_runtime.py and tests/test_web_runtime.py share, made once per test session: the
shipped model's export (kinema.portable.cache under pytest's base temp folder) and the fp32 pipeline
whose ``generate`` the exported runtimes are compared with."""

from __future__ import annotations

import functools
from pathlib import Path


def export_once(tmp_path_factory) -> Path:
    from kinema.portable.cache import cached_export

    return cached_export("default", tmp_path_factory.getbasetemp() / "onnx-cache")


@functools.cache
def fp32_pipeline():
    import kinema

    return kinema.load_model("default", precision="fp32")
