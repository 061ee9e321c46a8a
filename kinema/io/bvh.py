"""BVH reading: a raw layer (`parse_bvh` -> `BVHData`, file units and degrees, exactly as written)
and its conversion to a `Motion` (`read_bvh` / `bvh_data_to_motion`: metres, quaternions wxyz).
Writing lives in kinema.io.bvh_writer.

The raw layer accepts any per-joint channel layout (0-6 channels, any rotation order, position
channels on any joint), End Sites, CRLF/CR line ends, tabs, scientific notation and ``.gz`` files.
The MOTION block is parsed by numpy in one call, so a whole dataset reads in seconds; the slow,
line-by-line scan only runs after that call has failed, to name the offending line in the
`BVHError` (every error names the file and, when it has one, the 1-based line).
"""

from __future__ import annotations

import gzip
import io
import math
import os
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinema.errors import BVHError
from kinema.geometry.rotations import euler_to_quat, quat_rotate
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

#: Channel names as written in files; matching is case-insensitive.
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CANONICAL = {n.lower(): n for n in CHANNEL_NAMES}
_MOTION_RE = re.compile(r"^[ \t]*MOTION[ \t]*$", re.M)
_FRAMES_RE = re.compile(r"Frames\s*:\s*(\S*)\s*$", re.I)
_FRAME_TIME_RE = re.compile(r"Frame\s+Time\s*:\s*(\S*)\s*$", re.I)
#: Largest rotation channel value read (degrees): beyond it the angle has lost all precision (a
#: corrupt file), though unwrapped angles of many turns are fine.
MAX_DEGREES = 1e7
#: Largest length read, in metres after ``scale``: beyond it a value is corrupt (or the scale wrong),
#: and it would not fit the float32 arrays of kinema's npz format either.
MAX_METRES = 1e6


@dataclass(eq=False)
class BVHData:
    """A BVH file exactly as written: file units, Euler angles in degrees, channels as listed.

    ``values[:, c]`` is channel ``c`` counted across joints in hierarchy order (the order of
    ``names``); `column_starts` gives where each joint's channels begin.
    """

    names: list[str]
    parents: list[int]
    offsets: np.ndarray  # (J, 3) float64, file units
    channels: list[list[str]]  # per joint, canonical names in file order
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)  # joint -> (3,) End Site offset
    frame_time: float = 1.0 / 30.0
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (T, C) float64
    path: str = ""

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    @property
    def column_starts(self) -> list[int]:
        """Index into ``values`` of each joint's first channel."""
        starts, c = [], 0
        for chans in self.channels:
            starts.append(c)
            c += len(chans)
        return starts


def parse_bvh(path_or_text: str | os.PathLike | bytes, *, source_name: str | None = None) -> BVHData:
    """Parse a BVH file (path; ``.gz`` is decompressed) or BVH text (str/bytes containing a newline).

    ``source_name`` names in-memory text in error messages. Raises `BVHError` for any malformed input.
    """
    if isinstance(path_or_text, bytes):
        name = source_name or "<bytes>"
        text = _decode(path_or_text)
    elif isinstance(path_or_text, str) and (
        "\n" in path_or_text or "\r" in path_or_text or not path_or_text.strip()
    ):
        name, text = source_name or "<string>", path_or_text
    else:
        name = source_name or str(path_or_text)
        text = _decode(_read_bytes(Path(path_or_text), name))
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    if not text or text.isspace():
        raise BVHError("empty file", name, 1)

    m = _MOTION_RE.search(text)
    header = text[: m.start()] if m else text
    names, parents, offsets, channels, end_sites = _parse_hierarchy(header.split("\n"), name)
    if m is None:
        raise BVHError("missing MOTION section after the hierarchy", name, text.count("\n") + 1)
    motion_line = header.count("\n") + 1
    num_frames, frame_time, data_start, data_line = _parse_motion_header(text, m.end(), motion_line, name)
    num_channels = sum(len(c) for c in channels)
    if num_channels == 0:
        raise BVHError("the hierarchy declares no channels", name, motion_line)
    values = _parse_values(text[data_start:], data_line, num_frames, num_channels, name)
    flat = [c for chans in channels for c in chans]
    is_rot = np.array([c.endswith("rotation") for c in flat])
    bad = ~np.isfinite(values) | (is_rot[None] & (np.abs(values) > MAX_DEGREES))
    if bad.any():
        frame, col = (int(i[0]) for i in np.nonzero(bad))
        joint = int(np.searchsorted(np.cumsum([len(c) for c in channels]), col, side="right"))
        chan = flat[col]
        line = _frame_lines(text[data_start:], data_line)[frame]
        what = "non-finite value" if not np.isfinite(values[frame, col]) else "rotation out of range:"
        limit = f" (|angle| <= {MAX_DEGREES:g} degrees)" if np.isfinite(values[frame, col]) else ""
        raise BVHError(
            f"{what} {values[frame, col]:g} in frame {frame + 1} ({names[joint]} {chan}){limit}", name, line
        )
    return BVHData(names, parents, offsets, channels, end_sites, frame_time, values, name)


