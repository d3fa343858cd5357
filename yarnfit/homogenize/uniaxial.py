"""Uniaxial tension along weft or warp: the free transverse Green strain E⊥ where Ū is least,
found by secants on the envelope-theorem slope dŪ/dE⊥, each trial a warm-started solve. Its
stopping criteria are the bias search's too (:mod:`.bias`)."""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..engine import ConvergenceWarning, QuasiStaticOptions, QuasiStaticResult, Residual, RodModel
from ..engine.contact import TilingReachError
from ..relax import RelaxedRepeat
from ..samples import SampleResult, SampleSpec, stretch_share
from .equilibrium import _axis_change, _green_slope, _solve_from
from .surface import TiledRepeat, tile_repeat


# Tolerance on the free Green strain E⊥ = (μ² − 1)/2: Ū is flat at its minimum, so an error δ
# costs about ½ k δ² with k the pure transverse stiffness (~1e5 J/m² for the presets): 1e-4 leaves
# ~5e-4 J/m², a few percent of the smallest uniaxial Ū measured (jersey at 1 %: 3e-2 J/m²) and far
# less at the larger strains the fit weighs most.
FREE_STRAIN_TOLERANCE = 1e-4
# Search interval of E⊥ in units of the prescribed strain E: knits contract by up to ~1.5 times
# their stretch at small strain (measured on cotton jersey); 3 leaves room; μ stays ≥ 0.5.
FREE_STRAIN_RANGE = 3.0
SMALLEST_FREE_STRETCH = 0.5
# First trial of E⊥ / E when the pure stretch's slope gives no curvature yet: a woven's Poisson
# ratio (0.2–0.3); the secants take it from there.
FREE_STRAIN_GUESS = -0.3
# Solves per uniaxial sample at most; the secants on the slope typically need 2–6. With
# fibre-assembly yarns a jersey's minimum can sit at a kink (its wales jam) and warm starts land on
# a neighbouring branch of equilibria, which a search approaches at bisection's pace: wool jersey,
# course-wise at 15 %, took 27 solves of the parabolas this search replaced.
FREE_STRAIN_SOLVES = 40
# A trial E⊥ whose solve fails from the nearest equilibrium is approached by solving halfway first,
# at most this many times nested (each halving is one more point the search can use).
FREE_STRAIN_HALVINGS = 3
# Inside a bracket the search stops when the decrease of Ū the least slope still promises,
# s² / (2 k), is below this relative to Ū *and* that slope is below FREE_SLOPE_RTOL of the pure
# stretch's (or the root is within FREE_STRAIN_TOLERANCE). Ū alone is too flat about its minimum
# to place E⊥ (satin at 5 %: ½ k δ² ≈ 1e-3 Ū for δ = 0.009, ±10 % on the Poisson ratio), and the
# slope alone is fooled by a jersey's slack side (slope 0.2 % of the pure stretch's, Ū 8 % above
# the least). Points whose Ū lies within this of the least found count as one equilibrium, and
# the result is the one of least slope among them: warm-started solves of a knit land in nearby
# equilibria whose Ū differ by ~1e-4, while a point further above is on another branch
# (polyester jersey, wale-wise at 5 %: slope 0.03 J/m² at a Ū 2.2e-3 above the least found).
SEARCH_ENERGY_RTOL = 1e-3
# The transverse stress left at the result, as a fraction of the pure stretch's (the slope at
# E⊥ = 0): where the slope is near linear this puts E⊥ within 1 % of its root, the Poisson ratio
# to ~1 %.
FREE_SLOPE_RTOL = 0.01
# A slope this small against Ū over the whole search interval means Ū does not depend on E⊥
# (nothing resists the transverse direction, as between straight parallel yarns): round-off of
# the energy sum (1e-16 × the number of terms) over the slope's step, with a wide margin.
FLAT_ENERGY_RTOL = 1e-6
# Shortest step of an unbracketed search: ten tolerances, past a minimum its secant step has
# all but reached, so that the slope changes sign there.
FREE_STRAIN_PROBE = 10.0 * FREE_STRAIN_TOLERANCE
# A minimum at the interval's lower end counts as a plateau if Ū would fall by less than this
# (relative) towards its neighbour: the energy has stopped changing with E⊥ to the accuracy the
# fit can use.
PLATEAU_RTOL = 1e-3


@dataclass(frozen=True)
class _FreeStrainPoint:
    """One converged solve of a uniaxial search: E⊥, Ū (J/m²) and dŪ/dE⊥ (J/m²)."""

    free: float
    energy: float
    slope: float


