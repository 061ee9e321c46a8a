"""`kinema bench` sub-command (being written)."""

from __future__ import annotations


def register(sub) -> None:
    """Add the `bench` sub-command to the top-level parser."""
    p = sub.add_parser("bench", help="(not yet available)")
    p.set_defaults(func=lambda args: 0)
