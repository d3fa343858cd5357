"""The yarn model (:mod:`yarnfit.yarn`): fibre + construction → the rod's rigidities.

1. every formula of the module docstring against a case worked by hand in this file, and the
   helix averages' closed forms against quadrature of their defining integrals over the section;
2. the limits: φ = 1, α = 0 no slip is the paper's solid rod; free slip is N single fibres; the
   default cotton yarn sits about two orders below the solid rod in bending;
3. measured rigidities replacing the model's;
4. a simulated cantilever of the built yarn giving back its EI;
5. bad input as one-line ``ValueError``;
6. the command line rejecting bad yarn options before any relaxation starts.
"""

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

import yarnfit.relax
from yarnfit.cli import main
from yarnfit.engine import Loads, QuasiStaticOptions, QuasiStaticSolver, Rod, RodMaterial, RodModel, RodState, straight_points
from yarnfit.fibers import Fiber, get_fiber, load_fiber_file
from yarnfit.yarn import (
    SPINNING_DEFAULTS,
    Yarn,
    YarnConstruction,
    hardening_helix_factor,
    load_yarn_file,
    mean_cos_helix,
    no_slip_bending_factor,
    tensile_helix_factor,
)

# -- the hand-worked case -------------------------------------------------------------------------
# A fibre with round numbers: ρ = 1500 kg/m³, E 6 → 8 GPa at ε_max = 0.1 (k = 2e10 Pa), ν = 0.25
# (G = 2.4 GPa), 2 dtex = 0.2 tex, R_b = 0.5e-9, R_t = 0.2e-9 N·m²/tex².
FIBRE = Fiber(
    name="roundfibre", density_kg_m3=1500.0, young_min_pa=6e9, young_max_pa=8e9, breaking_strain=0.1, poisson=0.25,
    friction=0.3, fineness_dtex=2.0, flexural_rigidity_nm2_per_tex2=0.5e-9, torsional_rigidity_nm2_per_tex2=0.2e-9,
)
PHI = 0.5
ALPHA_DEG = 30.0  # t² = tan² 30° = 1/3
RADIUS = 100e-6  # m

# -- tolerances ------------------------------------------------------------------------------------
# Closed forms evaluated here against the module's: the same ≤ 10 rounded operations in another
# order (and log instead of log1p, sqrt(1+t²) − 1 instead of its rationalised form). The worst
# cancellation is ln(4/3) − 1/4 in the bending factor, which loses a factor ~8 (≈ 1e-15). 1e-14
# leaves room; any wrong formula (a missing φ, cos α for cos²α, r³ for r⁴) is off by O(1).
ROUNDOFF_RTOL = 1e-14
# Quadrature of the helix averages is asked for 1e-13 relative (scipy's floor is 50 ε ≈ 1.1e-14;
# its own error estimates here are ≤ 1.1e-14, the measured differences ≤ 3.3e-16). 1e-13 is what
# the reference is good to.
QUADRATURE_EPSREL = 1e-13
QUADRATURE_RTOL = 1e-13
# The no-slip bending factor near the module's series switch (t² = 1e-4), used for
# 1e-5 < t² < 1e-2: the series' first omitted term −(8/5) t⁶ is 1.6e-12 just below the switch, and
# the closed form's cancellation (≈ 2 ε / t², above 1e-13 up to t² ≈ 2e-3) leaves 1.5e-12 just
# above it (both measured 1.5–1.6e-12). 5e-12 is 3× that. It still fails a two-term series
# (1.5e-8 off at the switch) and the closed form used without the switch (1.7e-8 off at
# α = 1e-4 rad, 1.8e-10 at 1e-3 rad, both checked at QUADRATURE_RTOL).
SERIES_SWITCH_RTOL = 5e-12
# Literal values of the hand-worked case, quoted in this file to 6 significant figures.
QUOTED_RTOL = 5e-6
# Sanity bound, not a tuned value: textile mechanics puts a staple yarn's bending rigidity about
# two orders of magnitude below the solid rod of the same mass (fibres slip; Platt, Klein &
# Hamburger 1959; HGB ch. 11). One decade either side of 1e-2.
BENDING_VS_SOLID_BOUNDS = (1e-3, 1e-1)

