"""Reading the JSON files users hand to yarnfit (fibre files, material files) with one-line errors,
and the one rule for writing a number that may be NaN into strict JSON."""

from __future__ import annotations

import json
import math
import os


def finite_or_none(value: float) -> float | None:
    """``value`` as a float, or ``None`` (JSON null) when it is NaN or infinite: strict JSON has
    neither, and yarnfit's files write an unknown figure as null."""
    return float(value) if math.isfinite(value) else None


def read_json(path: str | os.PathLike, what: str) -> tuple[str, object]:
    """``(where, data)``: the path as a string and the decoded JSON value of the file.

    Args:
        path: the file.
        what: what the file is, for messages (``"fibre file"``, ``"material file"``).

    Raises:
        ValueError: a one-line message starting with the path: no such file, unreadable, not UTF-8
            text, or invalid JSON (with line and column).
    """
    where = os.fspath(path)
    try:
        with open(where, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise ValueError(f"{where}: no such {what}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{where}: cannot read {what}: not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise ValueError(f"{where}: cannot read {what}: {exc.strerror or exc}") from None
    try:
        return where, json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
