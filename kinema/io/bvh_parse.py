"""BVH text -> `BVHData` (`parse_bvh`): input decoding, the MOTION header and the frame values.

The MOTION block is parsed by numpy in one call, so a whole dataset reads in seconds; the slow,
line-by-line scan only runs after that call has failed, to name the offending line in the
`BVHError` (every error names the file and, when it has one, the 1-based line). The HIERARCHY
block is kinema.io.bvh_hierarchy's.
"""

from __future__ import annotations

import io
import math
import os
import re
from pathlib import Path

import numpy as np

from kinema.errors import BVHError, KinemaError
from kinema.input_files import read_bytes_bounded
from kinema.io.bvh_data import MAX_DEGREES, BVHData
from kinema.io.bvh_hierarchy import parse_hierarchy
from kinema.limits import MAX_ASSET_BYTES

_MOTION_RE = re.compile(r"^[ \t]*MOTION[ \t]*$", re.M)
_FRAMES_RE = re.compile(r"Frames\s*:\s*(\S*)\s*$", re.I)
_FRAME_TIME_RE = re.compile(r"Frame\s+Time\s*:\s*(\S*)\s*$", re.I)


def parse_bvh(path_or_text: str | os.PathLike | bytes, *, source_name: str | None = None) -> BVHData:
    """Parse a BVH file (path; ``.gz`` is decompressed) or BVH text (str/bytes containing a newline).

    ``source_name`` names in-memory text in error messages. Raises `BVHError` for any malformed input.
    """
    name, text = _source_text(path_or_text, source_name)
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    if not text or text.isspace():
        raise BVHError("empty file", name, 1)

    m = _MOTION_RE.search(text)
    header = text[: m.start()] if m else text
    names, parents, offsets, channels, end_sites = parse_hierarchy(header.split("\n"), name)
    if m is None:
        raise BVHError("missing MOTION section after the hierarchy", name, text.count("\n") + 1)
    motion_line = header.count("\n") + 1
    num_frames, frame_time, data_start, data_line = _parse_motion_header(text, m.end(), motion_line, name)
    num_channels = sum(len(c) for c in channels)
    if num_channels == 0:
        raise BVHError("the hierarchy declares no channels", name, motion_line)
    values = _parse_values(text[data_start:], data_line, num_frames, num_channels, name)
    _check_values(values, names, channels, text[data_start:], data_line, name)
    return BVHData(names, parents, offsets, channels, end_sites, frame_time, values, name)


# ----------------------------------------------------------------------------- input


def _source_text(path_or_text: str | os.PathLike | bytes, source_name: str | None) -> tuple[str, str]:
    """(name for error messages, decoded text) of a path, a text string or bytes."""
    if isinstance(path_or_text, bytes):
        return source_name or "<bytes>", _decode(path_or_text)
    if isinstance(path_or_text, str) and ("\n" in path_or_text or "\r" in path_or_text or not path_or_text.strip()):
        return source_name or "<string>", path_or_text
    name = source_name or str(path_or_text)
    return name, _decode(_read_bytes(Path(path_or_text), name))


def _read_bytes(path: Path, name: str) -> bytes:
    """File contents, gunzipped when the name ends in ``.gz``; both sizes bound by `MAX_ASSET_BYTES`."""
    try:
        return read_bytes_bounded(path, "BVH file", MAX_ASSET_BYTES)
    except KinemaError as err:  # as a BVHError naming the file as the caller does
        raise BVHError(str(err).removeprefix(f"{path}: "), name) from None


