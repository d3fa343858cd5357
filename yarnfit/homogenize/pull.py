"""The periodic pull: the infinite fabric pulled along weft, warp or the bias with every other
stress free (a uniaxial sample), and its force per reference width: the yarn-level reference a cut
strip converges to as it widens, and that the fitted shell should follow."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..checks import positive_number
from ..engine import QuasiStaticOptions, Residual
from ..relax import RelaxedRepeat
from ..samples import Family, SampleSpec
from .sample import solve_sample

# A periodic pull's direction (PeriodicPull.direction) and the uniaxial family it is a sample of.
PULL_FAMILIES = {"weft": Family.WEFT_UNIAXIAL, "warp": Family.WARP_UNIAXIAL, "bias": Family.BIAS_UNIAXIAL,
                 "other bias": Family.NEGATIVE_BIAS_UNIAXIAL}


@dataclass(frozen=True)
class PeriodicPull:
    """The periodic fabric pulled along weft, warp or the bias with every other stress free: what
    a uniaxial-tension sample gives a tensile test (:func:`periodic_pull`,
    :func:`periodic_bias_pull`).

    Attributes:
        direction: ``"weft"``, ``"warp"``, ``"bias"`` (45° from weft) or ``"other bias"`` (−45°).
        strain: the pull's engineering strain λ − 1.
        force_n_per_m: force per reference width, dŪ/dλ (N/m).
        width_ratio: the distance between the strip's long edges (which stay lines along the
            pull) over the reference width, ``√det I / λ``: the free transverse stretch μ along
            weft or warp.
        converged: the sample converged (its solve and the free-strain search).
        residual: the solve's residuals at the result.
        iterations: Newton iterations over every trial of the search.
        seconds: wall time (s).
        form: ``(2, 2)`` the first form found (the pull and its free strains); ``None`` where
            nothing converged.
        energy_density: Ū (J/m²) of the yarns at the result (NaN where nothing converged).
        friction_work: work the friction at the yarn contacts dissipated on the way (J/m² of
            reference area; 0 without friction): a pull with friction
            (:func:`~yarnfit.homogenize.frictional_periodic_pull`) has done ``Ū − Ū(rest) +
            friction_work`` of work on the fabric.
    """

    direction: str
    strain: float
    force_n_per_m: float
    width_ratio: float
    converged: bool
    residual: Residual
    iterations: int
    seconds: float
    form: np.ndarray | None = None
    energy_density: float = math.nan
    friction_work: float = 0.0


def periodic_pull(relaxed: RelaxedRepeat, axis: int, strain: float,
                  options: QuasiStaticOptions | None = None) -> PeriodicPull:
    """The infinite fabric of ``relaxed`` pulled to the engineering ``strain`` (λ − 1) along
    ``axis`` (0 weft, 1 warp) with the other direction free: the uniaxial-tension sample
    (:func:`_solve_uniaxial`) and its force per reference width ``dŪ/dλ = λ dŪ/dE`` (N/m), ``λ``
    times the sample's ``pull_slope``. The yarn-level reference a cut strip converges to as it
    widens, and that the fitted shell's :meth:`~yarnfit.shell.ShellMaterial.uniaxial_pull` should
    follow. Warns :class:`~yarnfit.engine.ConvergenceWarning` when the sample does not converge."""
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (weft) or 1 (warp), got {axis!r}")
    return _periodic_pull(relaxed, ("weft", "warp")[axis], strain, options)


def _periodic_pull(relaxed: RelaxedRepeat, direction: str, strain: float,
                   options: QuasiStaticOptions | None) -> PeriodicPull:
    """:class:`PeriodicPull` ``direction`` (a key of :data:`PULL_FAMILIES`): its uniaxial family's
    sample at ``strain`` (:func:`solve_sample`), force ``λ`` times its ``pull_slope``; width the
    free transverse stretch along a yarn axis, ``√det I / λ`` off it."""
    family = PULL_FAMILIES[direction]
    strain = positive_number(strain, "strain")
    start = time.perf_counter()
    sample = solve_sample(relaxed, SampleSpec.at(family, strain), options)
    stretch = 1.0 + strain
    if not math.isfinite(sample.pull_slope):
        width = math.nan
    elif family.uniaxial_axis is not None:
        width = math.sqrt(sample.I[1 - family.uniaxial_axis, 1 - family.uniaxial_axis])
    else:
        width = math.sqrt(float(np.linalg.det(sample.I))) / stretch
    return PeriodicPull(direction, strain, stretch * sample.pull_slope, width, sample.converged, sample.residual,
                        sample.iterations, time.perf_counter() - start,
                        sample.spec.I if math.isfinite(sample.pull_slope) else None, sample.energy_density)


def periodic_bias_pull(relaxed: RelaxedRepeat, strain: float,
                       options: QuasiStaticOptions | None = None, other: bool = False) -> PeriodicPull:
    """The infinite fabric of ``relaxed`` pulled to the engineering ``strain`` (λ − 1) on the bias
    (45° from weft; ``other``: the other bias, −45°, direction ``"other bias"``) with every other
    stress free: the bias uniaxial sample (:func:`_solve_bias`: the transverse strain and the pull
    frame's shear both free) and its force per reference width ``λ dŪ/de`` (N/m), ``e`` the pull's
    Green strain, ``λ`` times the sample's ``pull_slope``. The reference a cut bias strip
    converges to as it widens. Warns :class:`~yarnfit.engine.ConvergenceWarning` when the search
    does not converge."""
    return _periodic_pull(relaxed, "other bias" if other else "bias", strain, options)
