"""Fibres: the first stage of yarnfit, from a fibre name on a label to the data the yarn model needs.

A :class:`Fiber` holds what the yarn model needs from a fibre, in SI units: density
(kg/m³), the modulus at zero strain ``E_min`` and the tangent modulus at the breaking strain
``E_max`` (Pa), the breaking strain ``ε_max`` (dimensionless), Poisson's ratio and the
fibre-on-fibre friction coefficient (and, for the fibre-assembly yarn, fineness and specific
rigidities). :class:`yarnfit.yarn.Yarn` builds the rod's section from it in the next stage.

Nonlinear stretch (paper §4.1, ``docs/design.md`` §4): the tangent modulus grows linearly with
strain, ``E(ε) = E_min + k |ε|``, with the slope chosen so that it reaches ``E_max`` at
``ε_max``::

    k = (E_max − E_min) / ε_max        (Pa)

A fibre with a single handbook modulus is linear: ``E_min == E_max`` and ``k = 0``.

What the fibre-assembly yarn (:mod:`yarnfit.yarn`) needs besides: the fibre's fineness (linear
density, dtex; for a round fibre ``ρ π d²/4``), its specific flexural and torsional rigidities
``R_b``, ``R_t`` (N·m²/tex²; the handbook's mN·mm²/tex² are 10⁻⁹ N·m²/tex²), so that one fibre of
fineness ``T_f`` (tex) has bending rigidity ``R_b T_f²`` and torsional rigidity ``R_t T_f²``,
and the spinning system its yarns are usually made by (``ring-spun`` staple or ``filament``).
They are optional: the solid-rod yarn of the paper needs none of them.

:data:`FIBERS` is the built-in database. Wool, cotton and polyester carry the paper's values
unchanged. The other fibres come from W. E. Morton & J. W. S. Hearle, *Physical Properties of
Textile Fibres*, 4th ed., Woodhead 2008 ("M&H"): densities at 65 % r.h. from Table 5.1, breaking
extensions and initial moduli at 65 % r.h., 20 °C from Tables 13.1 (Meredith's data) and 13.2.
M&H give moduli as specific moduli in N/tex; ``E = specific modulus × ρ``
(1 N/tex = 10⁶ N·m/kg). Specific flexural and torsional rigidities are M&H Table 17.2 (65 % r.h.,
20 °C), read from two independent transcriptions of the table that agree; the primary table was
not consulted.

Units checked against the sources (issue 12): the M&H-derived moduli were already converted from
N/tex with ρ (nylon 3.0 N/tex × 1140 kg/m³ = 3.42 GPa, ...). The paper's three fibres are given
in GPa by its table, whose source (Serra et al. 2019) we could not read; beside M&H they are: wool
E_min 2.3 GPa against Botany 64s 2.3 N/tex = 3.0 GPa (Table 13.1), cotton 5.3 GPa against
Uppers 5.0 N/tex = 7.6 GPa (Table 13.1; 7.7 GPa in Table 17.2), polyester 1.5–10.6 GPa against
Terylene 10.6 N/tex = 14.7 GPa (Table 13.2). Wool's and polyester's upper figures equal M&H's N/tex
numbers, so a N/tex–GPa mix-up in the paper's table is possible, but its E_min/E_max are the two
ends of a fitted hardening law, not an initial modulus, and the paper's predictions are made with
them. They are kept unchanged; ``docs/design.md`` §4 records the comparison. Every entry's ``source`` names the origin of each value and says
plainly which values are assumptions: no fibre-level Poisson's ratio was found for any fibre but
cotton and polyester, nor a friction coefficient for silk, linen and acrylic. Users with better
data supply their own fibre as JSON (:func:`load_fiber_file`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from .checks import check_keys, finite_number, positive_or_none
from .jsonfile import read_json

__all__ = ["FIBERS", "Fiber", "UnknownFiberError", "get_fiber", "load_fiber_file"]

# Largest accepted breaking strain: textile fibres break below ~0.7 (wool, nylon 6 staple); 1.5
# leaves room for textured or partly elastomeric user fibres but rejects percentages typed as
# fractions (e.g. 30 for 30 %).
MAX_BREAKING_STRAIN = 1.5
# Largest accepted friction coefficient: fibre-on-fibre values lie in 0.1–0.8; above 2 is a typo.
MAX_FRICTION = 2.0

# Spinning systems the yarn model knows (yarnfit.yarn): staple fibres twisted on a ring frame, and
# continuous filaments.
SPINNING_SYSTEMS = ("ring-spun", "filament")
# The optional fibre data of the fibre-assembly yarn, numeric.
ASSEMBLY_KEYS = ("fineness_dtex", "flexural_rigidity_nm2_per_tex2", "torsional_rigidity_nm2_per_tex2")
# Every optional field of a fibre (written into material files where known).
OPTIONAL_FIBER_FIELDS = ASSEMBLY_KEYS + ("spinning",)
# The handbook's unit of specific rigidity, mN·mm²/tex², in N·m²/tex².
MN_MM2_PER_TEX2 = 1e-9


@dataclass(frozen=True)
class Fiber:
    """Mechanical data of one textile fibre (SI units).

    Attributes:
        name: fibre name, the key used by :func:`get_fiber` (lower case for built-in fibres).
        density_kg_m3: ρ (kg/m³).
        young_min_pa: E_min (Pa), the modulus at zero strain.
        young_max_pa: E_max (Pa), the tangent modulus reached at the breaking strain;
            equal to ``young_min_pa`` for a linear fibre.
        breaking_strain: ε_max (dimensionless), e.g. 0.1 for 10 % extension at break.
        poisson: Poisson's ratio ν, in (−1, 0.5); gives the shear modulus G = E / (2 (1 + ν)).
        friction: fibre-on-fibre friction coefficient μ, in [0, 2].
        source: citation for the values.
        fineness_dtex: linear density of one fibre (dtex = 10⁻⁷ kg/m), or ``None``.
        flexural_rigidity_nm2_per_tex2: specific flexural rigidity R_b (N·m²/tex²), or ``None``.
        torsional_rigidity_nm2_per_tex2: specific torsional rigidity R_t (N·m²/tex²), or ``None``.
        spinning: the spinning system of this fibre's usual yarns (one of :data:`SPINNING_SYSTEMS`),
            or ``None`` (ring-spun staple).
    """

    name: str
    density_kg_m3: float
    young_min_pa: float
    young_max_pa: float
    breaking_strain: float
    poisson: float
    friction: float
    source: str = ""
    fineness_dtex: float | None = None
    flexural_rigidity_nm2_per_tex2: float | None = None
    torsional_rigidity_nm2_per_tex2: float | None = None
    spinning: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"name must be a non-empty string, got {self.name!r}")
        # Store plain floats so that ints from JSON or literals compare and print like floats.
        for field_name in ("density_kg_m3", "young_min_pa", "young_max_pa", "breaking_strain", "poisson", "friction"):
            object.__setattr__(self, field_name, finite_number(getattr(self, field_name), field_name))

        if self.density_kg_m3 <= 0.0:
            raise ValueError(f"density_kg_m3 must be > 0, got {self.density_kg_m3!r}")
        if self.young_min_pa <= 0.0:
            raise ValueError(f"young_min_pa must be > 0, got {self.young_min_pa!r}")
        if self.young_min_pa > self.young_max_pa:
            raise ValueError(
                f"young_min_pa ({self.young_min_pa!r}) must not exceed young_max_pa ({self.young_max_pa!r})"
            )
        if not 0.0 < self.breaking_strain <= MAX_BREAKING_STRAIN:
            raise ValueError(
                f"breaking_strain must lie in (0, {MAX_BREAKING_STRAIN}] (a fraction, not a percentage), "
                f"got {self.breaking_strain!r}"
            )
        if not -1.0 < self.poisson < 0.5:
            raise ValueError(f"poisson must lie in (-1, 0.5), got {self.poisson!r}")
        if not 0.0 <= self.friction <= MAX_FRICTION:
            raise ValueError(f"friction must lie in [0, {MAX_FRICTION}], got {self.friction!r}")
        for field_name in ASSEMBLY_KEYS:
            object.__setattr__(self, field_name, positive_or_none(getattr(self, field_name), field_name))
        if self.spinning is not None and self.spinning not in SPINNING_SYSTEMS:
            raise ValueError(f"spinning must be one of {', '.join(SPINNING_SYSTEMS)}, got {self.spinning!r}")

    @property
    def fineness_tex(self) -> float | None:
        """One fibre's linear density in tex (g/km), or ``None``."""
        return None if self.fineness_dtex is None else 0.1 * self.fineness_dtex

    @property
    def hardening_pa(self) -> float:
        """Stretch hardening slope ``k = (E_max − E_min) / ε_max`` (Pa); 0 for a linear fibre."""
        return (self.young_max_pa - self.young_min_pa) / self.breaking_strain

    def describe(self) -> str:
        """One line for ``yarnfit materials``: name, ρ, E range, ε_max, ν, μ and the source's first clause."""
        e_min, e_max = self.young_min_pa / 1e9, self.young_max_pa / 1e9
        modulus = f"{e_min:.1f} GPa" if self.young_min_pa == self.young_max_pa else f"{e_min:.1f}–{e_max:.1f} GPa"
        short_source = self.source.split(";")[0].strip() or "no source"
        fineness = "  –      " if self.fineness_dtex is None else f"{self.fineness_dtex:4.2f} dtex"
        rigidity = ("R_b, R_t –" if self.flexural_rigidity_nm2_per_tex2 is None
                    else f"R_b {self.flexural_rigidity_nm2_per_tex2 * 1e9:.3g}, R_t "
                         f"{(self.torsional_rigidity_nm2_per_tex2 or math.nan) * 1e9:.3g} mN·mm²/tex²")
        return (
            f"{self.name:<10} {self.density_kg_m3:5.0f} kg/m³  E {modulus:<13} ε_max {self.breaking_strain:.2f}  "
            f"ν {self.poisson:.2f}  μ {self.friction:.2f}  {fineness} {self.spinning or '':<9}  {rigidity}  ({short_source})"
        )