def _decode(raw: bytes) -> str:
    """UTF-8 text, falling back to latin-1 so that any byte string decodes (old exporters)."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


# ----------------------------------------------------------------------------- motion


def _parse_motion_header(text: str, pos: int, motion_line: int, name: str) -> tuple[int, float, int, int]:
    """(frames, frame time, data start position, line number just before the data) after MOTION."""
    nl = text.find("\n", pos)
    pos, lineno, fields = (len(text) if nl < 0 else nl + 1), motion_line, []
    for regex, what in ((_FRAMES_RE, "'Frames: N' after MOTION"), (_FRAME_TIME_RE, "'Frame Time: s'")):
        line = ""
        while not line and pos < len(text):  # the next non-blank line
            end = text.find("\n", pos)
            end = len(text) if end < 0 else end
            line, pos, lineno = text[pos:end].strip(), end + 1, lineno + 1
        m = regex.fullmatch(line)
        if m is None:
            raise BVHError(f"expected {what}, found {line or 'nothing'!r}", name, lineno + (not line))
        fields.append((m.group(1), lineno))
    (count, count_line), (seconds, time_line) = fields
    if not count.isdigit():
        raise BVHError(f"bad frame count {count!r}", name, count_line)
    if int(count) == 0:
        raise BVHError("the file declares zero frames", name, count_line)
    try:
        frame_time = float(seconds)
    except ValueError:
        frame_time = math.nan
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise BVHError(f"bad Frame Time {seconds!r} (expected seconds > 0)", name, time_line)
    return int(count), frame_time, pos, time_line


def _parse_values(block: str, line_before: int, frames: int, channels: int, name: str) -> np.ndarray:
    """(frames, channels) float64 from the frame lines; one numpy call, diagnosis only on failure."""
    if block and not block.isspace():
        try:
            values = np.loadtxt(io.StringIO(block), dtype=np.float64, comments=None, ndmin=2)
        except ValueError:
            values = None
        if values is not None and values.shape == (frames, channels):
            return values
    _diagnose(block, line_before, frames, channels, name)
    raise BVHError("could not parse the frame values", name, line_before + 1)  # pragma: no cover


def _check_values(
    values: np.ndarray, names: list[str], channels: list[list[str]], block: str, line_before: int, name: str
) -> None:
    """Every value must be finite and every rotation within `MAX_DEGREES`; else name the frame's line."""
    flat = [c for chans in channels for c in chans]
    is_rot = np.array([c.endswith("rotation") for c in flat])
    bad = ~np.isfinite(values) | (is_rot[None] & (np.abs(values) > MAX_DEGREES))
    if not bad.any():
        return
    frame, col = (int(i[0]) for i in np.nonzero(bad))
    joint = int(np.searchsorted(np.cumsum([len(c) for c in channels]), col, side="right"))
    chan = flat[col]
    line = _frame_lines(block, line_before)[frame]
    what = "non-finite value" if not np.isfinite(values[frame, col]) else "rotation out of range:"
    limit = f" (|angle| <= {MAX_DEGREES:g} degrees)" if np.isfinite(values[frame, col]) else ""
    raise BVHError(f"{what} {values[frame, col]:g} in frame {frame + 1} ({names[joint]} {chan}){limit}", name, line)


def _frame_lines(block: str, line_before: int) -> list[int]:
    """1-based file line of every non-blank line of the data block (error path only)."""
    return [line_before + k for k, ln in enumerate(block.split("\n"), start=1) if ln.strip()]


def _diagnose(block: str, line_before: int, frames: int, channels: int, name: str) -> None:
    """Scan frame lines one by one and raise a `BVHError` at the first bad one."""
    rows = [(line_before + k, ln.split()) for k, ln in enumerate(block.split("\n"), start=1) if ln.strip()]
    for frame, (lineno, toks) in enumerate(rows):
        if frame >= frames:
            raise BVHError(f"more frame lines than the {frames} declared", name, lineno)
        for tok in toks:
            try:
                if "_" in tok:
                    raise ValueError
                float(tok)
            except ValueError:
                raise BVHError(f"non-numeric value {tok!r} in frame {frame + 1}", name, lineno) from None
        if len(toks) != channels:
            short = "truncated motion: " if frame == len(rows) - 1 and len(toks) < channels else ""
            raise BVHError(f"{short}frame {frame + 1} has {len(toks)} values, expected {channels}", name, lineno)
    if len(rows) < frames:
        last = rows[-1][0] if rows else line_before
        raise BVHError(f"truncated motion: {frames} frames declared but {len(rows)} found", name, last + 1)
