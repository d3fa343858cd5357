"""Membrane samples along frictional load paths: what a tensile or shear test of the yarn-level
fabric measures on loading, for a shell fitted to the fabric's loading response.

The paper's samples are frictionless minimisers: Ū(I, II) is the least yarn energy at each
deformation. A cut strip, and a real fabric in a tensile tester, is loaded with the fibre's
friction at the crossings, which holds loops that a frictionless path lets trade yarn: the
periodic pull with friction is 1.3–1.9 times the frictionless one on the jerseys and is what
their frictional strips tend to as they widen (docs/design.md §3, session 41). Here each membrane
family is loaded from rest along its ray, as its pull would be, in lagged frictional load steps
of at most :data:`~yarnfit.engine.lagged.FRICTION_STRAIN_STEP` (:mod:`.frictional`), one path per
family and sign for all its magnitudes, and each sample's "energy" is the work done on the repeat
along the path, ``W = Ū + D``: the yarns' energy at the sample plus the work ``D`` the friction
dissipated on the way (each step's friction potential at its end: its anchors beyond their slip
length pull μ N along their slip), which without friction is the frictionless sample's Ū
exactly. ``W`` is the potential of a hyperelastic model that loads as the fabric does (a
deformation theory: one path per ray, so ``W`` is a function of the deformation). A uniaxial
family's path is the frictional pull (:func:`~yarnfit.homogenize.frictional_periodic_pull`), its
samples' ``pull_slope`` the pull's ``dW/dE`` and their form the free strains found.

Bends stay frictionless minimisers: a curved tiling's maps turn, which lagged anchors do not
follow (:meth:`~yarnfit.engine.friction.FrictionAnchors.transformed`).

What it cannot represent: unloading (a fabric's hysteresis; the shell is elastic), and the path
dependence of a deformation reached other than along its ray.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from typing import Sequence

import numpy as np

from ..engine import ConvergenceWarning, QuasiStaticOptions
from ..engine.contact import TilingReachError
from ..engine.lagged import FRICTION_STRAIN_STEP, in_halves
from ..relax import RelaxedRepeat
from ..samples import OTHER_BIAS_FAMILIES, Family, Group, SampleResult, SampleSpec, stretch_share
from .equilibrium import MAX_ITERATIONS, _solve_from
from .frictional import (_frictional_step, _Pass, _rest, _Step, _Trial, frictional_periodic_bias_pull,
                         frictional_periodic_pull)
from .surface import _form_map

__all__ = ["loading_path_samples"]

# Two magnitudes of a path count as the same sample when closer than this (a sample's parameter
# is also a step's end; round-off of the grid).
PARAMETER_MATCH = 1e-12


def _path_grid(magnitudes: Sequence[float], strain_step: float) -> list[float]:
    """The steps' ends of a path through ``magnitudes`` (> 0): every multiple of ``strain_step``
    below the largest and the magnitudes themselves, ascending (no step longer than
    ``strain_step``)."""
    top = max(magnitudes)
    grid = {float(v) for v in np.arange(strain_step, top, strain_step)} | {float(v) for v in magnitudes}
    merged = []
    for value in sorted(grid):
        if merged and value - merged[-1] <= PARAMETER_MATCH:
            continue
        merged.append(value)
    return merged


def loading_path_samples(relaxed: RelaxedRepeat, family: Family, parameters: Sequence[float], coefficient: float,
                         options: QuasiStaticOptions | None = None,
                         strain_step: float = FRICTION_STRAIN_STEP) -> list[SampleResult]:
    """The membrane ``family``'s samples at ``parameters`` (all of one sign), loaded from rest
    along one frictional path with friction ``coefficient`` μ (see the module docstring), in the
    order given. ``energy_density`` is the work ``W`` done along the path (J/m²); a sample is
    converged when every step since the last sample's solved and settled its normal forces."""
    family = Family.named(family)
    if family.group is not Group.MEMBRANE:
        raise ValueError(f"{family} is not a membrane family: bends are sampled frictionless")
    parameters = [float(p) for p in parameters]
    if not parameters or any(not math.isfinite(p) or p == 0.0 for p in parameters):
        raise ValueError(f"parameters must be finite and non-zero, got {parameters!r}")
    sign = math.copysign(1.0, parameters[0])
    if any(math.copysign(1.0, p) != sign for p in parameters):
        raise ValueError(f"a path's parameters share one sign, got {parameters!r}")
    options = options or QuasiStaticOptions(max_iterations=MAX_ITERATIONS)
    magnitudes = sorted({abs(p) for p in parameters})
    grid = _path_grid(magnitudes, strain_step)
    with warnings.catch_warnings():
        # A step's own warning is not the verdict: each sample carries its segment's, warned below.
        warnings.simplefilter("ignore", ConvergenceWarning)
        if family.uniaxial_angle is not None:
            samples = _uniaxial_path(relaxed, family, grid, coefficient, options, strain_step)
        else:
            samples = _fixed_path(relaxed, family, sign, grid, coefficient, options)
    # A sample carries the verdict of its own segment of the path: every step since the last
    # sample's (a step that did not converge or settle between two samples leaves the later one's
    # path off, though its own solves converged). A path whose own step at a sample failed too has
    # stopped: the fabric does not bear that deformation (cotton jersey's weft compression jams at
    # 7.1 %, docs/design.md §6; "tension and compression where the fabric bears it", issue 14), so
    # the sample is taken at the last step of its segment reached with every step converged, and
    # says so (SampleResult.design_parameter).
    by_magnitude, segment, borne = {}, True, None
    # How far the path got with every step converged, which says more than a failed step's residuals.
    reached, unbroken = 0.0, True
    for magnitude, sample in zip(grid, samples):
        unbroken &= sample.converged
        reached = magnitude if unbroken else reached
        segment &= sample.converged
        if segment:
            borne = (magnitude, sample)
        if any(abs(magnitude - m) <= PARAMETER_MATCH for m in magnitudes):
            if not sample.converged and borne is not None and borne[0] < magnitude:
                by_magnitude[magnitude] = borne
            else:
                by_magnitude[magnitude] = (magnitude, replace(sample, converged=segment))
            segment, borne = True, None
    out = []
    for p in parameters:
        match = min(by_magnitude, key=lambda m: abs(m - abs(p)))
        magnitude, sample = by_magnitude[match]
        if magnitude != match:
            out.append(replace(sample, spec=SampleSpec(family, sample.spec.I, sample.spec.II, sign * magnitude),
                               design_parameter=p))
            warnings.warn(f"loading path {family} {p:+.3g} did not converge beyond {sign * magnitude:+.3g}: sampled "
                          f"there, the largest {family} the fabric bore on its path", ConvergenceWarning,
                          stacklevel=2)
            continue
        out.append(replace(sample, spec=SampleSpec(family, sample.spec.I, sample.spec.II, p)))
        if not sample.converged:
            warnings.warn(f"loading path {family} {p:+.3g} did not converge: a step since the last sample's did not "
                          f"solve or settle its normal forces ({sample.residual}); every step converged up to "
                          f"{sign * reached:+.3g}", ConvergenceWarning, stacklevel=2)
    return out