def _modulus_from_specific(n_per_tex: float, density_kg_m3: float) -> float:
    """Young's modulus (Pa) from a specific modulus (N/tex): 1 N/tex = 10⁶ N·m/kg, times ρ (kg/m³)."""
    return n_per_tex * 1e6 * density_kg_m3


def fineness_from_diameter(diameter_m: float, density_kg_m3: float) -> float:
    """Fineness (dtex) of a round fibre of diameter ``d`` (m): ``ρ π d²/4`` kg/m, 1 dtex = 10⁻⁷ kg/m."""
    return density_kg_m3 * math.pi * diameter_m**2 / 4.0 * 1e7


_PAPER = "Zhang et al., Estimating Cloth Elasticity Parameters From Homogenized Yarn-Level Models, supplementary fibre table (after Serra et al. 2019)"
# The only fibre-on-fibre table found lists static/kinetic pairs (rayon 0.35/0.26, nylon
# 0.47/0.40, polyester 0.15/0.12, cotton 0.51/0.26, wool with/against scale 0.13/0.11 and
# 0.61/0.38). Kinetic values are used: yarns slide at the contacts that friction acts on.
_FRICTION_NOTES = "lecture notes '3.1 Frictional Properties' (Scribd 764285656), primary source not given"
# Friction for fibres with no value found: the median of the five kinetic values sourced above
# (0.12, 0.245, 0.26, 0.26, 0.40).
_UNSOURCED_FRICTION = 0.26
_UNSOURCED_FRICTION_NOTE = f"μ {_UNSOURCED_FRICTION} unverified: no value found, median of the sourced μk"
# Poisson's ratio for fibres with no value found: one of the paper's two values, polyester's for
# the melt/solution-spun synthetics, cotton's for cellulose fibres and (lacking any protein-fibre
# value) for wool and silk. It enters only through G = E/(2(1 + ν)): shear and twist stiffness.
_NU_COTTON = "ν 0.36 assumed (cotton's value from the paper's notes, none found for this fibre)"
_NU_POLYESTER = "ν 0.25 assumed (polyester's value from the paper's notes, none found for this fibre)"

