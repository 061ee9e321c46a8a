"""JSON schemas of `GenerationRequest` (kinema.pipeline.request) for the server and batch, as pydantic models.

`request_model` turns every request field into a pydantic field typed and bounded by its `Option`
(strings with their length and choices, integers and numbers with their bounds, never a bool for a
number, pairs, booleans); a face passes ``overrides`` only for the fields whose JSON shape is its own
(the server's typed inline constraints, a batch line's file names) and ``extra`` for keys that are
not part of a request (``model``, a batch line's ``id``). A field added to the request therefore shows up
in both schemas without touching them (tests/test_pipeline.py adds one and looks).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StrictBool, StrictInt, create_model

from kinema.pipeline.request import GenerationRequest, Option, RequestBounds, options, request_bounds


class Strict(BaseModel):
    """Base of every request model: unknown keys are errors (typos must not be silently ignored)."""

    model_config = ConfigDict(extra="forbid")


class Segment(Strict):
    """One timeline segment: a prompt held for ``seconds``."""

    prompt: str
    seconds: Annotated[float, Field(gt=0, allow_inf_nan=False)]


def number_only(value: Any) -> Any:
    """Numbers only: JSON ``true`` is not 1 and ``"5"`` is not 5 (pydantic would take both), as integer
    fields (StrictInt) take neither."""
    if isinstance(value, bool | str):
        raise ValueError(f"expected a number, got {'a boolean' if isinstance(value, bool) else 'a string'}")
    return value


def _number_type(opt: Option, bounds: RequestBounds, integer: bool) -> Any:
    limits: dict[str, Any] = {}
    if opt.low is not None:
        limits["gt" if opt.open_low else "ge"] = opt.low
    high = opt.high_value(bounds)
    if high is not None:
        limits["le"] = high
    if integer:
        return Annotated[StrictInt, Field(**limits)]
    return Annotated[float, BeforeValidator(number_only), Field(allow_inf_nan=False, **limits)]


def field_type(opt: Option, bounds: RequestBounds | None = None) -> Any:
    """The pydantic type of one request field (see the module docstring); ``bounds``: `request_bounds`."""
    bounds = bounds or request_bounds()
    if opt.kind == "int":
        return _number_type(opt, bounds, True)
    if opt.kind == "float":
        return _number_type(opt, bounds, False)
    if opt.kind == "bool":
        return StrictBool
    if opt.kind == "pair":
        one = _number_type(opt, bounds, False)
        return tuple[one, one]
    if opt.kind == "str":
        if opt.choices is not None:
            return Literal[opt.choices]
        high = opt.high_value(bounds)
        return Annotated[str, Field(max_length=int(high))] if high is not None else str
    return Any


def request_model(name: str, *, cls: type = GenerationRequest, bounds: RequestBounds | None = None,
                  overrides: dict[str, Any] | None = None, extra: dict[str, tuple[Any, Any]] | None = None,
                  base: type[BaseModel] = Strict) -> type[BaseModel]:
    """A pydantic model named ``name`` with one optional field per field of ``cls`` (the request's own
    default when left out), ``overrides`` (field -> type or ``(type, FieldInfo)``) replacing the derived
    type, and ``extra`` fields (name -> ``(type, default or FieldInfo)``) added."""
    overrides = overrides or {}
    fields: dict[str, Any] = {}
    for f, opt in options(cls):
        given = overrides.get(f.name, field_type(opt, bounds))
        kind, info = given if isinstance(given, tuple) and len(given) == 2 and _is_field_info(given[1]) else (
            given, None)
        default = None if f.default is None or not isinstance(f.default, str | int | float | bool) else f.default
        if info is None:
            info = Field(default, description=opt.help)
        fields[f.name] = (kind | None if default is None else kind, info)
    for key, spec in (extra or {}).items():
        fields[key] = spec
    return create_model(name, __base__=base, **fields)


def _is_field_info(value: Any) -> bool:
    return type(value).__name__ == "FieldInfo"


def to_request(body: BaseModel, *, cls: type = GenerationRequest, **given) -> GenerationRequest:
    """The request a validated body holds (keys the client left out keep the request's defaults); ``given``
    fields replace the body's (a face's own reading of them: files read, a prompt as a timeline)."""
    names = {f.name for f, _ in options(cls)}
    values = {k: v for k, v in body.model_dump(exclude_unset=True).items() if k in names}
    if isinstance(values.get("guidance"), list):
        values["guidance"] = tuple(values["guidance"])
    return cls(**(values | given))
