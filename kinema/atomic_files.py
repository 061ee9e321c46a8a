"""Atomic file writes: a temp file in the target folder, flushed, then renamed over the target.

A crash or error leaves either the old file or the new one, never a half-written file, and no temp file.
:func:`atomic_folder` does the same for a folder of files (checkpoints, exported models).
Files get ordinary permissions (``0666 & ~umask``; ``mkstemp`` alone would make them 0600).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from kinema.errors import KinemaError


def check_output_path(path: str | Path) -> Path:
    """Check, before any long work, that a file can be written at ``path``; returns it as a Path.

    Missing parent folders are fine (the writers create them). A ``path`` that is a folder, a parent
    that is a file, or a folder that cannot be written to (tried with a temporary file, so it also
    holds for root on a read-only file system) raise a one-line `KinemaError`; nothing is left behind.
    """
    path = Path(path)
    if path.is_dir():
        raise KinemaError(f"{path}: is a folder; give a file name to write")
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise KinemaError(f"{path}: cannot write there, {folder} is a file, not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".kinema-write-test.", dir=folder)
    except OSError as err:
        raise KinemaError(f"{path}: cannot write to the folder {folder} ({err.strerror or err})") from None
    os.close(fd)
    os.unlink(probe)
    return path


def make_output_folder(path: str | Path) -> Path:
    """Create the output folder ``path`` (and its parents) if needed; a one-line `KinemaError` when it
    is a file, a parent is a file, or it cannot be created."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise KinemaError(f"{path}: is a file; give a folder for the outputs")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise KinemaError(f"{path}: cannot create the output folder ({err.strerror or err})") from None
    return path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (creating the parent folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """UTF-8 text version of :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"))


@contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """Build a folder under a temporary name next to ``path``; on success it replaces ``path``.

    ``with atomic_folder(out) as tmp: write files into tmp``. Files and the folder get ordinary
    permissions; on any error the temporary folder is removed and an existing ``path`` is untouched.
    (Between removing an old ``path`` and the rename there is a short window without it.)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes 0700; the result is an ordinary folder
        for f in tmp.rglob("*"):
            if f.is_file():
                os.chmod(f, 0o666 & ~umask)
        if path.exists():
            shutil.rmtree(path)
        os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