# Cantilever of the built cotton yarn. P L²/EI = 1e-3: the geometric nonlinearity is
# −0.10 (P L²/EI)² = 1e-7 of the deflection (measured 1.03e-7 at N = 20, 1.09e-7 at N = 40). The
# solver stops once the force residual is below its round-off floor, which this very
# stiff-in-tension yarn (EA L²/EI ≈ 8e5) puts at 1.9e-6 of the force scale, so where it stops
# depends on the last Newton step's round-off: at N = 40 it stopped at a residual of 1.3e-7 with
# the deflection 1.29e-6 off the linear closed form on an AMD EPYC (its BLAS), 1.09e-7 where this
# test was written. 3e-6 holds both with room; a rigidity off by 1e-5 still shows. (At
# P L²/EI = 1e-4 that floor alone is ~1e-6 of the deflection.)
CANTILEVER_LOAD = 1e-3
CANTILEVER_LENGTH = 5e-3  # m: ~55 yarn diameters, slender
CANTILEVER_EDGES = 20
LINEAR_THEORY_RTOL = 3e-6
# Richardson 2 v(2N) − v(N) against the continuum P L³/(3 EI): the discrete sum leaves exactly
# −1/(4N²) = 6.3e-4 at N = 20, shear adds 3 EI/(GA L²) = 8e-6. 1e-3 fails any first-order error
# (3/(2N) = 7.5 % at N = 20).
RICHARDSON_RTOL = 1e-3
# Displacement off the load's plane (m): round-off only; 1e-15 m is 1e-9 of the ~1.7 µm deflection.
OFF_PLANE_ATOL = 1e-15


def approx(expected: float, rel: float):
    # pytest.approx keeps its default absolute tolerance of 1e-12 beside any rel given; rigidities
    # here are 1e-10–1e-7 N·m², where that alone would be a relative tolerance of up to 1e-2.
    # Every comparison in this file is relative only.
    return pytest.approx(expected, rel=rel, abs=0.0)


def build(fiber=FIBRE, radius=RADIUS, **construction) -> Yarn:
    return Yarn.build(fiber, YarnConstruction(**construction), radius)


def hand_case() -> Yarn:
    return build(packing_fraction=PHI, twist_angle_deg=ALPHA_DEG)


# -- 1. formulas against the hand-worked case --------------------------------------------------------


def test_hand_worked_yarn():
    yarn = hand_case()
    rho, e, nu = 1500.0, 6e9, 0.25
    k = (8e9 - 6e9) / 0.1
    g = e / (2.0 * (1.0 + nu))
    t_f = 0.2  # tex
    r_b, r_t = 0.5e-9, 0.2e-9
    t = math.tan(math.radians(ALPHA_DEG))
    t2 = t * t
    # Reference (module docstring, written out):
    #   A_f = φ π r²,  T_y = ρ A_f · 1e6 tex,  ⟨cos θ⟩ = 2 (√(1 + t²) − 1)/t²,  N = (T_y/T_f) ⟨cos θ⟩
    #   EA = E A_f cos²α,  H = k A_f (2 + t²)/(2 (1 + t²)²),  GA = G A_f
    #   EI_free = N R_b T_f²,  GJ_free = N R_t T_f²
    #   EI_no-slip = φ E (π r⁴/4) (2/t⁴)(ln(1 + t²) − t²/(1 + t²)),  GJ_no-slip = φ G π r⁴/2
    #   EI_solid-same-mass = E A_f²/(4π)   (π r_s² = A_f)
    area = PHI * math.pi * RADIUS**2
    tex = rho * area * 1e6
    mean_cos = 2.0 * (math.sqrt(1.0 + t2) - 1.0) / t2
    fibres = tex / t_f * mean_cos
    expected = {
        "packing_fraction": PHI,
        "twist_angle_deg": ALPHA_DEG,
        "radius_m": RADIUS,
        "mass_per_length": rho * area,
        "linear_density_tex": tex,
        "fibres_per_section": fibres,
        "tensile_rigidity_n": e * area * math.cos(math.radians(ALPHA_DEG)) ** 2,
        "hardening_n": k * area * (2.0 + t2) / (2.0 * (1.0 + t2) ** 2),
        "shear_rigidity_n": g * area,
        "bending_free_slip_nm2": fibres * r_b * t_f**2,
        "torsion_free_slip_nm2": fibres * r_t * t_f**2,
        "bending_no_slip_nm2": PHI * e * math.pi * RADIUS**4 / 4.0 * 2.0 / t2**2 * (math.log(1.0 + t2) - t2 / (1.0 + t2)),
        "torsion_no_slip_nm2": PHI * g * math.pi * RADIUS**4 / 2.0,
        "solid_bending_rigidity_nm2": e * area**2 / (4.0 * math.pi),
        # The default model is fibre-assembly with free slip.
        "bending_rigidity_nm2": fibres * r_b * t_f**2,
        "torsional_rigidity_nm2": fibres * r_t * t_f**2,
    }
    for name, value in expected.items():
        assert getattr(yarn, name) == approx(value, rel=ROUNDOFF_RTOL), name
    assert yarn.bending_vs_solid == approx(expected["bending_rigidity_nm2"] / expected["solid_bending_rigidity_nm2"],
                                                  rel=ROUNDOFF_RTOL)
    assert yarn.model == "fibre-assembly" and yarn.spinning == "ring-spun"

    # The same case simplified by hand (t² = 1/3, G = 2.4 GPa, A_f = π/2 · 1e-8 m²): a check of the
    # arithmetic above that does not share its expressions.
    assert expected["linear_density_tex"] == approx(7.5 * math.pi, rel=ROUNDOFF_RTOL)
    assert mean_cos == approx(4.0 * math.sqrt(3.0) - 6.0, rel=ROUNDOFF_RTOL)
    assert expected["tensile_rigidity_n"] == approx(22.5 * math.pi, rel=ROUNDOFF_RTOL)  # 6e9 · A_f · 3/4
    assert expected["hardening_n"] == approx(65.625 * math.pi, rel=ROUNDOFF_RTOL)  # 2e10 · A_f · 21/32
    assert expected["shear_rigidity_n"] == approx(12.0 * math.pi, rel=ROUNDOFF_RTOL)
    assert expected["torsion_no_slip_nm2"] == approx(6e-8 * math.pi, rel=ROUNDOFF_RTOL)
    assert expected["solid_bending_rigidity_nm2"] == approx(3.75e-8 * math.pi, rel=ROUNDOFF_RTOL)
    # And the numbers, to 6 figures.
    quoted = {"fibres_per_section": 109.351, "bending_rigidity_nm2": 2.18703e-9, "torsional_rigidity_nm2": 8.74811e-10,
              "bending_no_slip_nm2": 1.59815e-7, "solid_bending_rigidity_nm2": 1.17810e-7}
    for name, value in quoted.items():
        assert getattr(yarn, name) == approx(value, rel=QUOTED_RTOL), name
    assert yarn.bending_vs_solid == approx(0.0185641, rel=QUOTED_RTOL)


