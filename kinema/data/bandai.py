"""Bandai Namco Research motion datasets 1 and 2: list their clips and load one as a `Motion`.

Layout expected under ``root`` (as published at github.com/BandaiNamcoResearchInc/
Bandai-Namco-Research-Motiondataset, CC BY-NC 4.0)::

    root/Bandai-Namco-Research-Motiondataset-1/cfg/{content,style}_label.txt
    root/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_<content>_<style>_<take>.bvh.gz
    root/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_<content>_<style>_<take>.json
    root/Bandai-Namco-Research-Motiondataset-2/...

``root`` may also be one ``Bandai-Namco-Research-Motiondataset-N`` folder itself. Each BVH file has
a JSON twin ``{"content": i, "style": j}`` indexing the label files; the labels are read from the
JSON and must agree with the file name, so a renamed or mislabelled file is caught instead of
silently producing wrong captions. A JSON file without a BVH file is skipped (dataset 1 publishes
labels for ``dance-long`` but no motion).

The files are 30 fps and in centimetres. Their hierarchy starts with a static ``joint_Root`` (all
zeros) whose child ``Hips`` carries the animated translation; `read_bvh` moves that translation into
``root_translation`` and `load_clip` prunes ``joint_Root`` so that ``Hips`` becomes the root
(21 joints).
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from kinema.data.captions import load_labels
from kinema.data.split import parse_clip_name
from kinema.errors import DataError, KinemaError
from kinema.motion.core import Motion

#: Centimetres -> metres.
BANDAI_SCALE = 0.01
#: The static helper joint above the hips that the loader removes.
STATIC_ROOT = "joint_Root"
_DATASET_DIR = re.compile(r"^Bandai-Namco-Research-Motiondataset-(\d+)$")


@dataclass(frozen=True)
class ClipInfo:
    """One take on disk: its labels (from the JSON twin), take number and BVH path."""

    dataset: str  # "dataset-1" or "dataset-2"
    content: str  # e.g. "walk-left"
    style: str  # e.g. "happy"
    take: int
    clip_id: str  # file name without suffix, e.g. "dataset-1_walk-left_happy_001"
    path: Path  # the .bvh.gz file
    relpath: str  # path relative to the root given to list_clips (POSIX separators)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["path"] = str(self.path)
        return d


def dataset_dirs(root: str | Path) -> list[Path]:
    """The ``Bandai-Namco-Research-Motiondataset-N`` folders under ``root`` (or ``root`` itself)."""
    root = Path(root)
    if not root.is_dir():
        raise DataError(f"{root}: dataset root does not exist or is not a directory")
    if _DATASET_DIR.match(root.name) and (root / "data").is_dir():
        return [root]
    found = sorted(
        (p for p in root.iterdir() if p.is_dir() and _DATASET_DIR.match(p.name)),
        key=lambda p: int(_DATASET_DIR.match(p.name).group(1)),
    )
    if not found:
        raise DataError(
            f"{root}: no Bandai-Namco-Research-Motiondataset-N folder found "
            "(expected the unpacked Bandai Namco datasets here)"
        )
    return found


def _read_twin(json_path: Path) -> dict:
    """The JSON twin of a BVH file, with integer ``content`` and ``style`` indices."""
    try:
        d = json.loads(json_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{json_path}: label file missing (every .bvh.gz needs a .json twin)") from None
    except (OSError, ValueError) as exc:
        raise DataError(f"{json_path}: cannot read labels: {exc}") from None
    if not (isinstance(d, dict) and isinstance(d.get("content"), int) and isinstance(d.get("style"), int)):
        raise DataError(f'{json_path}: expected {{"content": int, "style": int}}, got {d!r}')
    return d


def list_clips(root: str | Path) -> list[ClipInfo]:
    """Every clip of every dataset under ``root``, sorted by clip id.

    Raises `DataError` naming the file when a name does not parse, a JSON twin is missing or
    malformed, its indices are out of range, or its labels disagree with the file name.
    """
    root = Path(root)
    clips: list[ClipInfo] = []
    for ddir in dataset_dirs(root):
        number = _DATASET_DIR.match(ddir.name).group(1)
        contents, styles = load_labels(ddir)
        for bvh in sorted((ddir / "data").glob("*.bvh.gz")):
            try:
                fields = parse_clip_name(bvh.name)
            except KinemaError as exc:
                raise DataError(f"{bvh}: {exc}") from None
            if fields["dataset"] != f"dataset-{number}":
                raise DataError(f"{bvh}: file of {fields['dataset']} inside {ddir.name}")
            twin = bvh.with_name(bvh.name[: -len(".bvh.gz")] + ".json")
            labels = _read_twin(twin)
            ci, si = labels["content"], labels["style"]
            if not (0 <= ci < len(contents) and 0 <= si < len(styles)):
                raise DataError(
                    f"{twin}: label index out of range (content {ci} of {len(contents)}, "
                    f"style {si} of {len(styles)})"
                )
            content, style = contents[ci], styles[si]
            if (content, style) != (fields["content"], fields["style"]):
                raise DataError(
                    f"{twin}: labels ({content}, {style}) disagree with the file name "
                    f"({fields['content']}, {fields['style']})"
                )
            try:
                rel = bvh.relative_to(root).as_posix()
            except ValueError:  # root is the dataset folder itself
                rel = bvh.name
            clips.append(
                ClipInfo(fields["dataset"], content, style, fields["take"], fields["clip_id"], bvh, rel)
            )
    clips.sort(key=lambda c: c.clip_id)
    for a, b in zip(clips, clips[1:], strict=False):
        if a.clip_id == b.clip_id:
            raise DataError(f"{b.path}: clip id {b.clip_id} appears twice")
    return clips


def load_clip(info: ClipInfo, fps: float) -> Motion:
    """The clip as a 21-joint `Motion` in metres at ``fps``: read, drop ``joint_Root``, resample.

    Raises `DataError` naming the file when the BVH cannot be read, has no ``joint_Root``, or its
    pelvis does not move at all over a locomotion clip (a sign that the reader dropped the hips
    translation, which would make every feature wrong).
    """
    from kinema.io.bvh import read_bvh

    try:
        motion = read_bvh(info.path, scale=BANDAI_SCALE)
    except KinemaError as exc:
        raise DataError(f"{info.path}: {exc}") from None
    if STATIC_ROOT not in motion.skeleton.names:
        raise DataError(f"{info.path}: expected a {STATIC_ROOT} joint above Hips")
    motion = motion.prune([STATIC_ROOT]).resample(fps)
    if not motion.is_finite():
        raise DataError(f"{info.path}: motion contains NaN or inf")
    if info.content in ("walk", "run", "dash") and motion.num_frames > 1:
        travel = (motion.root_translation[-1, [0, 2]] - motion.root_translation[0, [0, 2]]).norm()
        if travel < 0.1:
            raise DataError(f"{info.path}: the pelvis of a {info.content} clip travels only {travel:.3f} m")
    return motion


def min_toe_height(motion: Motion) -> float:
    """Lowest height (metres, y) reached by either toe joint over the clip.

    The floor is y = 0 and contact labels assume it; on Bandai Namco the toe joints sit about
    4 cm above the floor when planted (the joint is inside the shoe), so values near 0.04 mean
    the clip stands on the floor, while a clip with a clearly different value would be floating
    or sunk. The build records this per clip (``clips.json``) so such clips can be found.
    """
    roles = motion.skeleton.require_roles(["left_toe", "right_toe"])
    P = motion.positions
    toes = P[:, [roles["left_toe"], roles["right_toe"]], 1]
    return float(torch.min(toes))
