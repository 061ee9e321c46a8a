"""BVH reader errors: a corpus of broken files (each a one-line edit of ``GOOD``) that must fail with
a `BVHError` naming the file and the 1-based line, plus unreadable gzip and missing files.
``GOOD`` is also the small valid file other tests use (tests/test_bvh.py, tests/hardening_fixtures.py)."""

from __future__ import annotations

import gzip

import pytest

from kinema.errors import BVHError
from kinema.io.bvh import parse_bvh

GOOD = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 90 0 0 0 0 10 0 0
1 90 0 0 5 0 20 0 0
2 90 0 0 10 0 30 0 0
"""


def edit(line: int, new: str | None) -> str:
    """GOOD with 1-based line ``line`` replaced (None deletes it)."""
    lines = GOOD.split("\n")
    lines[line - 1 : line] = [] if new is None else [new]
    return "\n".join(lines)


BROKEN = {
    "truncated_last_frame": (edit(21, "2 90 0 0 10 0"), 21, "truncated"),
    "missing_frame": (edit(21, None), 21, "3 frames declared but 2"),
    "extra_value": (edit(20, "1 90 0 0 5 0 20 0 0 7"), 20, "10 values, expected 9"),
    "extra_frame": (GOOD + "3 90 0 0 0 0 0 0 0\n", 22, "more frame lines"),
    "non_numeric": (edit(20, "1 90 0 0 abc 0 20 0 0"), 20, "'abc'"),
    "nan": (edit(20, "1 90 0 0 nan 0 20 0 0"), 20, "non-finite"),
    "inf": (edit(19, "0 90 0 0 0 0 10 -inf 0"), 19, "Chest Xrotation"),
    "zero_frames": (edit(17, "Frames: 0"), 17, "zero frames"),
    "bad_frame_count": (edit(17, "Frames: 2.5"), 17, "frame count"),
    "missing_frames_line": (edit(17, None), 17, "Frames"),
    "missing_frame_time": (edit(18, None), 18, "Frame Time"),
    "negative_frame_time": (edit(18, "Frame Time: -0.1"), 18, "Frame Time"),
    "text_frame_time": (edit(18, "Frame Time: fast"), 18, "Frame Time"),
    "missing_hierarchy": (edit(1, None), 1, "HIERARCHY"),
    "missing_motion": (GOOD.split("MOTION")[0], 16, "MOTION"),
    "unclosed_brace": (edit(14, None), 15, "never closed"),
    "extra_brace": (edit(16, "}\nMOTION"), 16, "unbalanced"),
    "joint_outside_parent": (edit(16, "JOINT Tail\n{\nOFFSET 0 0 0\n}\nMOTION"), 16, "outside"),
    "missing_offset": (edit(8, None), 6, "no OFFSET"),
    "bad_offset": (edit(8, "    OFFSET 0 x 0"), 8, "not a finite number"),
    "channel_count_too_big": (edit(9, "    CHANNELS 7 Zrotation Xrotation Yrotation"), 9, "CHANNELS count"),
    "channel_count_mismatch": (
        edit(5, "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation"),
        5,
        "lists 5",
    ),
    "unknown_channel": (edit(9, "    CHANNELS 3 Zrotation Wrotation Yrotation"), 9, "Wrotation"),
    "duplicate_channel": (edit(9, "    CHANNELS 3 Zrotation Zrotation Yrotation"), 9, "twice"),
    "second_root": (edit(16, "ROOT Other\n{\nOFFSET 0 0 0\n}\nMOTION"), 16, "ROOT"),
    "stray_word": (edit(8, "    OFFSET 0 10 0 junk"), 8, "junk"),
    "empty": ("", 1, "empty"),
    "blank": ("\n \n\t\n", 1, "empty"),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_files_name_file_and_line(tmp_path, case):
    text, line, fragment = BROKEN[case]
    path = tmp_path / f"broken_{case}.bvh"
    path.write_text(text)
    with pytest.raises(BVHError) as info:
        parse_bvh(path)
    msg = str(info.value)
    assert f"broken_{case}.bvh:{line}:" in msg, msg
    assert fragment in msg and info.value.line == line


@pytest.mark.parametrize("payload", [b"not gzip at all", gzip.compress(GOOD.encode())[:40]])
def test_bad_gzip(tmp_path, payload):
    path = tmp_path / "bad.bvh.gz"
    path.write_bytes(payload)
    with pytest.raises(BVHError, match="bad.bvh.gz.*gzip"):
        parse_bvh(path)


def test_missing_file_and_source_name(tmp_path):
    with pytest.raises(BVHError, match="nope.bvh"):
        parse_bvh(tmp_path / "nope.bvh")
    with pytest.raises(BVHError, match=r"^mem\.bvh:20: "):
        parse_bvh(edit(20, "1 2 3"), source_name="mem.bvh")
