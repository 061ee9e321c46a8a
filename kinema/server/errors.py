"""Client errors of the HTTP API as data: where in the request (``loc`` and a JSONPath) and why.

Why a type of its own: a bad request can be found by pydantic (schema), by the server (unknown model,
steps above the model's limit) or by kinema itself (a constraint that does not fit the skeleton); all
three must reach the client the same way, a 422 naming the field, and a failed job stores the same data.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from kinema.constraints.types import ConstraintError
from kinema.errors import KinemaError


class RequestError(Exception):
    """A request that cannot be served as asked: a 422 listing ``items`` (see `error_item`)."""

    def __init__(self, items: list[dict]):
        self.items = items
        super().__init__("; ".join(f"{i['path']}: {i['msg']}" for i in items))

    @classmethod
    def at(cls, loc: Sequence[str | int], msg: str, kind: str = "value_error") -> RequestError:
        return cls([error_item(loc, msg, kind)])


def json_path(loc: Sequence[str | int]) -> str:
    """``["body", "constraints", 0, "bvh"]`` -> ``$.constraints[0].bvh`` (the leading "body" dropped)."""
    parts = list(loc[1:] if loc and loc[0] == "body" else loc)
    out = "$"
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else f".{p}"
    return out


def error_item(loc: Sequence[str | int], msg: str, kind: str = "value_error") -> dict:
    """One ``ErrorItem`` dict."""
    loc = [p if isinstance(p, int) else str(p) for p in loc]
    return {"loc": loc, "path": json_path(loc), "msg": msg, "type": kind}


def from_pydantic(errors: Sequence[dict]) -> list[dict]:
    """FastAPI/pydantic error dicts -> ErrorItems, without the echoed input (it may be a whole body)."""
    items = []
    for e in errors:
        msg = str(e.get("msg", "invalid value")).removeprefix("Value error, ")
        items.append(error_item(tuple(e.get("loc", ("body",))), msg, str(e.get("type", "value_error"))))
    return items


def json_syntax_error(errors: Sequence[dict]) -> str | None:
    """The 400 message when the body is no JSON text at all (pydantic's ``json_invalid``: a syntax
    error, or bytes that are not UTF-8), naming the character where parsing stopped; else None."""
    if not errors or any(e.get("type") != "json_invalid" for e in errors):
        return None
    loc = tuple(errors[0].get("loc", ()))
    at = f" at character {loc[-1]}" if loc and isinstance(loc[-1], int) else ""
    return f"the body is not valid JSON{at} (check quotes, commas and brackets, and that it is UTF-8 text)"


def from_kinema(err: KinemaError, hide: str | None = None) -> RequestError:
    """A KinemaError raised while generating -> a RequestError located in the request where possible.

    ConstraintErrors carry the constraint's index and field; other errors (e.g. a timeline segment
    shorter than one frame) are the body's. ``hide``: a private folder (the request's scratch files)
    whose path never reaches the client; it reads ``<inline>`` instead.
    """
    loc: list[str | int] = ["body"]
    msg = str(err)
    if isinstance(err, ConstraintError):
        loc, msg = ["body", "constraints"], err.reason
        if err.index is not None:
            loc.append(err.index)
            if err.field:
                loc.append(err.field)
    if hide:
        for path in (str(Path(hide).resolve()), str(hide)):
            msg = msg.replace(path, "<inline>")
    return RequestError.at(loc, msg)
