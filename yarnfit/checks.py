"""Input checks shared by every stage: one way to say a number is wrong.

Each takes the value and the name of the field it fills and returns the value as a float, or
raises ``ValueError`` with one line naming the field (the CLI prints it and exits 2). Booleans are
refused although ``bool`` is an ``int``: ``true`` in a JSON file must not read as 1.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["finite_number", "positive_or_none", "real_number"]


def real_number(value: object, name: str) -> float:
    """``value`` as a float (NaN and infinities pass), or ValueError if it is not a real number."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    return float(value)


def finite_number(value: object, name: str) -> float:
    """``value`` as a float, or ValueError if it is not a finite real number."""
    value = real_number(value, name)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def positive_or_none(value: object, name: str) -> float | None:
    """``None`` as is, else ``value`` as a positive finite float."""
    if value is None:
        return None
    value = finite_number(value, name)
    if value <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return value