# Specific rigidities, M&H 2008 Table 17.2 (65 % r.h., 20 °C), mN·mm²/tex²; a range is used at its
# middle.
_MH_RIGIDITY = "R_b, R_t from Morton & Hearle 2008, Table 17.2 (mN·mm²/tex², 65 % r.h.)"
# Fineness that no handbook gave us: typical apparel values, marked as assumptions in the sources.
_ASSUMED_FINENESS = "fineness {:g} dtex assumed (typical apparel value; no handbook value found)"
# Cotton: micronaire (µg per inch) read as linear density is 0.3937 dtex per unit; Mic 4.0–4.9, the
# range of ring-spinning cottons in Rieter's spinning handbook, gives 1.58–1.93 dtex; its middle.
_COTTON_MICRONAIRE = 4.45
_MICRONAIRE_DTEX = 1e-9 / 0.0254 * 1e7
# Wool: M&H's tensile data are for Botany 64s; the 64s grade spans 20.60–22.04 µm mean fibre
# diameter (ASTM D3991, US wool grades); its middle.
_WOOL_DIAMETER_M = 21.32e-6
# Linen: no specific rigidity found. A round solid fibre of tensile modulus E has R_b = E/(4π ρ²)
# and, isotropic, R_t = G/(2π ρ²), G = E/(2(1 + ν)) (M&H ch. 17 with shape factor 1): an upper
# estimate, since flax is far softer in shear than an isotropic solid.
_LINEN_DENSITY = 1500.0
_NYLON_DENSITY = 1140.0
_SILK_DENSITY = 1340.0
_VISCOSE_DENSITY = 1490.0
_ACRYLIC_DENSITY = 1190.0