def test_section_carries_the_yarns_rigidities():
    # The engine's RodSection is the Yarn's figures, EI about both directors, hardening in tension
    # and compression alike.
    yarn = hand_case()
    section = yarn.section()
    assert section.tensile_rigidity == yarn.tensile_rigidity_n
    assert section.shear_rigidity == yarn.shear_rigidity_n
    assert section.bending_rigidity == (yarn.bending_rigidity_nm2, yarn.bending_rigidity_nm2)
    assert section.torsional_rigidity == yarn.torsional_rigidity_nm2
    assert section.mass_per_length == yarn.mass_per_length
    assert section.hardening_tension == section.hardening_compression == yarn.hardening_n


def test_spinning_defaults_follow_their_stated_derivation():
    # Peirce 1937: φ = 1/(v ρ) with v = 1.1 cm³/g, ρ = 1520 kg/m³ → 0.598 → 0.60;
    # tan α = π αe/28 with αe = 4.0 → α = 24.17° → 24.2°. Filament: α = 0, φ = 0.60.
    assert SPINNING_DEFAULTS["ring-spun"].packing_fraction == round(1.0 / (1.1e-3 * 1520.0), 2) == 0.60
    assert SPINNING_DEFAULTS["ring-spun"].twist_angle_deg == 24.2
    assert math.degrees(math.atan(math.pi * 4.0 / 28.0)) == pytest.approx(24.2, abs=0.05)
    assert (SPINNING_DEFAULTS["filament"].packing_fraction, SPINNING_DEFAULTS["filament"].twist_angle_deg) == (0.60, 0.0)
    # A construction given nothing takes the fibre's spinning system's values; a fibre naming none
    # is ring-spun.
    assert build(get_fiber("polyester")).spinning == "filament"
    assert build(get_fiber("polyester")).twist_angle_deg == 0.0
    cotton = build(get_fiber("cotton"))
    assert (cotton.spinning, cotton.packing_fraction) == ("ring-spun", 0.60)
    assert cotton.twist_angle_deg == approx(24.2, rel=ROUNDOFF_RTOL)
    assert build(replace(FIBRE, spinning=None)).spinning == "ring-spun"
    assert build(FIBRE, spinning="filament").twist_angle_deg == 0.0


# Angles (rad) for the helix averages: 0; tiny ones where the bending factor uses its series
# (t² < 1e-4); either side of the switch at t² = 1e-4 (α ≈ 0.01 rad); textile angles up to the
# 45° bound.
HELIX_ANGLES = [
    0.0,
    1e-4,
    1e-3,
    math.atan(math.sqrt(0.99e-4)),
    math.atan(math.sqrt(1.01e-4)),
    0.1,
    math.radians(24.2),
    math.radians(35.0),
    math.radians(44.9),
]


def section_average(t: float, f) -> float:
    # ⟨f⟩ over the idealised helix's section, uniform packing: a fibre at u = ρ'/r turns at
    # tan θ = u t, and the ring at u holds the share 2u du of the area: ⟨f⟩ = ∫₀¹ 2u f(θ(u)) du.
    value, error = quad(lambda u: 2.0 * u * f(math.atan(u * t)), 0.0, 1.0, epsabs=0.0, epsrel=QUADRATURE_EPSREL)
    assert error <= QUADRATURE_RTOL * abs(value)
    return value


