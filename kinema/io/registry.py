"""Motion file formats by filename suffix: ``register_format``, ``load_motion``, ``save_motion``.

A format is a set of suffixes (``".bvh"``, ``".bvh.gz"``; matched case-insensitively, longest first)
with an optional reader ``reader(path, **options) -> Motion`` and writer
``writer(motion, path, **options) -> Path``. Either may be given as a callable or as a
``"package.module:function"`` string, imported on first use, so that registering the built-in formats
costs no import of torch (``import kinema`` stays fast). This module imports nothing heavy.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import NamedTuple

from kinema.errors import KinemaError

Handler = Callable | str


class MotionFormat(NamedTuple):
    """One registered format: its name, suffixes (lower case, with the dot) and handlers (a named tuple,
    not a dataclass: ``import kinema`` stays free of the dataclasses module)."""

    name: str
    suffixes: tuple[str, ...]
    reader: Handler | None = None
    writer: Handler | None = None


_FORMATS: dict[str, MotionFormat] = {}  # suffix -> format


def _check_suffix(suffix: str) -> str:
    if not isinstance(suffix, str) or not suffix.startswith(".") or len(suffix) < 2:
        raise ValueError(f"a format suffix starts with a dot, e.g. '.bvh', got {suffix!r}")
    return suffix.lower()


def register_format(
    suffixes: str | Iterable[str],
    *,
    reader: Handler | None = None,
    writer: Handler | None = None,
    name: str | None = None,
    replace: bool = False,
) -> MotionFormat:
    """Register a reader and/or writer for filenames ending in ``suffixes``.

    A suffix that is already registered is an error unless ``replace`` is true (so two plug-ins
    cannot silently fight over ``.glb``). Returns the registered format."""
    sufs = (suffixes,) if isinstance(suffixes, str) else tuple(suffixes)
    sufs = tuple(_check_suffix(s) for s in sufs)
    if not sufs or (reader is None and writer is None):
        raise ValueError("register_format needs at least one suffix and a reader or a writer")
    taken = [s for s in sufs if s in _FORMATS]
    if taken and not replace:
        raise ValueError(
            f"suffixes {taken} are already registered (format {_FORMATS[taken[0]].name!r}); "
            "pass replace=True to override"
        )
    fmt = MotionFormat(name or sufs[0].lstrip("."), sufs, reader, writer)
    for s in sufs:
        _FORMATS[s] = fmt
    return fmt


def registered_suffixes(*, readable: bool = False, writable: bool = False) -> list[str]:
    """Suffixes known to the registry (only readable / writable ones when asked), sorted."""
    return sorted(
        s
        for s, f in _FORMATS.items()
        if (not readable or f.reader is not None) and (not writable or f.writer is not None)
    )


def format_for(path: str | Path) -> MotionFormat | None:
    """The format whose longest suffix ends ``path``'s name (case-insensitive), or None."""
    name = Path(path).name.lower()
    for suffix in sorted(_FORMATS, key=len, reverse=True):
        if name.endswith(suffix):
            return _FORMATS[suffix]
    return None


def _resolve(handler: Handler) -> Callable:
    if callable(handler):
        return handler
    module, _, attr = handler.partition(":")
    return getattr(importlib.import_module(module), attr)


def _handler(path: Path, kind: str) -> Callable:
    fmt = format_for(path)
    handler = None if fmt is None else getattr(fmt, kind)
    if handler is None:
        known = ", ".join(registered_suffixes(readable=kind == "reader", writable=kind == "writer"))
        verb = "read" if kind == "reader" else "write"
        raise KinemaError(f"{path}: unknown motion format; kinema can {verb} {known}")
    return _resolve(handler)


def load_motion(path: str | Path, **options):
    """Read a motion file with the reader registered for its suffix (e.g. ``scale=0.01`` for a
    centimetre BVH)."""
    path = Path(path)
    return _handler(path, "reader")(path, **options)


def save_motion(motion, path: str | Path, **options) -> Path:
    """Write ``motion`` with the writer registered for ``path``'s suffix; returns the path."""
    path = Path(path)
    out = _handler(path, "writer")(motion, path, **options)
    return Path(out) if out is not None else path
