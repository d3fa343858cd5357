"""One sample of any family (:func:`solve_sample`) and the ranges the fibre bears."""

from __future__ import annotations

import time

import numpy as np

from ..engine import QuasiStaticOptions
from ..relax import RelaxedRepeat
from ..samples import SampleRanges, SampleResult, SampleSpec
from .bend import _solve_bend
from .bias import _solve_bias
from .equilibrium import MAX_ITERATIONS, _solve_with_continuation
from .uniaxial import _solve_uniaxial


def solve_sample(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions | None = None) -> SampleResult:
    """Tile ``relaxed`` on the sample's surface and minimise the yarn energy under ``C_RVE``.

    A uniaxial-tension sample also minimises over its free strains: the transverse stretch μ along
    a yarn axis (:func:`_solve_uniaxial`), and on the bias the transverse strain and the pull
    frame's shear (:func:`_solve_bias`); its result's spec carries the form found. A bending
    sample is solved at zero membrane force, its three membrane strains free (:func:`_solve_bend`:
    the paper's ``I = Id`` pulls the yarns of a bend's stretched side straight)."""
    start = time.perf_counter()
    options = options or QuasiStaticOptions(max_iterations=MAX_ITERATIONS)
    if spec.family.uniaxial_axis is not None:
        return _solve_uniaxial(relaxed, spec, options, start)
    if spec.family.uniaxial_angle is not None:
        return _solve_bias(relaxed, spec, options, start)
    if not spec.is_membrane:
        return _solve_bend(relaxed, spec, options, start)
    tiled, result, iterations = _solve_with_continuation(relaxed, spec.I, spec.II, options)
    if result is None:
        # No solve of this deformation stayed within the mapped tiles: nothing to report but that.
        return SampleResult.unsolved(spec, iterations, time.perf_counter() - start, tiled.state.node_position)
    return SampleResult.of_solve(spec, result, tiled.area, result.converged, iterations, time.perf_counter() - start)


# -- sample ranges --------------------------------------------------------------------------------

# Largest curvature times repeat size (rad): keeps the saddles' Gauss defect (~κ² p² / 16 of
# strain at the repeat's corners) small. Measured on cotton twill, a saddle's Ū/κ² grows by 4 %
# from 0.05 to 0.2 rad per repeat and by 10 % to 0.4 rad; single and dome bends by under 2 %.
MAX_TURN_PER_REPEAT = 0.25



def default_ranges(relaxed: RelaxedRepeat) -> SampleRanges:
    """What the fibre can bear: stretch up to its breaking strain, curvature up to the one that
    strains a yarn's surface fibres to breaking (``ε_max / r``), and no more than
    MAX_TURN_PER_REPEAT across one repeat; compression as :class:`~yarnfit.samples.SampleRanges`
    defaults it (the stretch range, at most ``samples.COMPRESSION_LIMIT``)."""
    strain = relaxed.fiber.breaking_strain
    curvature = min(strain / relaxed.radius, MAX_TURN_PER_REPEAT / float(max(relaxed.repeat_size)))
    return SampleRanges(stretch=strain, curvature=curvature)


def _expected_cost(spec: SampleSpec) -> tuple:
    """Sort key of a sample's expected solve time (larger first): uniaxial searches, then membrane
    samples by strain, then bends by curvature."""
    strain = float(np.abs(spec.I - np.eye(2)).max())
    return (spec.family.uniaxial_angle is not None, float(np.abs(spec.II).max()) == 0.0, strain,
            float(np.abs(spec.II).max()))