FIBERS: dict[str, Fiber] = {
    fiber.name: fiber
    for fiber in (
        Fiber(
            name="wool",
            density_kg_m3=1310.0,
            young_min_pa=2.3e9,
            young_max_pa=3.4e9,
            breaking_strain=0.3,
            poisson=0.36,
            friction=0.245,
            source=(
                f"{_PAPER}; ρ, E, ε_max from that table; {_NU_COTTON}; "
                f"μk 0.245 = mean of with-scale 0.11 and against-scale 0.38, {_FRICTION_NOTES}; "
                f"fineness of a round fibre of 21.32 µm (middle of the 64s grade, 20.60–22.04 µm, ASTM D3991: "
                f"M&H's tensile data are for Botany 64s); {_MH_RIGIDITY}: 0.24, 0.12"
            ),
            fineness_dtex=fineness_from_diameter(_WOOL_DIAMETER_M, 1310.0),
            flexural_rigidity_nm2_per_tex2=0.24 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.12 * MN_MM2_PER_TEX2,
            spinning="ring-spun",
        ),
        Fiber(
            name="cotton",
            density_kg_m3=1520.0,
            young_min_pa=5.3e9,
            young_max_pa=6.2e9,
            breaking_strain=0.1,
            poisson=0.36,
            friction=0.26,
            source=(
                f"{_PAPER}; ρ, E, ε_max from that table; ν from the paper's notes; μk {_FRICTION_NOTES}; "
                f"fineness from micronaire {_COTTON_MICRONAIRE} (middle of Mic 4.0–4.9, Rieter spinning handbook; "
                f"0.3937 dtex per Mic); {_MH_RIGIDITY}: 0.53, 0.16"
            ),
            fineness_dtex=_COTTON_MICRONAIRE * _MICRONAIRE_DTEX,
            flexural_rigidity_nm2_per_tex2=0.53 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.16 * MN_MM2_PER_TEX2,
            spinning="ring-spun",
        ),
        Fiber(
            name="polyester",
            density_kg_m3=1380.0,
            young_min_pa=1.5e9,
            young_max_pa=10.6e9,
            breaking_strain=0.4,
            poisson=0.25,
            friction=0.12,
            source=(
                f"{_PAPER}; ρ, E, ε_max from that table; ν from the paper's notes; μk {_FRICTION_NOTES}; "
                f"{_ASSUMED_FINENESS.format(1.7)}; {_MH_RIGIDITY}, Terylene: 0.30, 0.067"
            ),
            fineness_dtex=1.7,
            flexural_rigidity_nm2_per_tex2=0.30 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.067 * MN_MM2_PER_TEX2,
            spinning="filament",
        ),
        Fiber(
            name="nylon",
            density_kg_m3=_NYLON_DENSITY,
            young_min_pa=_modulus_from_specific(3.0, _NYLON_DENSITY),
            young_max_pa=_modulus_from_specific(3.0, _NYLON_DENSITY),
            breaking_strain=0.20,
            poisson=0.25,
            friction=0.40,
            source=(
                "Morton & Hearle 2008, Tables 5.1, 13.2; ρ at 65 % r.h.; nylon 6.6 medium-tenacity: "
                f"3.0 N/tex, ε_max 0.20; {_NU_POLYESTER}; μk {_FRICTION_NOTES}; {_ASSUMED_FINENESS.format(3.3)}; "
                f"{_MH_RIGIDITY}, nylon 6.6 (3 types): 0.15–0.22, 0.041–0.060"
            ),
            fineness_dtex=3.3,
            flexural_rigidity_nm2_per_tex2=0.185 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.0505 * MN_MM2_PER_TEX2,
            spinning="filament",
        ),
        Fiber(
            name="silk",
            density_kg_m3=_SILK_DENSITY,
            young_min_pa=_modulus_from_specific(7.3, _SILK_DENSITY),
            young_max_pa=_modulus_from_specific(7.3, _SILK_DENSITY),
            breaking_strain=0.234,
            poisson=0.36,
            friction=_UNSOURCED_FRICTION,
            source=(
                "Morton & Hearle 2008, Tables 5.1, 13.1; ρ at 65 % r.h.; silk: 7.3 N/tex, ε_max 0.234; "
                f"{_NU_COTTON}; {_UNSOURCED_FRICTION_NOTE}; {_ASSUMED_FINENESS.format(1.1)}; {_MH_RIGIDITY}: 0.60, 0.16"
            ),
            fineness_dtex=1.1,
            flexural_rigidity_nm2_per_tex2=0.60 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.16 * MN_MM2_PER_TEX2,
            spinning="filament",
        ),
        Fiber(
            name="viscose",
            density_kg_m3=_VISCOSE_DENSITY,
            # Handbook spread over variants (regular filament 4.8 N/tex to high-tenacity
            # 8.8 N/tex) read as E_min–E_max, as the paper does with its own ranges.
            young_min_pa=_modulus_from_specific(4.8, _VISCOSE_DENSITY),
            young_max_pa=_modulus_from_specific(8.8, _VISCOSE_DENSITY),
            breaking_strain=0.157,
            poisson=0.36,
            friction=0.26,
            source=(
                "Morton & Hearle 2008, Tables 5.1, 13.1, 13.2; ρ at 65 % r.h.; E from 4.8 N/tex (regular "
                "filament, Table 13.1) to 8.8 N/tex (high-tenacity, Table 13.2); ε_max 0.157 of Fibro regular "
                f"staple (Table 13.1); {_NU_COTTON}; μk rayon on rayon, {_FRICTION_NOTES}; "
                f"{_ASSUMED_FINENESS.format(1.7)}; {_MH_RIGIDITY}, Fibro staple: 0.35, 0.058–0.083"
            ),
            fineness_dtex=1.7,
            flexural_rigidity_nm2_per_tex2=0.35 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.0705 * MN_MM2_PER_TEX2,
            spinning="ring-spun",
        ),
        Fiber(
            name="linen",
            density_kg_m3=_LINEN_DENSITY,
            young_min_pa=_modulus_from_specific(18.0, _LINEN_DENSITY),
            young_max_pa=_modulus_from_specific(18.0, _LINEN_DENSITY),
            breaking_strain=0.030,
            poisson=0.36,
            friction=_UNSOURCED_FRICTION,
            source=(
                "Morton & Hearle 2008, Table 13.1; flax: 18.0 N/tex, ε_max 0.030; ρ 1500 unverified, not "
                "read from a table (Bunsell 2018, Table 1.1 gives 1.53 g/cm³; M&H Table 5.1 puts cellulose "
                f"fibres 0.03 lower at 65 % r.h.); {_NU_COTTON}; {_UNSOURCED_FRICTION_NOTE}; "
                f"{_ASSUMED_FINENESS.format(2.5)}; R_b, R_t unverified: estimated as a round isotropic solid "
                "of the fibre's E and ν (no Table 17.2 row for flax)"
            ),
            fineness_dtex=2.5,
            flexural_rigidity_nm2_per_tex2=_modulus_from_specific(18.0, _LINEN_DENSITY) / (4.0 * math.pi * _LINEN_DENSITY**2) * 1e-12,
            torsional_rigidity_nm2_per_tex2=(_modulus_from_specific(18.0, _LINEN_DENSITY) / (2.0 * (1.0 + 0.36)))
            / (2.0 * math.pi * _LINEN_DENSITY**2) * 1e-12,
            spinning="ring-spun",
        ),
        Fiber(
            name="acrylic",
            density_kg_m3=_ACRYLIC_DENSITY,
            young_min_pa=_modulus_from_specific(6.2, _ACRYLIC_DENSITY),
            young_max_pa=_modulus_from_specific(6.2, _ACRYLIC_DENSITY),
            breaking_strain=0.25,
            poisson=0.25,
            friction=_UNSOURCED_FRICTION,
            source=(
                "Morton & Hearle 2008, Tables 5.1, 13.2; ρ at 65 % r.h.; acrylic staple: 6.2 N/tex, "
                f"ε_max 0.25; {_NU_POLYESTER}; {_UNSOURCED_FRICTION_NOTE}; {_ASSUMED_FINENESS.format(1.7)}; "
                f"{_MH_RIGIDITY}, acrylic (3 types): 0.33–0.48, 0.12–0.18"
            ),
            fineness_dtex=1.7,
            flexural_rigidity_nm2_per_tex2=0.405 * MN_MM2_PER_TEX2,
            torsional_rigidity_nm2_per_tex2=0.15 * MN_MM2_PER_TEX2,
            spinning="ring-spun",
        ),
    )
}


