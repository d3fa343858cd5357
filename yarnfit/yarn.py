"""Yarns: from a fibre and the yarn's construction to the rigidities of the rod that models it.

The stage between the fibre (:mod:`yarnfit.fibers`) and the relaxed repeat
(:mod:`yarnfit.relax`). A :class:`YarnConstruction` says how a fabric's yarn is made (spinning
system, packing fraction φ, surface twist angle α) and which model to use; :meth:`Yarn.build`
turns it, with the fibre and the yarn's contact radius, into a :class:`Yarn`: linear density,
fibres per cross-section and the five rigidities of :class:`yarnfit.engine.RodSection`.

Two models (``docs/design.md`` §4):

``solid``
    The paper's yarn (§3.2): a solid cylinder of fibre material of the contact radius r,
    ``EA = E π r²``, ``EI = E π r⁴/4``, ``GJ = G π r⁴/2``, ``G = E/(2(1 + ν))``, mass ``ρ π r²``
    per length. φ = 1, α = 0.

``fibre-assembly`` (default)
    A bundle of N fibres that slide on each other, after Hearle, Grosberg & Backer, *Structural
    Mechanics of Fibers, Yarns and Fabrics* (1969, "HGB"), and Morton & Hearle, *Physical
    Properties of Textile Fibres* (4th ed. 2008, "M&H"). The yarn is the idealised helix of HGB
    ch. 4: fibres packed at φ in a cylinder of radius r, a fibre at radius ρ' turning at angle θ
    with ``tan θ = (ρ'/r) tan α``. Then, with ``t = tan α`` and the averages over the section
    taken exactly (uniform packing):

    - fibre area in a cross-section ``A_f = φ π r²``; mass per length ``ρ_f A_f``; linear density
      ``T_y = ρ_f A_f`` (1 tex = 10⁻⁶ kg/m). So the yarn radius from the areal density is the
      paper's formula with the yarn density ``φ ρ_f`` (:func:`yarnfit.fabric.radius_from_areal_density`).
    - fibres cut by a cross-section ``N = (T_y / T_f) ⟨cos θ⟩``, ``⟨cos θ⟩ = 2(√(1 + t²) − 1)/t²``
      (a fibre crosses a section obliquely), ``T_f`` the fibre's fineness.
    - tensile rigidity: a yarn strain ε strains a fibre at θ by ``ε cos²θ`` (no lateral
      contraction: HGB's simplest continuous-filament case) and its stress acts along the yarn
      with ``cos²θ``, so ``EA = E_f A_f ⟨cos⁴θ⟩ = E_f A_f cos²α`` (HGB's cos²α law) and the
      paper's hardening term, quadratic in the fibre strain, gives
      ``H = k A_f ⟨cos⁶θ⟩ = k A_f (2 + t²)/(2 (1 + t²)²)``. The fibre-slippage reduction of staple
      yarns (HGB ch. 14) is not modelled: it needs fibre length and migration data.
    - bending and twisting rigidity between two limits:
      *free slip* (every fibre bends and twists about its own axis): ``EI = N R_b T_f²``,
      ``GJ = N R_t T_f²`` with M&H's specific flexural and torsional rigidities (Table 17.2), the
      fibres taken as parallel to the yarn in bending and twisting;
      *no slip* (the section bends as one solid of the packed fibres): the fibres' axial
      stiffness with the same helix factor, ``EI = φ E_f (π r⁴/4) f(α)``,
      ``f(α) = 4 ∫₀¹ u³ cos⁴θ du = (2/t⁴)(ln(1 + t²) − t²/(1 + t²))`` (1 at α = 0), and
      ``GJ = φ G_f π r⁴/2``. At φ = 1, α = 0 the no-slip yarn is the paper's solid rod.
      Where a real yarn sits: at fabric curvatures its fibres slip and its rigidity is near the
      free-slip sum — Platt, Klein & Hamburger, Textile Res. J. 29 (1959) 611, measured singles
      yarns near the free-slip value; HGB ch. 11 and M&H ch. 17 state the same for bending and
      torsion. The model uses free slip. (The frictional couple that yarns show at the smallest
      curvatures, Grosberg 1966, is not elastic and is not modelled.)
    - shear rigidity ``GA = G_f A_f`` (the rod's transverse shear only keeps its frames along its
      centreline; slender rods do not feel its value).

    Measured rigidities of a single yarn (``tensile_rigidity_n``, ``bending_rigidity_nm2``,
    ``torsional_rigidity_nm2``) replace the model's; a measured EA scales the hardening with it.

Construction defaults (:data:`SPINNING_DEFAULTS`): ring-spun staple φ = 0.60 from Peirce's
specific volume of cotton yarn, 1.1 cm³/g (F. T. Peirce, J. Textile Inst. 28 (1937) T45:
φ = 1/(1.1 × 1.52) = 0.598), and a surface twist angle of 24.2° from Peirce's yarn diameter
``d = 1/(28 √Ne)`` inch (the same specific volume) at the twist multiplier αe = 4.0 turns/inch
per √Ne: ``tan α = π d T = π αe/28``. Continuous filament: producer twist of ≤ 10 turns/m on a
0.1–0.2 mm yarn is below 0.5°, so α = 0; no measured packing fraction of flat filament yarns was
found, and the ring yarn's 0.60 is used. Each fibre names its usual spinning system
(:attr:`yarnfit.fibers.Fiber.spinning`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

from .checks import finite_number, positive_or_none
from .fibers import SPINNING_SYSTEMS, Fiber
from .jsonfile import read_json

if TYPE_CHECKING:  # the engine compiles Numba kernels: imported only when a rod is built
    from .engine import RodSection

__all__ = ["SPINNING_DEFAULTS", "YARN_MODELS", "Yarn", "YarnConstruction", "load_yarn_file"]

YARN_MODELS = ("fibre-assembly", "solid")
DEFAULT_YARN_MODEL = "fibre-assembly"
# Surface twist angles are accepted in [0°, 45°): at 45° a fibre makes a full turn every 2π r,
# far beyond any textile yarn (hard-twisted crepe yarns reach ~35°).
MAX_TWIST_DEG = 45.0
# Below this t² the no-slip bending factor uses its series 1 − 4t²/3 + 3t⁴/2: the closed form
# subtracts two numbers that agree to O(t⁴), which loses 2 log10(1/t²) digits.
_SERIES_T2 = 1e-4
# Peirce (1937): specific volume of cotton yarn 1.1 cm³/g; cotton 1520 kg/m³.
_PEIRCE_SPECIFIC_VOLUME = 1.1e-3
_COTTON_DENSITY = 1520.0
# Twist multiplier αe (turns/inch per √Ne) of the ring-spun default; Peirce's diameter constant 28.
_TWIST_MULTIPLIER = 4.0
_PEIRCE_DIAMETER_CONSTANT = 28.0


@dataclass(frozen=True)
class SpinningDefaults:
    """Default construction of one spinning system: packing fraction, surface twist angle (°) and
    where they come from."""

    packing_fraction: float
    twist_angle_deg: float
    source: str


SPINNING_DEFAULTS: dict[str, SpinningDefaults] = {
    "ring-spun": SpinningDefaults(
        packing_fraction=round(1.0 / (_PEIRCE_SPECIFIC_VOLUME * _COTTON_DENSITY), 2),
        twist_angle_deg=round(math.degrees(math.atan(math.pi * _TWIST_MULTIPLIER / _PEIRCE_DIAMETER_CONSTANT)), 1),
        source="Peirce 1937: yarn specific volume 1.1 cm³/g (φ = 0.60); diameter 1/(28 √Ne) in at twist multiplier "
               "4.0 (tan α = π 4/28, α = 24.2°)",
    ),
    "filament": SpinningDefaults(
        packing_fraction=0.60,
        twist_angle_deg=0.0,
        source="producer twist < 0.5° (α = 0); φ unverified: ring yarn's 0.60, no filament-yarn value found",
    ),
}

_RIGIDITY_KEYS = ("tensile_rigidity_n", "bending_rigidity_nm2", "torsional_rigidity_nm2")
_CONSTRUCTION_KEYS = ("spinning", "packing_fraction", "twist_angle_deg")


@dataclass(frozen=True)
class YarnConstruction:
    """How a fabric's yarn is made, and which model turns it into a rod.

    Attributes:
        model: ``"fibre-assembly"`` (default) or ``"solid"`` (the paper's solid rod; takes no
            construction).
        spinning: ``"ring-spun"`` or ``"filament"``; ``None``: the fibre's usual system.
        packing_fraction: φ in (0, 1]; ``None``: the spinning system's default.
        twist_angle_deg: surface twist angle α in [0°, 45°); ``None``: the spinning system's.
        tensile_rigidity_n: a measured EA (N) of the single yarn, replacing the model's; or ``None``.
        bending_rigidity_nm2: a measured EI (N·m²), or ``None``.
        torsional_rigidity_nm2: a measured GJ (N·m²), or ``None``.
    """

    model: str = DEFAULT_YARN_MODEL
    spinning: str | None = None
    packing_fraction: float | None = None
    twist_angle_deg: float | None = None
    tensile_rigidity_n: float | None = None
    bending_rigidity_nm2: float | None = None
    torsional_rigidity_nm2: float | None = None

    def __post_init__(self) -> None:
        if self.model not in YARN_MODELS:
            raise ValueError(f"yarn model must be one of {', '.join(YARN_MODELS)}, got {self.model!r}")
        if self.spinning is not None and self.spinning not in SPINNING_SYSTEMS:
            raise ValueError(f"spinning must be one of {', '.join(SPINNING_SYSTEMS)}, got {self.spinning!r}")
        if self.packing_fraction is not None:
            phi = finite_number(self.packing_fraction, "packing fraction")
            if not 0.0 < phi <= 1.0:
                raise ValueError(f"packing fraction must lie in (0, 1], got {phi!r}")
            object.__setattr__(self, "packing_fraction", phi)
        if self.twist_angle_deg is not None:
            alpha = finite_number(self.twist_angle_deg, "twist angle")
            if not 0.0 <= alpha < MAX_TWIST_DEG:
                raise ValueError(f"twist angle must lie in [0°, {MAX_TWIST_DEG:g}°), got {alpha!r}°")
            object.__setattr__(self, "twist_angle_deg", alpha)
        for key in _RIGIDITY_KEYS:
            object.__setattr__(self, key, positive_or_none(getattr(self, key), key))
        if self.model == "solid":
            given = [key for key in _CONSTRUCTION_KEYS + _RIGIDITY_KEYS if getattr(self, key) is not None]
            if given:
                raise ValueError(f"the solid yarn model takes no construction or measured rigidities "
                                 f"(given: {', '.join(given)}); use the fibre-assembly model")

    def check_fiber(self, fiber: Fiber) -> None:
        """Raise ``ValueError`` (one line, naming the keys) if the fibre lacks data this model needs:
        the fibre-assembly model needs the fineness, and the specific flexural and torsional
        rigidities unless EI and GJ were measured."""
        if self.model == "solid":
            return
        missing = [key for key, needed, value in (
            ("fineness_dtex", True, fiber.fineness_dtex),
            ("flexural_rigidity_nm2_per_tex2", self.bending_rigidity_nm2 is None, fiber.flexural_rigidity_nm2_per_tex2),
            ("torsional_rigidity_nm2_per_tex2", self.torsional_rigidity_nm2 is None,
             fiber.torsional_rigidity_nm2_per_tex2),
        ) if needed and value is None]
        if missing:
            raise ValueError(f"fibre {fiber.name!r} has no {', '.join(missing)}: the fibre-assembly yarn model needs "
                             f"{'it' if len(missing) == 1 else 'them'} (add {'it' if len(missing) == 1 else 'them'} "
                             f"to the fibre file, or use the solid yarn model)")

    def spinning_for(self, fiber: Fiber) -> str | None:
        """The spinning system: as given, else the fibre's, else ring-spun (``None`` for solid)."""
        if self.model == "solid":
            return None
        return self.spinning or fiber.spinning or "ring-spun"

    def packing_fraction_for(self, fiber: Fiber) -> float:
        """φ: 1 for the solid model, else as given or the spinning system's default."""
        if self.model == "solid":
            return 1.0
        if self.packing_fraction is not None:
            return self.packing_fraction
        return SPINNING_DEFAULTS[self.spinning_for(fiber)].packing_fraction

    def twist_angle_deg_for(self, fiber: Fiber) -> float:
        """α (°): 0 for the solid model, else as given or the spinning system's default."""
        if self.model == "solid":
            return 0.0
        if self.twist_angle_deg is not None:
            return self.twist_angle_deg
        return SPINNING_DEFAULTS[self.spinning_for(fiber)].twist_angle_deg

    def yarn_density(self, fiber: Fiber) -> float:
        """Mass per yarn volume ``φ ρ_f`` (kg/m³): the density in the areal-density radius formula."""
        return self.packing_fraction_for(fiber) * fiber.density_kg_m3

    def to_dict(self) -> dict:
        """The construction as given (``None`` for defaults), for the material file's inputs."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: dict, where: str = "yarn") -> "YarnConstruction":
        """Inverse of :meth:`to_dict`; unknown keys are an error naming them."""
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a JSON object with keys among {', '.join(_ALLOWED_KEYS)}")
        unknown = sorted(key for key in data if key not in _ALLOWED_KEYS)
        if unknown:
            raise ValueError(f"{where}: unknown keys: {', '.join(unknown)} (allowed: {', '.join(_ALLOWED_KEYS)})")
        try:
            return cls(**{key: value for key, value in data.items()})
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None


_ALLOWED_KEYS = tuple(f.name for f in fields(YarnConstruction))


def load_yarn_file(path: str | os.PathLike) -> YarnConstruction:
    """A :class:`YarnConstruction` from a JSON file: one object with any of the keys ``model``,
    ``spinning``, ``packing_fraction``, ``twist_angle_deg``, ``tensile_rigidity_n`` (N),
    ``bending_rigidity_nm2``, ``torsional_rigidity_nm2`` (N·m²). Example::

        {"spinning": "ring-spun", "packing_fraction": 0.55, "twist_angle_deg": 20}

    Raises ``ValueError`` with a one-line message starting with the file name.
    """
    where, data = read_json(path, "yarn file")
    return YarnConstruction.from_dict(data, where)


@dataclass(frozen=True)
class Yarn:
    """A yarn as the rod engine sees it (SI units; see the module docstring for the formulas).

    Attributes:
        fiber: the fibre.
        construction: the construction as given.
        model: ``"fibre-assembly"`` or ``"solid"``.
        spinning: the spinning system used (``None`` for the solid model).
        packing_fraction: φ.
        twist_angle_deg: α (°).
        radius_m: contact radius r (m).
        linear_density_tex: T_y (tex = g/km).
        mass_per_length: kg/m, ``ρ_f A_f``.
        fibres_per_section: N, or ``None`` (solid model of a fibre without fineness).
        tensile_rigidity_n: EA (N) at zero strain.
        hardening_n: H (N): the tangent rigidity grows as ``EA + H |ε|``.
        shear_rigidity_n: GA (N).
        bending_rigidity_nm2: EI (N·m²), the same about both axes.
        torsional_rigidity_nm2: GJ (N·m²).
        bending_free_slip_nm2, bending_no_slip_nm2, torsion_free_slip_nm2, torsion_no_slip_nm2:
            the two limits (N·m²), ``None`` where the fibre lacks the data.
        solid_bending_rigidity_nm2: EI of the solid rod of the same mass, ``E_f π r_s⁴/4`` with
            ``π r_s² = A_f``.
    """

    fiber: Fiber
    construction: YarnConstruction
    model: str
    spinning: str | None
    packing_fraction: float
    twist_angle_deg: float
    radius_m: float
    linear_density_tex: float
    mass_per_length: float
    fibres_per_section: float | None
    tensile_rigidity_n: float
    hardening_n: float
    shear_rigidity_n: float
    bending_rigidity_nm2: float
    torsional_rigidity_nm2: float
    bending_free_slip_nm2: float | None
    bending_no_slip_nm2: float
    torsion_free_slip_nm2: float | None
    torsion_no_slip_nm2: float
    solid_bending_rigidity_nm2: float

    @classmethod
    def build(cls, fiber: Fiber, construction: YarnConstruction, radius: float) -> "Yarn":
        """The yarn of ``fiber`` made as ``construction`` with contact radius ``radius`` (m).

        Raises ``ValueError`` (one line, naming the missing keys) when the fibre-assembly model
        needs fibre data the fibre does not have.
        """
        radius = finite_number(radius, "yarn radius")
        if radius <= 0.0:
            raise ValueError(f"yarn radius must be positive, got {radius!r} m")
        phi = construction.packing_fraction_for(fiber)
        alpha = math.radians(construction.twist_angle_deg_for(fiber))
        t2 = math.tan(alpha) ** 2
        e_f = fiber.young_min_pa
        g_f = e_f / (2.0 * (1.0 + fiber.poisson))
        fibre_area = phi * math.pi * radius**2
        mass_per_length = fiber.density_kg_m3 * fibre_area
        linear_density = mass_per_length * 1e6
        # Grouped as RodMaterial.section groups them, so that φ = 1, α = 0 gives its solid rod to
        # the last bit.
        inertia = 0.25 * math.pi * radius**4
        no_slip_bending = phi * (e_f * inertia) * no_slip_bending_factor(t2)
        no_slip_torsion = phi * (g_f * (2.0 * inertia))
        fibres = free_bending = free_torsion = None
        if fiber.fineness_tex is not None:
            fibres = linear_density / fiber.fineness_tex * mean_cos_helix(t2)
            if fiber.flexural_rigidity_nm2_per_tex2 is not None:
                free_bending = fibres * fiber.flexural_rigidity_nm2_per_tex2 * fiber.fineness_tex**2
            if fiber.torsional_rigidity_nm2_per_tex2 is not None:
                free_torsion = fibres * fiber.torsional_rigidity_nm2_per_tex2 * fiber.fineness_tex**2
        construction.check_fiber(fiber)
        if construction.model == "solid":
            bending, torsion = no_slip_bending, no_slip_torsion
        else:
            bending = construction.bending_rigidity_nm2 or free_bending
            torsion = construction.torsional_rigidity_nm2 or free_torsion
        tensile = e_f * fibre_area * tensile_helix_factor(t2)
        hardening = fiber.hardening_pa * fibre_area * hardening_helix_factor(t2)
        if construction.tensile_rigidity_n is not None:
            hardening *= construction.tensile_rigidity_n / tensile
            tensile = construction.tensile_rigidity_n
        return cls(
            fiber=fiber,
            construction=construction,
            model=construction.model,
            spinning=construction.spinning_for(fiber),
            packing_fraction=phi,
            twist_angle_deg=math.degrees(alpha),
            radius_m=radius,
            linear_density_tex=linear_density,
            mass_per_length=mass_per_length,
            fibres_per_section=fibres,
            tensile_rigidity_n=tensile,
            hardening_n=hardening,
            shear_rigidity_n=g_f * fibre_area,
            bending_rigidity_nm2=bending,
            torsional_rigidity_nm2=torsion,
            bending_free_slip_nm2=free_bending,
            bending_no_slip_nm2=no_slip_bending,
            torsion_free_slip_nm2=free_torsion,
            torsion_no_slip_nm2=no_slip_torsion,
            solid_bending_rigidity_nm2=e_f * fibre_area**2 / (4.0 * math.pi),
        )

    @property
    def bending_vs_solid(self) -> float:
        """EI over the solid rod of the same mass (1 for the solid model)."""
        return self.bending_rigidity_nm2 / self.solid_bending_rigidity_nm2

    def section(self) -> RodSection:
        """The engine's :class:`~yarnfit.engine.RodSection` of this yarn; the hardening acts in
        tension and compression alike (the paper derives it from tensile tests only)."""
        from .engine import RodSection  # the engine compiles Numba kernels: only when a rod is built

        return RodSection(
            tensile_rigidity=self.tensile_rigidity_n,
            shear_rigidity=self.shear_rigidity_n,
            bending_rigidity=(self.bending_rigidity_nm2, self.bending_rigidity_nm2),
            torsional_rigidity=self.torsional_rigidity_nm2,
            mass_per_length=self.mass_per_length,
            hardening_tension=self.hardening_n,
            hardening_compression=self.hardening_n,
        )

    def to_dict(self) -> dict:
        """The material file's ``yarn`` figures (SI units, unit in every key)."""
        return {
            "model": self.model,
            "spinning": self.spinning,
            "linear_density_tex": self.linear_density_tex,
            "fibres_per_section": self.fibres_per_section,
            "packing_fraction": self.packing_fraction,
            "twist_angle_deg": self.twist_angle_deg,
            "radius_m": self.radius_m,
            "tensile_rigidity_n": self.tensile_rigidity_n,
            "hardening_n": self.hardening_n,
            "shear_rigidity_n": self.shear_rigidity_n,
            "bending_rigidity_nm2": self.bending_rigidity_nm2,
            "torsional_rigidity_nm2": self.torsional_rigidity_nm2,
            "bending_vs_solid": self.bending_vs_solid,
            "limits": {
                "bending_free_slip_nm2": self.bending_free_slip_nm2,
                "bending_no_slip_nm2": self.bending_no_slip_nm2,
                "torsion_free_slip_nm2": self.torsion_free_slip_nm2,
                "torsion_no_slip_nm2": self.torsion_no_slip_nm2,
            },
        }

    def describe(self) -> list[str]:
        """Lines for the command line, in textile units beside SI."""
        fibres = "–" if self.fibres_per_section is None else f"{self.fibres_per_section:.0f}"
        spinning = "" if self.spinning is None else f", {self.spinning}"
        return [
            f"yarn ({self.model}{spinning}): {self.linear_density_tex:.4g} tex, {fibres} fibres per section, "
            f"φ {self.packing_fraction:.2f}, twist {self.twist_angle_deg:.1f}°, r {self.radius_m * 1e6:.4g} µm",
            f"  EA {self.tensile_rigidity_n:.4g} N, EI {self.bending_rigidity_nm2:.4g} N·m² "
            f"({self.bending_rigidity_nm2 * 1e9:.4g} mN·mm²), GJ {self.torsional_rigidity_nm2:.4g} N·m² "
            f"({self.torsional_rigidity_nm2 * 1e9:.4g} mN·mm²), EI / solid rod of the same mass {self.bending_vs_solid:.3g}",
        ]


