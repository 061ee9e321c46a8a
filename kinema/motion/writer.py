"""The one slot through which ``Motion.save`` reaches a file writer.

``Motion`` knows no file format and never imports ``kinema.io``: kinema.io fills this slot with its
format registry's writer when it is imported, and ``kinema/__init__`` imports kinema.io (which is
torch-free and cheap), so the slot is filled before any ``Motion`` can exist. This module imports
nothing from kinema, so both sides can import it without a cycle.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

#: ``writer(motion, path, **options) -> Path``, installed by kinema.io
_writer: Callable[..., Path] | None = None


def install_writer(writer: Callable[..., Path]) -> None:
    """Set the function ``Motion.save`` calls (kinema.io does this once, at import)."""
    global _writer
    _writer = writer


def write_motion(motion, path: str | Path, **options) -> Path:
    """Write ``motion`` to ``path`` through the installed writer."""
    if _writer is None:  # only reachable if kinema/__init__ was bypassed
        raise RuntimeError("no motion writer installed: import kinema.io first")
    return _writer(motion, path, **options)