class UnknownFiberError(ValueError):
    """A fibre name that is not in :data:`FIBERS`; the message lists the known names."""


def get_fiber(name: str) -> Fiber:
    """The built-in fibre called ``name`` (case-insensitive, surrounding blanks ignored).

    Raises:
        UnknownFiberError: ``name`` is not a built-in fibre.
    """
    key = name.strip().lower() if isinstance(name, str) else None
    if key not in FIBERS:
        raise UnknownFiberError(f"unknown fibre {name!r}; known fibres: {', '.join(sorted(FIBERS))}")
    return FIBERS[key]


_NUMERIC_KEYS = ("density_kg_m3", "young_min_pa", "young_max_pa", "breaking_strain", "poisson", "friction")
_REQUIRED_KEYS = ("name",) + _NUMERIC_KEYS
# Optional: what the fibre-assembly yarn needs (a round fibre may give its diameter instead of its
# fineness), and the usual spinning system.
_OPTIONAL_NUMERIC_KEYS = ASSEMBLY_KEYS + ("diameter_m",)
_ALLOWED_KEYS = _REQUIRED_KEYS + ("source", "spinning") + _OPTIONAL_NUMERIC_KEYS


def load_fiber_file(path: str | os.PathLike) -> Fiber:
    """A user fibre from a JSON file.

    The file holds one object with the keys ``name``, ``density_kg_m3``, ``young_min_pa``,
    ``young_max_pa``, ``breaking_strain``, ``poisson``, ``friction`` (SI units, as in
    :class:`Fiber`), optionally ``source``, and, for the fibre-assembly yarn model (the
    default), ``fineness_dtex`` (or ``diameter_m`` of a round fibre),
    ``flexural_rigidity_nm2_per_tex2`` and ``torsional_rigidity_nm2_per_tex2`` (N·m²/tex²: the
    handbook's mN·mm²/tex² times 10⁻⁹) and optionally ``spinning`` (``ring-spun`` or
    ``filament``). ``young_min_pa == young_max_pa`` makes a linear fibre. Example::

        {"name": "hemp", "density_kg_m3": 1480, "young_min_pa": 3.2e10, "young_max_pa": 3.2e10,
         "breaking_strain": 0.022, "poisson": 0.36, "friction": 0.3, "diameter_m": 2.2e-5,
         "flexural_rigidity_nm2_per_tex2": 1.1e-9, "torsional_rigidity_nm2_per_tex2": 0.3e-9,
         "source": "my tests"}

    Raises:
        ValueError: a one-line message starting with the file name: the file is missing or
            unreadable, is not valid JSON (with line and column), lacks keys or has unknown ones
            (all listed), has a non-numeric value, or fails :class:`Fiber` validation.
    """
    where, data = read_json(path, "fibre file")
    if not isinstance(data, dict):
        kind = type(data).__name__
        raise ValueError(f"{where}: expected a JSON object with keys {', '.join(_REQUIRED_KEYS)}, got a {kind}")

    check_keys(data, _REQUIRED_KEYS, where, allowed=_ALLOWED_KEYS)

    if "fineness_dtex" in data and "diameter_m" in data:
        raise ValueError(f"{where}: give fineness_dtex or diameter_m, not both")
    non_numeric = [
        f"{key}={data[key]!r}"
        for key in _NUMERIC_KEYS + _OPTIONAL_NUMERIC_KEYS
        if key in data and (isinstance(data[key], bool) or not isinstance(data[key], (int, float)))
    ]
    if non_numeric:
        raise ValueError(f"{where}: non-numeric values: {', '.join(non_numeric)}")
    for key in ("name", "source", "spinning"):
        if key in data and not isinstance(data[key], str):
            raise ValueError(f"{where}: {key} must be a string, got {data[key]!r}")

    fields = dict(data)
    if "diameter_m" in fields:
        diameter = fields.pop("diameter_m")
        if not (math.isfinite(diameter) and diameter > 0.0):
            raise ValueError(f"{where}: diameter_m must be a positive length in m, got {diameter!r}")
        fields["fineness_dtex"] = fineness_from_diameter(diameter, float(data["density_kg_m3"]))
    fields.setdefault("source", f"user fibre file {where}")
    try:
        return Fiber(**fields)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
