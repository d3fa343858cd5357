"""A bending sample at zero membrane force: its second form prescribed, its three membrane Green
strains free, found where Ū is least by the quasi-Newton of :mod:`.search` on envelope-theorem
slopes taken on the curved tiling (:func:`~.equilibrium._surface_green_slope`).

The paper samples a bend at ``I = Id``: the tiling's reference surface, the mean height of the
repeat's nodes, keeps its length. A fabric is stiff in tension and gives way in compression (a
knit's loops nest, a woven's crimp deepens), so bent about that surface it pulls the yarns of its
stretched side straight, and which side that is depends on the bend's sign and the structure's
asymmetry: cotton jersey's weft bend at ∓325 /m cost 19.8 and 0.032 J/m² (docs/design.md §6). The
shell has no membrane–bending coupling, so the bending it needs is the fabric's where nothing pulls
it in its plane, as in a drape, a cantilever or a KES bending test: Ū least over the membrane
strains. Freeing only the strain along the curvature (the neutral surface's offset) is not enough:
wool jersey's wales shorten by ~1 % as its courses bend, and a twill's bend shears it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..engine import QuasiStaticOptions, QuasiStaticResult
from ..relax import RelaxedRepeat
from ..samples import SMALLEST_CURVATURE, SampleResult, SampleSpec
from .equilibrium import _solve_near, _solve_with_continuation, _surface_green_slope
from .search import Trial, probe_hessian, promised_decrease, quasi_newton, warn_unconverged
from .surface import CarriedEquilibrium, TiledRepeat
from .uniaxial import FLAT_ENERGY_RTOL, FREE_SLOPE_RTOL, FREE_STRAIN_SOLVES, SEARCH_ENERGY_RTOL, SMALLEST_FREE_STRETCH


# The free strains' natural size is the bend's strain across the fabric's thickness, |κ| times
# its reach (:func:`fabric_reach`): a neutral surface lies within the fabric. (At least the
# smallest sampled curvature's: the unbent repeat's free strains, the rest state the bends are
# measured from, are of the smallest bend's size.) Measured answers
# (session 42, Nelder–Mead): wool jersey at -42.3 /m shortened its wales by 0.9 % (|κ| reach
# 2.3 %), the twill at 32.3 /m sheared 0.4 %. The search's probes are a tenth of it, as the bias
# pull's are of its pull; its steps at most all of it; the step at which the free strains count
# as found 1e-4 of it, as the bias pull's 1e-7 is of its 1e-3 smallest pull.
BEND_PROBE_FRACTION = 0.1
BEND_STEP_LIMIT_FRACTION = 1.0
BEND_STEP_TOLERANCE_FRACTION = 1e-4
# The free strains are held within this many times the bend's strain scale. A neutral surface lies
# within the fabric, so the strain along the curvature is within one scale; what the others do is
# set by the fabric's membrane stiffness, which bounds them in any real fabric (the answers measured
# lie within one scale: the stockinette's weft bend at 16.6 /m 0.96, the others 0.4 or less), but
# not in a mechanism: straight yarns that do not touch, bent on the
# bias, relieve their twist by shearing the sheet without end (Ū fell 1.81 -> 1.30 J/m² as E01 went
# to -0.2 at -125 /m). A bend ending at the bound bounds the free bend's Ū from above.
BEND_STRAIN_BOUND_FRACTION = 2.0
# A bend's least Ū can sit at a kink, where its Newton model never settles: a jersey's wales go
# slack on one side (cotton jersey's weft bend at +47.3 /m: dŪ/dE11 -7.7e-5 on one side of it,
# +6e-4 on the other, J/m²), and the search then takes step after step that lowers Ū by round-off
# (26 more solves moved Ū by 6e-5 of itself); or in a direction Ū hardly depends on (the satin at
# 1 /m: 14 solves moved its shear strain back and forth, Ū by 1e-4 of itself). It counts as found
# when the last this many accepted steps lowered Ū by less than SEARCH_ENERGY_RTOL of it.
BEND_SETTLED_STEPS = 3
# The free strains: (E00, E11, E01), each slope along E + h change (dŪ/dE01 for the off-diagonal).
_CHANGES = (np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 0.0], [0.0, 1.0]]),
            np.array([[0.0, 1.0], [1.0, 0.0]]))


def fabric_reach(relaxed: RelaxedRepeat) -> float:
    """The farthest a yarn's surface lies from the tiling's reference surface, the mean height of
    the repeat's nodes (:func:`~yarnfit.homogenize.tile_repeat`) (m)."""
    height = relaxed.state.node_position[:, 2]
    return float(np.abs(height - height.mean()).max() + relaxed.radius)


def membrane_form(free: np.ndarray) -> np.ndarray:
    """``I = Id + 2 E`` ``(2, 2)`` of the free Green strains ``(E00, E11, E01)``."""
    return np.eye(2) + 2.0 * np.array([[free[0], free[2]], [free[2], free[1]]])


