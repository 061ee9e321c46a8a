"""Code shape (issue 32): no function in kinema/ over 60 lines (decorators, signature and docstring
included), except the ones listed below, which were longer before this test and may only shrink."""

from __future__ import annotations

import ast
from pathlib import Path

import kinema

KINEMA = Path(kinema.__file__).parent
MAX_LINES = 60
#: "path:function" -> its length when this test was written; split them when you touch them
KNOWN_LONG: dict[str, int] = {}


def function_lengths() -> dict[str, int]:
    """``"path:function"`` -> lines from its first decorator to its last line, for every function in kinema/."""
    out = {}
    for path in sorted(KINEMA.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                start = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                key = f"{path.relative_to(KINEMA).as_posix()}:{node.name}"
                out[key] = max(out.get(key, 0), node.end_lineno - start + 1)
    return out


def test_no_function_over_60_lines() -> None:
    too_long = {k: n for k, n in function_lengths().items() if n > max(MAX_LINES, KNOWN_LONG.get(k, 0))}
    assert not too_long, f"functions over {MAX_LINES} lines (or longer than before): {too_long}"
