"""Input checks shared by every stage: one way to say a number is wrong.

Each takes the value and the name of the field it fills and returns the value as a float, or
raises ``ValueError`` with one line naming the field (the CLI prints it and exits 2). Booleans are
refused although ``bool`` is an ``int``: ``true`` in a JSON file must not read as 1.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection, Mapping

import numpy as np

__all__ = ["check_keys", "error_line", "finite_number", "non_negative_number", "positive_number", "positive_or_none",
           "real_number"]


def error_line(error: BaseException) -> str:
    """The one line a failure is reported by: its message's first line, or its type's name when
    the message is empty."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


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


def positive_number(value: object, name: str) -> float:
    """``value`` as a float, or ValueError if it is not a finite real number > 0."""
    value = finite_number(value, name)
    if value <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return value


def non_negative_number(value: object, name: str) -> float:
    """``value`` as a float, or ValueError if it is not a finite real number >= 0."""
    value = finite_number(value, name)
    if value < 0.0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return value


def positive_or_none(value: object, name: str) -> float | None:
    """``None`` as is, else ``value`` as a positive finite float."""
    return None if value is None else positive_number(value, name)


def check_keys(data: Mapping, required: Collection[str], where: str, allowed: Collection[str] | None = None,
               prefix: str = "") -> None:
    """ValueError ``"<where>: missing keys: …; unknown keys: … (allowed: …)"`` for a JSON object
    lacking one of ``required`` or holding a key outside ``allowed`` (default: ``required``),
    keys shown behind ``prefix``. Both are reported together: a misspelt key shows up as one of
    each."""
    allowed = required if allowed is None else allowed
    problems = []
    missing = [f"{prefix}{key}" for key in required if key not in data]
    unknown = sorted(f"{prefix}{key}" for key in data if key not in allowed)
    if missing:
        problems.append(f"missing keys: {', '.join(missing)}")
    if unknown:
        problems.append(f"unknown keys: {', '.join(unknown)} (allowed: {', '.join(prefix + k for k in allowed)})")
    if problems:
        raise ValueError(f"{where}: {'; '.join(problems)}")