# ----------------------------------------------------------------------------- input


def _read_bytes(path: Path, name: str) -> bytes:
    """File contents, gunzipped when the name ends in ``.gz``."""
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise BVHError(f"cannot read file: {err.strerror or err}", name) from None
    if path.name.lower().endswith(".gz"):
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as err:
            raise BVHError(f"not a readable gzip file ({err})", name) from None
    return raw


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


# ----------------------------------------------------------------------------- hierarchy


def _tokens(lines: list[str]) -> list[tuple[str, int]]:
    """Whitespace tokens with their 1-based line; braces are tokens even when glued to a word."""
    out = []
    for lineno, line in enumerate(lines, start=1):
        if "{" in line or "}" in line:
            line = line.replace("{", " { ").replace("}", " } ")
        out.extend((tok, lineno) for tok in line.split())
    return out


def _parse_hierarchy(lines: list[str], name: str):
    """(names, parents, offsets, channels, end_sites) from the lines before MOTION."""
    toks = _tokens(lines)
    eof_line = len(lines)  # the MOTION line (or one past the last line when there is none)
    if not toks or toks[0][0].upper() != "HIERARCHY":
        found = f"found {toks[0][0]!r}" if toks else "found nothing"
        raise BVHError(f"missing HIERARCHY keyword ({found})", name, toks[0][1] if toks else 1)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray | None] = []
    channels: list[list[str]] = []
    decl_lines: list[int] = []
    end_sites: dict[int, np.ndarray] = {}
    stack: list[int] = []  # open joints; -1 - j marks joint j's End Site block
    i, n = 1, len(toks)

    def need(what: str) -> tuple[str, int]:
        if i >= n:
            raise BVHError(f"unexpected end of hierarchy, expected {what}", name, eof_line)
        return toks[i]

    def open_brace(after: str) -> None:
        tok2, line2 = need("'{'")
        if tok2 != "{":
            raise BVHError(f"expected '{{' after {after}, found {tok2!r}", name, line2)

    while i < n:
        tok, line = toks[i]
        key = tok.upper()
        i += 1
        if key in ("ROOT", "JOINT"):
            if key == "ROOT" and (stack or names):
                raise BVHError("ROOT inside a joint or a second ROOT (one root only)", name, line)
            if key == "JOINT" and (not stack or stack[-1] < 0):
                raise BVHError("JOINT outside a parent joint", name, line)
            words = []
            while i < n and toks[i][1] == line and toks[i][0] != "{":
                words.append(toks[i][0])
                i += 1
            if not words:
                raise BVHError(f"{tok} without a name", name, line)
            open_brace(f"{tok} {' '.join(words)}")
            i += 1
            names.append(" ".join(words))
            parents.append(stack[-1] if stack else -1)
            offsets.append(None)
            channels.append([])
            decl_lines.append(line)
            stack.append(len(names) - 1)
        elif key == "END":
            tok2, line2 = need("'Site'")
            if tok2.upper() != "SITE":
                raise BVHError(f"expected 'End Site', found 'End {tok2}'", name, line2)
            i += 1
            if not stack or stack[-1] < 0:
                raise BVHError("End Site outside a joint", name, line)
            if stack[-1] in end_sites:
                raise BVHError(f"joint {names[stack[-1]]} has a second End Site", name, line)
            open_brace("End Site")
            i += 1
            end_sites[stack[-1]] = np.full(3, np.nan)
            stack.append(-1 - stack[-1])
        elif key == "OFFSET":
            if not stack:
                raise BVHError("OFFSET outside a joint", name, line)
            nums = []
            for _ in range(3):
                tok2, line2 = need("3 OFFSET numbers")
                try:
                    nums.append(float(tok2) if math.isfinite(float(tok2)) else float("x"))
                except ValueError:
                    raise BVHError(f"OFFSET: {tok2!r} is not a finite number", name, line2) from None
                i += 1
            j = stack[-1]
            if j < 0:
                if not np.isnan(end_sites[-1 - j]).all():
                    raise BVHError("End Site has a second OFFSET", name, line)
                end_sites[-1 - j] = np.array(nums)
            else:
                if offsets[j] is not None:
                    raise BVHError(f"joint {names[j]} has a second OFFSET", name, line)
                offsets[j] = np.array(nums)
        elif key == "CHANNELS":
            if not stack or stack[-1] < 0:
                raise BVHError("CHANNELS outside a joint", name, line)
            j = stack[-1]
            tok2, line2 = need("a channel count")
            if not tok2.isdigit() or int(tok2) > 6:
                raise BVHError(f"bad CHANNELS count {tok2!r} (expected 0 to 6)", name, line2)
            count = int(tok2)
            i += 1
            if channels[j]:
                raise BVHError(f"joint {names[j]} has a second CHANNELS line", name, line)
            for k in range(count):
                tok2, line2 = need("a channel name")
                canon = _CANONICAL.get(tok2.lower())
                if canon is None and line2 != line:
                    raise BVHError(f"CHANNELS declares {count} channels but lists {k}", name, line)
                if canon is None:
                    raise BVHError(f"unknown channel name {tok2!r}", name, line2)
                if canon in channels[j]:
                    raise BVHError(f"channel {canon} listed twice for joint {names[j]}", name, line2)
                channels[j].append(canon)
                i += 1
        elif tok == "}":
            if not stack:
                raise BVHError("unbalanced '}' (no open block)", name, line)
            j = stack.pop()
            if j < 0 and np.isnan(end_sites[-1 - j]).any():
                raise BVHError(f"End Site of {names[-1 - j]} has no OFFSET", name, line)
            if j >= 0 and offsets[j] is None:
                raise BVHError(f"joint {names[j]} has no OFFSET", name, decl_lines[j])
        else:
            raise BVHError(f"unexpected {tok!r} in the hierarchy", name, line)
    if stack:
        j = stack[-1] if stack[-1] >= 0 else -1 - stack[-1]
        raise BVHError(f"unbalanced braces: block of {names[j]} is never closed", name, eof_line)
    if not names:
        raise BVHError("the hierarchy has no ROOT", name, eof_line)
    return names, parents, np.stack(offsets), channels, end_sites


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
            raise BVHError(
                f"{short}frame {frame + 1} has {len(toks)} values, expected {channels}", name, lineno
            )
    if len(rows) < frames:
        last = rows[-1][0] if rows else line_before
        raise BVHError(f"truncated motion: {frames} frames declared but {len(rows)} found", name, last + 1)