def tensile_helix_factor(t2: float) -> float:
    """``⟨cos⁴θ⟩ = 1/(1 + t²) = cos²α`` over the idealised helix's section, ``t = tan α``."""
    return 1.0 / (1.0 + t2)


def hardening_helix_factor(t2: float) -> float:
    """``⟨cos⁶θ⟩ = (2 + t²)/(2 (1 + t²)²)`` over the idealised helix's section."""
    return (2.0 + t2) / (2.0 * (1.0 + t2) ** 2)


def mean_cos_helix(t2: float) -> float:
    """``⟨cos θ⟩ = 2 (√(1 + t²) − 1)/t²`` (1 at t = 0) over the idealised helix's section."""
    return 1.0 if t2 == 0.0 else 2.0 / (math.sqrt(1.0 + t2) + 1.0)


def no_slip_bending_factor(t2: float) -> float:
    """``f = 4 ∫₀¹ u³ du / (1 + u² t²)² = (2/t⁴)(ln(1 + t²) − t²/(1 + t²))``: the no-slip bending
    rigidity of the helix over that of parallel fibres (1 at t = 0)."""
    if t2 < _SERIES_T2:
        return 1.0 - 4.0 * t2 / 3.0 + 1.5 * t2 * t2
    return 2.0 / t2**2 * (math.log1p(t2) - t2 / (1.0 + t2))