@pytest.mark.parametrize("alpha", HELIX_ANGLES, ids=lambda a: f"{a:.6g}rad")
def test_helix_averages_against_quadrature(alpha):
    t = math.tan(alpha)
    t2 = t * t
    assert mean_cos_helix(t2) == approx(section_average(t, math.cos), rel=QUADRATURE_RTOL)
    assert tensile_helix_factor(t2) == approx(section_average(t, lambda th: math.cos(th) ** 4), rel=QUADRATURE_RTOL)
    assert hardening_helix_factor(t2) == approx(section_average(t, lambda th: math.cos(th) ** 6),
                                                       rel=QUADRATURE_RTOL)
    # HGB's cos²α law: ⟨cos⁴θ⟩ = cos²α.
    assert tensile_helix_factor(t2) == approx(math.cos(alpha) ** 2, rel=ROUNDOFF_RTOL)


@pytest.mark.parametrize("alpha", HELIX_ANGLES, ids=lambda a: f"{a:.6g}rad")
def test_no_slip_bending_factor_against_quadrature(alpha):
    # Reference: f = ∫ y² cos⁴θ dA / ∫ y² dA over the section = 4 ∫₀¹ u³ cos⁴θ du, tan θ = u t.
    t = math.tan(alpha)
    value, error = quad(lambda u: 4.0 * u**3 * math.cos(math.atan(u * t)) ** 4, 0.0, 1.0, epsabs=0.0,
                        epsrel=QUADRATURE_EPSREL)
    assert error <= QUADRATURE_RTOL * value
    t2 = t * t
    near_switch = 1e-5 < t2 < 1e-2
    assert no_slip_bending_factor(t2) == approx(value, rel=SERIES_SWITCH_RTOL if near_switch else QUADRATURE_RTOL)


def test_no_slip_bending_factor_is_continuous_at_the_series_switch():
    # Either side of t² = 1e-4 the series and the closed form must agree to their own accuracy
    # (the quadrature test above bounds both); a jump here would be a step in EI(α).
    below, above = no_slip_bending_factor(math.nextafter(1e-4, 0.0)), no_slip_bending_factor(1e-4)
    assert above == approx(below, rel=SERIES_SWITCH_RTOL)
    assert above < below  # f decreases with the twist


# -- 2. limits -------------------------------------------------------------------------------------


def solid_material(fiber: Fiber) -> RodMaterial:
    k = fiber.hardening_pa
    return RodMaterial(fiber.young_min_pa, fiber.poisson, fiber.density_kg_m3, k, k)


@pytest.mark.parametrize("fiber", [FIBRE, get_fiber("cotton"), get_fiber("polyester")], ids=lambda f: f.name)
def test_no_slip_at_full_packing_and_no_twist_is_the_solid_rod(fiber):
    # Reference: φ = 1, α = 0 makes the no-slip yarn the paper's solid cylinder of radius r
    # (RodMaterial.section). The fibre-assembly model still uses free slip for EI and GJ, so only
    # the no-slip limits and the other rigidities are compared.
    r = 1.7e-4
    yarn = build(fiber, r, packing_fraction=1.0, twist_angle_deg=0.0)
    solid = solid_material(fiber).section(r)
    assert yarn.bending_no_slip_nm2 == approx(solid.bending_rigidity[0], rel=ROUNDOFF_RTOL)
    assert yarn.torsion_no_slip_nm2 == approx(solid.torsional_rigidity, rel=ROUNDOFF_RTOL)
    assert yarn.tensile_rigidity_n == approx(solid.tensile_rigidity, rel=ROUNDOFF_RTOL)
    assert yarn.shear_rigidity_n == approx(solid.shear_rigidity, rel=ROUNDOFF_RTOL)
    assert yarn.mass_per_length == approx(solid.mass_per_length, rel=ROUNDOFF_RTOL)
    assert yarn.hardening_n == approx(solid.hardening_tension, rel=ROUNDOFF_RTOL)
    assert yarn.solid_bending_rigidity_nm2 == approx(solid.bending_rigidity[0], rel=ROUNDOFF_RTOL)


@pytest.mark.parametrize("fiber", [FIBRE, get_fiber("cotton"), get_fiber("wool"),
                                   replace(FIBRE, fineness_dtex=None, flexural_rigidity_nm2_per_tex2=None,
                                           torsional_rigidity_nm2_per_tex2=None)],
                         ids=["roundfibre", "cotton", "wool", "no-assembly-data"])
def test_solid_model_section_is_the_rod_material_section_exactly(fiber):
    # The solid model is the paper's yarn: its RodSection is RodMaterial(E_min, ν, ρ, k, k).section(r)
    # to the last bit, and it needs none of the fibre-assembly data.
    r = 9e-5
    yarn = build(fiber, r, model="solid")
    assert yarn.section() == solid_material(fiber).section(r)
    assert (yarn.packing_fraction, yarn.twist_angle_deg, yarn.spinning) == (1.0, 0.0, None)
    assert yarn.bending_vs_solid == approx(1.0, rel=ROUNDOFF_RTOL)
    assert (yarn.fibres_per_section is None) == (fiber.fineness_dtex is None)