# ----------------------------------------------------------------------------- conversion to Motion


def read_bvh(path: str | os.PathLike, *, scale: float = 1.0, root_follows_child: bool = True) -> Motion:
    """Read a ``.bvh``/``.bvh.gz`` file as a `Motion`; every length is multiplied by ``scale``
    (0.01 for centimetre files such as Bandai Namco). See `bvh_data_to_motion` for the rules."""
    return bvh_data_to_motion(parse_bvh(path), scale=scale, root_follows_child=root_follows_child)


def bvh_data_to_motion(data: BVHData, *, scale: float = 1.0, root_follows_child: bool = True) -> Motion:
    """Convert raw BVH data to a `Motion` (float64, metres, full local rotations).

    - Rotation channels, in the order listed, are intrinsic Euler angles in degrees
      (``ZXY`` means ``R = Rz @ Rx @ Ry``); missing rotation axes count as zero, no rotation
      channels give the identity.
    - Position channels replace the joint's offset (missing axes keep the OFFSET value). A
      `Skeleton` has constant offsets, so the first frame's values become the offset; channels that
      move (by more than 1e-6 m) are kept per frame in ``Motion.local_translations``.
    - The root's world position is its position channels (its OFFSET when it has none).
    - When the root has a single child with position channels (Bandai Namco: a static
      ``joint_Root`` whose child ``Hips`` carries the translation), that child's movement is moved
      into ``root_translation``: every joint below the root keeps its exact file position, and only
      the root joint itself is displaced by the child's movement since frame 1 (Bandai's dummy root
      then follows the hips). ``Motion.prune(["joint_Root"])`` removes it exactly. With
      ``root_follows_child=False`` the root stays where the file puts it and the child's movement is
      kept in ``local_translations`` (every joint exact: creatures whose root is a real bone, e.g.
      BVH written from a GLB).
    - ``fps = 1 / frame_time``, snapped to the nearest integer when within 0.01 % (``0.0333333``
      is 30 fps).
    """
    import torch


    if not (math.isfinite(scale) and scale > 0):
        raise BVHError(f"scale must be a positive number, got {scale}", data.path)
    T, J, C = data.num_frames, data.num_joints, data.num_channels
    _check_lengths(data, scale)
    vals = np.concatenate([data.values, np.zeros((T, 1))], axis=1)  # column C is a constant zero
    offsets = data.offsets * scale
    positions: dict[int, np.ndarray] = {}  # joint -> (T, 3) scaled, for joints with position channels
    by_order: dict[str, tuple[list[int], list[list[int]]]] = {}
    for j, (start, chans) in enumerate(zip(data.column_starts, data.channels, strict=True)):
        pos_cols = {c[0]: start + k for k, c in enumerate(chans) if c.endswith("position")}
        rot_cols = {c[0]: start + k for k, c in enumerate(chans) if c.endswith("rotation")}
        if pos_cols:
            p = np.repeat(offsets[j][None], T, axis=0)
            for axis, col in pos_cols.items():
                p[:, "XYZ".index(axis)] = vals[:, col] * scale
            positions[j] = p
            offsets[j] = p[0]
        if rot_cols:
            order = "".join(rot_cols) + "".join(a for a in "XYZ" if a not in rot_cols)
            joints, cols = by_order.setdefault(order, ([], []))
            joints.append(j)
            cols.append([rot_cols.get(a, C) for a in order])
    quats = torch.zeros(T, J, 4, dtype=torch.float64)
    quats[..., 0] = 1.0
    for order, (joints, cols) in by_order.items():
        angles = torch.from_numpy(np.deg2rad(vals[:, np.array(cols)]))  # (T, n, 3)
        quats[:, joints] = euler_to_quat(angles, order)
    root = torch.from_numpy(positions.get(0, np.repeat(offsets[:1], T, axis=0)).copy())

    children = [j for j in range(J) if data.parents[j] == 0]
    carried = children[0] if root_follows_child and len(children) == 1 and children[0] in positions else None
    if carried is not None:
        moved = torch.from_numpy(positions[carried] - positions[carried][:1])
        root = root + quat_rotate(quats[:, 0], moved)
    moving = [j for j, p in positions.items() if j not in (0, carried) and float(np.abs(p - p[:1]).max()) > 1e-6]
    local_t = None
    if moving:  # bones whose translation is animated (e.g. glTF creatures written by kinema)
        local_t = torch.from_numpy(np.repeat(offsets[None], T, axis=0))
        for j in moving:
            local_t[:, j] = torch.from_numpy(positions[j])
    fps = 1.0 / data.frame_time
    if round(fps) > 0 and abs(fps - round(fps)) <= 1e-4 * fps:
        fps = float(round(fps))
    name = Path(data.path).name
    for suffix in (".gz", ".bvh"):
        name = name[: -len(suffix)] if name.lower().endswith(suffix) else name
    ends = {j: tuple(float(x) for x in v * scale) for j, v in data.end_sites.items()}
    skeleton = Skeleton(data.names, data.parents, offsets, end_sites=ends, name=name)
    return Motion(skeleton, fps, root, quats, None, local_t)


