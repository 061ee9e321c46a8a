"""The command line's generation flags, derived from `GenerationRequest` (kinema.pipeline.request).

Every request field becomes a flag (``--name-with-dashes``) typed and bounded by its `Option`, unless
its Option says ``cli=False`` (``format`` comes from ``--out``'s suffix, ``objectives`` from the
constraints file). Special spellings: ``prompt`` is the positional argument, a field whose default is
True is turned off by ``--no-NAME``, a pair takes two numbers, ``file`` fields take a path,
``--heading`` takes degrees (the request holds radians), and ``--robot-mapping`` is also ``--mapping``.
Every flag defaults to None ("not given"), so a command can fill what the user left out (a Kimodo
meta.json) and the request keeps its own defaults.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

from kinema.pipeline.request import GenerationRequest, Option, RequestBounds, options

#: other spellings of a field's flag: ``--mapping`` as every command that takes ``--robot`` spells it
CLI_ALIASES = {"robot_mapping": ("--mapping",)}
#: fields the CLI spells in a unit other than the request's: name -> (help in the CLI's unit, to request unit)
CLI_UNITS = {"heading": ("first-frame facing about +Y in degrees (0 faces +Z, 90 faces +X)", math.radians)}


def _bounded(name: str, opt: Option, bounds: RequestBounds):
    """argparse type of a numeric field: parses it and checks its lower bound (the upper bounds are the
    request's to check, with a one-line error that names them)."""
    integer = opt.kind == "int"

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if integer else 'a number'}, "
                                             f"got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        low = None if name in CLI_UNITS else opt.low  # a unit-converted value is checked by the request
        if low is not None and (value <= low if opt.open_low else value < low):
            raise argparse.ArgumentTypeError(f"expected a number {'>' if opt.open_low else '>='} {low:g}, "
                                             f"got {text!r}")
        return value  # upper bounds: the request's one-line error names the bound (and the model its own)

    return parse


def flag(name: str, opt: Option) -> str:
    """The command-line spelling of a request field."""
    if isinstance(opt.cli, str):
        return opt.cli
    return "--" + name.replace("_", "-")


def add_request_arguments(p: argparse.ArgumentParser, cls: type = GenerationRequest,
                          bounds: RequestBounds | None = None) -> None:
    """One argument per request field of ``cls`` (see the module docstring)."""
    for f, opt in options(cls):
        if opt.cli is False:
            continue
        help_text = CLI_UNITS[f.name][0] if f.name in CLI_UNITS else opt.help
        if opt.cli == "PROMPT":
            p.add_argument("prompt", nargs="?", default=None, help=help_text)
        elif opt.kind == "bool" and f.default is True:
            p.add_argument(f"--no-{f.name.replace('_', '-')}", dest=f.name, action="store_const", const=False,
                           default=None, help=f"turn off: {help_text}")
        elif opt.kind == "bool":
            p.add_argument(flag(f.name, opt), dest=f.name, action="store_const", const=True, default=None,
                           help=help_text)
        elif opt.kind == "pair":
            p.add_argument(flag(f.name, opt), dest=f.name, nargs=2, type=_bounded(f.name, opt, bounds),
                           metavar=opt.metavar, default=None, help=help_text)
        elif opt.kind in ("int", "float"):
            p.add_argument(flag(f.name, opt), dest=f.name, type=_bounded(f.name, opt, bounds),
                           metavar=opt.metavar, default=None, help=help_text)
        else:
            p.add_argument(flag(f.name, opt), *CLI_ALIASES.get(f.name, ()), dest=f.name, type=Path if opt.file else str,
                           metavar=opt.metavar, choices=opt.choices, default=None, help=help_text)


def request_from_args(args: argparse.Namespace, cls: type = GenerationRequest, **extra) -> GenerationRequest:
    """The request the parsed flags ask for (flags not given keep the request's defaults); ``extra``
    fields (those the CLI spells otherwise, like ``format``) are added as they are."""
    values = {}
    for f, opt in options(cls):
        value = getattr(args, f.name, None)
        if opt.cli is False or value is None:
            continue
        if f.name in CLI_UNITS:
            value = CLI_UNITS[f.name][1](value)
        if opt.kind == "pair" and isinstance(value, list):
            value = tuple(value)
        values[f.name] = value
    return cls(**(values | extra))


def request_fields(cls: type = GenerationRequest) -> list[str]:
    """The names of ``cls``'s fields (the tests compare every face's list with this one)."""
    return [f.name for f in dataclasses.fields(cls)]