def test_free_slip_of_a_one_fibre_yarn_is_that_fibre():
    # Reference: a yarn whose cross-section holds exactly one fibre's area, untwisted, is one fibre:
    # φ π r² = T_f · 1e-6 / ρ gives N = 1, so EI = R_b T_f², GJ = R_t T_f² (M&H's definition of the
    # specific rigidities). Four times the area is four fibres: EI and GJ scale with N.
    t_f, rho = 0.2, 1500.0
    r1 = math.sqrt(t_f * 1e-6 / (rho * PHI * math.pi))
    one = build(FIBRE, r1, packing_fraction=PHI, twist_angle_deg=0.0)
    assert one.fibres_per_section == approx(1.0, rel=ROUNDOFF_RTOL)
    assert one.bending_free_slip_nm2 == approx(0.5e-9 * t_f**2, rel=ROUNDOFF_RTOL)
    assert one.torsion_free_slip_nm2 == approx(0.2e-9 * t_f**2, rel=ROUNDOFF_RTOL)
    four = build(FIBRE, 2.0 * r1, packing_fraction=PHI, twist_angle_deg=0.0)
    assert four.fibres_per_section == approx(4.0, rel=ROUNDOFF_RTOL)
    assert four.bending_free_slip_nm2 == approx(4.0 * one.bending_free_slip_nm2, rel=ROUNDOFF_RTOL)
    assert four.torsion_free_slip_nm2 == approx(4.0 * one.torsion_free_slip_nm2, rel=ROUNDOFF_RTOL)
    # And in the twisted hand case, per fibre cut by the section, the same single-fibre rigidities.
    yarn = hand_case()
    assert yarn.bending_free_slip_nm2 / yarn.fibres_per_section == approx(0.5e-9 * t_f**2, rel=ROUNDOFF_RTOL)
    assert yarn.torsion_free_slip_nm2 / yarn.fibres_per_section == approx(0.2e-9 * t_f**2, rel=ROUNDOFF_RTOL)


def test_default_cotton_yarn_bends_about_two_orders_below_the_solid_rod():
    yarn = build(get_fiber("cotton"), 90e-6)
    low, high = BENDING_VS_SOLID_BOUNDS
    assert low <= yarn.bending_vs_solid <= high
    # Free slip lies below no slip (fibres that slide store less), and the default uses free slip.
    assert yarn.bending_rigidity_nm2 == yarn.bending_free_slip_nm2 < yarn.bending_no_slip_nm2
    assert yarn.torsional_rigidity_nm2 == yarn.torsion_free_slip_nm2 < yarn.torsion_no_slip_nm2


# -- 3. measured rigidities --------------------------------------------------------------------------

MEASURED = {"tensile_rigidity_n": 55.0, "bending_rigidity_nm2": 3.1e-9, "torsional_rigidity_nm2": 1.3e-9}


def test_measured_rigidities_replace_the_models():
    model = hand_case()
    yarn = build(packing_fraction=PHI, twist_angle_deg=ALPHA_DEG, **MEASURED)
    assert yarn.tensile_rigidity_n == MEASURED["tensile_rigidity_n"]
    assert yarn.bending_rigidity_nm2 == MEASURED["bending_rigidity_nm2"]
    assert yarn.torsional_rigidity_nm2 == MEASURED["torsional_rigidity_nm2"]
    # The hardening scales with EA_measured / EA_model: the same hardening per unit EA.
    assert yarn.hardening_n == approx(model.hardening_n * 55.0 / model.tensile_rigidity_n, rel=ROUNDOFF_RTOL)
    assert yarn.hardening_n != approx(model.hardening_n, rel=1e-3)  # the scaling is not a no-op here
    # What was not measured stays the model's, and the limits are still reported.
    for name in ("shear_rigidity_n", "mass_per_length", "linear_density_tex", "fibres_per_section",
                 "bending_free_slip_nm2", "bending_no_slip_nm2", "torsion_free_slip_nm2", "torsion_no_slip_nm2",
                 "solid_bending_rigidity_nm2"):
        assert getattr(yarn, name) == getattr(model, name), name
    section = yarn.section()
    assert (section.tensile_rigidity, section.bending_rigidity, section.torsional_rigidity) == (
        55.0, (3.1e-9, 3.1e-9), 1.3e-9)
    assert section.hardening_tension == section.hardening_compression == yarn.hardening_n


@pytest.mark.parametrize("key", sorted(MEASURED))
def test_one_measured_rigidity_leaves_the_others_to_the_model(key):
    model = hand_case()
    yarn = build(packing_fraction=PHI, twist_angle_deg=ALPHA_DEG, **{key: MEASURED[key]})
    for other in MEASURED:
        assert getattr(yarn, other) == (MEASURED[key] if other == key else getattr(model, other)), other
    if key != "tensile_rigidity_n":
        assert yarn.hardening_n == model.hardening_n