def _check_lengths(data: BVHData, scale: float) -> None:
    """OFFSETs and position channels, times ``scale``, must be finite and at most `MAX_METRES`."""
    for j, off in enumerate(data.offsets):
        if not np.all(np.abs(off * scale) <= MAX_METRES):
            raise BVHError(f"OFFSET of joint {data.names[j]} is {off.tolist()} x scale {scale:g}: not a "
                           f"length within {MAX_METRES:g} m", data.path)
    for j, site in data.end_sites.items():
        if not np.all(np.abs(site * scale) <= MAX_METRES):
            raise BVHError(f"End Site OFFSET of joint {data.names[j]} is {site.tolist()} x scale {scale:g}: "
                           f"not a length within {MAX_METRES:g} m", data.path)
    cols = [(start + k, j, c) for j, (start, chans) in enumerate(zip(data.column_starts, data.channels, strict=True))
            for k, c in enumerate(chans) if c.endswith("position")]
    if not cols or data.values.size == 0:
        return
    pos = data.values[:, [c for c, _, _ in cols]] * scale
    bad = ~(np.abs(pos) <= MAX_METRES)
    if bad.any():
        frame, k = (int(i[0]) for i in np.nonzero(bad))
        _, j, chan = cols[k]
        raise BVHError(f"{data.names[j]} {chan} in frame {frame + 1} is {data.values[frame, cols[k][0]]:g} x scale "
                       f"{scale:g}: not a position within {MAX_METRES:g} m", data.path)

