"""Error types raised for bad user input; the CLI prints them as one line and exits non-zero."""

from __future__ import annotations


class KinemaError(Exception):
    """Base class for errors caused by user input (files, arguments, configs)."""


class BVHError(KinemaError):
    """A BVH file could not be read: the message names the file and, when known, the line."""

    def __init__(self, message: str, path: str | None = None, line: int | None = None):
        self.path = path
        self.line = line
        where = ""
        if path is not None:
            where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(f"{where}{message}")


class SkeletonError(KinemaError):
    """A skeleton is inconsistent (bad parents, unknown joint or role, ...)."""


class DataError(KinemaError):
    """A dataset or cache on disk is missing or malformed."""
