"""`kinema convert` sub-command (being written)."""

from __future__ import annotations


def register(sub) -> None:
    """Add the `convert` sub-command to the top-level parser."""
    p = sub.add_parser("convert", help="(not yet available)")
    p.set_defaults(func=lambda args: 0)
