"""Woven repeats from their drafts.

A draft is a 0/1 interlacement matrix with one row per pick (weft yarn, along x) and one column per
end (warp yarn, along y); ``draft[i, j] = 1`` means end j passes over pick i at their crossing.
The repeat is ``n_ends / ends_per_m`` by ``n_picks / picks_per_m``. At every crossing the two
centrelines are ``H`` apart, the yarn on top above; between crossings each yarn's height follows a
half cosine, so floats stay flat and interlacings bend smoothly.

The crimp is shared so that both yarn families start equally curved: a yarn ramping over thread
spacing ``s`` with amplitude ``A`` has curvature ``~A / s²``, so picks (ramping over the end
spacing ``s_e``) get ``A_p = f H`` and ends ``A_e = (1 − f) H`` with ``f = s_e² / (s_e² + s_p²)``.
A warp-faced satin, ends twice as dense as picks, thus starts with nearly straight picks and
crimped ends, as it is woven. ``H`` is the smallest separation (with 5 % to spare, at least 2r)
that keeps two radii between a yarn changing sides and the crossing yarns it passes: at distance
``d`` along its ramp from a crossing yarn's axis, a pick sits ``A_e + A_p cos(π d / s_e)`` below
or above it, so ``d² + (A_e + A_p cos(π d / s_e))² ≥ 4 r²`` on [0, s_e], and likewise for ends.
Checking only the ramp mid-point misses its steep part next to the binding yarn and starts a
dense satin with 10 % overlaps. This is the initial geometry; relaxation closes the gaps and
gives the crimp its equilibrium shape.
"""

from __future__ import annotations

import numpy as np

from .base import PatternError, YarnPattern, int_matrix

