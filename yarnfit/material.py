"""A fabric's shell material end to end: relax the repeat, homogenize the samples, fit the shell,
and write the material file.

``fit_fabric(fabric)`` runs the three stages (:mod:`yarnfit.relax`, :mod:`yarnfit.homogenize`,
:mod:`yarnfit.fit`) and returns a :class:`FabricFit`; ``FabricFit.write(path)`` writes the material
file, JSON in SI units with stable keys:

- ``yarnfit_version``;
- ``inputs``: ``fabric`` (name), ``fiber`` (name, density_kg_m3, young_min_pa, young_max_pa,
  breaking_strain, poisson, friction, source, and where known fineness_dtex,
  flexural_rigidity_nm2_per_tex2, torsional_rigidity_nm2_per_tex2, spinning), ``yarn`` (the
  construction as given: model, spinning, packing_fraction, twist_angle_deg and measured
  rigidities, null for defaults), ``pattern`` (named structure or file), ``family``,
  ``counts_per_m`` (``[ends, picks]`` or ``[courses, wales]``, null for a file used as written),
  ``areal_density_kg_m2`` (null likewise);
- ``yarn``: the yarn (:meth:`yarnfit.yarn.Yarn.to_dict`: ``model``, ``spinning``,
  ``linear_density_tex``, ``fibres_per_section``, ``packing_fraction``, ``twist_angle_deg``,
  ``radius_m``, ``tensile_rigidity_n``, ``hardening_n``, ``shear_rigidity_n``,
  ``bending_rigidity_nm2``, ``torsional_rigidity_nm2``, ``bending_vs_solid``, ``limits``), the
  fibre's ``young_modulus_pa`` (E_min), ``hardening_pa``, ``poisson``, ``density_kg_m3``,
  ``friction``, and ``shrink``, ``repeat_size_m``, ``yarn_length_per_area_m_per_m2``,
  ``areal_density_kg_m2`` (of the relaxed repeat) and the relaxation's ``converged``,
  ``iterations``, ``residual`` and ``worst_overlap``;
- ``shell``: ``thickness_m``, ``membrane_pa`` {s00, s01, s11, s22}, ``bending_pa`` {b00, b01,
  b11, b22} (:meth:`yarnfit.shell.ShellMaterial.from_json` reads it back);
- ``engineering``: the constants of ``docs/design.md`` §3 (``weft_stretch_n_per_m``, …);
- ``fit``: the fit's quality (model, parameters and standard errors, R² and relative RMS per
  family, active bounds, weights, used and excluded samples);
- ``samples``: every sample — ``family``, ``parameter``, ``I``, ``II``, ``energy_density_j_m2``,
  ``converged``, ``residual`` {force, torque, penetration, energy_change}, ``iterations``,
  ``seconds`` — including those that did not converge (excluded from the fit, never used).

The shell thickness is the relaxed repeat's: the span of the yarn centrelines across the fabric
plus one diameter. It only scales S and B; the engineering constants do not depend on it.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from . import __version__
from .fabric import Fabric
from .fit import COUPLING_LIMIT, ShellFit, fit_shell
from .homogenize import default_ranges, solve_samples
from .materials import OPTIONAL_FIBER_FIELDS
from .relax import RelaxedRepeat, relax
from .samples import SampleRanges, SampleResult, levels_for, sample_design
from .shell import ShellMaterial

# Two magnitudes per family and sign of deformation, uniaxial tension at the smaller (28 in all):
# enough to see curvature of the response, few enough that a preset fits in about a minute on two
# cores.
DEFAULT_SAMPLES = 28


class UnusableRelaxation(ValueError):
    """The repeat's relaxation did not converge or leaves yarns overlapping: nothing to fit."""


def shell_thickness(relaxed: RelaxedRepeat) -> float:
    """Thickness ``h`` (m) of the relaxed repeat: span of the centrelines normal to the fabric
    plus one yarn diameter."""
    z = relaxed.state.node_position[:, 2]
    return float(z.max() - z.min() + 2.0 * relaxed.radius)