def test_measured_bending_and_torsion_need_only_the_fineness():
    # The module asks for R_b only when EI is not measured and R_t only when GJ is not; the
    # fineness is always needed under the fibre-assembly model (it gives N).
    bare = replace(FIBRE, flexural_rigidity_nm2_per_tex2=None, torsional_rigidity_nm2_per_tex2=None)
    yarn = build(bare, packing_fraction=PHI, twist_angle_deg=ALPHA_DEG, bending_rigidity_nm2=3.1e-9,
                 torsional_rigidity_nm2=1.3e-9)
    assert (yarn.bending_rigidity_nm2, yarn.torsional_rigidity_nm2) == (3.1e-9, 1.3e-9)
    assert yarn.bending_free_slip_nm2 is None and yarn.torsion_free_slip_nm2 is None
    assert yarn.fibres_per_section == approx(hand_case().fibres_per_section, rel=ROUNDOFF_RTOL)
    # Only EI measured: R_t is still needed, and the message names only it.
    with pytest.raises(ValueError, match="torsional_rigidity_nm2_per_tex2") as info:
        build(bare, bending_rigidity_nm2=3.1e-9)
    assert "flexural" not in str(info.value) and "fineness" not in str(info.value)
    # Every rigidity measured but no fineness: still refused (N cannot be computed).
    no_fineness = replace(bare, fineness_dtex=None)
    with pytest.raises(ValueError, match=r"has no fineness_dtex:"):
        build(no_fineness, **MEASURED)


# -- 4. a simulated cantilever gives back the yarn's EI ------------------------------------------------


def cotton_cantilever(yarn: Yarn, n_edges: int, direction) -> np.ndarray:
    rod = Rod(straight_points(CANTILEVER_LENGTH, n_edges), radius=yarn.radius_m, material=yarn.section(),
              pinned_nodes=[0], pinned_frames=[0])
    model = RodModel.from_rods([rod])
    loads = Loads.zeros(model)
    loads.node_force[-1] = CANTILEVER_LOAD * yarn.bending_rigidity_nm2 / CANTILEVER_LENGTH**2 * np.asarray(direction)
    result = QuasiStaticSolver(model, QuasiStaticOptions(contact=False)).solve(RodState.from_model(model), loads)
    assert result.converged
    return result.state.node_position[-1]


def test_cantilever_of_the_built_yarn_recovers_its_bending_rigidity():
    # Reference (discrete rod, small deflection; tests/test_rod_section.py): the tip deflects by
    #   v_N = (P L³/(3 EI)) (N − 1)(2N − 1)/(2N²) + P L/GA,
    # so EI = P L³ c_N / (3 (v − P L/GA)), c_N = (N − 1)(2N − 1)/(2N²); the continuum
    # v = P L³/(3 EI) is reached by Richardson extrapolation 2 v(2N) − v(N).
    yarn = build(get_fiber("cotton"), 90e-6)
    ei, ga, length = yarn.bending_rigidity_nm2, yarn.shear_rigidity_n, CANTILEVER_LENGTH
    force = CANTILEVER_LOAD * ei / length**2
    deflection = {}
    for n in (CANTILEVER_EDGES, 2 * CANTILEVER_EDGES):
        for axis in (1, 2):  # EI about both directors
            direction = np.zeros(3)
            direction[axis] = -1.0
            tip = cotton_cantilever(yarn, n, direction)
            v = -tip[axis]
            assert abs(tip[3 - axis]) <= OFF_PLANE_ATOL
            c_n = (n - 1) * (2 * n - 1) / (2.0 * n * n)
            recovered = force * length**3 * c_n / (3.0 * (v - force * length / ga))
            assert recovered == approx(ei, rel=LINEAR_THEORY_RTOL), (n, axis)
            deflection[n] = v
    extrapolated = 2.0 * deflection[2 * CANTILEVER_EDGES] - deflection[CANTILEVER_EDGES]
    assert force * length**3 / (3.0 * extrapolated) == approx(ei, rel=RICHARDSON_RTOL)
    # The solid rod's EI (≈ 50× larger) or the no-slip EI would be far outside either tolerance.
    assert yarn.solid_bending_rigidity_nm2 > 10.0 * ei


# -- 5. bad input -----------------------------------------------------------------------------------


def one_line_error(call, match: str) -> str:
    with pytest.raises(ValueError, match=match) as info:
        call()
    message = str(info.value)
    assert "\n" not in message and message.strip() == message, message
    return message


@pytest.mark.parametrize("phi", [0.0, -0.1, 1.2, math.nan, math.inf], ids=repr)
def test_packing_fraction_outside_zero_one(phi):
    one_line_error(lambda: YarnConstruction(packing_fraction=phi), r"^packing fraction must (lie in \(0, 1\]|be finite)")


@pytest.mark.parametrize("alpha", [-1.0, 45.0, 60.0, math.nan], ids=repr)
def test_twist_angle_outside_zero_45(alpha):
    one_line_error(lambda: YarnConstruction(twist_angle_deg=alpha), r"^twist angle must (lie in \[0°, 45°\)|be finite)")