def _transverse_slope(model: RodModel, result, axis: int, free: float, area: float) -> float:
    """dŪ/dE⊥ (J/m²) of a sample pulled along ``axis`` at the free Green strain E⊥ = ``free``
    (:func:`_green_slope` across the pull; the form's pulled entry does not enter: it is diagonal)."""
    form = np.eye(2)
    form[1 - axis, 1 - axis] = 1.0 + 2.0 * free
    return _green_slope(model, result, form, _axis_change(1 - axis), area)


def _next_free_strain(points: Sequence[_FreeStrainPoint], low: float, strain: float) -> tuple[float | None, str]:
    """The next E⊥ a uniaxial search should solve, from its converged ``points`` (E⊥ in
    ``[low, 0]``, prescribed Green strain ``strain``), or ``None`` with the search's verdict:

    - ``"minimum"``: within a bracket, the point of least slope ``s`` promises a decrease of Ū
      (``s² / 2k``, ``k`` the smaller positive secant curvature with its neighbours) below
      :data:`SEARCH_ENERGY_RTOL` and ``|s|`` is below :data:`FREE_SLOPE_RTOL` of the pure
      stretch's, or the slope's root lies within :data:`FREE_STRAIN_TOLERANCE` of it (``|s| / k``),
      or the bracket is narrower than that; or Ū does not depend on E⊥;
    - ``"upper end"``: the slope at E⊥ = 0 is not positive (the fabric would widen; the interval
      stops at 0);
    - ``"plateau"`` / ``"lower end"``: every slope is positive down to ``low``, and Ū there has
      (has not) stopped changing.

    ``points`` come in the order they were solved. A bracket (a negative slope left of a positive
    one) is narrowed by the secant step from the point of least slope (its curvature the smaller
    neighbour secant) when that lands inside the bracket, else by the secant through the bracket's
    ends as the Illinois variant of regula falsi takes it: an end kept while k ≥ 2 later points
    were solved enters with its slope halved k − 1 times (a jersey's slope, steep where its wales
    jam and flat beyond, otherwise moved one end by 5e-4 at a time). Without one the search
    steps towards where the slope points by the secant curvature of its two outermost points (by
    :data:`FREE_STRAIN_GUESS` from the pure stretch alone), at least :data:`FREE_STRAIN_PROBE`
    and, once a secant step has fallen short, at least as far as its last: a jersey's slope falls
    steeply while its wales jam and then tails off slowly, and secant steps on that tail crept
    (cotton jersey at 2 %: six steps of 5e-4 to 3e-3 towards a minimum 5e-3 away). It stops only
    with a bracket: a secant across a kink gives the jammed side's curvature, which would promise
    nothing where much is left."""
    order = {id(p): i for i, p in enumerate(points)}
    points = sorted(points, key=lambda p: p.free)
    closest = min(points, key=lambda p: abs(p.slope))
    span = max(-low, FREE_STRAIN_TOLERANCE)
    if abs(closest.slope) * span <= FLAT_ENERGY_RTOL * max(abs(closest.energy), np.finfo(float).tiny):
        return None, "minimum"
    top = points[-1]
    if top.free == 0.0 and top.slope <= 0.0:
        return None, "upper end"

    # Curvature at the point of least slope: the smaller secant with its neighbours (a secant
    # across a jersey's kink is the jammed side's, far stiffer than the slack side it stops on).
    i = points.index(closest)
    neighbours = [(points[j], points[j + 1]) for j in (i - 1, i) if 0 <= j < len(points) - 1]
    secants = [k for k in ((b.slope - a.slope) / (b.free - a.free) for a, b in neighbours) if k > 0.0]
    near_root = bool(secants) and abs(closest.slope) / min(secants) <= FREE_STRAIN_TOLERANCE
    pure = max((abs(p.slope) for p in points if p.free == 0.0), default=max(abs(p.slope) for p in points))
    settled = (bool(secants) and closest.slope**2 / (2.0 * min(secants)) <= SEARCH_ENERGY_RTOL * abs(closest.energy)
               and abs(closest.slope) <= FREE_SLOPE_RTOL * pure)

    rising = [p for p in points if p.slope > 0.0]
    right = rising[0] if rising else None
    left = next((p for p in reversed(points) if p.slope < 0.0 and (right is None or p.free < right.free)), None)
    if left is not None and right is not None:
        width = right.free - left.free
        if width <= FREE_STRAIN_TOLERANCE or near_root or settled:
            return None, "minimum"
        margin = min(0.1 * width, 0.5 * FREE_STRAIN_TOLERANCE)
        # The secant step from the point of least slope first (converges fast once near the
        # root, whatever the bracket's far end looks like: polyester jersey's bracket end beyond
        # a kink, slope −65 against ±0.05 near the root, made regula falsi creep by 5e-5 a
        # solve), if it lands inside the bracket.
        if secants:
            trial = closest.free - closest.slope / min(secants)
            if left.free + margin <= trial <= right.free - margin:
                return trial, "search"
        older = min(left, right, key=lambda p: order[id(p)])
        kept = len(order) - 1 - order[id(older)]
        slopes = [p.slope * (0.5 ** (kept - 1) if p is older and kept >= 2 else 1.0) for p in (left, right)]
        trial = left.free - slopes[0] * width / (slopes[1] - slopes[0])
        return min(max(trial, left.free + margin), right.free - margin), "search"
    # Unbracketed: every slope points the same way.
    outer, inner = (points[0], points[1:2]) if left is None else (points[-1], points[-2:-1])
    if left is None and outer.free <= low:
        falls = outer.slope * (inner[0].free - outer.free) if inner else math.inf
        return None, "plateau" if falls <= PLATEAU_RTOL * abs(outer.energy) else "lower end"
    if not inner:
        return min(max(FREE_STRAIN_GUESS * strain, low), 0.0), "search"
    inner = inner[0]
    last = outer.free - inner.free
    curvature = (inner.slope - outer.slope) / (inner.free - outer.free)
    step = -outer.slope / curvature if curvature > 0.0 else 2.0 * last
    # Not a minimum until the slope has changed sign: the curvature an unbracketed secant gives
    # can be the other side of a kink's, and promise nothing where much is left.
    shortest = abs(last) if len(points) >= 3 else FREE_STRAIN_PROBE
    step = math.copysign(max(abs(step), shortest), last)
    return min(max(outer.free + step, low), 0.0), "search"


