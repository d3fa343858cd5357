"""Sample families, the sample design, and the two sample types every stage shares.

A sample is a constant surface deformation ``(I, II)`` of the fabric (first fundamental form,
dimensionless, SPD; second fundamental form, 1/m, symmetric; the rest surface is flat with
``I = Id``) that the homogenization solves at the yarn level and the shell fit fits. Every sample
belongs to one :class:`Family`; this module is the one place a family is defined: its group
(membrane samples have ``II = 0``, bending samples ``I = Id``), the scalar parameter it varies and
its unit, its ``(I, II)`` at a parameter, the shell parameter it determines, its uniaxial axis
(uniaxial tension with the transverse direction free) and whether the fit needs it.

- :class:`SampleSpec`: what to solve (family, ``I``, ``II``, parameter); checked on construction.
- :class:`SampleResult`: what the solve gave (Ū in J/m², the solver's residuals, iterations, time,
  the final node positions); the fit, the material file and the recording all take it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Callable

import numpy as np

from .checks import real_number
from .engine import Residual
from .jsonfile import finite_or_none
from .shell import as_first_fundamental_form, as_second_fundamental_form

__all__ = [
    "BENDING_FAMILIES",
    "FAMILIES",
    "Family",
    "Group",
    "MEMBRANE_FAMILIES",
    "OPTIONAL_FAMILIES",
    "OTHER_BIAS_FAMILIES",
    "SampleRanges",
    "SampleResult",
    "SampleSpec",
    "UNIAXIAL_FAMILIES",
    "design_size",
    "family_deformation",
    "free_rest_sample",
    "identity_sample",
    "levels_for",
    "magnitudes",
    "sample_design",
    "stretch_share",
    "uniaxial_strains",
]

# Largest accepted |I − Id| entry of a bending sample (dimensionless strain). The homogenizer
# prescribes I = Id; 1e-12 admits round-off in building it (~1e-16) and is far below the smallest
# strain any sample resolves (~1e-4), so the membrane energy it carries (~s·h·1e-24 J/m²) is nil.
PURE_STRAIN_ATOL = 1e-12
# Largest accepted |II| entry of a membrane sample (1/m). For any shell thinner than 1 cm its
# surface strain h|II|/2 stays below 5e-12, the same order as PURE_STRAIN_ATOL.
PURE_CURVATURE_ATOL = 1e-9


class Group(StrEnum):
    """Membrane samples stretch the flat surface (``II = 0``); bending samples bend it without
    stretching (``I = Id``). No shell parameter is shared between the two."""

    MEMBRANE = "membrane"
    BENDING = "bending"


# How a family's parameters are laid out in the design (see :func:`sample_design`).
_TENSION_AND_COMPRESSION = "tension and compression"
_BOTH_SIGNS = "both signs"
_UNIAXIAL_TENSION = "tension up to UNIAXIAL_LARGEST_STRAIN"


def _stretched(axis: int | None):
    def deformation(e: float) -> tuple[np.ndarray, np.ndarray]:
        I = np.eye(2)
        if axis is None:
            I *= (1.0 + e) ** 2  # biaxial: both directions
        else:
            I[axis, axis] = (1.0 + e) ** 2
        return I, np.zeros((2, 2))
    return deformation


def _pulled(angle: float):
    """The pure stretch along ``angle`` (rad from weft): ``I = 1 + 2 q diag(E, 0) qᵀ``."""
    def deformation(e: float) -> tuple[np.ndarray, np.ndarray]:
        direction = np.array([math.cos(angle), math.sin(angle)])
        return np.eye(2) + ((1.0 + e) ** 2 - 1.0) * np.outer(direction, direction), np.zeros((2, 2))
    return deformation


def _sheared(e: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([[1.0, e], [e, 1.0]]), np.zeros((2, 2))


def _bent(shape):
    def deformation(e: float) -> tuple[np.ndarray, np.ndarray]:
        return np.eye(2), shape(e)
    return deformation


class Family(StrEnum):
    """The sample families (paper §4.6, plus saddles for b01 and uniaxial tension). A member is
    its name (a ``str``: it compares equal to ``"weft_stretch"`` and is written as that), with:

    - ``group``: :class:`Group`;
    - ``quantity`` and ``unit``: what the parameter measures (λ − 1 along the stretched direction,
      ``I12`` for shear, the curvature κ in 1/m for bends);
    - ``determines``: the shell parameter whose diagonal or coupling the family pins (``None`` for
      the uniaxial families, which add a tensile test's free width);
    - ``uniaxial_angle``: the direction (rad from weft) of a uniaxial tension with every other
      stress free (weft 0, warp π/2, bias π/4, the other bias −π/4; the solve finds the free
      strains, the spec holds the pure stretch along the pull as the search's start), else
      ``None``; ``uniaxial_axis``: 0
      (weft) or 1 (warp) for those along a yarn axis (one free strain, the transverse stretch μ),
      else ``None``;
    - ``optional``: the fit does without it (the pure families determine every parameter);
    - ``layout``: which parameter values the design samples;
    - :meth:`deformation`: ``(I, II)`` at a parameter value.
    """

    def __new__(cls, name, group, quantity, unit, determines, uniaxial_angle, optional, layout, deformation):
        member = str.__new__(cls, name)
        member._value_ = name
        member.group = group
        member.quantity = quantity
        member.unit = unit
        member.determines = determines
        member.uniaxial_angle = uniaxial_angle
        member.uniaxial_axis = {0.0: 0, 0.5 * math.pi: 1}.get(uniaxial_angle)
        member.optional = optional
        member.layout = layout
        member._deformation = deformation
        return member

    WEFT_STRETCH = ("weft_stretch", Group.MEMBRANE, "λ − 1", "", "s00", None, False, _TENSION_AND_COMPRESSION,
                    _stretched(0))
    WARP_STRETCH = ("warp_stretch", Group.MEMBRANE, "λ − 1", "", "s11", None, False, _TENSION_AND_COMPRESSION,
                    _stretched(1))
    BIAXIAL_STRETCH = ("biaxial_stretch", Group.MEMBRANE, "λ − 1", "", "s01", None, False, _TENSION_AND_COMPRESSION,
                       _stretched(None))
    SHEAR = ("shear", Group.MEMBRANE, "I12", "", "s22", None, False, _BOTH_SIGNS, _sheared)
    # The free strains are found by the solve; the deformation is where its search starts.
    WEFT_UNIAXIAL = ("weft_uniaxial", Group.MEMBRANE, "λ − 1", "", None, 0.0, True, _UNIAXIAL_TENSION, _stretched(0))
    WARP_UNIAXIAL = ("warp_uniaxial", Group.MEMBRANE, "λ − 1", "", None, 0.5 * math.pi, True, _UNIAXIAL_TENSION,
                     _stretched(1))
    BIAS_UNIAXIAL = ("bias_uniaxial", Group.MEMBRANE, "λ − 1", "", None, 0.25 * math.pi, True, _UNIAXIAL_TENSION,
                     _pulled(0.25 * math.pi))
    # The other bias (−45°), sampled only where the shell keeps the shear's two signs apart
    # (sample_design(both_biases=True): a woven, whose twill or satin line makes the two biases
    # differ; a knit's jersey repeat pulls alike along both).
    NEGATIVE_BIAS_UNIAXIAL = ("negative_bias_uniaxial", Group.MEMBRANE, "λ − 1", "", None, -0.25 * math.pi, True,
                              _UNIAXIAL_TENSION, _pulled(-0.25 * math.pi))
    WEFT_BEND = ("weft_bend", Group.BENDING, "curvature", "1/m", "b00", None, False, _BOTH_SIGNS,
                 _bent(lambda e: np.diag([e, 0.0])))
    WARP_BEND = ("warp_bend", Group.BENDING, "curvature", "1/m", "b11", None, False, _BOTH_SIGNS,
                 _bent(lambda e: np.diag([0.0, e])))
    # Cylinder at +45° for positive parameters, at −45° (curvature |e|) for negative ones.
    BIAS_BEND = ("bias_bend", Group.BENDING, "curvature", "1/m", "b22", None, False, _BOTH_SIGNS,
                 _bent(lambda e: 0.5 * abs(e) * np.array([[1.0, np.sign(e)], [np.sign(e), 1.0]])))
    SADDLE_BEND = ("saddle_bend", Group.BENDING, "curvature", "1/m", "b01", None, False, _BOTH_SIGNS,
                   _bent(lambda e: np.diag([e, -e])))

    def deformation(self, parameter: float) -> tuple[np.ndarray, np.ndarray]:
        """``(I, II)`` of this family's sample at ``parameter`` (see the class docstring)."""
        return self._deformation(float(parameter))

    @property
    def label(self) -> str:
        """The parameter with its unit, for plots: ``"λ − 1"``, ``"I12"``, ``"curvature (1/m)"``."""
        return f"{self.quantity} ({self.unit})" if self.unit else self.quantity

    @classmethod
    def named(cls, name: object) -> "Family":
        """The family called ``name``; ValueError listing the families otherwise."""
        try:
            return cls(name)
        except ValueError:
            raise ValueError(f"unknown sample family {name!r}; families: {', '.join(cls)}") from None


FAMILIES = tuple(Family)
MEMBRANE_FAMILIES = tuple(f for f in Family if f.group is Group.MEMBRANE)
BENDING_FAMILIES = tuple(f for f in Family if f.group is Group.BENDING)
OPTIONAL_FAMILIES = tuple(f for f in Family if f.optional)
UNIAXIAL_FAMILIES = tuple(f for f in Family if f.uniaxial_angle is not None)
# The families a design samples only when asked for both biases (sample_design(both_biases=True)).
OTHER_BIAS_FAMILIES = (Family.NEGATIVE_BIAS_UNIAXIAL,)


def family_deformation(family: str, parameter: float) -> tuple[np.ndarray, np.ndarray]:
    """``(I, II)`` of a sample of ``family`` (a :class:`Family` or its name) at ``parameter``."""
    return Family.named(family).deformation(parameter)


@dataclass(frozen=True, eq=False)
class SampleSpec:
    """A sampled deformation: ``family`` (a :class:`Family`; its name is accepted), ``I`` ``(2, 2)``
    SPD (the identity for bending families), ``II`` ``(2, 2)`` symmetric (1/m; zero for membrane
    families) and the finite scalar ``parameter`` that varies along the family (``family.label``).
    The forms are kept as read-only copies. ValueError names the field at fault."""

    family: Family
    I: np.ndarray
    II: np.ndarray
    parameter: float

    def __post_init__(self) -> None:
        if not isinstance(self.family, str) or self.family not in FAMILIES:
            raise ValueError(f"SampleSpec.family must be one of {', '.join(FAMILIES)}, got {self.family!r}")
        family = Family(self.family)
        I = _single_form(as_first_fundamental_form, self.I, "I")
        II = _single_form(as_second_fundamental_form, self.II, "II")
        if family.group is Group.MEMBRANE and np.max(np.abs(II)) > PURE_CURVATURE_ATOL:
            raise ValueError(
                f"SampleSpec.II must be zero for membrane family {family} (a sample never mixes "
                f"membrane and bending; tolerance {PURE_CURVATURE_ATOL} 1/m), got {II.tolist()}"
            )
        if family.group is Group.BENDING and np.max(np.abs(I - np.eye(2))) > PURE_STRAIN_ATOL:
            raise ValueError(
                f"SampleSpec.I must be the identity for bending family {family} (a sample never mixes "
                f"membrane and bending; tolerance {PURE_STRAIN_ATOL}), got {I.tolist()}"
            )
        parameter = real_number(self.parameter, "SampleSpec.parameter")
        if not math.isfinite(parameter):
            raise ValueError(f"SampleSpec.parameter must be finite, got {parameter!r}")
        I.setflags(write=False)
        II.setflags(write=False)
        object.__setattr__(self, "family", family)
        object.__setattr__(self, "I", I)
        object.__setattr__(self, "II", II)
        object.__setattr__(self, "parameter", parameter)

    @classmethod
    def at(cls, family: str, parameter: float) -> "SampleSpec":
        """The sample of ``family`` at ``parameter`` (its forms from :meth:`Family.deformation`)."""
        family = Family.named(family)
        return cls(family, *family.deformation(parameter), parameter)

    @property
    def is_membrane(self) -> bool:
        return self.family.group is Group.MEMBRANE

    @property
    def compressed(self) -> bool:
        """An in-plane compression sample: weft, warp or biaxial stretch at λ < 1."""
        return self.family.layout == _TENSION_AND_COMPRESSION and self.parameter < 0.0


# A stretch share may exceed 1 by round-off when bending and twist hold nothing (a straight yarn).
STRETCH_SHARE_SLACK = 1e-9


def stretch_share(terms) -> float:
    """Fraction of the rods' internal energy in stretch and shear (``terms``: an
    :class:`~yarnfit.engine.EnergyTerms`); NaN for a zero or negative total."""
    internal = terms.internal
    return (terms.stretch + terms.shear) / internal if internal > 0.0 else math.nan


@dataclass(frozen=True, eq=False)
class SampleResult:
    """A solved sample: its ``spec`` (for a uniaxial family, with the transverse stretch found),
    ``energy_density`` Ū (J/m² of reference area; NaN only if not ``converged``), ``converged``,
    the solver's ``residual`` (:class:`~yarnfit.engine.Residual`; NaN only if not converged: no
    state was reached), ``iterations`` (Newton iterations of every solve), wall ``seconds``, the
    final node positions ``position (N, 3)`` (m; ``None`` when not kept) and ``stretch_share``, the
    fraction of Ū the rods store in stretching and shearing their centrelines (the rest is bending
    and twist; NaN when unknown: no state, a zero Ū, or a file written before it was kept). A
    knit's or a woven's structure gives way by bending its yarns; a share near 1 at a small strain
    says the structure is jammed and the yarn itself is pulled (``docs/design.md`` §4).
    ``pull_slope`` (N/m = J/m²), uniaxial samples only: ``dŪ/dE`` along the pull at the free
    width found, ``E`` the pull's Green strain; the force per reference width is ``λ`` times it
    (NaN for other families, a sample with no state, or a file written before it was kept).
    ``across_slope`` (N/m), uniaxial samples only: ``dŪ/dE⊥`` across the pull at that width, ~0
    where the search found Ū's minimum, and not where it stopped at an end of its interval (a
    fabric that would widen stops at E⊥ = 0 with a negative slope); NaN as ``pull_slope``.
    ``free_membrane_strain``, bending samples only: ``(E00, E11, E01)`` the membrane Green strains
    the bend was solved at, where Ū is least (zero membrane force; the spec keeps ``I = Id``:
    :mod:`yarnfit.homogenize.bend`); NaN for other families and files written before bends were
    solved so. ``design_parameter``: the parameter the design asked for, when the sample was taken
    short of it because its loading path converged no further (a jam: the fabric does not bear
    that deformation, :func:`~yarnfit.homogenize.loading_path_samples`); NaN otherwise.

    Non-converged samples are reported and never fitted. ValueError names the field at fault."""

    spec: SampleSpec
    energy_density: float
    converged: bool
    residual: Residual
    iterations: int = 0
    seconds: float = 0.0
    position: np.ndarray | None = None
    stretch_share: float = math.nan
    pull_slope: float = math.nan
    across_slope: float = math.nan
    free_membrane_strain: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    design_parameter: float = math.nan

    def __post_init__(self) -> None:
        if not isinstance(self.spec, SampleSpec):
            raise ValueError(f"SampleResult.spec must be a SampleSpec, got {type(self.spec).__name__}")
        if not isinstance(self.converged, (bool, np.bool_)):
            raise ValueError(f"SampleResult.converged must be a bool, got {self.converged!r}")
        converged = bool(self.converged)
        energy = real_number(self.energy_density, "SampleResult.energy_density")
        if converged and not math.isfinite(energy):
            raise ValueError(f"SampleResult.energy_density must be finite for a converged sample, got {energy!r}")
        if not isinstance(self.residual, Residual):
            raise ValueError(f"SampleResult.residual must be a Residual, got {type(self.residual).__name__}")
        for name in ("force", "torque"):
            value = real_number(getattr(self.residual, name), f"SampleResult.residual.{name}")
            if converged and not math.isfinite(value):
                raise ValueError(f"SampleResult.residual.{name} must be finite for a converged sample, got {value!r}")
            if value < 0.0:
                raise ValueError(f"SampleResult.residual.{name} must be >= 0, got {value!r}")
        share = real_number(self.stretch_share, "SampleResult.stretch_share")
        if not (math.isnan(share) or 0.0 <= share <= 1.0 + STRETCH_SHARE_SLACK):
            raise ValueError(f"SampleResult.stretch_share must lie in [0, 1] or be NaN, got {share!r}")
        object.__setattr__(self, "converged", converged)
        object.__setattr__(self, "energy_density", energy)
        object.__setattr__(self, "stretch_share", share)
        for name in ("pull_slope", "across_slope"):
            slope = real_number(getattr(self, name), f"SampleResult.{name}")
            if not math.isnan(slope) and self.spec.family.uniaxial_angle is None:
                raise ValueError(f"SampleResult.{name} is only defined for a uniaxial family, got {slope!r} "
                                 f"for {self.spec.family}")
            object.__setattr__(self, name, slope)
        strain = self.free_membrane_strain
        if not (isinstance(strain, (tuple, list, np.ndarray)) and len(strain) == 3):
            raise ValueError(f"SampleResult.free_membrane_strain must be three Green strains, got {strain!r}")
        strain = tuple(real_number(e, "SampleResult.free_membrane_strain") for e in strain)
        if any(math.isinf(e) for e in strain):
            raise ValueError(f"SampleResult.free_membrane_strain must be finite or NaN, got {strain!r}")
        if any(not math.isnan(e) for e in strain) and self.spec.family.group is not Group.BENDING:
            raise ValueError(f"SampleResult.free_membrane_strain is only defined for a bending family, got "
                             f"{strain!r} for {self.spec.family}")
        object.__setattr__(self, "free_membrane_strain", strain)
        design = real_number(self.design_parameter, "SampleResult.design_parameter")
        if math.isinf(design):
            raise ValueError(f"SampleResult.design_parameter must be finite or NaN, got {design!r}")
        object.__setattr__(self, "design_parameter", design)

    @classmethod
    def unsolved(cls, spec: SampleSpec, iterations: int, seconds: float,
                 position: np.ndarray | None = None) -> "SampleResult":
        """A sample no solve brought to a state to measure (every one left the mapped tiles, or a
        search's first solve failed): not converged, its energy and residuals NaN."""
        return cls(spec=spec, energy_density=math.nan, converged=False,
                   residual=Residual(math.nan, math.nan, math.nan, math.nan), iterations=iterations, seconds=seconds,
                   position=position)

    @classmethod
    def of_solve(cls, spec: SampleSpec, result, area: float, converged: bool, iterations: int, seconds: float,
                 **fields) -> "SampleResult":
        """The sample ``spec`` at a solve's ``result`` (a
        :class:`~yarnfit.engine.QuasiStaticResult` on a tiling of ``area`` m²): its Ū, residual,
        node positions and stretch share; other fields (a uniaxial sample's slopes, a bend's free
        strains) by keyword."""
        return cls(spec=spec, energy_density=result.energy.internal / area, converged=converged,
                   residual=result.residual, iterations=iterations, seconds=seconds,
                   position=result.state.node_position, stretch_share=stretch_share(result.energy), **fields)

    # The spec's fields, read through (the fit and the recording work with results).
    @property
    def family(self) -> Family:
        return self.spec.family

    @property
    def I(self) -> np.ndarray:
        return self.spec.I

    @property
    def II(self) -> np.ndarray:
        return self.spec.II

    @property
    def parameter(self) -> float:
        return self.spec.parameter

    @property
    def is_membrane(self) -> bool:
        return self.spec.is_membrane

    @property
    def worst_residual(self) -> float:
        """The worse of the force and torque imbalances (dimensionless; NaN without a state)."""
        return max(self.residual.force, self.residual.torque)

    def to_dict(self) -> dict:
        """JSON form (the material file's ``samples`` entries); NaN is written as ``None``."""
        r = self.residual
        return {
            "family": str(self.family),
            "parameter": self.parameter,
            "I": self.I.tolist(),
            "II": self.II.tolist(),
            "energy_density_j_m2": finite_or_none(self.energy_density),
            "converged": self.converged,
            # A sample with no state to measure (every solve left the mapped tiles) has NaN residuals.
            "residual": {key: finite_or_none(value) for key, value in (
                ("force", r.force), ("torque", r.torque), ("energy_change", r.energy_change),
                ("penetration", r.penetration))},
            "iterations": self.iterations,
            "seconds": self.seconds,
            "stretch_share": finite_or_none(self.stretch_share),
            "pull_slope_n_per_m": finite_or_none(self.pull_slope),
            "across_slope_n_per_m": finite_or_none(self.across_slope),
            "free_membrane_strain": [finite_or_none(e) for e in self.free_membrane_strain],
            "design_parameter": finite_or_none(self.design_parameter),
        }

    @classmethod
    def from_dict(cls, data: object, where: str = "sample") -> "SampleResult":
        """Inverse of :meth:`to_dict` (``None`` reads back as NaN; the node positions are not
        kept). ValueError ``<where>: ...`` naming the key at fault."""
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected an object (family, parameter, I, II, energy_density_j_m2, "
                             f"converged, residual), got {type(data).__name__}")
        missing = [key for key in ("family", "parameter", "I", "II", "energy_density_j_m2", "converged")
                   if key not in data]
        if missing:
            raise ValueError(f"{where}: missing key{'s' if len(missing) > 1 else ''} {', '.join(missing)}")
        residual = data.get("residual") or {}
        if not isinstance(residual, dict):
            raise ValueError(f"{where}: residual must be an object, got {residual!r}")

        def number(value: object, key: str) -> float:
            return math.nan if value is None else real_number(value, f"{where}: {key}")

        try:
            spec = SampleSpec(data["family"], data["I"], data["II"], data["parameter"])
            return cls(spec, number(data["energy_density_j_m2"], "energy_density_j_m2"), data["converged"],
                       Residual(*(number(residual.get(key), f"residual.{key}")
                                  for key in ("force", "torque", "energy_change", "penetration"))),
                       int(data.get("iterations", 0)), float(data.get("seconds", 0.0)),
                       stretch_share=number(data.get("stretch_share"), "stretch_share"),
                       pull_slope=number(data.get("pull_slope_n_per_m"), "pull_slope_n_per_m"),
                       across_slope=number(data.get("across_slope_n_per_m"), "across_slope_n_per_m"),
                       free_membrane_strain=_free_membrane_strain(data.get("free_membrane_strain"), number),
                       design_parameter=number(data.get("design_parameter"), "design_parameter"))
        except (TypeError, ValueError) as exc:
            message = str(exc)
            raise ValueError(message if message.startswith(where) else f"{where}: {message}") from None


def _free_membrane_strain(value: object, number: Callable[[object, str], float]) -> tuple[float, float, float]:
    """A file's ``free_membrane_strain`` (absent or null: unknown)."""
    if value is None:
        return (math.nan, math.nan, math.nan)
    if not isinstance(value, list) or len(value) != 3:
        raise ValueError(f"free_membrane_strain must be a list of three Green strains, got {value!r}")
    return tuple(number(e, f"free_membrane_strain[{k}]") for k, e in enumerate(value))


# -- sample design --------------------------------------------------------------------------------

# The design's energy references: the undeformed sample, and the unbent one at zero membrane force.
REFERENCE_SAMPLES = 2
# Samples per level of the default design: weft, warp and biaxial stretch in tension and in
# compression, shear of both signs, four bend families of both signs; plus weft, warp and bias
# uniaxial tension at UNIAXIAL_LEVELS strains each and between the largest (uniaxial_strains), and
# with both biases the other bias's (−45°) too.
SAMPLES_PER_LEVEL = 16
# Uniaxial tension (the transverse direction free) per direction: log-spaced from SMALLEST_STRAIN
# to the range or UNIAXIAL_LARGEST_STRAIN, whichever is less. The strain-stiffening membrane follows
# a free-width pull only where one is sampled: a knit's pull jams across its width between 2 and
# 10 % (cotton jersey's warp energy grows sevenfold from 5 to 7.5 %), which neither the pure
# stretches nor one uniaxial sample show (with one per direction the five presets' shells met their
# periodic free-width pulls at 2 / 5 / 10 % in 15 of 30 cases, with three from 2 to 10 % in 24;
# session 35, the same samples), and at small strain a knit's free width is a mechanism the pure
# stretches leave undetermined (with none below 2 % the jerseys' fitted weft stretch at small
# strain came out 0 N/m; cotton jersey's periodic repeat pulls at 324 N/m at 0.1 %). 10 %: the
# largest strain the yarn swatches are compared at; past it a polyester's range (40 %) collapses the
# satin's weft past half its width (not converged) and costs HYLC's stockinette 49 s for two samples.
# Small-strain uniaxial samples converge in one solve each since the transverse strain became an
# unknown of it (session 33; cotton jersey at 0.1 %: 0.4 s).
# Eight levels (session 45, not kept): the default shells' pulls against the periodic ones at 2 /
# 5 / 10 % within 20 % at 42 of 45 points against 44 with six (cotton jersey's warp at 5 % −41 →
# −12 %, but the twill's bias +6 / −2 → +29 / −32 %: its bias stiffens 180-fold from 2 to 10 %,
# R² 0.14–0.25 either way, and more samples only move the misfit); its loading fit (--friction) met
# its own frictional pulls within 15 % at all nine (six levels: warp +27 %, bias +13 %).
# Seven levels (session 48; 0.1, 0.22, 0.46, 1, 2.2, 4.6, 10 %), once a woven was pulled along both
# biases with its membrane rays fitted each on its own (session 47): the twill's weft stiffens
# tenfold between six levels' samples at 1.6 and 4 %, and its shell pulled +33 / +20 % off its
# periodic pull at 2 / 5 % there, whatever the knots; with seven +9 / −4 %. The five presets'
# shells then meet their own periodic pulls along weft, warp and both biases at 0.1 / 1 / 2 / 5 /
# 10 % within 20 % at 89 of 100 points against 83 with six (validation/periodic_pulls.py), and
# their largest yarn strips at 28 of 35 cells against 25; the stockinette's one-worker mean per
# sample unchanged (0.49–0.50 s either way, paired): its new samples cost what its others do.
# Plus one in each of the largest UNIAXIAL_REFINED_INTERVALS intervals (session 52; their
# geometric means, 3.2 and 6.8 % at a 10 % reach), where a fabric's pull stiffens most: a woven's
# bias locks (the cotton twill's twentyfold, 2.90 → 61.5 N/m from 4.6 to 10 %) and a knit jams
# (cotton jersey's loading warp pull tenfold, 64 → 698 N/m from 3 to 4.6 %). With no sample
# inside such an interval nothing pins where on it the stiffening sets in: the default twill's
# shell, within 6 % of its periodic pull at 4.6 and 10 %, pulled +81 / +159 / +120 % off it at
# 5.5 / 6 / 7.5 % (validation/periodic_pulls.py; 11 of 44 points beyond 20 % at 11 strains along
# weft, warp and both biases; over the five presets 42 of 220). With the 6.8 % sample alone (and
# ten knots per ray) the twill 3 of 44, but cotton jersey's warp at 3 % +73 % (−25 % before), 27
# of 220; with both and twelve knots (ridge_fit.RIDGE_KNOTS) 19, ten of them the knits' −45° pulls,
# which their designs do not sample. Cost (validation/bench.py fit, paired): the satin's fit +12 %,
# the twill's +17 %, the stockinette's mean per sample +7 % (docs/design.md §3).
UNIAXIAL_LEVELS = 7
UNIAXIAL_LARGEST_STRAIN = 0.10
UNIAXIAL_REFINED_INTERVALS = 2
UNIAXIAL_STRAINS_PER_DIRECTION = UNIAXIAL_LEVELS + UNIAXIAL_REFINED_INTERVALS
UNIAXIAL_SAMPLES = (len(UNIAXIAL_FAMILIES) - len(OTHER_BIAS_FAMILIES)) * UNIAXIAL_STRAINS_PER_DIRECTION  # weft, warp, bias
# Smallest sampled strain (λ − 1, and I12 for shear): the design's levels are spaced
# logarithmically from here up to the range, so the small-strain stiffness that a drape, a low-load
# tensile test or a robot's grasp sees is measured, not extrapolated from a few per cent. 0.1 %
# (issue 14): the strain energy there, ~s h 1e-6/2 ≈ 1e-4 J/m² for a cotton woven, is still eight
# orders above the solver's energy tolerance, and Green and engineering strain differ by 0.05 %.
SMALLEST_STRAIN = 1.0e-3
# Smallest sampled curvature (1/m): a draping fabric's folds have radii of 1 cm – 1 m; a metre's
# radius is where a drape's gentlest curvature lies.
SMALLEST_CURVATURE = 1.0
# Largest in-plane compression (1 − λ) a default design samples (SampleRanges.compression). The
# drapes' compressed regions reach −2 to −5 % in their plane before they fold (the cotton twill's
# Cusick specimen, docs/design.md §8), and a repeat pressed further jams (HYLC's stockinette at
# 10 %: three times its tensile stiffness), where its solves cost more (wool jersey frictionless:
# 0.1 s a sample to 5 %, 0.3 s at 20 %); past the largest sample the membrane's last tangent
# carries on.
COMPRESSION_LIMIT = 0.10


@dataclass(frozen=True)
class SampleRanges:
    """Largest sampled deformations: ``stretch`` (λ − 1 along a yarn direction, and ``I12`` for
    shear), ``curvature`` (1/m) and ``compression`` (1 − λ), the in-plane compression sampled along
    weft, along warp and along both at once, at as many levels as tension (``None``, the default:
    ``stretch``, but no more than :data:`COMPRESSION_LIMIT`; 0: none).

    Why compression is sampled (session 56): the shell is the repeat's material law, and the
    repeat's own compression (its yarns pressed together, bowing within a repeat) is part of it;
    buckling over many repeats is the cloth's, which the simulated sheet does itself. Left out, the
    strain-stiffening membrane extrapolated compression from the free-width pulls' transverse
    strains: wool jersey's weft at −1 % 2.2× the energy its compression samples give, the cotton
    twill's biaxial −1 % 1/30 of it (a sheet that shrinks in its plane for free and flows instead
    of folding; docs/design.md §8). The linear StVK membrane, even in the strain's sign, is fitted
    to tension only (:attr:`SampleSpec.compressed`): fitted to both it took a compromise.
    """

    stretch: float
    curvature: float
    compression: float | None = None

    def __post_init__(self) -> None:
        for name in ("stretch", "curvature"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"sample range {name} must be positive, got {value!r}")
        if self.compression is None:
            object.__setattr__(self, "compression", min(float(self.stretch), COMPRESSION_LIMIT))
        if not (math.isfinite(self.compression) and 0.0 <= self.compression < 1.0):
            raise ValueError(f"sample range compression must be a strain 1 − λ in [0, 1) (0: none), "
                             f"got {self.compression!r}")


def sample_design(ranges: SampleRanges, levels: int = 2, both_biases: bool = False) -> list[SampleSpec]:
    """The samples (paper §4.6, plus saddles for b01): ``levels`` magnitudes per family and sign,
    in :data:`FAMILIES` order (:meth:`Family.deformation` gives each one's ``I`` and ``II``). The
    magnitudes (:func:`magnitudes`) are spaced logarithmically from :data:`SMALLEST_STRAIN` (and
    :data:`SMALLEST_CURVATURE` for bends) up to the range. The first sample is the undeformed
    one (:func:`identity_sample`): the relaxed repeat's own energy, the reference of every
    membrane sample's Ū (a knit's relaxed repeat carries a few hundredths of a J/m², of the order
    of its 0.1 % samples). The second is the unbent repeat at zero membrane force
    (:func:`free_rest_sample`), the reference of the bends, which are solved so.

    - weft, warp, biaxial stretch: ``I = diag(λ², 1)`` / ``diag(1, λ²)`` / ``λ² Id``, λ − 1 at the
      stretch magnitudes and 1 − λ at as many compression magnitudes, from :data:`SMALLEST_STRAIN`
      to ``ranges.compression`` (none if that is 0);
    - shear: ``I = [[1, s], [s, 1]]``, ``s = ±`` the stretch magnitudes;
    - weft, warp uniaxial tension: λ − 1 at :func:`uniaxial_strains`, the other direction free
      (its stretch μ minimises Ū; the spec holds μ = 1, the result the μ found);
    - bias uniaxial tension: the same strains along 45°, the transverse strain and the pull
      frame's shear free (the spec holds the pure stretch along the pull, the result the form
      found): a shear with the normal strains relaxed, which no other family samples; with
      ``both_biases`` along −45° as well (:data:`OTHER_BIAS_FAMILIES`): the shear's other sign,
      for a fabric whose two biases differ (a twill's line, a satin's step);
    - weft, warp bends: ``II = diag(κ, 0)`` / ``diag(0, κ)``, ``κ = ±`` the curvature magnitudes;
    - bias bends: cylinders at ±45°, ``II = κ/2 [[1, ±1], [±1, 1]]``;
    - saddles: ``II = ±κ diag(1, −1)`` (the only samples that separate b01 from b22).
    """
    if not (isinstance(levels, int) and levels >= 1):
        raise ValueError(f"levels must be a positive integer, got {levels!r}")
    specs = []
    for group, largest, smallest in ((Group.MEMBRANE, ranges.stretch, SMALLEST_STRAIN),
                                     (Group.BENDING, ranges.curvature, SMALLEST_CURVATURE)):
        values = magnitudes(largest, smallest, levels)
        compressions = (magnitudes(ranges.compression, smallest, levels)
                        if group is Group.MEMBRANE and ranges.compression > 0 else np.empty(0))
        layouts = {
            _TENSION_AND_COMPRESSION: np.concatenate([-compressions[::-1], values]),
            _BOTH_SIGNS: np.concatenate([-values[::-1], values]),
            _UNIAXIAL_TENSION: uniaxial_strains(largest),
        }
        for family in FAMILIES:
            if family.group is group and (both_biases or family not in OTHER_BIAS_FAMILIES):
                specs += [SampleSpec.at(family, float(value)) for value in layouts[family.layout]]
    order = {family: k for k, family in enumerate(FAMILIES)}
    return [identity_sample(), free_rest_sample()] + sorted(specs, key=lambda spec: order[spec.family])


def magnitudes(largest: float, smallest: float, levels: int) -> np.ndarray:
    """``levels`` magnitudes ``(levels,)`` spaced logarithmically from ``smallest`` to ``largest``
    (the range itself is always the last). A range at or below ``smallest`` is sampled at
    ``j/levels`` of itself instead (a log spacing would repeat it)."""
    if largest <= smallest or levels == 1:
        return largest * np.arange(1, levels + 1) / levels
    return np.geomspace(smallest, largest, levels)


def uniaxial_strains(largest: float) -> np.ndarray:
    """The uniaxial families' ``λ − 1`` for a stretch range ``largest``, ascending,
    :data:`UNIAXIAL_STRAINS_PER_DIRECTION` of them: :data:`UNIAXIAL_LEVELS` magnitudes
    (:func:`magnitudes`) from :data:`SMALLEST_STRAIN` to ``largest`` or
    :data:`UNIAXIAL_LARGEST_STRAIN`, whichever is less, and the geometric mean of each pair of
    neighbours among the largest ``UNIAXIAL_REFINED_INTERVALS + 1``."""
    levels = magnitudes(min(float(largest), UNIAXIAL_LARGEST_STRAIN), SMALLEST_STRAIN, UNIAXIAL_LEVELS)
    top = levels[-UNIAXIAL_REFINED_INTERVALS - 1:]
    return np.sort(np.concatenate([levels, np.sqrt(top[:-1] * top[1:])]))


def design_size(levels: int, both_biases: bool = False) -> int:
    """Samples in a design of ``levels`` magnitudes per family and sign (``both_biases``: with
    the uniaxial pulls along −45°, :func:`sample_design`), compression sampled (the default)."""
    other = len(OTHER_BIAS_FAMILIES) * UNIAXIAL_STRAINS_PER_DIRECTION if both_biases else 0
    return REFERENCE_SAMPLES + SAMPLES_PER_LEVEL * levels + UNIAXIAL_SAMPLES + other


def levels_for(samples: int) -> int:
    """Magnitudes per family and sign for about ``samples`` samples in all (at least
    ``design_size(1)``), counted without the other bias's pulls (a design with ``both_biases``
    has :data:`UNIAXIAL_STRAINS_PER_DIRECTION` more)."""
    smallest = design_size(1)
    if not (isinstance(samples, int) and samples >= smallest):
        raise ValueError(f"the sample design needs at least {smallest} samples (one per family and sign), "
                         f"got {samples!r}")
    return min(range(1, samples // SAMPLES_PER_LEVEL + 2), key=lambda levels: abs(design_size(levels) - samples))


def identity_sample() -> SampleSpec:
    """The undeformed surface (``I = Id``, ``II = 0``): the membrane samples' energy reference."""
    return SampleSpec.at(Family.WEFT_STRETCH, 0.0)


def free_rest_sample() -> SampleSpec:
    """The unbent surface as a bending sample (``II = 0``; solved at zero membrane force, as
    every bend is): the bends' energy reference. The relaxed repeat is not quite free of membrane
    stress at ``I = Id`` (its settle's tolerance), and freed it releases most of its own energy
    (session 43: 85–98 %, e.g. cotton jersey 2.4e-6 → 4e-8 J/m²), as much as a 1 /m bend stores:
    measured from ``I = Id`` the smallest bends came out negative."""
    return SampleSpec.at(Family.WEFT_BEND, 0.0)


def _single_form(check, value: object, name: str) -> np.ndarray:
    try:
        form = check(value)
    except ValueError as exc:
        raise ValueError(f"SampleSpec.{name}: {exc}") from None
    if form.shape != (2, 2):
        raise ValueError(f"SampleSpec.{name} must have shape (2, 2), got shape {form.shape}")
    return form.copy()