def test_edges_of_the_accepted_ranges_are_accepted():
    assert YarnConstruction(packing_fraction=1.0).packing_fraction == 1.0
    assert YarnConstruction(packing_fraction=1e-6).packing_fraction == 1e-6
    assert YarnConstruction(twist_angle_deg=0).twist_angle_deg == 0.0
    assert YarnConstruction(twist_angle_deg=44.99).twist_angle_deg == 44.99


@pytest.mark.parametrize("value", ["0.5", True, [0.5]], ids=repr)
def test_non_numbers_are_refused(value):
    one_line_error(lambda: YarnConstruction(packing_fraction=value), r"^packing fraction must be a real number")


@pytest.mark.parametrize("key", sorted(MEASURED))
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan], ids=repr)
def test_measured_rigidities_must_be_positive(key, value):
    one_line_error(lambda: YarnConstruction(**{key: value}), rf"^{key} must be")


def test_unknown_model_and_spinning():
    message = one_line_error(lambda: YarnConstruction(model="rope"), r"^yarn model must be one of")
    assert "fibre-assembly" in message and "solid" in message and "'rope'" in message
    message = one_line_error(lambda: YarnConstruction(spinning="open-end"), r"^spinning must be one of")
    assert "ring-spun" in message and "filament" in message and "'open-end'" in message


@pytest.mark.parametrize("key,value", [("spinning", "ring-spun"), ("packing_fraction", 0.5), ("twist_angle_deg", 10.0),
                                       *MEASURED.items()])
def test_solid_model_takes_no_construction(key, value):
    message = one_line_error(lambda: YarnConstruction(model="solid", **{key: value}), r"^the solid yarn model takes no")
    assert f"given: {key}" in message


ASSEMBLY_KEYS = ("fineness_dtex", "flexural_rigidity_nm2_per_tex2", "torsional_rigidity_nm2_per_tex2")


@pytest.mark.parametrize("missing", ASSEMBLY_KEYS)
def test_fibre_assembly_needs_the_fibres_data(missing):
    fiber = replace(FIBRE, **{missing: None})
    message = one_line_error(lambda: build(fiber), rf"^fibre 'roundfibre' has no {missing}:")
    for other in ASSEMBLY_KEYS:
        assert (other in message) == (other == missing), other
    build(fiber, model="solid")  # the solid model does not need it


def test_fibre_missing_all_assembly_data_names_every_key():
    fiber = replace(FIBRE, fineness_dtex=None, flexural_rigidity_nm2_per_tex2=None, torsional_rigidity_nm2_per_tex2=None)
    message = one_line_error(lambda: build(fiber), r"^fibre 'roundfibre' has no ")
    assert all(key in message for key in ASSEMBLY_KEYS)


@pytest.mark.parametrize("radius", [0.0, -1e-4, math.nan], ids=repr)
def test_yarn_radius_must_be_positive(radius):
    one_line_error(lambda: build(radius=radius), r"^yarn radius must be")


FIBRE_JSON = {"name": "roundfibre", "density_kg_m3": 1500, "young_min_pa": 6e9, "young_max_pa": 8e9,
              "breaking_strain": 0.1, "poisson": 0.25, "friction": 0.3,
              "flexural_rigidity_nm2_per_tex2": 0.5e-9, "torsional_rigidity_nm2_per_tex2": 0.2e-9}


def write_json(path: Path, data) -> Path:
    path.write_text(json.dumps(data))
    return path


def test_fibre_file_with_diameter_gives_the_round_fibres_fineness(tmp_path):
    # Reference: a round fibre of diameter d has ρ π d²/4 kg/m = ρ π d²/4 · 1e7 dtex;
    # d = 20 µm, ρ = 1500: 1500 π · 1e-10 · 1e7 = 1.5 π dtex.
    fiber = load_fiber_file(write_json(tmp_path / "f.json", {**FIBRE_JSON, "diameter_m": 20e-6}))
    assert fiber.fineness_dtex == approx(1500.0 * math.pi * (20e-6) ** 2 / 4.0 * 1e7, rel=ROUNDOFF_RTOL)
    assert fiber.fineness_dtex == approx(1.5 * math.pi, rel=ROUNDOFF_RTOL)
    yarn = Yarn.build(fiber, YarnConstruction(), RADIUS)  # enough for the fibre-assembly model
    assert yarn.fibres_per_section is not None
    # Giving the fineness itself is the same fibre.
    same = load_fiber_file(write_json(tmp_path / "g.json", {**FIBRE_JSON, "fineness_dtex": 1.5 * math.pi}))
    assert same.fineness_dtex == approx(fiber.fineness_dtex, rel=ROUNDOFF_RTOL)


def test_fibre_file_with_fineness_and_diameter_is_refused(tmp_path):
    path = write_json(tmp_path / "f.json", {**FIBRE_JSON, "fineness_dtex": 2.0, "diameter_m": 20e-6})
    message = one_line_error(lambda: load_fiber_file(path), "give fineness_dtex or diameter_m, not both")
    assert message.startswith(str(path))


