"""The HIERARCHY block of a BVH file: a token scan that returns the joints (names, parents,
offsets in file units, channels as listed, End Sites) or raises a `BVHError` naming the file and
the 1-based line of the first problem. Used by kinema.io.bvh_parse."""

from __future__ import annotations

import math

import numpy as np

from kinema.errors import BVHError
from kinema.io.bvh_data import CHANNEL_NAMES

_CANONICAL = {n.lower(): n for n in CHANNEL_NAMES}


def _tokens(lines: list[str]) -> list[tuple[str, int]]:
    """Whitespace tokens with their 1-based line; braces are tokens even when glued to a word."""
    out = []
    for lineno, line in enumerate(lines, start=1):
        if "{" in line or "}" in line:
            line = line.replace("{", " { ").replace("}", " } ")
        out.extend((tok, lineno) for tok in line.split())
    return out


def parse_hierarchy(lines: list[str], name: str):
    """(names, parents, offsets, channels, end_sites) from the lines before MOTION."""
    return _HierarchyParser(lines, name).parse()


class _HierarchyParser:
    """One scan over the hierarchy tokens: a cursor, the joints read so far and the stack of open
    blocks, with one method per keyword so that each rule (and its error message) stands alone."""

    def __init__(self, lines: list[str], name: str):
        self.toks = _tokens(lines)
        self.name = name
        self.eof_line = len(lines)  # the MOTION line (or one past the last line when there is none)
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[np.ndarray | None] = []
        self.channels: list[list[str]] = []
        self.decl_lines: list[int] = []
        self.end_sites: dict[int, np.ndarray] = {}
        self.stack: list[int] = []  # open joints; -1 - j marks joint j's End Site block
        self.i = 1

    def parse(self):
        """Check the HIERARCHY keyword, dispatch every following token, then check all blocks closed."""
        toks, name = self.toks, self.name
        if not toks or toks[0][0].upper() != "HIERARCHY":
            found = f"found {toks[0][0]!r}" if toks else "found nothing"
            raise BVHError(f"missing HIERARCHY keyword ({found})", name, toks[0][1] if toks else 1)
        keywords = {
            "ROOT": self._joint,
            "JOINT": self._joint,
            "END": self._end_site,
            "OFFSET": self._offset,
            "CHANNELS": self._channels,
        }
        while self.i < len(toks):
            tok, line = toks[self.i]
            self.i += 1
            handler = keywords.get(tok.upper())
            if handler is not None:
                handler(tok, line)
            elif tok == "}":
                self._close(line)
            else:
                raise BVHError(f"unexpected {tok!r} in the hierarchy", name, line)
        if self.stack:
            j = self.stack[-1] if self.stack[-1] >= 0 else -1 - self.stack[-1]
            raise BVHError(f"unbalanced braces: block of {self.names[j]} is never closed", name, self.eof_line)
        if not self.names:
            raise BVHError("the hierarchy has no ROOT", name, self.eof_line)
        return self.names, self.parents, np.stack(self.offsets), self.channels, self.end_sites

    def _need(self, what: str) -> tuple[str, int]:
        """The token under the cursor; running out of tokens is an error naming ``what`` was expected."""
        if self.i >= len(self.toks):
            raise BVHError(f"unexpected end of hierarchy, expected {what}", self.name, self.eof_line)
        return self.toks[self.i]

    def _open_brace(self, after: str) -> None:
        """Consume the '{' that must follow a ROOT/JOINT/End Site declaration."""
        tok2, line2 = self._need("'{'")
        if tok2 != "{":
            raise BVHError(f"expected '{{' after {after}, found {tok2!r}", self.name, line2)
        self.i += 1

    def _joint(self, tok: str, line: int) -> None:
        """ROOT or JOINT: the name is every word up to '{' on the same line; opens the joint's block."""
        key, name, stack = tok.upper(), self.name, self.stack
        if key == "ROOT" and (stack or self.names):
            raise BVHError("ROOT inside a joint or a second ROOT (one root only)", name, line)
        if key == "JOINT" and (not stack or stack[-1] < 0):
            raise BVHError("JOINT outside a parent joint", name, line)
        words = []
        while self.i < len(self.toks) and self.toks[self.i][1] == line and self.toks[self.i][0] != "{":
            words.append(self.toks[self.i][0])
            self.i += 1
        if not words:
            raise BVHError(f"{tok} without a name", name, line)
        self._open_brace(f"{tok} {' '.join(words)}")
        self.names.append(" ".join(words))
        self.parents.append(stack[-1] if stack else -1)
        self.offsets.append(None)
        self.channels.append([])
        self.decl_lines.append(line)
        stack.append(len(self.names) - 1)

    def _end_site(self, tok: str, line: int) -> None:
        """End Site: at most one per joint; opens a block whose OFFSET is the site's."""
        tok2, line2 = self._need("'Site'")
        if tok2.upper() != "SITE":
            raise BVHError(f"expected 'End Site', found 'End {tok2}'", self.name, line2)
        self.i += 1
        stack = self.stack
        if not stack or stack[-1] < 0:
            raise BVHError("End Site outside a joint", self.name, line)
        if stack[-1] in self.end_sites:
            raise BVHError(f"joint {self.names[stack[-1]]} has a second End Site", self.name, line)
        self._open_brace("End Site")
        self.end_sites[stack[-1]] = np.full(3, np.nan)
        stack.append(-1 - stack[-1])

    def _offset(self, tok: str, line: int) -> None:
        """OFFSET: three finite numbers for the open joint or End Site, given once."""
        if not self.stack:
            raise BVHError("OFFSET outside a joint", self.name, line)
        nums = []
        for _ in range(3):
            tok2, line2 = self._need("3 OFFSET numbers")
            try:
                nums.append(float(tok2) if math.isfinite(float(tok2)) else float("x"))
            except ValueError:
                raise BVHError(f"OFFSET: {tok2!r} is not a finite number", self.name, line2) from None
            self.i += 1
        j = self.stack[-1]
        if j < 0:
            if not np.isnan(self.end_sites[-1 - j]).all():
                raise BVHError("End Site has a second OFFSET", self.name, line)
            self.end_sites[-1 - j] = np.array(nums)
        else:
            if self.offsets[j] is not None:
                raise BVHError(f"joint {self.names[j]} has a second OFFSET", self.name, line)
            self.offsets[j] = np.array(nums)

    def _channels(self, tok: str, line: int) -> None:
        """CHANNELS n name...: 0 to 6 known, distinct channel names for the open joint, given once."""
        name = self.name
        if not self.stack or self.stack[-1] < 0:
            raise BVHError("CHANNELS outside a joint", name, line)
        j = self.stack[-1]
        tok2, line2 = self._need("a channel count")
        if not tok2.isdigit() or int(tok2) > 6:
            raise BVHError(f"bad CHANNELS count {tok2!r} (expected 0 to 6)", name, line2)
        count = int(tok2)
        self.i += 1
        if self.channels[j]:
            raise BVHError(f"joint {self.names[j]} has a second CHANNELS line", name, line)
        for k in range(count):
            tok2, line2 = self._need("a channel name")
            canon = _CANONICAL.get(tok2.lower())
            if canon is None and line2 != line:
                raise BVHError(f"CHANNELS declares {count} channels but lists {k}", name, line)
            if canon is None:
                raise BVHError(f"unknown channel name {tok2!r}", name, line2)
            if canon in self.channels[j]:
                raise BVHError(f"channel {canon} listed twice for joint {self.names[j]}", name, line2)
            self.channels[j].append(canon)
            self.i += 1

    def _close(self, line: int) -> None:
        """'}': closes the innermost block, which must have had its OFFSET."""
        if not self.stack:
            raise BVHError("unbalanced '}' (no open block)", self.name, line)
        j = self.stack.pop()
        if j < 0 and np.isnan(self.end_sites[-1 - j]).any():
            raise BVHError(f"End Site of {self.names[-1 - j]} has no OFFSET", self.name, line)
        if j >= 0 and self.offsets[j] is None:
            raise BVHError(f"joint {self.names[j]} has no OFFSET", self.name, self.decl_lines[j])
