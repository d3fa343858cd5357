"""Isotropic parts of an orthotropic shell for MuJoCo's built-in flex elasticity.

MuJoCo's 2D flexes have one elastic law of their own: isotropic plane-stress StVK with Green strain
(``<elasticity young poisson thickness elastic2d>``). In the convention of
:mod:`yarnfit.shell` (energy per area ``(h/2) εᵀ S ε``, ``ε = (E00, E11, 2 E01)``) its membrane is

    S_iso(E, ν) = E C(ν),   C(ν) = [[1, ν, 0], [ν, 1, 0], [0, 0, (1 − ν)/2]] / (1 − ν²)

(``λ* + 2μ = E/(1 − ν²)``, ``λ* = Eν/(1 − ν²)``, ``μ = E/(2(1 + ν))``), and its bending stores
``D κ²/2`` per area for a cylindrical bend, ``D = E h³/(12(1 − ν²))``.

What it gives, one function each:

* :func:`builtin_isotropic` — the **split**. The ``yarnfit.shell`` plugin's forces are explicit
  under every integrator, MuJoCo's own elasticity is implicit under ``discrete``. One degree of
  freedom of mass ``m`` under semi-implicit stepping with implicit stiffness ``k_b`` and explicit
  stiffness ``k_r`` is stable iff ``−k_b ≤ k_r ≤ k_b + 4m/Δt²``, for every ``Δt`` iff
  ``|k_r| ≤ k_b``. So the built-in part carries ``S_iso ⪰ S/2``: the explicit remainder
  ``S − S_iso`` then lies between ``−S_iso`` and ``+S_iso`` whatever the material's anisotropy.
  Among those, the one of least trace (least added stiffness).
* :func:`isotropic_fallback` — the **fallback** for hosts without the plugin: one isotropic
  material (E, ν, h) that matches the geometric means of the weft and warp tensile and bending
  stiffnesses.
* :func:`builtin_elasticity` — the split rounded to what an MJCF file can hold (``spec.to_xml()``
  writes 6 significant digits), rounded so that ``S_iso ⪰ S/2`` still holds exactly.
* :func:`anisotropic_share` — the **anisotropic share** the plugin writes over MuJoCo's isotropic
  membrane metric (its key ``implicit_share``): half the tangent the isotropic share covers
  (:func:`membrane_to_cover`: ``S``, or the ridge membrane's largest within the strain bound)
  itself, in the material frame, so that the implicit part is no stiffer than that in any mode (the
  soft modes are no longer held back by a drag sized for the stiffest; plugins/README.md, Split).
  The ``<elasticity>`` is then :func:`builtin_elasticity`'s as before: it sizes the bending share
  and allocates the metric.

Nothing here imports ``mujoco``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import eigvalsh
from scipy.optimize import minimize_scalar

from ..shell import ShellMaterial

__all__ = [
    "DEFAULT_STIFFENING_BOUND",
    "MJCF_DIGITS",
    "MUJOCO_POISSON_MAX",
    "POISSON_LIMIT",
    "BuiltinElasticity",
    "IsotropicFallback",
    "IsotropicPart",
    "anisotropic_share",
    "builtin_bending_rigidity",
    "builtin_elasticity",
    "builtin_isotropic",
    "membrane_to_cover",
    "isotropic_fallback",
    "isotropic_stiffness",
]

# MuJoCo 4.0 rejects a Poisson ratio outside [0, 0.5) ("Poisson ratio must be in [0, 0.5)",
# measured: 0.4999999 compiles, 0.5 and -0.1 do not). The bound is the 3D one (λ diverges at 0.5);
# plane stress stays finite there, but a ratio a hair below 0.5 would sit on MuJoCo's own check.
MUJOCO_POISSON_MAX = 0.5
# Largest ratio the split and the fallback use: clearly inside MuJoCo's range, and the plane-stress
# ratio λ*/μ = 2ν/(1 − ν) = 1.92 at 0.49 is already close to its limit of 2 at 0.5, so a larger
# bound would change the split's trace by well under a percent.
POISSON_LIMIT = 0.49
# Strain (dimensionless, every Voigt component within ±) up to which the built-in membrane share
# covers half the strain-stiffening membrane's largest tangent (builtin_elasticity). Measured on the
# hanging 0.5 m cloth (40 × 40, two corners pinned, discrete) with the earlier polynomial membrane:
# polyester jersey's explicit stiffening diverged at 1 and 4 ms with no cover and ran 2 s stably at
# both with 1 % (so did wool and cotton jersey); 2 % doubles that margin. With a ridge membrane
# (session 35, validation/bench.py plugin_nonlinear_stable_step, 2 cm cells): 16 ms stable with this
# cover, 2.8 ms without. A larger cover costs drag in the material's soft modes (plugins/README.md, the split's
# trade-off): on the sphere at 16 ms steps a cotton jersey's centre of mass still stood 1.6, 1.9
# and 2.5 cm above its 1 ms rest after 2 s with 2, 5 and 10 % cover.
DEFAULT_STIFFENING_BOUND = 0.02
# Significant digits mujoco.MjSpec.to_xml writes for a real attribute (%g; measured on 4.0.0:
# young=123456.789 is written as "123457").
MJCF_DIGITS = 6
# The split's objective is scanned on this many Poisson ratios before a bounded minimisation
# refines the best one: the objective is a maximum of smooth functions of ν (kinks where the
# binding eigenvalue changes), so a local search alone could stop in the wrong branch. 1/200 of the
# range brackets every branch of the 3×3 problem.
POISSON_SCAN = 201
# Poisson ratio tolerance of the refinement: far below anything the 6-digit file resolves.
POISSON_XATOL = 1e-10
# The anisotropic share's least eigenvalue, relative to its largest: half the cover may be singular
# (a membrane with no tangent in some mode within the bound: a ridge membrane fitted without a base),
# and MuJoCo factorises the step's matrix with it (the plugin refuses a share that is not positive
# definite). A mode that stiff adds ~1e-6 of the stiffest mode's drag, nothing a drape sees.
SHARE_FLOOR = 1e-6
# A weft/warp ratio or a shear stiffness within 1 % of the fallback's is reported as matched: the
# fit's own standard errors are rarely below a percent.
ANISOTROPY_NOTE_RTOL = 0.01


class IsotropicPart(NamedTuple):
    """Isotropic material for MuJoCo's built-in elasticity, at the material's thickness."""

    young_pa: float
    poisson: float


class BuiltinElasticity(NamedTuple):
    """``<elasticity young poisson thickness elastic2d>`` of the split, exactly representable in an
    MJCF file. ``bending``: the built-in part also bends (``elastic2d="both"``), its rigidity
    ``young thickness³ / (12 (1 − poisson²))``; else it only stretches (``"stretch"``)."""

    young_pa: float
    poisson: float
    thickness_m: float
    bending: bool = False

    @property
    def elastic2d(self) -> str:
        return "both" if self.bending else "stretch"

    @property
    def bending_rigidity_nm(self) -> float:
        """D (N·m) of the built-in hinge bending, 0 without it."""
        return self.young_pa * self.thickness_m**3 / (12.0 * (1.0 - self.poisson**2)) if self.bending else 0.0


class IsotropicFallback(NamedTuple):
    """Isotropic stand-in for an orthotropic material (MuJoCo's ``elastic2d="both"`` alone).

    Attributes:
        young_pa: E (Pa).
        poisson: ν, within ``[0, POISSON_LIMIT]``.
        thickness_m: h (m).
        notes: what the isotropic material cannot carry over, in words: a limited Poisson ratio,
            the weft/warp anisotropy lost, a shear stiffness that differs from the material's.
    """

    young_pa: float
    poisson: float
    thickness_m: float
    notes: tuple[str, ...]


def isotropic_stiffness(young_pa: float, poisson: float) -> np.ndarray:
    """``S_iso (3, 3)`` (Pa) of MuJoCo's plane-stress membrane in yarnfit's Voigt convention."""
    return young_pa * _unit_stiffness(poisson)


def membrane_to_cover(material: ShellMaterial, stiffening_bound: float = 0.0) -> np.ndarray:
    """``(3, 3)`` (Pa): the membrane tangent the built-in part must cover half of: ``S``, or with a
    strain-stiffening membrane the largest tangent it reaches while every Voigt strain stays within
    ``±stiffening_bound`` (:meth:`~yarnfit.shell.RidgeMembrane.largest_tangent`; at 0, its tangent
    at zero strain, the one-sided ridges included): the ridges' forces are explicit, so the implicit
    share must grow with them for the step to stay stable."""
    if material.nonlinear is None:
        return material.S
    return material.nonlinear.largest_tangent(stiffening_bound)


def builtin_isotropic(material: ShellMaterial, stiffening_bound: float = 0.0) -> IsotropicPart:
    """The isotropic part MuJoCo's implicit built-in elasticity should carry (see the module
    docstring): ``S_iso(E, ν) ⪰ S/2`` of least trace, ``ν ∈ [0, POISSON_LIMIT]``, thickness the
    material's; with ``stiffening_bound``, ``S`` is :func:`membrane_to_cover`'s tangent.

    For each ν the least admissible E is the largest generalized eigenvalue of ``(S/2, C(ν))``;
    the trace ``E(ν) tr C(ν)`` is then minimised over ν. An isotropic material ``S = E0 C(ν0)``
    (ν0 within the bound) gives ``(E0/2, ν0)``: a PSD difference has non-negative trace, so
    ``tr S_iso ≥ tr S/2`` with equality only at ``S_iso = S/2``.

    Raises:
        ValueError: the membrane block is not positive definite.
    """
    if not material.membrane_positive_definite:
        material.check_positive_definite()  # raises, naming the entries
    half = 0.5 * membrane_to_cover(material, stiffening_bound)

    def trace(poisson: float) -> float:
        unit = _unit_stiffness(poisson)
        return _least_young(half, unit) * float(np.trace(unit))

    grid = np.linspace(0.0, POISSON_LIMIT, POISSON_SCAN)
    values = [trace(nu) for nu in grid]
    best = int(np.argmin(values))
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
    refined = minimize_scalar(trace, bounds=(low, high), method="bounded", options={"xatol": POISSON_XATOL})
    poisson = float(refined.x) if refined.fun < values[best] else float(grid[best])
    return IsotropicPart(_least_young(half, _unit_stiffness(poisson)), poisson)


def anisotropic_share(material: ShellMaterial, stiffening_bound: float = DEFAULT_STIFFENING_BOUND) -> np.ndarray:
    """``C (3, 3)`` (Pa, at the material's thickness, material-frame Voigt strain): the implicit
    membrane share the plugin's ``implicit_share`` key writes into MuJoCo's metric, half of
    :func:`membrane_to_cover`'s tangent (so ``−C ⪯ T − C ⪯ C`` for every tangent ``T`` the membrane
    reaches within ``±stiffening_bound``, the split's stability condition, in every mode), its
    eigenvalues floored at :data:`SHARE_FLOOR` of the largest so that it is positive definite.

    Raises:
        ValueError: the membrane block is not positive definite.
    """
    if not material.membrane_positive_definite:
        material.check_positive_definite()  # raises, naming the entries
    half = 0.5 * membrane_to_cover(material, stiffening_bound)  # symmetric: S, or sums of outer products
    values, vectors = np.linalg.eigh(half)
    floor = SHARE_FLOOR * values.max()
    if values.min() >= floor:
        return half
    return (vectors * np.maximum(values, floor)) @ vectors.T


def builtin_bending_rigidity(material: ShellMaterial) -> float:
    """Least isotropic hinge rigidity D (N·m) at least as stiff as the material's bending in every
    mode: ``D diag(1, 1, ½) ⪰ h³ B``, i.e. ``D = h³ max(λ_max(B_normal), 2 b22)`` (with a signed
    bending, ``B`` its stiffer side's, :attr:`~yarnfit.shell.SignedBending.upper`).

    MuJoCo's 2D hinge bending stores ``½ D (κ00² + κ11² + 2 κ01²)`` per area (measured on a 21 × 21
    grid: a cylinder, a sphere and a saddle at 0.95, 1.9 and 1.9 times ``½ D κ²``, the 5 % the free
    edges' missing hinges), ours ``½ h³ κᵀ B κ`` with ``κ = (κ00, κ11, 2 κ01)``.

    Raises:
        ValueError: ``B`` is not positive definite, or the signed bending not convex.
    """
    signed = material.signed_bending
    if not material.bending_positive_definite or (signed is not None and not signed.positive_definite):
        material.check_positive_definite()  # raises, naming the entries
    # A signed bending (ShellMaterial.signed_bending): its stiffer side in each direction, above
    # every quadrant's matrix.
    B = material.B if signed is None else signed.upper
    return material.thickness**3 * max(float(eigvalsh(B[:2, :2])[-1]), 2.0 * B[2, 2])


def builtin_elasticity(material: ShellMaterial, digits: int = MJCF_DIGITS, *, bending: bool = True,
                       stiffening_bound: float = DEFAULT_STIFFENING_BOUND) -> BuiltinElasticity:
    """The split's built-in part (:func:`builtin_isotropic`, and with ``bending`` an isotropic
    hinge bending :func:`builtin_bending_rigidity`), every value exactly representable in
    ``digits`` significant digits so that the ``<elasticity>`` attributes and the plugin's
    ``builtin_*`` keys written to an MJCF file are the same numbers.

    MuJoCo ties the built-in bending to the membrane, ``D_b = E_b t_b³/(12(1 − ν²))`` with the same
    ``E_b t_b`` as its membrane stiffness (N/m), so the thickness is what sets the bending share:
    ``t_b = √(12 (1 − ν²) D / (E_b t_b))``. Without bending ``t_b`` is the material's thickness.
    Thickness (with bending) is rounded **up**, ν to nearest, then ``E_b`` is the least admissible
    modulus for them (``t_b E_b C(ν_b) ⪰ h S/2``), rounded **up**: rounding keeps the built-in
    membrane at least half the material's and its bending at least the material's in every mode.

    Why at least the material's, where the membrane needs half: the plugin removes MuJoCo's hinge
    forces exactly (its own operator is what the total bends with), so the explicit remainder is
    ``K_plugin(B) − K_hinge(D)``; one degree of freedom stays stable at every step while that lies
    between ``−K_hinge`` and ``+K_hinge``, and the two discrete operators differ by up to 1.8× on
    some meshes (plugins/README.md), which a full share covers and a half share does not.

    ``stiffening_bound`` (dimensionless Voigt strain, :data:`DEFAULT_STIFFENING_BOUND`): the
    membrane share covers half the strain-stiffening membrane's tangent up to that strain
    (:func:`membrane_to_cover`; 0: half of S only, as for a linear material).
    """
    part = builtin_isotropic(material, stiffening_bound)
    poisson = min(_round(part.poisson, digits), _round_down(POISSON_LIMIT, digits))
    if bending:
        stretch = part.young_pa * material.thickness  # E_b t_b (N/m)
        thickness = _round_up(math.sqrt(12.0 * (1.0 - poisson**2) * builtin_bending_rigidity(material) / stretch),
                              digits)
    else:
        thickness = _round(material.thickness, digits)
    cover = membrane_to_cover(material, stiffening_bound)
    young = _least_young(0.5 * cover * (material.thickness / thickness), _unit_stiffness(poisson))
    return BuiltinElasticity(_round_up(young, digits), poisson, thickness, bending)


def isotropic_fallback(material: ShellMaterial) -> IsotropicFallback:
    """One isotropic (E, ν, h) for MuJoCo's built-in elasticity alone (no plugin).

    Matches, with the engineering constants of ``docs/design.md`` §3:

    * tensile stiffness: ``E h = √(weft_stretch · warp_stretch)`` (N/m; isotropic uniaxial
      stiffness with free width is ``E h``);
    * bending: ``E h³/(12(1 − ν²)) = √(bending_weft · bending_warp)`` (N·m; MuJoCo stores
      ``D κ²/2`` per area for a cylindrical bend, ours ``½ bending κ²``);
    * ``ν = √(poisson_weft · poisson_warp)``, limited to ``[0, POISSON_LIMIT]`` (0 when the two
      have opposite signs, as a ridge membrane's can): a limited ratio is said so in ``notes``,
      never silently.

    Hence ``h = √(12 (1 − ν²) D / (E h))`` and ``E = (E h)/h``. An isotropic material whose
    bending is Kirchhoff's (``b00 = b11 = E/(12(1 − ν²))``) returns itself.

    Raises:
        ValueError: ``S`` or ``B`` is not positive definite.
    """
    eng = material.engineering()  # raises for an indefinite material
    stretch = math.sqrt(eng["weft_stretch_n_per_m"] * eng["warp_stretch_n_per_m"])
    bending = math.sqrt(eng["bending_weft_nm"] * eng["bending_warp_nm"])
    notes = []
    # For StVK the product is s01²/(s00 s11) >= 0 and s01 < 0 flips both ratios. A ridge membrane's
    # small-strain ratios come from a pull in each direction (one-sided ridges at zero), and a knit
    # can contract across a course-wise pull and widen across a wale-wise one: no isotropic ratio
    # has both, so the fallback takes 0 and says so.
    poisson_weft, poisson_warp = eng["poisson_weft"], eng["poisson_warp"]
    if poisson_weft * poisson_warp < 0.0:
        poisson = 0.0
        notes.append(f"Poisson ratio limited: the material's ν_weft = {poisson_weft:.4g} and ν_warp = "
                     f"{poisson_warp:.4g} have opposite signs, which no isotropic material has; used 0")
    else:
        requested = math.copysign(math.sqrt(poisson_weft * poisson_warp), poisson_weft + poisson_warp)
        poisson = min(max(requested, 0.0), POISSON_LIMIT)
        if poisson != requested:
            notes.append(f"Poisson ratio limited: the material's geometric mean √(ν_weft ν_warp) = {requested:.4g} "
                         f"is outside [0, {POISSON_LIMIT}] (MuJoCo accepts [0, {MUJOCO_POISSON_MAX})); used {poisson:g}")
    thickness = math.sqrt(12.0 * (1.0 - poisson**2) * bending / stretch)
    young = stretch / thickness
    ratios = {
        "weft/warp tensile stiffness": eng["weft_stretch_n_per_m"] / eng["warp_stretch_n_per_m"],
        "weft/warp bending": eng["bending_weft_nm"] / eng["bending_warp_nm"],
    }
    for what, ratio in ratios.items():
        if not math.isclose(ratio, 1.0, rel_tol=ANISOTROPY_NOTE_RTOL):
            notes.append(f"anisotropy lost: {what} is {ratio:.3g} in the material, 1 in the fallback")
    shear = young * thickness / (2.0 * (1.0 + poisson))
    if not math.isclose(shear, eng["shear_n_per_m"], rel_tol=ANISOTROPY_NOTE_RTOL):
        notes.append(f"shear stiffness {shear:.4g} N/m in the fallback against {eng['shear_n_per_m']:.4g} N/m "
                     "in the material")
    return IsotropicFallback(young, poisson, thickness, tuple(notes))



def _unit_stiffness(poisson: float) -> np.ndarray:
    """``C(ν) = S_iso / E`` (dimensionless)."""
    d = 1.0 / (1.0 - poisson**2)
    return np.array([[d, poisson * d, 0.0], [poisson * d, d, 0.0], [0.0, 0.0, 0.5 / (1.0 + poisson)]])


def _least_young(half: np.ndarray, unit: np.ndarray) -> float:
    """Least ``E`` with ``E unit ⪰ half``: the largest generalized eigenvalue of ``(half, unit)``."""
    return float(eigvalsh(half, unit)[-1])


def _round(value: float, digits: int) -> float:
    return float(f"{value:.{digits}g}")


def _ulp_of_digits(value: float, digits: int) -> float:
    """One unit in the last of ``digits`` significant digits of ``value`` (> 0)."""
    return 10.0 ** (math.floor(math.log10(value)) - digits + 1)


def _round_up(value: float, digits: int) -> float:
    """Least number with ``digits`` significant digits that is ≥ ``value`` (> 0)."""
    rounded = _round(value, digits)
    return rounded if rounded >= value else _round(rounded + _ulp_of_digits(rounded, digits), digits)


def _round_down(value: float, digits: int) -> float:
    """Largest number with ``digits`` significant digits that is ≤ ``value`` (> 0)."""
    rounded = _round(value, digits)
    return rounded if rounded <= value else _round(rounded - _ulp_of_digits(rounded, digits), digits)