def _fixed_path(relaxed: RelaxedRepeat, family: Family, sign: float, grid: Sequence[float], coefficient: float,
                options: QuasiStaticOptions) -> list[SampleResult]:
    """One sample per step of ``grid`` (magnitudes) of a family without free strains: each a
    lagged frictional step at the family's form (:func:`_frictional_step`, one solve a pass), taken
    in halves when it does not converge or settle (:func:`~yarnfit.engine.lagged.in_halves`), its
    work the yarns' energy there plus the friction's dissipation so far. A step that fails even so
    ends the path: it is not converged and the larger ones are unsolved."""
    flat = np.zeros((2, 2))
    state = _rest(relaxed, options)
    dissipated, samples, previous = 0.0, [], 0.0

    def lagged_step(start: _Trial, low: float, magnitude: float) -> _Step:
        """The lagged step from ``start`` (the path's state at ``low``) to the load ``magnitude``."""
        form = family.deformation(sign * magnitude)[0]

        def solve_pass(anchors, anchor_form, warm, contacts, guess, probe) -> _Pass:
            mapped = anchors.transformed(_form_map(form, anchor_form))
            try:
                tiled, result = _solve_from(relaxed, form, flat, options, (warm.result.state, warm.form),
                                            friction=mapped, contacts=contacts)
            except TilingReachError:
                return _Pass(_Trial(0.0, form, None, None, mapped, None), 0, "failed")
            return _Pass(_Trial(0.0, form, tiled, result, mapped, None), result.iterations,
                         "minimum" if result.converged else "failed")

        return _frictional_step(solve_pass, start, coefficient, 0.0, 0.0)

    def dissipation(step) -> float:
        return step.trial.anchors.energy_gradient(step.trial.result.state.node_position)[0] / step.trial.tiled.area

    for reached, magnitude in enumerate(grid):
        clock = time.perf_counter()
        form = family.deformation(sign * magnitude)[0]
        path, tried = in_halves(lagged_step, _Step.accepted, _Step.end, state, previous, magnitude)
        step, iterations, previous = path[-1], sum(s.iterations for s in tried), magnitude
        trial, result = step.trial, step.trial.result
        if result is None:
            # Its solves left the tiles mapped (a jam's yarns pushed past one another under
            # compression: the cotton jersey pattern's in one of validate.paper's other fibres):
            # the path ends, this sample and every larger one unsolved, not the whole fit.
            samples.append(SampleResult.unsolved(SampleSpec(family, form, flat, sign * magnitude), iterations,
                                                 time.perf_counter() - clock))
            samples += [SampleResult.unsolved(SampleSpec.at(family, sign * m), 0, 0.0) for m in grid[reached + 1:]]
            break
        dissipated += sum(dissipation(s) for s in path)
        state = trial
        converged = step.accepted()
        samples.append(SampleResult(
            spec=SampleSpec(family, form, flat, sign * magnitude),
            energy_density=result.energy.internal / trial.tiled.area + dissipated,
            converged=converged, residual=result.residual, iterations=iterations,
            seconds=time.perf_counter() - clock, position=result.state.node_position,
            stretch_share=stretch_share(result.energy)))
        if not converged:
            # Not even its halves converged and settled: the path has stopped (cotton jersey's
            # compression jams at 7.1 %). A step from this state would start from no equilibrium
            # of the path (its solves then "converged" at -10 % with yarns pushed through one
            # another), so the larger steps are left unsolved.
            samples += [SampleResult.unsolved(SampleSpec.at(family, sign * m), 0, 0.0) for m in grid[reached + 1:]]
            break
    return samples