@dataclass(frozen=True)
class _UniaxialSearch:
    """Outcome of :func:`_search_uniaxial`: the free Green strain E⊥ chosen, the solve there (its
    quasi-static result, ``None`` if none was usable) on ``tiled``, the Newton iterations of every
    trial, why it did not converge (``None`` if it did), and Ū's slope dŪ/dE⊥ at the E⊥ chosen
    (J/m²; ~0 at a minimum, the slope where the search stopped at an end of its interval; NaN
    without a converged solve there)."""

    free: float
    form: np.ndarray
    result: QuasiStaticResult | None
    tiled: TiledRepeat
    iterations: int
    failure: str | None
    free_slope: float = math.nan


def _search_uniaxial(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions) -> _UniaxialSearch:
    """Find the free transverse Green strain E⊥ where Ū is least, each trial a full solve started
    from the nearest solved E⊥'s equilibrium stretched across (exact for its affine part, and it
    keeps C_RVE's values, which are linear in the positions), each solve giving Ū's slope
    dŪ/dE⊥ too (:func:`_transverse_slope`), and the trials chosen by :func:`_next_free_strain`.
    Not converged if the solve at the result did not converge, the search ran out of solves, or
    E⊥ ends at the interval's lower end still falling (the fabric would contract further)."""
    axis = spec.family.uniaxial_axis
    stretch = math.sqrt(float(spec.I[axis, axis]))
    strain = 0.5 * (stretch**2 - 1.0)
    low = max(0.5 * (SMALLEST_FREE_STRETCH**2 - 1.0), -FREE_STRAIN_RANGE * strain)
    solved: dict[float, tuple] = {}  # E⊥ -> (quasi-static result, tiled repeat, point or None if unusable)
    iterations = 0

    def form(free: float) -> np.ndarray:
        diagonal = [0.0, 0.0]
        diagonal[axis], diagonal[1 - axis] = stretch**2, 1.0 + 2.0 * free
        return np.diag(diagonal)

    def usable(e: float) -> bool:
        return solved[e][2] is not None

    def nearest_usable(free: float) -> float | None:
        warm = [e for e in solved if usable(e)]
        return min(warm, key=lambda e: abs(e - free)) if warm else None

    def solve_at(free: float) -> tuple:
        nonlocal iterations
        nearest = nearest_usable(free)
        previous = None if nearest is None else (solved[nearest][0].state, form(nearest))
        try:
            # A trial E⊥ that does not converge is a point the search does without (or approaches
            # by halves); the warning below gives the sample's verdict.
            tiled, result = _solve_from(relaxed, form(free), spec.II, options, previous)
            iterations += result.iterations
        except TilingReachError:
            # The solver's steps ran beyond the tiles mapped (a strongly squeezed width): this
            # E⊥ is unusable, and the search treats it as a wall. (The pure stretch, solved
            # first, fails as any pure sample would.)
            if not solved:
                raise
            tiled, result = tile_repeat(relaxed, form(free), spec.II), None
        point = None
        if result is not None and result.converged:
            point = _FreeStrainPoint(free, result.energy.internal / tiled.area,
                                     _transverse_slope(tiled.model, result, axis, free, tiled.area))
        return result, tiled, point

    def solve(free: float, depth: int = 0) -> None:
        outcome = solve_at(free)
        nearest = nearest_usable(free)
        if outcome[2] is None and nearest is not None and depth < FREE_STRAIN_HALVINGS:
            # Too far from the nearest equilibrium for one solve (soft yarns: a jersey's width
            # contracting by a third): solve halfway first, then again from there.
            halfway = 0.5 * (nearest + free)
            if abs(halfway - nearest) > FREE_STRAIN_TOLERANCE and halfway not in solved:
                solve(halfway, depth + 1)
                if usable(halfway):
                    outcome = solve_at(free)
        solved[free] = outcome

    solve(0.0)  # the pure stretch first: every later start is near it
    verdict = "search"
    for _ in range(FREE_STRAIN_SOLVES):
        points = [solved[e][2] for e in solved if usable(e)]
        if points:
            trial, verdict = _next_free_strain(points, low, strain)
        else:
            trial, verdict = (FREE_STRAIN_GUESS * strain, "search") if len(solved) == 1 else (None, "failed")
        if trial is None:
            break
        if trial in solved:
            # A trial that failed before: approach it from the nearest equilibrium instead.
            nearest = nearest_usable(trial)
            if nearest is None or abs(trial - nearest) <= FREE_STRAIN_TOLERANCE:
                verdict = "failed"
                break
            trial = 0.5 * (trial + nearest)
        solve(trial)
    else:
        verdict = "out of solves"
    points = [solved[e][2] for e in solved if usable(e)]
    if not points:
        free = next(iter(solved))
    elif verdict in ("upper end", "plateau", "lower end"):
        free = max(p.free for p in points) if verdict == "upper end" else min(p.free for p in points)
    else:
        least = min(p.energy for p in points)
        free = min((p for p in points if p.energy <= least + SEARCH_ENERGY_RTOL * abs(least)),
                   key=lambda p: abs(p.slope)).free
    result, tiled, _ = solved[free]
    converged = verdict in ("minimum", "upper end", "plateau")
    failure = None if converged else {
        "lower end": "the free strain reached the search interval's end with Ū still falling",
        "out of solves": "the search ran out of solves",
        "failed": "the solves near the best free strain did not converge"}[verdict]
    point = solved[free][2]
    return _UniaxialSearch(free, form(free), result, tiled, iterations, failure,
                           point.slope if point is not None else math.nan)


