"""`kinema data` sub-command (being written)."""

from __future__ import annotations


def register(sub) -> None:
    """Add the `data` sub-command to the top-level parser."""
    p = sub.add_parser("data", help="(not yet available)")
    p.set_defaults(func=lambda args: 0)
