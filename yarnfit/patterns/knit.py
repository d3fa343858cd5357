"""Weft-knitted repeats: jersey (stockinette), 1×1 rib, garter, seed, or any knit/purl chart.

Loop shape in the fabric plane after K. Crane, "A Simple Parametric Model of Plain-Knit Yarns"
(2023, MIT): over one wale, ``x(t) = w (t + a sin 2t) / 2π`` and ``y(t) = c (h/ρ) cos t`` with
a = 1.5, h = 4 and the row offset ρ = 4.5 of that model (t ∈ [−π, π): sinker, leg, head at t = 0,
leg, sinker), w the wale spacing and c the course spacing. Its 2π : 4.5 proportion matches a
typical jersey (13 wales and 18 courses per cm).

Depth: a stitch chart ``s[k, j]`` (+1 knit, −1 purl; course k, wale j) says how the loops of course
k pass through those of course k − 1. For the loop of course k to catch the head of course k − 1
on the right side, the head of loop (k, j) lies at depth ``2 d s[k + 1, j]`` and its sinkers at
``2 d s[k, j]``, with the legs in the mid-plane; between them the depth follows ``cos² t`` (for
jersey, all +1, this is Crane's ``d (1 + cos 2t)``; for garter it is ``∓2d cos t``). Where
neighbouring wales differ (rib, seed) the sinker crosses the mid-plane at the wale boundary (see
:func:`_loop`). ``d = 2r`` (Crane's depth equals his yarn diameter). The result is the initial
geometry (loops start up to a quarter of a diameter too close); relaxation settles them.
"""

from __future__ import annotations

import math

import numpy as np

from .base import PatternError, YarnPattern, int_matrix

# Stitch charts: rows = courses (bottom to top), columns = wales; +1 knit, −1 purl.
STITCHES: dict[str, np.ndarray] = {
    "jersey": np.array([[1]]),
    "rib-1x1": np.array([[1, -1]]),
    "garter": np.array([[1], [-1]]),
    "seed": np.array([[1, -1], [-1, 1]]),
}

# Crane's loop-shape parameters (normalised units, wale width 2π).
LOOP_ROUNDNESS = 1.5
LOOP_HEIGHT = 4.0
ROW_OFFSET = 4.5
# Parameter span (rad) over which a course changes sides at a knit/purl wale boundary (rib, seed).
WALE_CROSSING = 0.2
# Nodes per loop: edges of about half a yarn radius at usual gauges, enough to resolve a loop.
SEGMENTS_PER_LOOP = 24


def check_chart(stitches) -> np.ndarray:
    """The stitch chart as an int array of ±1, or :class:`PatternError`."""
    return int_matrix(stitches, (1, -1), "stitch chart", "+1 (knit) and -1 (purl)")


def _loop(t: np.ndarray, head: float, own: float, left: float, right: float) -> np.ndarray:
    """Depth of one loop over t ∈ [−π, π): head at t = 0, legs at ±π/2 (mid-plane), sinkers at ±π.

    ``own``, ``left`` and ``right`` are the sinker depths of this loop's stitch and of its
    neighbours'. The sinker half is ``own cos² t`` (peak at the wale boundary, as in jersey).
    Where a neighbour's stitch differs, the yarn must change sides at the wale boundary, between
    the legs of the course below, which it meets within ~0.2 rad of the boundary: that half is
    scaled by a smoothstep rising from 0 at the boundary to 1 within ``WALE_CROSSING`` rad.
    """
    head_part = head * np.cos(t) ** 2
    same = np.where(t < 0.0, left == own, right == own)
    u = np.clip((np.pi - np.abs(t)) / WALE_CROSSING, 0.0, 1.0)
    crossing = np.where(same, 1.0, u * u * (3.0 - 2.0 * u))
    sinker_part = own * np.cos(t) ** 2 * crossing
    return np.where(np.abs(t) < 0.5 * np.pi, head_part, sinker_part)


def knit(stitches, courses_per_m: float, wales_per_m: float, radius: float, name: str = "knit",
         segments_per_loop: int = SEGMENTS_PER_LOOP) -> YarnPattern:
    """Knitted repeat of the stitch chart at the given gauge (courses and wales per metre) and
    yarn radius (m). Each course is one yarn running along +x."""
    s = check_chart(stitches)
    n_courses, n_wales = s.shape
    for value, what in ((courses_per_m, "courses per metre"), (wales_per_m, "wales per metre"), (radius, "radius")):
        if not (np.isfinite(value) and value > 0):
            raise PatternError(f"{what} must be positive, got {value!r}")
    wale = 1.0 / wales_per_m
    course = 1.0 / courses_per_m
    depth = 2.0 * radius
    t = -np.pi + 2.0 * np.pi * np.arange(segments_per_loop) / segments_per_loop
    loop_x = wale * (t + np.pi + LOOP_ROUNDNESS * np.sin(2.0 * t)) / (2.0 * np.pi)
    loop_y = course * (LOOP_HEIGHT / ROW_OFFSET) * np.cos(t)
    yarns = []
    for k in range(n_courses):
        above = s[(k + 1) % n_courses]
        points = []
        for j in range(n_wales):
            sinker = depth * s[k]
            z = _loop(t, 2.0 * depth * above[j], sinker[j], sinker[j - 1], sinker[(j + 1) % n_wales])
            points.append(np.column_stack([j * wale + loop_x, (k + 0.5) * course + loop_y, z]))
        yarns.append((np.concatenate(points), (1, 0)))
    return YarnPattern.from_yarns(name, "knit", (n_wales * wale, n_courses * course), radius, yarns)


def loop_length_per_wale(courses_per_m: float, wales_per_m: float, samples: int = 4096) -> float:
    """Length of one loop of the in-plane (x, y) path (m), a lower bound of the yarn per stitch."""
    t = np.linspace(-math.pi, math.pi, samples + 1)
    x = (t + LOOP_ROUNDNESS * np.sin(2 * t)) / (2 * math.pi * wales_per_m)
    y = (LOOP_HEIGHT / ROW_OFFSET) * np.cos(t) / courses_per_m
    return float(np.sum(np.hypot(np.diff(x), np.diff(y))))
