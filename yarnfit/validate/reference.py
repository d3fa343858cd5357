"""Measured stretch curves of real fabrics (``validation/reference/*.csv``) and their comparison
with the suite's stretch test.

Format: CSV, ``#`` lines are comments (say where the data come from), then a header row whose
numeric columns carry their unit in brackets, then one row per measured point::

    # cotton twill, FAB tensile meter, 8 x 5 cm strips, our lab 2026-10
    direction,strain [1],force per width [N/m],compression ratio [1]
    weft,0.01,120.5,0.998
    warp,0.01,230.1,

Columns: ``direction`` (``weft``, ``warp`` or ``bias``, no unit), ``strain`` (``[1]`` or ``[%]``),
``force per width`` (``[N/m]``, ``[N/cm]``, ``[N/mm]`` or ``[gf/cm]``), optionally ``compression
ratio`` (``[1]``; empty cells allowed). Points of one direction need not be sorted.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import DIRECTIONS

# Unit → factor to SI (strain: 1, force per width: N/m). 1 gf = 9.80665e-3 N.
STRAIN_UNITS = {"1": 1.0, "-": 1.0, "%": 0.01}
FORCE_UNITS = {"N/m": 1.0, "N/cm": 100.0, "N/mm": 1000.0, "gf/cm": 0.980665}
RATIO_UNITS = {"1": 1.0, "-": 1.0}
_HEADER = re.compile(r"^\s*([A-Za-z_ ]+?)\s*(?:\[(.*)\])?\s*$")


@dataclass(frozen=True)
class Curve:
    """One direction's measured points, sorted by strain: arrays ``(n,)`` in SI (NaN where a
    compression ratio was not measured)."""

    strain: np.ndarray
    force_per_width: np.ndarray
    compression_ratio: np.ndarray


@dataclass(frozen=True)
class Reference:
    name: str
    curves: dict[str, Curve]


def read_reference(path: str | os.PathLike) -> Reference:
    """Read a reference CSV. Raises ``ValueError("<file>: ...")``, one line, naming the problem."""
    path = Path(path)
    where = str(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ValueError(f"{where}: cannot read the reference file ({exc.strerror or exc})") from None
    rows = [row for row in csv.reader(line for line in lines if line.strip() and not line.lstrip().startswith("#"))]
    if not rows:
        raise ValueError(f"{where}: no header row (direction,strain [1],force per width [N/m])")
    columns = {}
    for index, cell in enumerate(rows[0]):
        match = _HEADER.match(cell) if cell.strip() else None
        if not match:
            raise ValueError(f"{where}: header cell {cell!r} is not 'name [unit]'")
        columns[match.group(1).lower().replace("_", " ")] = (index, match.group(2))
    factors = {}
    for name, units, required in (("strain", STRAIN_UNITS, True), ("force per width", FORCE_UNITS, True),
                                  ("compression ratio", RATIO_UNITS, False)):
        if name not in columns:
            if required:
                raise ValueError(f"{where}: missing column '{name} [unit]'")
            continue
        unit = columns[name][1]
        if unit is None:
            raise ValueError(f"{where}: column '{name}' has no unit; write it as '{name} [{next(iter(units))}]'")
        if unit.strip() not in units:
            raise ValueError(f"{where}: column '{name}' has unit [{unit}]; use one of "
                             + ", ".join(f"[{u}]" for u in units))
        factors[name] = units[unit.strip()]
    if "direction" not in columns:
        raise ValueError(f"{where}: missing column 'direction' (weft, warp or bias)")
    points: dict[str, list[tuple[float, float, float]]] = {}
    for number, row in enumerate(rows[1:], start=2):
        def cell(name):
            index = columns[name][0]
            return row[index].strip() if index < len(row) else ""

        direction = cell("direction").lower()
        if direction not in DIRECTIONS:
            raise ValueError(f"{where}: data row {number - 1}: direction {direction!r} is not one of "
                             + ", ".join(DIRECTIONS))
        values = []
        for name in ("strain", "force per width", "compression ratio"):
            text = cell(name) if name in columns else ""
            if not text and name == "compression ratio":
                values.append(math.nan)
                continue
            try:
                value = float(text)
            except ValueError:
                raise ValueError(f"{where}: data row {number - 1}: {name} {text!r} is not a number") from None
            if not math.isfinite(value):
                raise ValueError(f"{where}: data row {number - 1}: {name} {text!r} is not finite")
            values.append(value * factors[name])
        if values[0] < 0:
            raise ValueError(f"{where}: data row {number - 1}: negative strain {values[0]!r}")
        points.setdefault(direction, []).append(tuple(values))
    if not points:
        raise ValueError(f"{where}: no data rows")
    curves = {}
    for direction, rows_ in points.items():
        data = np.array(sorted(rows_))
        curves[direction] = Curve(data[:, 0], data[:, 1], data[:, 2])
    return Reference(path.stem, curves)


def compare(reference: Reference, strips: dict) -> dict:
    """Relative differences of the suite's 8 × 5 cm strips (``run_stretch`` summary ``strips``)
    from the reference, at the reference's strains inside the simulated range. Per direction:
    ``points``, ``strain``, ``relative_difference`` (ours / measured − 1), ``rms_relative``,
    ``max_abs_relative``."""
    out = {"name": reference.name}
    for direction, curve in reference.curves.items():
        strip = strips.get(f"8x5_{direction}")
        if strip is None:
            out[direction] = {"points": 0, "note": "no simulated strip in this direction"}
            continue
        strain, force = np.asarray(strip["strain"]), np.asarray(strip["force_per_width_n_per_m"])
        inside = (curve.strain >= strain[0]) & (curve.strain <= strain[-1]) & (curve.force_per_width != 0)
        ours = np.interp(curve.strain[inside], strain, force)
        relative = ours / curve.force_per_width[inside] - 1.0
        out[direction] = {
            "points": int(inside.sum()),
            "strain": curve.strain[inside].tolist(),
            "relative_difference": relative.tolist(),
            "rms_relative": float(np.sqrt(np.mean(relative**2))) if inside.any() else None,
            "max_abs_relative": float(np.abs(relative).max()) if inside.any() else None,
        }
    return out
