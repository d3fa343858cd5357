"""A bending sample about its own neutral surface: the membrane strain along each principal
curvature free, as in a drape, a cantilever or a KES bending test, where nothing pulls the fabric
in its plane.

The paper samples a bend at ``I = Id``: the tiling's reference surface, the mean height of the
repeat's nodes, keeps its length. A fabric is stiff in tension and gives way in compression (a
knit's loops nest, a woven's crimp deepens), so bent about that surface it pulls the yarns on its
stretched side straight, and which side that is depends on the bend's sign and the structure's
asymmetry: cotton jersey's weft bend at ±325 /m cost 19.8 and 0.032 J/m², the twill's warp bend
5.2 and 0.18, the satin's weft bend 0.56 and 0.063 (docs/design.md §3, session 42). Freed, each
bend finds the surface about which its yarns balance, its neutral surface: cotton jersey's −325
/m weft bend then costs 0.33 J/m², the satin's ±175 /m weft bends 0.026 and 0.029. The shell has
no membrane–bending coupling, so its bending stiffness is the fabric's at zero membrane force,
which is this.

The free strain is that of a parallel surface: for principal curvatures ``κ_k`` along ``n_k``
the first form is ``I = (Id − Σ_k z_k κ_k n_k n_kᵀ)²``, ``z_k`` the neutral surface's offset
along the normal as seen by the curvature ``κ_k``; a single or bias bend has one offset, a saddle
two (the weft and warp neutral surfaces of a knit differ). The offsets are found where Ū is least,
each trial solve warm-started from the nearest offsets' equilibrium: one offset by a bounded
scalar minimisation (Brent's, scipy), a saddle's two by Nelder–Mead, within the fabric: ``|z_k|
<=`` the farthest a yarn's surface lies from the reference surface. An offset at that bound (a
flat valley, or Ū still falling) is kept and reported (:func:`at_reach`).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from ..engine import ConvergenceWarning, QuasiStaticOptions, QuasiStaticResult, Residual
from ..relax import RelaxedRepeat
from ..samples import SampleResult, SampleSpec, stretch_share
from .equilibrium import _solve_near, _solve_with_continuation
from .surface import TiledRepeat

# The offsets' accuracy, as a fraction of the fabric's reach (the bound on |z|). Ū is quadratic
# about its minimum in the offset, with the stiffer side's membrane tangent A: an error δz costs
# ~½ A (δz κ)², which for the straight-yarn sheet (A = EA/d, bending EI/d, reach ~r) is 4 (δz/r)²
# of the bending energy: 4e-6 at 1e-3 of the reach, far below the 1 % its closed form is held to.
# On cotton jersey's single bends 1e-2 moved Ū by up to 9e-4, 3e-2 by 3e-3.
NEUTRAL_OFFSET_TOLERANCE = 1e-3
# A saddle's two offsets (Nelder–Mead) to this fraction of the reach, and until the simplex's
# energies agree within NEUTRAL_ENERGY_RTOL of the saddle's Ū at the reference surface: on
# cotton jersey's saddles 1e-2 of the reach gave the Ū of 1e-3 to 3e-5 in 25 % fewer solves
# (the simplex shrinks onto a valley whose floor is flat to that).
SADDLE_OFFSET_TOLERANCE = 1e-2
NEUTRAL_ENERGY_RTOL = 1e-4
# Principal curvatures below this (1/m) carry no offset (a cylinder's axis).
FLAT_CURVATURE = 1e-12
# What the minimiser sees of an offset whose solve did not converge (J/m²): above any Ū.
FAILED_ENERGY = 1e300


@dataclass(frozen=True)
class _Neutral:
    """One solve at offsets ``z`` (m, one per bent principal direction): its first form, tiling,
    result (None if it did not converge) and Ū (J/m², inf if it did not converge)."""

    z: tuple[float, ...]
    form: np.ndarray
    tiled: TiledRepeat
    result: QuasiStaticResult | None
    energy: float


def fabric_reach(relaxed: RelaxedRepeat) -> float:
    """The farthest a yarn's surface lies from the tiling's reference surface, the mean height of
    the repeat's nodes (:func:`~yarnfit.homogenize.tile_repeat`) (m): the bound on a neutral
    surface's offset."""
    height = relaxed.state.node_position[:, 2]
    return float(np.abs(height - height.mean()).max() + relaxed.radius)


