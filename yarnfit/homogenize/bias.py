"""Uniaxial tension off the yarn axes (the bias): two free strains of the pull's frame, the
transverse strain and the frame's shear, found by a two-strain Newton on the envelope-theorem
slopes."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..engine import QuasiStaticOptions, QuasiStaticResult
from ..engine.contact import TilingReachError
from ..engine.contact_lagrangian import ContactSet
from ..engine.energy import internal_forces
from ..engine.friction import FrictionAnchors
from ..relax import RelaxedRepeat
from ..samples import SampleResult, SampleSpec
from .equilibrium import _green_slope, _solve_from, _solve_with_continuation
from .search import Trial, probe_hessian, promised_decrease, quasi_newton, warn_unconverged
from .surface import TiledRepeat, _form_map, tile_repeat
from .uniaxial import FLAT_ENERGY_RTOL, FREE_SLOPE_RTOL, FREE_STRAIN_SOLVES, SEARCH_ENERGY_RTOL, SMALLEST_FREE_STRETCH


# A bias pull's search (:func:`_search_bias`): the pull's direction from weft (rad), and the
# largest step of its free strains per trial (Green strain): a Newton step from the pure stretch
# can promise a contraction the solver cannot reach from there in one solve.
BIAS_ANGLE = math.pi / 4
BIAS_STEP_LIMIT = 0.05
# ... and the Newton step (H⁻¹ times the slopes) below which the free strains count as found. Far
# tighter than the axis search's FREE_STRAIN_TOLERANCE: on the bias the pull's own stress is small
# against its coupling to the free strains (the plain weave at 1 %: ~0.3 N/m of force against
# ~4e4 N/m per unit of the transverse strain), so an error of 1e-5 in them moves the force by more
# than itself. Newton's last steps cost one solve each.
BIAS_STEP_TOLERANCE = 1e-7
# The probes that give the search its first Hessian, as a fraction of the pull's Green strain: the
# free strains' answer is of the pull's size (0.16–1.4 of it over the presets and the stockinette),
# and Ū is far from quadratic beyond it. The stockinette at 0.1 % probed with a fixed 1e-3 (six
# times its answer) met its loops jamming there, slopes 100x the start's; the Hessian from that
# sent the first step 50x too far and the search took 19 solves (497 Newton iterations, 2.8 s)
# where probes of a tenth of the pull take 10 (121).
BIAS_PROBE_FRACTION = 0.1


@dataclass(frozen=True)
class _BiasSearch:
    """Outcome of :func:`_search_bias`: the free Green strains ``(f, g)`` of the pull's frame
    chosen (across the pull, and the frame's shear), the first form there, its solve on ``tiled``
    (``None`` if none converged), the Newton iterations of every trial, why it did not converge
    (``None`` if it did), and Ū's slopes along ``f`` and ``g`` there (J/m²)."""

    free: np.ndarray
    form: np.ndarray
    result: QuasiStaticResult | None
    tiled: TiledRepeat | None
    iterations: int
    failure: str | None
    slopes: np.ndarray
    anchors: FrictionAnchors | None = None


def _search_bias(relaxed: RelaxedRepeat, strain: float, options: QuasiStaticOptions,
                 angle: float = BIAS_ANGLE, start: tuple | None = None,
                 friction: tuple[FrictionAnchors, np.ndarray] | None = None,
                 contacts: ContactSet | None = None) -> _BiasSearch:
    """The periodic repeat pulled to the engineering ``strain`` at ``angle`` from weft with every
    other stress free: in the pull's frame ``q`` the Green strain is ``[[e, g], [g, f]]``, ``e``
    prescribed and ``(f, g)`` where Ū is least. Off the yarn axes the two couple (a fabric pulled
    on the bias contracts and shears its own frame), so the search is a two-strain Newton on the
    envelope-theorem slopes (:func:`_green_slope` along ``q e_1 e_1ᵀ qᵀ`` and ``q (e_0 e_1ᵀ + e_1
    e_0ᵀ) qᵀ``), its Hessian from two probe solves and secant (BFGS) updates, steps at most
    :data:`BIAS_STEP_LIMIT` and halved until Ū or the slopes fall, each trial warm-started from
    the nearest equilibrium mapped by ``√I' √I⁻¹`` (which keeps C_RVE's values: they are linear in
    the positions). It starts from the pure stretch along the pull and stops when the Newton step
    is below :data:`BIAS_STEP_TOLERANCE`, or when no step lowers Ū any more and the slopes are below
    :data:`FREE_SLOPE_RTOL` of the pure stretch's with the decrease of Ū they promise below
    :data:`SEARCH_ENERGY_RTOL` of Ū, or at the least Ū solved where two contact states meet
    (:func:`~.search.kink_minimum`, within :data:`SEARCH_ENERGY_RTOL` of Ū); not converged
    otherwise or after :data:`FREE_STRAIN_SOLVES`.

    A frictional load step's pass (:mod:`.frictional`) starts instead from ``start = (free (2,),
    state, its first form)``, an equilibrium of the path warm-started at those free strains, and
    minimises Ū plus the friction potential of ``friction = (anchors, the form their maps are
    at)``, the anchors following each trial's tiling, each solve starting from ``contacts``'
    multipliers; its scales are then the probes' slopes over a change of the free strains of the
    pull's size and the affine pure stretch's Ū."""
    c, s = math.cos(angle), math.sin(angle)
    q = np.array([[c, -s], [s, c]])
    pulled = 0.5 * ((1.0 + strain) ** 2 - 1.0)
    changes = (q @ np.diag([0.0, 1.0]) @ q.T, q @ np.array([[0.0, 1.0], [1.0, 0.0]]) @ q.T)
    flat = np.zeros((2, 2))
    least_free = 0.5 * (SMALLEST_FREE_STRETCH**2 - 1.0)
    iterations = 0
    solved: list[Trial] = []

    def form(free: np.ndarray) -> np.ndarray:
        return np.eye(2) + 2.0 * q @ np.array([[pulled, free[1]], [free[1], free[0]]]) @ q.T

    def admissible(free: np.ndarray) -> bool:
        first = form(free)
        return bool(free[0] >= least_free and first[0, 0] > 0.0 and np.linalg.det(first) > 0.0)

    def solve_at(free: np.ndarray):
        nonlocal iterations
        first = form(free)
        anchors, solve_args = None, {}
        if friction is not None:
            anchors = friction[0].transformed(_form_map(first, friction[1]))
            solve_args = {"friction": anchors, "contacts": contacts}
        if not solved and start is None:
            tiled, result, count = _solve_with_continuation(relaxed, first, flat, options)
            iterations += count
        else:
            if solved:
                nearest = min(solved, key=lambda point: float(np.abs(point.free - free).max()))
                warm = (nearest.result.state, form(nearest.free))
            else:
                warm = (start[1], start[2])
            try:
                tiled, result = _solve_from(relaxed, first, flat, options, warm, **solve_args)
                iterations += result.iterations
            except TilingReachError:
                return None
        if result is None or not result.converged:
            return None
        slopes = np.array([_green_slope(tiled.model, result, first, change, tiled.area, anchors)
                           for change in changes])
        slip = 0.0 if anchors is None else anchors.energy_gradient(result.state.node_position)[0]
        point = Trial(np.array(free, dtype=np.float64), result, tiled, (result.energy.internal + slip) / tiled.area,
                      slopes, anchors)
        solved.append(point)
        return point

    origin = np.zeros(2) if start is None else np.asarray(start[0], dtype=np.float64)
    current = solve_at(origin)  # the pure stretch along the pull, or the path's start
    if current is None:
        return _BiasSearch(origin, form(origin), None, None, iterations,
                           "the pure stretch along the pull did not converge" if start is None else
                           "the path's start did not converge", np.full(2, math.nan))
    scale, start_energy = float(np.abs(current.slopes).max()), current.energy
    if start is not None:
        # Started on the path, the start's slopes and Ū are nearly balanced already: the energy's
        # scale is the affine pure stretch's Ū instead (an upper bound of the solved pure
        # stretch's, which the search from rest takes; no solve needed), the slopes' below.
        affine = tile_repeat(relaxed, form(np.zeros(2)), flat)
        rods = internal_forces(affine.model, affine.state.node_position, affine.state.edge_quaternion).terms
        start_energy = max(abs(start_energy), sum(rods) / affine.area)
    # The Hessian from two probes of the slopes from the pure stretch, one per free strain,
    # towards where each points, BIAS_PROBE_FRACTION of the pull's strain long.
    probed = probe_hessian(solve_at, admissible, current, np.full(2, BIAS_PROBE_FRACTION * pulled))
    if probed is None:
        return _BiasSearch(current.free, form(current.free), current.result, current.tiled, iterations,
                           "a probe of the free strains did not converge", current.slopes)
    hessian, probes = probed
    if start is not None:
        # The slopes' scale on the path: what the probes' slopes grow to over a change of the free
        # strains as large as the pull's, as the pure stretch's are off its free strains by about
        # that much.
        scale = max([scale] + [float(np.abs(point.slopes).max()) / BIAS_PROBE_FRACTION for point in probes])
    for point in probes:
        if point.energy < current.energy:
            current = point

    def balanced(point: Trial, w: np.ndarray, v: np.ndarray) -> bool:
        """Both slopes below FREE_SLOPE_RTOL of the pure stretch's, and the decrease of Ū they
        still promise below SEARCH_ENERGY_RTOL of Ū, as the axis search asks: a knit's free minimum
        can lie far below its jammed pure stretch (wool jersey at 2 %: Ū 0.03 against 2.0 J/m²),
        where slopes of 1 % of the pure stretch's still move Ū by a tenth."""
        slope = float(np.abs(point.slopes).max())
        # Or Ū does not depend on the free strains at all (straight parallel yarns on the bias: a
        # line of minima at Ū = 0 to round-off), as FLAT_ENERGY_RTOL says for the axis search.
        return (slope <= FREE_SLOPE_RTOL * scale and promised_decrease(point, w, v) <= SEARCH_ENERGY_RTOL * abs(point.energy)
                or slope * BIAS_STEP_LIMIT <= FLAT_ENERGY_RTOL * abs(start_energy))

    current, failure, _ = quasi_newton(solve_at, admissible, current, hessian, lambda: len(solved), FREE_STRAIN_SOLVES,
                                       BIAS_STEP_LIMIT, BIAS_STEP_TOLERANCE, balanced,
                                       kink_energy_rtol=SEARCH_ENERGY_RTOL)
    return _BiasSearch(current.free, form(current.free), current.result, current.tiled, iterations, failure, current.slopes,
                       current.anchors)


def _solve_bias(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions, start: float) -> SampleResult:
    """A uniaxial-tension sample off the yarn axes (:func:`_search_bias` at the family's angle):
    its spec carries the form found, its ``pull_slope`` dŪ/de along the pull (:func:`_green_slope`)
    and its ``across_slope`` the search's slope along the transverse strain (the pull frame's
    shear is free too: its slope is ~0 where the search converged)."""
    angle = spec.family.uniaxial_angle
    search = _search_bias(relaxed, spec.parameter, options, angle)
    warn_unconverged(f"uniaxial sample {spec.family} {spec.parameter:+.3g}", search.failure, search.result, 3)
    result = search.result
    if result is None:
        return SampleResult.unsolved(spec, search.iterations, time.perf_counter() - start)
    direction = np.array([math.cos(angle), math.sin(angle)])
    area = search.tiled.area
    return SampleResult.of_solve(
        SampleSpec(spec.family, search.form, spec.II, spec.parameter), result, area, search.failure is None,
        search.iterations, time.perf_counter() - start,
        pull_slope=_green_slope(search.tiled.model, result, search.form, np.outer(direction, direction), area),
        across_slope=float(search.slopes[0]))
