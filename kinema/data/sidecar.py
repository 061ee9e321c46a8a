"""Captions for your own motion files, from sidecar files next to them or one mapping file.

Three ways to caption the clips of a folder (``kinema data build folder``), combined freely:

- ``walk.txt`` next to ``walk.bvh`` (or ``Fox.txt`` next to a ``Fox.glb`` with one animation):
  one caption per non-empty line.
- ``captions.csv`` at the folder's root, with a header ``file,caption`` and one row per caption
  (a clip may have several rows).
- ``captions.jsonl`` at the root, one JSON object per line:
  ``{"file": "walk.bvh", "captions": ["A person walks.", ...]}`` (or ``"caption": "..."``).

In the mapping files ``file`` is the path relative to the root (``moves/walk.bvh``) or, when
unambiguous, the bare file name; a GLB animation is ``Fox.glb#Gallop`` (the animation's name as
stored in the file, e.g. ``Fox.glb#AnimalArmature|Gallop``). Captions from every source are
merged in that order with duplicates removed. A malformed line names the file and line.
"""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from pathlib import Path

from kinema.errors import DataError

MAPPING_FILES = ("captions.csv", "captions.jsonl")


def _clean(lines) -> list[str]:
    return [s.strip() for s in lines if s and s.strip()]


def read_mapping(root: Path) -> dict[str, list[str]]:
    """Captions from ``captions.csv`` / ``captions.jsonl`` under ``root``: {file key: [captions]}."""
    out: dict[str, list[str]] = defaultdict(list)
    csv_path = root / "captions.csv"
    if csv_path.is_file():
        with csv_path.open(encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            if reader.fieldnames is None or not {"file", "caption"} <= set(reader.fieldnames):
                raise DataError(f"{csv_path}: expected a header with columns 'file' and 'caption'")
            for n, row in enumerate(reader, start=2):
                key, text = (row.get("file") or "").strip(), (row.get("caption") or "").strip()
                if not key:
                    raise DataError(f"{csv_path}:{n}: empty 'file' field")
                if text:
                    out[key].append(text)
    jsonl = root / "captions.jsonl"
    if jsonl.is_file():
        for n, line in enumerate(jsonl.read_text(encoding="utf-8").splitlines(), start=1):
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
            except ValueError as exc:
                raise DataError(f"{jsonl}:{n}: not JSON ({exc.args[0]})") from None
            caps = obj.get("captions", obj.get("caption")) if isinstance(obj, dict) else None
            caps = [caps] if isinstance(caps, str) else caps
            if not isinstance(obj.get("file") if isinstance(obj, dict) else None, str) or not isinstance(caps, list):
                raise DataError(f'{jsonl}:{n}: expected {{"file": "...", "captions": ["...", ...]}}')
            out[obj["file"].strip()].extend(_clean(str(c) for c in caps))
    return dict(out)


def _sidecar(path: Path, animation: str | None, single: bool) -> list[str]:
    """Captions of ``walk.txt`` beside ``walk.bvh`` (or beside a GLB when it has one animation)."""
    stem = path.name
    for suffix in (".gz", ".bvh", ".glb", ".gltf"):
        if stem.lower().endswith(suffix):
            stem = stem[: -len(suffix)]
    txt = path.with_name(stem + ".txt")
    if not txt.is_file() or (animation is not None and not single):
        return []
    return _clean(txt.read_text(encoding="utf-8").splitlines())


class CaptionSource:
    """Looks up the captions of each clip of a folder (see the module docstring for the rules)."""

    def __init__(self, root: Path):
        self.root = root
        self.mapping = read_mapping(root)
        names: dict[str, int] = defaultdict(int)
        self._used: set[str] = set()
        for p in root.rglob("*"):
            names[p.name] += 1
        self._unique_names = {n for n, c in names.items() if c == 1}

    def captions(self, path: Path, animation: str | None = None, single: bool = True) -> list[str]:
        """Captions of ``path`` (a file under the root), or of its ``animation`` for a GLB."""
        rel = path.relative_to(self.root).as_posix()
        keys = [rel] + ([path.name] if path.name in self._unique_names else [])
        if animation is not None:
            keys = [f"{k}#{animation}" for k in keys] + (keys if single else [])
        found = _sidecar(path, animation, single)
        for k in keys:
            if k in self.mapping:
                self._used.add(k)
                found += self.mapping[k]
        return list(dict.fromkeys(found))

    def unused_keys(self) -> list[str]:
        """Mapping-file entries that matched no clip (typos), for a warning."""
        return sorted(set(self.mapping) - self._used)