def _solve_uniaxial(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions, start: float) -> SampleResult:
    """A uniaxial-tension sample (:func:`_search_uniaxial`): its spec carries the free strain found,
    its ``pull_slope`` the derivative of Ū in the pull's Green strain at that width
    (:func:`_green_slope`; the free strain is at Ū's minimum, so its own change adds nothing) and
    its ``across_slope`` the search's slope across the pull there."""
    search = _search_uniaxial(relaxed, spec, options)
    result, area = search.result, search.tiled.area
    if search.failure is not None:
        warnings.warn(f"uniaxial sample {spec.family} {spec.parameter:+.3g} did not converge: {search.failure} "
                      f"(E⊥ = {search.free:.4g}, {search.iterations} iterations)"
                      + ("" if result is None else f": {result.residual}"), ConvergenceWarning, stacklevel=3)
    converged = search.failure is None
    form = SampleSpec(spec.family, search.form, spec.II, spec.parameter)
    slope = math.nan
    if result is not None:
        axis = spec.family.uniaxial_axis
        slope = _green_slope(search.tiled.model, result, form.I, _axis_change(axis), area)
    return SampleResult(
        spec=form,
        energy_density=result.energy.internal / area if result is not None else math.nan,
        converged=converged,
        residual=result.residual if result is not None else Residual(math.nan, math.nan, math.nan, math.nan),
        iterations=search.iterations,
        seconds=time.perf_counter() - start,
        position=result.state.node_position if result is not None else None,
        stretch_share=stretch_share(result.energy) if result is not None else math.nan,
        pull_slope=slope,
        across_slope=search.free_slope,
    )
