"""The manifest of a batch (``OUT/manifest.jsonl``) and the other crash-safety pieces of an output folder.

Why JSONL appended with fsync: each finished job adds one line after its files were written atomically,
so after a crash or Ctrl-C the manifest lists exactly the jobs whose files are complete (at worst a job
whose files were written but not yet recorded, which a resumed batch simply redoes, rewriting the same
files atomically). A torn last line (killed mid-write) is cut off before appending; leftover temporary
files of interrupted writes are removed; a lock file keeps two batches out of one folder.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from kinema.errors import KinemaError

MANIFEST = "manifest.jsonl"
LOCK = ".kinema-batch.lock"
#: Temporary files of kinema.atomic_files writes of batch outputs (".NAME.XXXXXXXX.tmp").
TEMP_FILE = re.compile(r"^\..+\.(?:bvh|bvh\.gz|npz)\.[A-Za-z0-9_]+\.tmp$")


class Manifest:
    """Append-only JSONL of job records; the last record of an id is that job's state."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / MANIFEST
        self._repair()
        self._fh = self.path.open("a", encoding="utf-8")

    def _repair(self) -> None:
        """Cut a torn last line (no newline: the writer was killed mid-line)."""
        if not self.path.exists():
            return
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            with self.path.open("r+b") as fh:
                fh.truncate(data.rfind(b"\n") + 1)

    def records(self) -> list[dict]:
        """Every readable record, in order (lines that are not JSON objects are skipped)."""
        out = []
        if not self.path.exists():
            return out
        for line in self.path.read_text(encoding="utf-8", errors="replace").splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict):
                out.append(rec)
        return out

    def finished(self, folder: Path) -> dict[str, dict]:
        """id -> its last record, for jobs whose last record is ``ok`` and whose outputs all exist."""
        last: dict[str, dict] = {}
        for rec in self.records():
            if isinstance(rec.get("id"), str):
                last[rec["id"]] = rec
        return {k: r for k, r in last.items()
                if r.get("status") == "ok" and all((Path(folder) / o).is_file() for o in r.get("outputs", []))}

    def append(self, record: dict) -> None:
        """Add one record durably (one line, flushed and fsynced)."""
        self._fh.write(json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        self._fh.close()


def remove_stale_temps(folder: Path) -> int:
    """Delete temporary files that an interrupted atomic write left behind; returns how many."""
    n = 0
    for p in Path(folder).iterdir():
        if p.is_file() and TEMP_FILE.match(p.name):
            p.unlink(missing_ok=True)
            n += 1
    return n


class FolderLock:
    """An exclusive lock on an output folder for the lifetime of a batch (released on exit, even on kill)."""

    def __init__(self, folder: Path):
        import fcntl

        self.fh = (Path(folder) / LOCK).open("a")
        try:
            fcntl.flock(self.fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.fh.close()
            raise KinemaError(f"{folder}: another kinema batch is writing there (lock {LOCK})") from None

    def release(self) -> None:
        self.fh.close()