def _uniaxial_path(relaxed: RelaxedRepeat, family: Family, grid: Sequence[float], coefficient: float,
                   options: QuasiStaticOptions, strain_step: float) -> list[SampleResult]:
    """One sample per step of ``grid`` (strains) of a uniaxial family: the frictional pull's
    (:func:`frictional_periodic_pull`), its work the yarns' energy plus the pull's friction work,
    its ``pull_slope`` the pull's force over λ (``dW/dE`` along the pull: the free strains' slopes
    vanish at each pass's minimum)."""
    flat = np.zeros((2, 2))
    if family.uniaxial_axis is not None:
        pulls = frictional_periodic_pull(relaxed, family.uniaxial_axis, grid, coefficient, options, strain_step)
    else:
        pulls = frictional_periodic_bias_pull(relaxed, grid, coefficient, options, strain_step,
                                              other=family in OTHER_BIAS_FAMILIES)
    return [SampleResult(
        spec=SampleSpec(family, pull.form if pull.form is not None else np.full((2, 2), math.nan), flat, pull.strain),
        energy_density=pull.energy_density + pull.friction_work, converged=pull.converged, residual=pull.residual,
        iterations=pull.iterations, seconds=pull.seconds, pull_slope=pull.force_n_per_m / (1.0 + pull.strain),
        across_slope=0.0) for pull in pulls]