@dataclass(frozen=True, eq=False)
class FabricFit:
    """A fabric fitted end to end.

    Attributes:
        fabric: the input.
        relaxed: the relaxed repeat.
        ranges: the largest sampled stretch and curvature.
        samples: every solved sample, in design order.
        fit: the shell fit (its material has thickness :func:`shell_thickness`).
        seconds: wall time per stage, ``{"relax", "homogenize", "fit"}``.
    """

    fabric: Fabric
    relaxed: RelaxedRepeat
    ranges: SampleRanges
    samples: list[SampleResult]
    fit: ShellFit
    seconds: dict

    @property
    def material(self) -> ShellMaterial:
        return self.fit.material

    def to_dict(self) -> dict:
        """The material file as a JSON-serialisable dict (see the module docstring)."""
        fabric, relaxed, fiber = self.fabric, self.relaxed, self.fabric.fiber
        residual = relaxed.residual
        return {
            "yarnfit_version": __version__,
            "inputs": {
                "fabric": fabric.name,
                "fiber": {
                    "name": fiber.name,
                    "density_kg_m3": fiber.density_kg_m3,
                    "young_min_pa": fiber.young_min_pa,
                    "young_max_pa": fiber.young_max_pa,
                    "breaking_strain": fiber.breaking_strain,
                    "poisson": fiber.poisson,
                    "friction": fiber.friction,
                    "source": fiber.source,
                    **{key: getattr(fiber, key) for key in OPTIONAL_FIBER_FIELDS if getattr(fiber, key) is not None},
                },
                "yarn": fabric.yarn.to_dict(),
                "pattern": fabric.structure if fabric.structure is not None else str(fabric.pattern_file),
                "family": relaxed.pattern.family,
                "counts_per_m": None if fabric.uses_file_as_is else list(_counts(fabric, relaxed)),
                "areal_density_kg_m2": fabric.areal_density,
            },
            "yarn": {
                **relaxed.yarn.to_dict(),
                "young_modulus_pa": fiber.young_min_pa,
                "hardening_pa": fiber.hardening_pa,
                "poisson": fiber.poisson,
                "density_kg_m3": fiber.density_kg_m3,
                "friction": fiber.friction,
                "shrink": relaxed.shrink,
                "repeat_size_m": [float(v) for v in relaxed.repeat_size],
                "yarn_length_per_area_m_per_m2": relaxed.yarn_length_per_area,
                "areal_density_kg_m2": relaxed.areal_density,
                "relaxation": {
                    "converged": relaxed.converged,
                    "iterations": relaxed.iterations,
                    "relaxations": relaxed.relaxations,
                    "residual": {"force": residual.force, "torque": residual.torque,
                                 "energy_change": residual.energy_change, "penetration": residual.penetration},
                    "worst_overlap": relaxed.penetration,
                    "seconds": relaxed.seconds,
                },
            },
            "shell": self.material.to_dict(),
            "engineering": self.material.engineering(),
            "fit": {**self.fit.quality_dict(), "stretch_range": self.ranges.stretch,
                    "curvature_range_per_m": self.ranges.curvature},
            "samples": [s.to_dict() for s in self.samples],
            "seconds": dict(self.seconds),
        }

    def write(self, path: str | os.PathLike) -> Path:
        """Write the material file (directories created); returns its path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")
        return path


def _counts(fabric: Fabric, relaxed: RelaxedRepeat) -> tuple[float, float]:
    return fabric.counts_per_m(relaxed.pattern)


def fit_fabric(
    fabric: Fabric,
    samples: int = DEFAULT_SAMPLES,
    model: str = "full",
    ranges: SampleRanges | None = None,
    workers: int | None = None,
    relaxed: RelaxedRepeat | None = None,
    on_relaxed: Callable[[RelaxedRepeat], None] | None = None,
    progress: Callable[[int, int, SampleResult], None] | None = None,
    relax_progress: Callable | None = None,
    on_relax_start: Callable | None = None,
    coupling_limit: float | None = COUPLING_LIMIT,
) -> FabricFit:
    """Relax ``fabric`` (unless ``relaxed`` is given), solve about ``samples`` samples over
    ``ranges`` (default :func:`yarnfit.homogenize.default_ranges`) on ``workers`` processes, and fit
    the shell (``model`` "full" or "paper"). ``relax_progress`` and ``on_relax_start`` go to
    :func:`yarnfit.relax.relax`; ``on_relaxed(relaxed)`` is called once the repeat is relaxed,
    ``progress(done, total, result)`` after each sample. ``coupling_limit`` bounds the couplings
    (see :func:`yarnfit.fit.fit_shell`; ``None``: unbounded, an indefinite fit raises).

    Raises ``ValueError`` for bad options, :class:`UnusableRelaxation` for a relaxation that did
    not converge or leaves overlaps, :class:`yarnfit.fit.IndefiniteFitError` (only with
    ``coupling_limit=None``) for a fit that is not positive definite, naming the sample family at
    fault.
    """
    levels = levels_for(samples)
    if model not in ("full", "paper"):
        raise ValueError(f"model must be 'full' or 'paper', got {model!r}")
    seconds = {}
    start = time.perf_counter()
    if relaxed is None:
        relaxed = relax(fabric, progress=relax_progress, on_start=on_relax_start)
    seconds["relax"] = time.perf_counter() - start
    if not relaxed.valid:
        raise UnusableRelaxation(f"the relaxation of {fabric.name!r} is not usable: converged {relaxed.converged}, "
                                 f"worst overlap {100 * relaxed.penetration:.3g} % of the diameter ({relaxed.residual})")
    if on_relaxed is not None:
        on_relaxed(relaxed)
    ranges = ranges or default_ranges(relaxed)
    specs = sample_design(ranges, levels)
    start = time.perf_counter()
    results = solve_samples(relaxed, specs, workers=workers, progress=progress)
    seconds["homogenize"] = time.perf_counter() - start
    start = time.perf_counter()
    shell = fit_shell(results, shell_thickness(relaxed), model=model,
                      coupling_limit=coupling_limit)
    seconds["fit"] = time.perf_counter() - start
    return FabricFit(fabric, relaxed, ranges, results, shell, seconds)
