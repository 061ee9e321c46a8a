"""`model_sha256`: a checkpoint folder's fingerprint, so a batch manifest and ``GET /v1/models`` say exactly
which weights made a motion."""

from __future__ import annotations

import hashlib
from pathlib import Path

from kinema.errors import KinemaError


def model_sha256(folder: str | Path) -> str:
    """SHA-256 over a checkpoint folder's ``*.json`` and ``*.safetensors`` files (names and bytes, sorted)."""
    h = hashlib.sha256()
    files = sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix in (".json", ".safetensors"))
    if not files:
        raise KinemaError(f"{folder}: no checkpoint files to fingerprint")
    for p in files:
        h.update(p.name.encode() + b"\0")
        with p.open("rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()
