"""Whether an input value is a usable real number.

``math.isfinite`` raises OverflowError on a Python int too large for a float, and JSON allows integers of
any length (a 400-digit ``t`` or ``speed``), so input checks call `is_finite_real` instead (issue 61).
"""

from __future__ import annotations

import math
import numbers


def is_finite_real(value) -> bool:
    """True for a real number (not a bool) that is finite as a float; False for anything else, including
    an int too large for a float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False