@dataclass(frozen=True)
class _BendSearch:
    """Outcome of :func:`_search_bend`: the free strains ``(E00, E11, E01)`` found, their solve
    (``None`` if none converged) and tiling, the Newton iterations of every trial, why it did not
    converge (``None`` if it did), Ū's slopes there (J/m²), the solves it took, and what the next
    bend of a path starts from (:class:`_BendStart`; ``None`` if it did not converge)."""

    free: np.ndarray
    result: QuasiStaticResult | None
    tiled: TiledRepeat | None
    iterations: int
    failure: str | None
    slopes: np.ndarray
    solves: int
    onward: _BendStart | None = None


@dataclass(frozen=True)
class _BendStart:
    """Where a bend of a path starts (:func:`_solve_bend_path`): the previous bend's second form
    ``II``, free strains, equilibrium and tiling, the search's Hessian of Ū in the free strains
    (J/m²) and the slopes' scale it measured its convergence by (J/m²)."""

    II: np.ndarray
    free: np.ndarray
    tiled: TiledRepeat
    result: QuasiStaticResult
    hessian: np.ndarray
    slope_scale: float


def _search_bend(relaxed: RelaxedRepeat, II: np.ndarray, options: QuasiStaticOptions,
                 start: _BendStart | None = None) -> _BendSearch:
    """``relaxed`` bent to ``II`` ``(2, 2)`` (1/m) with its membrane strains where Ū is least:
    from the paper's ``I = Id``, a Hessian from three probe solves (:data:`BEND_PROBE_FRACTION`
    of the bend's strain scale each) and :func:`~.search.quasi_newton`, each trial warm-started
    from the nearest trial's equilibrium, its fluctuation carried over. Stops at the first trial
    whose slopes are spent by the bias pull's test (below :data:`FREE_SLOPE_RTOL` of ``I = Id``'s,
    with the decrease they promise below :data:`SEARCH_ENERGY_RTOL` of Ū, or Ū flat in them),
    asked before every step, or when Ū has settled (:data:`BEND_SETTLED_STEPS`).

    From a ``start`` (the previous, gentler bend of the same family and sign) the first trial is
    its free strains scaled by the ratio of the curvatures, warm-started from its equilibrium, and
    the search goes on with its Hessian and slope scale instead of probing afresh; from ``I = Id``
    as above if that trial does not converge."""
    curvature = float(np.abs(np.linalg.eigvalsh(II)).max())
    scale = max(curvature, SMALLEST_CURVATURE) * fabric_reach(relaxed)
    bound = np.full(3, BEND_STRAIN_BOUND_FRACTION * scale)
    least_free = 0.5 * (SMALLEST_FREE_STRETCH**2 - 1.0)
    solved: list[Trial] = []
    iterations = 0

    def admissible(free: np.ndarray) -> bool:
        return bool(free[0] >= least_free and free[1] >= least_free and np.linalg.det(membrane_form(free)) > 0.0)

    def solve_at(free: np.ndarray, near: tuple[TiledRepeat, QuasiStaticResult] | None = None) -> Trial | None:
        nonlocal iterations
        form = membrane_form(free)
        if solved and near is None:
            nearest = min(solved, key=lambda point: float(np.abs(point.free - free).max()))
            near = (nearest.tiled, nearest.result)
        if near is not None:
            tiled, result = _solve_near(relaxed, form, II, options, near)
            iterations += 0 if result is None else result.iterations
        else:
            tiled, result, count = _solve_with_continuation(relaxed, form, II, options)
            iterations += count
        if result is None or not result.converged:
            return None
        carried = CarriedEquilibrium(relaxed, tiled, result.state, result.contacts.pairs)
        slopes = np.array([_surface_green_slope(carried, result, form, change) for change in _CHANGES])
        point = Trial(np.array(free, dtype=np.float64), result, tiled, result.energy.internal / tiled.area, slopes)
        solved.append(point)
        return point

    current = None
    if start is not None:
        ratio = curvature / float(np.abs(np.linalg.eigvalsh(start.II)).max())
        guess = np.clip(ratio * start.free, -bound, bound)
        if admissible(guess):
            current = solve_at(guess, (start.tiled, start.result))
    if current is not None:
        hessian, slope_scale = start.hessian, ratio * start.slope_scale
    else:
        current = solve_at(np.zeros(3))  # the paper's sample
        if current is None:
            return _BendSearch(np.zeros(3), None, None, iterations, "the bend at I = Id did not converge",
                               np.full(3, math.nan), len(solved))
        slope_scale = float(np.abs(current.slopes).max())
        probed = probe_hessian(solve_at, admissible, current, np.full(3, BEND_PROBE_FRACTION * scale))
        if probed is None:
            return _BendSearch(current.free, current.result, current.tiled, iterations,
                               "a probe of the membrane strains did not converge", current.slopes, len(solved))
        hessian, probes = probed
        current = min([current] + probes, key=lambda point: point.energy)
    start_energy = solved[0].energy
    step_limit = BEND_STEP_LIMIT_FRACTION * scale
    # The yarns' own bending energy at this curvature (J/m²; at least the smallest sampled one, for
    # the unbent reference): their length per area bent to it.
    yarn_energy = (0.5 * relaxed.yarn.bending_rigidity_nm2 * max(curvature, SMALLEST_CURVATURE)**2
                   * float(relaxed.model.edge_rest_length.sum()) / float(np.prod(relaxed.repeat_size)))

    def balanced(point: Trial, w: np.ndarray, v: np.ndarray) -> bool:
        """The slopes spent: below FREE_SLOPE_RTOL of the start's with the decrease they promise
        below SEARCH_ENERGY_RTOL of Ū; or Ū flat in them (FLAT_ENERGY_RTOL, as the bias search);
        or a mechanism: what a limit-long step could still gain is below SEARCH_ENERGY_RTOL of the
        yarns' own bending energy (a jersey bent wale-wise one way: its loops nest, Ū ~1e-9 J/m²
        against 4e-4 for its yarns, round-off the quasi-Newton cannot descend; the unbent
        reference of a solid-yarn jersey 1.5 times as thick ended so, its Ū as settled as the
        solver's round-off lets it)."""
        slope = float(np.abs(point.slopes).max())
        return (slope <= FREE_SLOPE_RTOL * slope_scale
                and promised_decrease(point, w, v) <= SEARCH_ENERGY_RTOL * abs(point.energy)
                or slope * step_limit <= FLAT_ENERGY_RTOL * abs(start_energy)
                or slope * step_limit <= SEARCH_ENERGY_RTOL * yarn_energy)

    def settled(accepted: list[Trial]) -> bool:
        """Ū settled (BEND_SETTLED_STEPS), or already below SEARCH_ENERGY_RTOL of the yarns' own
        bending energy (a mechanism, as ``balanced`` says)."""
        if abs(accepted[-1].energy) <= SEARCH_ENERGY_RTOL * yarn_energy:
            return True
        if len(accepted) <= BEND_SETTLED_STEPS:
            return False
        fallen = accepted[-1 - BEND_SETTLED_STEPS].energy - accepted[-1].energy
        return fallen <= SEARCH_ENERGY_RTOL * abs(accepted[-1].energy)

    current, failure, hessian = quasi_newton(solve_at, admissible, current, hessian, lambda: len(solved),
                                             FREE_STRAIN_SOLVES, step_limit, BEND_STEP_TOLERANCE_FRACTION * scale,
                                             balanced, settled, bound, interpolate=True, balanced_ends=True)
    onward = None if failure is not None else _BendStart(II, current.free, current.tiled, current.result, hessian,
                                                         slope_scale)
    return _BendSearch(current.free, current.result, current.tiled, iterations, failure, current.slopes, len(solved),
                       onward)