def at_reach(sample: SampleResult, reach: float) -> bool:
    """Whether a bending sample's neutral surface ended at the fabric's ``reach`` (m,
    :func:`fabric_reach`): its Ū is an upper bound of the free bend's."""
    return any(abs(o) >= (1.0 - 2.0 * NEUTRAL_OFFSET_TOLERANCE) * reach for o in sample.neutral_offset
               if not math.isnan(o))


def _solve_bend(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions, start: float) -> SampleResult:
    """A bending sample about its neutral surface (see the module docstring): Ū at the offsets
    where it is least within the fabric's reach; not converged when no solve converged."""
    curvatures, directions = np.linalg.eigh(spec.II)
    bent = [k for k in range(2) if abs(curvatures[k]) > FLAT_CURVATURE]
    reach = fabric_reach(relaxed)
    tolerance = NEUTRAL_OFFSET_TOLERANCE * reach
    solved: dict[tuple[float, ...], _Neutral] = {}
    iterations = 0

    def solve(z: tuple[float, ...]) -> _Neutral:
        nonlocal iterations
        if z in solved:
            return solved[z]
        shift = np.eye(2)
        for offset, k in zip(z, bent):
            shift -= offset * curvatures[k] * np.outer(directions[:, k], directions[:, k])
        form = shift @ shift
        result = None
        if solved:
            # From the nearest offsets' equilibrium: the fluctuation changes little with the
            # offset, and a warm start takes a tenth of the affine start's iterations.
            near = min((p for p in solved.values() if p.result is not None),
                       key=lambda p: max(abs(a - b) for a, b in zip(p.z, z)), default=None)
            if near is not None:
                tiled, result = _solve_near(relaxed, form, spec.II, options, (near.tiled, near.result))
                iterations += 0 if result is None else result.iterations
        if result is None or not result.converged:
            tiled, result, count = _solve_with_continuation(relaxed, form, spec.II, options)
            iterations += count
        converged = result is not None and result.converged
        point = _Neutral(z, form, tiled, result, result.energy.internal / tiled.area if converged else math.inf)
        solved[z] = point
        return point

    def energy(offsets) -> float:
        # The minimisers need finite values: a solve that failed counts as far uphill.
        offsets = np.clip(np.atleast_1d(offsets), -reach, reach)
        value = solve(tuple(float(o) for o in offsets)).energy
        return value if math.isfinite(value) else FAILED_ENERGY

    if len(bent) == 1:
        minimize_scalar(energy, bounds=(-reach, reach), method="bounded", options={"xatol": tolerance})
    else:
        # A saddle's two offsets are coupled (yarns cross both curvatures; one at a time, in turn,
        # they crept towards the minimum over many sweeps: cotton jersey's −47 /m saddle stopped
        # 26 % above it): Nelder–Mead from the reference surface, its simplex a quarter of the
        # reach wide.
        reference = solve((0.0, 0.0)).energy
        scale = abs(reference) if math.isfinite(reference) else 1.0
        minimize(energy, np.zeros(2), method="Nelder-Mead",
                 options={"initial_simplex": np.vstack([np.zeros(2), 0.25 * reach * np.eye(2)]),
                          "xatol": SADDLE_OFFSET_TOLERANCE * reach, "fatol": NEUTRAL_ENERGY_RTOL * scale})
    best = min(solved.values(), key=lambda p: p.energy)
    failure = None
    if best.result is None:
        failure = "no solve about any offset of the neutral surface converged"
    # An offset at the fabric's reach is kept, as the sample's result says (``neutral_offset``;
    # ``yarnfit fit`` counts them): Ū there bounds the free bend from above, where Ū is flat out
    # to the reach (a mechanism: a jersey's loops nest and wale compression costs nothing) or
    # still falls (the relaxed repeat's own residual stress released by compressing it), and is
    # far below the reference surface's (cotton jersey of solid yarns, warp bend +47 /m).
    if failure is not None:
        warnings.warn(f"bending sample {spec.family} {spec.parameter:+.3g} did not converge: {failure}",
                      ConvergenceWarning, stacklevel=3)
    result = best.result
    if result is None:
        return SampleResult(spec=spec, energy_density=math.nan, converged=False,
                            residual=Residual(math.nan, math.nan, math.nan, math.nan), iterations=iterations,
                            seconds=time.perf_counter() - start)
    offsets = [math.nan, math.nan]
    for offset, k in zip(best.z, bent):
        offsets[k] = offset
    return SampleResult(
        spec=spec,
        energy_density=best.energy,
        converged=failure is None,
        residual=result.residual,
        iterations=iterations,
        seconds=time.perf_counter() - start,
        position=result.state.node_position,
        stretch_share=stretch_share(result.energy),
        neutral_offset=tuple(offsets),
    )