def test_yarn_file_valid(tmp_path):
    data = {"spinning": "ring-spun", "packing_fraction": 0.55, "twist_angle_deg": 20, "bending_rigidity_nm2": 3e-9}
    construction = load_yarn_file(write_json(tmp_path / "y.json", data))
    assert construction == YarnConstruction(spinning="ring-spun", packing_fraction=0.55, twist_angle_deg=20.0,
                                            bending_rigidity_nm2=3e-9)
    assert type(construction.twist_angle_deg) is float
    assert YarnConstruction.from_dict(construction.to_dict()) == construction
    assert load_yarn_file(write_json(tmp_path / "empty.json", {})) == YarnConstruction()


def test_yarn_file_with_unknown_keys(tmp_path):
    path = write_json(tmp_path / "y.json", {"packing": 0.5, "twist": 20, "spinning": "ring-spun"})
    message = one_line_error(lambda: load_yarn_file(path), r"unknown keys: packing, twist \(allowed: ")
    assert message.startswith(f"{path}: ")


@pytest.mark.parametrize("data,match", [({"packing_fraction": 2}, r"packing fraction must lie in"),
                                        ({"model": "solid", "twist_angle_deg": 5}, r"solid yarn model takes no"),
                                        ([0.5], r"expected a JSON object")], ids=["phi", "solid", "list"])
def test_yarn_file_with_bad_values(tmp_path, data, match):
    path = write_json(tmp_path / "y.json", data)
    message = one_line_error(lambda: load_yarn_file(path), match)
    assert message.startswith(f"{path}: ")


# -- 6. the command line ------------------------------------------------------------------------------


@pytest.fixture
def no_relaxation(monkeypatch):
    """Bad input must be refused before the rod solver is ever built."""

    def refuse(*args, **kwargs):
        raise AssertionError("bad input reached the relaxation's rod solver")

    monkeypatch.setattr(yarnfit.relax, "QuasiStaticSolver", refuse)


CLI_BAD_YARN = {
    "packing above 1": (["--yarn-packing", "1.5"], ["packing fraction", "1.5"]),
    "twist 50 degrees": (["--yarn-twist-deg", "50"], ["twist angle", "50"]),
    "solid with packing": (["--yarn-model", "solid", "--yarn-packing", "0.5"], ["solid", "packing_fraction"]),
    "file and option": (["--yarn", "{yarn_file}", "--yarn-packing", "0.5"], ["--yarn FILE", "not both"]),
}


@pytest.mark.parametrize("case", sorted(CLI_BAD_YARN))
def test_cli_bad_yarn_options_exit_2_with_one_line(case, tmp_path, capsys, no_relaxation):
    options, mentions = CLI_BAD_YARN[case]
    yarn_file = write_json(tmp_path / "yarn.json", {"packing_fraction": 0.5})
    options = [option.format(yarn_file=yarn_file) for option in options]
    recording = tmp_path / "x.rrd"
    status = main(["relax", "cotton-jersey", *options, "--rerun", str(recording)])
    out, err = capsys.readouterr()
    assert status == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("yarnfit relax: error: "), err
    for word in mentions:
        assert word in lines[0], (word, lines[0])
    assert out == ""
    assert not recording.exists()


def fibre_file_without_assembly_keys(tmp_path) -> Path:
    data = {key: value for key, value in FIBRE_JSON.items() if key not in ASSEMBLY_KEYS}
    return write_json(tmp_path / "plainfibre.json", data)


def test_cli_fibre_file_without_assembly_keys_exits_2_naming_them(tmp_path, capsys, no_relaxation):
    status = main(["relax", "--fiber-file", str(fibre_file_without_assembly_keys(tmp_path)), "--pattern", "plain",
                   "--gsm", "150", "--rerun", str(tmp_path / "x.rrd")])
    out, err = capsys.readouterr()
    assert status == 2, (out, err)
    errors = [line for line in err.splitlines() if line.startswith("yarnfit relax: error: ")]
    assert len(errors) == 1 and "Traceback" not in err, err
    assert all(key in errors[0] for key in ASSEMBLY_KEYS), errors[0]
    # The solid model needs none of them: the same fibre file is accepted up to the relaxation.
    with pytest.raises(AssertionError, match="reached the relaxation's rod solver"):
        main(["relax", "--fiber-file", str(fibre_file_without_assembly_keys(tmp_path)), "--pattern", "plain",
              "--gsm", "150", "--yarn-model", "solid", "--rerun", str(tmp_path / "y.rrd")])


def test_cli_fibre_file_without_assembly_keys_is_one_line_and_writes_no_file(tmp_path):
    # As tests/test_cli.py does it: the installed script, stderr as the user sees it.
    script = Path(sys.executable).parent / "yarnfit"
    recording = tmp_path / "x.rrd"
    out = subprocess.run([str(script), "relax", "--fiber-file", str(fibre_file_without_assembly_keys(tmp_path)),
                          "--pattern", "plain", "--gsm", "150", "--rerun", str(recording)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert not recording.exists()