def _solve_bend(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions, start: float) -> SampleResult:
    """A bending sample at zero membrane force (:func:`_search_bend`): Ū where it is least over
    the membrane strains, which the result carries (``free_membrane_strain``); its spec keeps
    ``I = Id``, as the shell it is fitted to has no membrane–bending coupling."""
    return _bend_result(spec, _search_bend(relaxed, spec.II, options), start)


def _solve_bend_path(relaxed: RelaxedRepeat, specs: Sequence[SampleSpec], options: QuasiStaticOptions) -> list[SampleResult]:
    """Bending samples of one family and sign in order of growing curvature, each search started
    from the previous one's answer (:func:`_search_bend`'s ``start``): its free strains scaled,
    its equilibrium and its Hessian. A bend whose search did not converge leaves the next to start
    afresh."""
    results, onward = [], None
    for spec in specs:
        start = time.perf_counter()
        search = _search_bend(relaxed, spec.II, options, onward)
        results.append(_bend_result(spec, search, start))
        onward = search.onward
    return results


def _bend_result(spec: SampleSpec, search: _BendSearch, start: float) -> SampleResult:
    """The sample's result of its search (warned of when it did not converge); ``start`` its
    wall-clock start (s, :func:`time.perf_counter`)."""
    warn_unconverged(f"bending sample {spec.family} {spec.parameter:+.3g}", search.failure, search.result, 4)
    result = search.result
    if result is None:
        return SampleResult.unsolved(spec, search.iterations, time.perf_counter() - start)
    return SampleResult.of_solve(spec, result, search.tiled.area, search.failure is None, search.iterations,
                                 time.perf_counter() - start, free_membrane_strain=tuple(float(e) for e in search.free))