# Named drafts (rows = picks, columns = ends, 1 = end over pick).
DRAFTS: dict[str, np.ndarray] = {
    "plain": np.array([[1, 0], [0, 1]]),
    "twill-2/1": np.array([[1, 1, 0], [0, 1, 1], [1, 0, 1]]),
    "twill-2/2": np.array([[1, 1, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [1, 0, 0, 1]]),
    "twill-3/1": np.array([[1, 1, 1, 0], [0, 1, 1, 1], [1, 0, 1, 1], [1, 1, 0, 1]]),
    # Warp-faced satins: each pick is bound by one end, the binding point moving by the counter
    # (4-harness: the "crow's foot" 1/3 broken twill, 5-harness counter 2, 8-harness counter 3).
    "satin-4": np.array([[1, 1, 1, 0], [1, 0, 1, 1], [1, 1, 0, 1], [0, 1, 1, 1]]),
    "satin-5": 1 - np.eye(5, dtype=int)[[0, 2, 4, 1, 3]],
    "satin-8": 1 - np.eye(8, dtype=int)[[0, 3, 6, 1, 4, 7, 2, 5]],
    "basket-2x2": np.array([[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 1], [0, 0, 1, 1]]),
}

# Clearance over the geometric minimum of the crossing height (see the module docstring).
HEIGHT_MARGIN = 1.05
# Samples of the ramp and bisection steps for the crossing separation: the clearance is checked
# every 1e-3 of the spacing and H found to 2^-40 of its bracket, far below the 5 % margin.
CLEARANCE_SAMPLES = 1001
BISECTION_STEPS = 40
# A separation beyond 2^10 diameters means the threads are too close to interlace at all.
MAX_DOUBLINGS = 10
# Node count per crossing interval of a yarn: edges ~ half a radius long at usual counts, enough
# to resolve the crimp (one half-cosine per interval).
SEGMENTS_PER_CROSSING = 8


def check_draft(draft) -> np.ndarray:
    """The draft as an int array, or :class:`PatternError` saying what is wrong with it."""
    d = int_matrix(draft, (0, 1), "draft (rows = picks, columns = ends)", "0 (pick over end) and 1 (end over pick)")
    for i, row in enumerate(d):
        if row.min() == row.max() and d.shape[1] > 1:
            raise PatternError(f"draft row {i} never interlaces (pick {i} lies on one side of every end)")
    for j, col in enumerate(d.T):
        if col.min() == col.max() and d.shape[0] > 1:
            raise PatternError(f"draft column {j} never interlaces (end {j} lies on one side of every pick)")
    return d


def _profile(heights: np.ndarray, segments: int) -> np.ndarray:
    """Periodic height profile through crossing heights, ``segments`` samples per interval, each
    interval a half cosine from one crossing height to the next (``len(heights) * segments``)."""
    n = len(heights)
    u = np.arange(segments) / segments
    blend = 0.5 * (1.0 - np.cos(np.pi * u))
    start = np.repeat(heights, segments)
    end = np.repeat(np.roll(heights, -1), segments)
    return start + (end - start) * np.tile(blend, n)


def crossing_separation(radius: float, end_spacing: float, pick_spacing: float) -> tuple[float, float]:
    """Crimp amplitudes ``(A_p, A_e)`` (m) of picks and ends: the smallest crossing separation
    ``A_p + A_e`` whose half-cosine ramps clear every crossing yarn by two radii, shared for equal
    curvature (see the module docstring)."""
    pick_share = end_spacing**2 / (end_spacing**2 + pick_spacing**2)
    u = np.linspace(0.0, 1.0, CLEARANCE_SAMPLES)
    cosine = np.cos(np.pi * u)

    def clears(separation: float) -> bool:
        a_p, a_e = pick_share * separation, (1.0 - pick_share) * separation
        pick_gap = (u * end_spacing) ** 2 + (a_e + a_p * cosine) ** 2
        end_gap = (u * pick_spacing) ** 2 + (a_p + a_e * cosine) ** 2
        return bool(min(pick_gap.min(), end_gap.min()) >= 4.0 * radius**2)

    low = high = 2.0 * radius
    for _ in range(MAX_DOUBLINGS):
        if clears(high):
            break
        low, high = high, 2.0 * high
    else:
        raise PatternError(
            f"yarns {2e6 * radius:.1f} µm thick cannot interlace at {0.01 / end_spacing:.4g} ends/cm × "
            f"{0.01 / pick_spacing:.4g} picks/cm ({end_spacing * 1e6:.1f} µm and {pick_spacing * 1e6:.1f} µm apart): "
            "fewer threads per cm or a lighter fabric"
        )
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (low + high)
        low, high = (low, middle) if clears(middle) else (middle, high)
    separation = HEIGHT_MARGIN * high
    return pick_share * separation, (1.0 - pick_share) * separation


def weave(draft, ends_per_m: float, picks_per_m: float, radius: float, name: str = "weave",
          segments_per_crossing: int = SEGMENTS_PER_CROSSING) -> YarnPattern:
    """Woven repeat of ``draft`` at the given thread counts (1/m) and yarn radius (m)."""
    d = check_draft(draft)
    n_picks, n_ends = d.shape
    for value, what in ((ends_per_m, "ends per metre"), (picks_per_m, "picks per metre"), (radius, "radius")):
        if not (np.isfinite(value) and value > 0):
            raise PatternError(f"{what} must be positive, got {value!r}")
    end_spacing = 1.0 / ends_per_m
    pick_spacing = 1.0 / picks_per_m
    px, py = n_ends * end_spacing, n_picks * pick_spacing
    pick_amplitude, end_amplitude = crossing_separation(radius, end_spacing, pick_spacing)
    # +1 where the end is on top at a crossing.
    warp_up = 2 * d - 1
    s = segments_per_crossing
    yarns = []
    for i in range(n_picks):
        # Pick i runs along x through the crossings with ends 0..n-1 (at x = (j + ½) spacing).
        x = (np.arange(n_ends * s) / s + 0.5) * end_spacing
        z = _profile(-pick_amplitude * warp_up[i], s)
        y = np.full_like(x, (i + 0.5) * pick_spacing)
        yarns.append((np.column_stack([x, y, z]), (1, 0)))
    for j in range(n_ends):
        y = (np.arange(n_picks * s) / s + 0.5) * pick_spacing
        z = _profile(end_amplitude * warp_up[:, j], s)
        x = np.full_like(y, (j + 0.5) * end_spacing)
        yarns.append((np.column_stack([x, y, z]), (0, 1)))
    return YarnPattern.from_yarns(name, "woven", (px, py), radius, yarns)
