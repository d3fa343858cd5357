"""Orthotropic StVK shell: moduli, engineering constants, energy and its gradient, JSON, bad input."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from yarnfit.material_file import MaterialFile
from yarnfit.shell import (
    GF_CM2_PER_CM,
    PARAMETER_NAMES,
    RIDGE_MODEL,
    SYMMETRY_RTOL,
    RidgeMembrane,
    ShellMaterial,
    bending_strain,
    membrane_strain,
)

from fabric_shell import FABRIC as MATERIAL, H  # a realistic woven

# Moduli ↔ stiffness and the closed forms below are a handful of multiplications and divisions:
# a few ulps each, 1e-13 leaves a factor ~100 of margin over float64 ε.
ROUND_OFF_REL = 1e-13
# The numerically minimised uniaxial energy: Brent's method finds E_pp to ~1e-8 relative (√ε), and the
# energy is quadratic around its minimum, so the minimum value is exact to ~(1e-8)² ≪ 1e-10.
MINIMISED_REL = 1e-10
# Relative finite-difference step, applied to the largest entry of the perturbed matrix. Below
# SYMMETRY_RTOL so that a probe of one off-diagonal entry stays an accepted (near-symmetric) form.
FD_STEP_REL = 1e-9
# W is quadratic in I and II, so central differences have no truncation error; what remains is
# round-off ε·W/(δ·max|dW|): ≈ 2e-16·0.1 J/m² / (1.2e-7 /m · 1.2e-3 J/m) ≈ 2e-7 for the II probes below
# (~3e-9 for the I probes). 1e-5 leaves a margin of 50 and is still 1e5 below the O(1) error of a
# wrong convention (a missing factor 2 on an off-diagonal entry).
FD_REL = 1e-5


I_GENERAL = np.array([[1.08, 0.04], [0.04, 0.97]])
II_GENERAL = np.array([[120.0, -35.0], [-35.0, 60.0]])


def test_moduli_round_trip_and_paper_relation():
    moduli = MATERIAL.moduli()
    bending = {name: getattr(MATERIAL, name) for name in ("b00", "b01", "b11", "b22")}
    again = ShellMaterial.from_moduli(H, **moduli, **bending)
    for name in PARAMETER_NAMES:
        assert getattr(again, name) == pytest.approx(getattr(MATERIAL, name), rel=ROUND_OFF_REL), name

    # Paper Eq. shell_stiffness_moduli written out: s00 = E_t/D, s11 = E_p/D, s01 = ν_pt E_t/D, s22 = μ.
    E_t, E_p, nu_tp, mu = 2.0e6, 1.0e6, 0.3, 1.0e5
    nu_pt = nu_tp * E_p / E_t  # reciprocity
    D = 1.0 - nu_tp * nu_pt
    m = ShellMaterial.from_moduli(H, E_t, E_p, nu_tp, nu_pt, mu, b00=1.0, b11=2.0, b22=3.0)
    assert m.s00 == pytest.approx(E_t / D, rel=ROUND_OFF_REL)
    assert m.s11 == pytest.approx(E_p / D, rel=ROUND_OFF_REL)
    assert m.s01 == pytest.approx(nu_pt * E_t / D, rel=ROUND_OFF_REL)
    assert m.s01 == pytest.approx(nu_tp * E_p / D, rel=ROUND_OFF_REL)
    assert m.s22 == mu and m.b01 == 0.0
    back = m.moduli()
    for name, value in {"E_t": E_t, "E_p": E_p, "nu_tp": nu_tp, "nu_pt": nu_pt, "mu": mu}.items():
        assert back[name] == pytest.approx(value, rel=ROUND_OFF_REL), name


def test_from_moduli_rejects_inconsistent_poisson_ratios_and_nonpositive_D():
    with pytest.raises(ValueError, match="reciprocity"):
        ShellMaterial.from_moduli(H, 2.0e6, 1.0e6, 0.3, 0.3, 1e5, 1.0, 1.0, 1.0)
    # ν_pt E_t = ν_tp E_p holds (0.5·4 = 2·1) but D = 1 − 2·0.5 = 0.
    with pytest.raises(ValueError, match=r"1 - nu_tp\*nu_pt must be > 0"):
        ShellMaterial.from_moduli(H, 4.0e6, 1.0e6, 2.0, 0.5, 1e5, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="E_p must be > 0"):
        ShellMaterial.from_moduli(H, 4.0e6, -1.0e6, 0.0, 0.0, 1e5, 1.0, 1.0, 1.0)


def _uniaxial_minimum(material: ShellMaterial, strain: float, axis: int) -> tuple[float, float]:
    """(min over the transverse Green strain of W, minimiser) for Green strain ``strain`` along ``axis``."""

    def energy(transverse: float) -> float:
        E = np.zeros((2, 2))
        E[axis, axis] = strain
        E[1 - axis, 1 - axis] = transverse
        return material.energy_density(np.eye(2) + 2.0 * E, np.zeros((2, 2)))

    result = minimize_scalar(energy, bracket=(-strain, 0.0), tol=1e-12)
    return result.fun, result.x


def test_stretch_constants_are_uniaxial_stiffness_with_transverse_direction_free():
    # Uniaxial test, transverse free, no shear: W_min(E) = ½ k E² with k the stretch stiffness (N/m),
    # and the free transverse strain is −ν E.
    eng = MATERIAL.engineering()
    strain = 1e-3
    cases = ((0, "weft_stretch_n_per_m", "poisson_weft"), (1, "warp_stretch_n_per_m", "poisson_warp"))
    for axis, stiffness, poisson in cases:
        W, transverse = _uniaxial_minimum(MATERIAL, strain, axis)
        assert 2.0 * W / strain**2 == pytest.approx(eng[stiffness], rel=MINIMISED_REL), stiffness
        # The minimiser itself is only known to Brent's x tolerance (√ε relative).
        assert -transverse / strain == pytest.approx(eng[poisson], rel=1e-6), poisson
    # Hand values for this material: h (s00 − s01²/s11) = 1000 − 120²/600 = 976 N/m, ν = 120/600.
    assert eng["weft_stretch_n_per_m"] == pytest.approx(976.0, rel=ROUND_OFF_REL)
    assert eng["warp_stretch_n_per_m"] == pytest.approx(600.0 - 120.0**2 / 1000.0, rel=ROUND_OFF_REL)
    assert eng["poisson_weft"] == pytest.approx(0.2, rel=ROUND_OFF_REL)
    assert eng["poisson_warp"] == pytest.approx(0.12, rel=ROUND_OFF_REL)


def test_shear_and_bending_constants_from_the_energy_of_pure_deformations():
    eng = MATERIAL.engineering()
    zero = np.zeros((2, 2))
    # Engineering shear strain γ = 2 E_tp = I_01: W = ½ (h s22) γ².
    g = 0.02
    W = MATERIAL.energy_density(np.array([[1.0, g], [g, 1.0]]), zero)
    assert 2.0 * W / g**2 == pytest.approx(eng["shear_n_per_m"], rel=ROUND_OFF_REL)
    assert eng["shear_n_per_m"] == pytest.approx(50.0, rel=ROUND_OFF_REL)

    # Cylindrical bend of curvature k with curvature direction d: II = k d dᵀ, W = ½ B_dir k².
    k = 150.0
    for angle, key, hand in (
        (0.0, "bending_weft_nm", 1.0e-5),
        (np.pi / 2, "bending_warp_nm", 6.0e-6),
        (np.pi / 4, "bending_bias_nm", (1.0e-5 + 6.0e-6 + 2 * 1.5e-6 + 4 * 2.0e-6) / 4),
    ):
        d = np.array([np.cos(angle), np.sin(angle)])
        W = MATERIAL.energy_density(np.eye(2), k * np.outer(d, d))
        assert 2.0 * W / k**2 == pytest.approx(eng[key], rel=ROUND_OFF_REL), key
        assert eng[key] == pytest.approx(hand, rel=ROUND_OFF_REL), key
    # The brief's form of the 45° bend.
    W = MATERIAL.energy_density(np.eye(2), 0.5 * k * np.ones((2, 2)))
    assert 2.0 * W / k**2 == pytest.approx(eng["bending_bias_nm"], rel=ROUND_OFF_REL)


def test_gf_cm_unit():
    # 1 gf = 9.80665e-3 N, 1 gf·cm²/cm = 1 gf·cm = 9.80665e-3 N × 1e-2 m.
    assert GF_CM2_PER_CM == pytest.approx(9.80665e-3 * 1e-2, rel=ROUND_OFF_REL)


def test_energy_matches_the_written_out_formula():
    # W_s = (h/2)(s00 ε0² + 2 s01 ε0 ε1 + s11 ε1² + s22 ε2²), ε = (½(I00−1), ½(I11−1), I01);
    # W_b = (h³/2)(b00 κ0² + 2 b01 κ0 κ1 + b11 κ1² + b22 κ2²), κ = (II00, II11, 2 II01).
    m, I, II = MATERIAL, I_GENERAL, II_GENERAL
    e0, e1, e2 = 0.5 * (I[0, 0] - 1), 0.5 * (I[1, 1] - 1), I[0, 1]
    k0, k1, k2 = II[0, 0], II[1, 1], 2 * II[0, 1]
    W_s = 0.5 * H * (m.s00 * e0**2 + 2 * m.s01 * e0 * e1 + m.s11 * e1**2 + m.s22 * e2**2)
    W_b = 0.5 * H**3 * (m.b00 * k0**2 + 2 * m.b01 * k0 * k1 + m.b11 * k1**2 + m.b22 * k2**2)
    assert isinstance(m.energy_density(I, II), float)
    assert m.energy_density(I, II) == pytest.approx(W_s + W_b, rel=ROUND_OFF_REL)
    np.testing.assert_allclose(membrane_strain(I), [e0, e1, e2], rtol=ROUND_OFF_REL)
    np.testing.assert_allclose(bending_strain(II), [k0, k1, k2], rtol=ROUND_OFF_REL)


def test_energy_is_vectorised_over_a_leading_axis():
    rng = np.random.default_rng(1)
    n = 5
    A = 0.05 * rng.standard_normal((n, 2, 2))
    Is = np.eye(2) + A + np.swapaxes(A, 1, 2)
    B = 80.0 * rng.standard_normal((n, 2, 2))
    IIs = B + np.swapaxes(B, 1, 2)
    W = MATERIAL.energy_density(Is, IIs)
    gI, gII = MATERIAL.energy_gradient(Is, IIs)
    assert W.shape == (n,) and gI.shape == (n, 2, 2) and gII.shape == (n, 2, 2)
    assert membrane_strain(Is).shape == (n, 3) and bending_strain(IIs).shape == (n, 3)
    # Batched and single evaluations may sum in a different order: equal to round-off.
    for k in range(n):
        assert W[k] == pytest.approx(MATERIAL.energy_density(Is[k], IIs[k]), rel=ROUND_OFF_REL)
        single_I, single_II = MATERIAL.energy_gradient(Is[k], IIs[k])
        np.testing.assert_allclose(gI[k], single_I, rtol=ROUND_OFF_REL)
        np.testing.assert_allclose(gII[k], single_II, rtol=ROUND_OFF_REL)
    # A single (2, 2) form broadcasts against a stack.
    stacked = MATERIAL.energy_density(np.stack([np.eye(2)] * n), IIs)
    np.testing.assert_array_equal(MATERIAL.energy_density(np.eye(2), IIs), stacked)


def _central_difference(f, A: np.ndarray, i: int, j: int) -> float:
    step = FD_STEP_REL * np.max(np.abs(A))
    plus, minus = A.copy(), A.copy()
    plus[i, j] += step
    minus[i, j] -= step
    # Divide by the steps actually represented, not the nominal ones.
    return (f(plus) - f(minus)) / (plus[i, j] - minus[i, j])


def test_energy_gradient_matches_central_differences_entry_by_entry():
    gI, gII = MATERIAL.energy_gradient(I_GENERAL, II_GENERAL)
    np.testing.assert_array_equal(gI, gI.T)
    np.testing.assert_array_equal(gII, gII.T)
    scale_I, scale_II = np.max(np.abs(gI)), np.max(np.abs(gII))
    # W = W_s(I) + W_b(II): each gradient is independent of the other form. Probing each form with the
    # other at rest keeps the other part's energy out of the differences, where it would only add
    # round-off (W_s is ~10× W_b here, and the II probes are limited to FD_STEP_REL).
    np.testing.assert_array_equal(MATERIAL.energy_gradient(I_GENERAL, np.zeros((2, 2)))[0], gI)
    np.testing.assert_array_equal(MATERIAL.energy_gradient(np.eye(2), II_GENERAL)[1], gII)
    for i in range(2):
        for j in range(2):
            # One entry alone: an off-diagonal probe makes the form slightly asymmetric (< SYMMETRY_RTOL).
            fd_I = _central_difference(lambda A: MATERIAL.energy_density(A, np.zeros((2, 2))), I_GENERAL, i, j)
            fd_II = _central_difference(lambda A: MATERIAL.energy_density(np.eye(2), A), II_GENERAL, i, j)
            assert abs(fd_I - gI[i, j]) <= FD_REL * scale_I, (i, j, fd_I, gI[i, j])
            assert abs(fd_II - gII[i, j]) <= FD_REL * scale_II, (i, j, fd_II, gII[i, j])

    # A symmetric variation of both off-diagonal entries pairs with the gradient by the Frobenius
    # product: dW = 2 d (dW/dI)_01.
    d = FD_STEP_REL
    E01 = np.array([[0.0, 1.0], [1.0, 0.0]])
    W_plus = MATERIAL.energy_density(I_GENERAL + d * E01, II_GENERAL)
    W_minus = MATERIAL.energy_density(I_GENERAL - d * E01, II_GENERAL)
    fd = (W_plus - W_minus) / (2 * d)
    assert abs(fd - 2.0 * gI[0, 1]) <= FD_REL * scale_I

    # Closed forms of the convention: dW/dI = (h/2)[[σ0, σ2], [σ2, σ1]], dW/dII = h³[[m0, m2], [m2, m1]].
    sigma = MATERIAL.S @ membrane_strain(I_GENERAL)
    moment = MATERIAL.B @ bending_strain(II_GENERAL)
    expected_I = 0.5 * H * np.array([[sigma[0], sigma[2]], [sigma[2], sigma[1]]])
    expected_II = H**3 * np.array([[moment[0], moment[2]], [moment[2], moment[1]]])
    np.testing.assert_allclose(gI, expected_I, rtol=ROUND_OFF_REL)
    np.testing.assert_allclose(gII, expected_II, rtol=ROUND_OFF_REL)


def test_probe_asymmetry_is_inside_the_accepted_tolerance():
    # The finite-difference probe above relies on this ordering of constants.
    assert FD_STEP_REL < SYMMETRY_RTOL


def test_positive_definiteness_checks_name_block_and_entries():
    assert MATERIAL.membrane_positive_definite and MATERIAL.bending_positive_definite
    MATERIAL.check_positive_definite()

    params = MATERIAL.parameters
    bad_membrane = ShellMaterial(H, **{**params, "s01": 2.0 * np.sqrt(params["s00"] * params["s11"])})
    assert not bad_membrane.membrane_positive_definite and bad_membrane.bending_positive_definite
    with pytest.raises(ValueError, match=r"membrane block S not positive definite: s01² = .* >= s00·s11"):
        bad_membrane.check_positive_definite()
    with pytest.raises(ValueError, match="s01²"):
        bad_membrane.engineering()
    with pytest.raises(ValueError, match="s01²"):
        bad_membrane.moduli()

    bad_bending = ShellMaterial(H, **{**params, "b22": -1.0})
    assert bad_bending.membrane_positive_definite and not bad_bending.bending_positive_definite
    with pytest.raises(ValueError, match=r"bending block B not positive definite: b22 = -1.0 <= 0"):
        bad_bending.check_positive_definite()
    bad_bending.moduli()  # moduli need only the membrane block


def test_matrices_and_parameters():
    m = MATERIAL
    np.testing.assert_array_equal(m.S, [[m.s00, m.s01, 0], [m.s01, m.s11, 0], [0, 0, m.s22]])
    np.testing.assert_array_equal(m.B, [[m.b00, m.b01, 0], [m.b01, m.b11, 0], [0, 0, m.b22]])
    assert tuple(MATERIAL.parameters) == PARAMETER_NAMES


# -- JSON ---------------------------------------------------------------------------------------------


def test_json_round_trip_through_a_material_file(tmp_path):
    path = tmp_path / "cotton_twill.json"
    document = {"fabric": {"fibre": "cotton"}, "shell": MATERIAL.to_dict(), "engineering": MATERIAL.engineering()}
    path.write_text(json.dumps(document), encoding="utf-8")
    assert MaterialFile.read(path).shell == MATERIAL
    assert MaterialFile.read(str(path)).shell == MATERIAL
    assert MaterialFile.read(document).shell == MATERIAL
    assert ShellMaterial.from_dict(MATERIAL.to_dict()) == MATERIAL
    assert ShellMaterial.from_dict(json.loads(json.dumps(MATERIAL.to_dict()))) == MATERIAL
    assert MATERIAL.to_dict()["membrane_pa"]["s01"] == MATERIAL.s01
    assert MATERIAL.to_dict()["thickness_m"] == H


def test_json_errors_name_the_key_and_the_file(tmp_path):
    path = tmp_path / "material.json"

    def write(document):
        path.write_text(json.dumps(document), encoding="utf-8")
        return path

    good = MATERIAL.to_dict()
    with pytest.raises(ValueError, match=r"material\.json: missing key 'shell'"):
        MaterialFile.read(write({"fabric": {}})).shell
    no_b22 = {**good, "bending_pa": {k: v for k, v in good["bending_pa"].items() if k != "b22"}}
    with pytest.raises(ValueError, match=r"material\.json: shell: missing keys: bending_pa\.b22"):
        MaterialFile.read(write({"shell": no_b22})).shell
    with pytest.raises(ValueError, match=r"material\.json: shell: missing keys: thickness_m"):
        MaterialFile.read(write({"shell": {k: v for k, v in good.items() if k != "thickness_m"}})).shell
    misspelt = {**good, "membrane_pa": {**good["membrane_pa"], "s10": 1.0}}
    with pytest.raises(ValueError, match=r"unknown keys: membrane_pa\.s10"):
        MaterialFile.read(write({"shell": misspelt})).shell
    with pytest.raises(ValueError, match=r"material\.json: shell: membrane_pa\.s00 must be a number, got '3e6'"):
        MaterialFile.read(write({"shell": {**good, "membrane_pa": {**good["membrane_pa"], "s00": "3e6"}}})).shell
    with pytest.raises(ValueError, match=r"bending_pa must be an object"):
        MaterialFile.read(write({"shell": {**good, "bending_pa": [1, 2, 3, 4]}})).shell
    with pytest.raises(ValueError, match=r"thickness must be > 0"):
        MaterialFile.read(write({"shell": {**good, "thickness_m": -1e-4}})).shell
    path.write_text("{not json", encoding="utf-8")
    with pytest.raises(ValueError, match=r"material\.json: invalid JSON at line 1"):
        MaterialFile.read(path).shell
    with pytest.raises(ValueError, match="no such material file"):
        MaterialFile.read(tmp_path / "absent.json").shell


# -- bad input ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "I",
    [
        np.array([[1.0, 0.0], [0.0, -0.5]]),  # negative eigenvalue
        np.array([[1.0, 2.0], [2.0, 1.0]]),  # positive diagonal, negative determinant
        np.array([[1.0, 0.1], [0.0, 1.0]]),  # asymmetric
        np.array([[np.nan, 0.0], [0.0, 1.0]]),
        np.array([[1.0, 0.0], [0.0, np.inf]]),
    ],
)
def test_first_fundamental_form_must_be_finite_symmetric_positive_definite(I):
    with pytest.raises(ValueError, match="first fundamental form must be symmetric positive definite, got"):
        MATERIAL.energy_density(I, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="first fundamental form must be symmetric positive definite"):
        membrane_strain(I)


def test_bad_form_in_a_stack_is_located():
    stack = np.stack([np.eye(2), np.eye(2), -np.eye(2)])
    with pytest.raises(ValueError, match=r"at index 2 \(of 3\)"):
        membrane_strain(stack)


@pytest.mark.parametrize(
    "II",
    [
        np.array([[1.0, 2.0], [-2.0, 1.0]]),
        np.array([[np.nan, 0.0], [0.0, 0.0]]),
        np.array([[0.0, 0.0], [0.0, -np.inf]]),
    ],
)
def test_second_fundamental_form_must_be_finite_and_symmetric(II):
    with pytest.raises(ValueError, match="second fundamental form must be finite and symmetric, got"):
        MATERIAL.energy_gradient(np.eye(2), II)
    with pytest.raises(ValueError, match="second fundamental form must be finite and symmetric"):
        bending_strain(II)


@pytest.mark.parametrize("shape", [(2,), (3, 3), (2, 2, 2, 2), (4, 2, 3)])
def test_forms_of_the_wrong_shape_are_rejected(shape):
    with pytest.raises(ValueError, match=r"must have shape \(2, 2\) or \(n, 2, 2\)"):
        membrane_strain(np.ones(shape))


def test_mismatched_stacks_are_rejected():
    with pytest.raises(ValueError, match="matching leading shapes"):
        MATERIAL.energy_density(np.stack([np.eye(2)] * 3), np.zeros((2, 2, 2)))


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("thickness", -3e-4, r"thickness must be > 0 \(m\), got -0.0003"),
        ("thickness", 0.0, r"thickness must be > 0"),
        ("thickness", float("nan"), "thickness must be finite, got nan"),
        ("s00", float("inf"), "s00 must be finite, got inf"),
        ("b22", float("nan"), "b22 must be finite"),
        ("s01", True, "s01 must be a real number, got True"),
        ("b11", "1e5", "b11 must be a real number"),
    ],
)
def test_bad_fields_are_rejected_by_name(field, value, message):
    fields = {"thickness": H, **MATERIAL.parameters, field: value}
    with pytest.raises(ValueError, match=message):
        ShellMaterial(**fields)


def test_indefinite_material_is_constructible():
    # A fit may produce one; the fitter reports it, the constructor does not refuse it.
    m = ShellMaterial(H, s00=1.0, s01=2.0, s11=1.0, s22=-1.0, b00=0.0, b01=0.0, b11=0.0, b22=0.0)
    assert not m.membrane_positive_definite and not m.bending_positive_definite


def test_uniaxial_tension_is_the_free_width_minimum_and_the_engineering_stretch():
    material = ShellMaterial(3e-4, s00=3e6, s01=9e5, s11=2e6, s22=1e5, b00=1e6, b01=1e5, b11=8e5, b22=2e5)
    eng = material.engineering()
    for axis, key in ((0, "weft_stretch_n_per_m"), (1, "warp_stretch_n_per_m")):
        I, W = material.uniaxial_tension(axis, 1.02)
        assert I[axis, axis] == pytest.approx(1.02**2) and I[0, 1] == 0.0
        assert W == pytest.approx(material.energy_density(I, np.zeros((2, 2))), rel=1e-13)
        assert W == pytest.approx(0.5 * eng[key] * (0.5 * (1.02**2 - 1.0)) ** 2, rel=1e-12)
        # The free direction is stationary: the transverse stress dW/dI vanishes there.
        stress = material.energy_gradient(I, np.zeros((2, 2)))[0]
        assert abs(stress[1 - axis, 1 - axis]) <= 1e-12 * abs(stress[axis, axis])
    with pytest.raises(ValueError, match="axis"):
        material.uniaxial_tension(2, 1.1)


# -- the strain-stiffening membrane -----------------------------------------------------------------

# A ridge membrane on the woven's S: weft and shear stiffen from 2 and 1 %, warp tension is stiffer
# than warp compression from zero (a one-sided ridge at knot 0), negative shear softer, a jam in
# combined compression, and a ridge across the normal-strain plane.
_C30, _S30 = math.cos(math.pi / 6), math.sin(math.pi / 6)
RIDGED_TERMS = RidgeMembrane(
    (MATERIAL.s00, MATERIAL.s01, MATERIAL.s11, MATERIAL.s22),
    ((1.0, 0.0, 0.0, 0.02, 5.0 * MATERIAL.s00),
     (0.0, 1.0, 0.0, 0.0, 0.5 * MATERIAL.s11),
     (_C30, _S30, 0.0, 0.03, 2.0 * MATERIAL.s00),
     (0.0, 0.0, 1.0, 0.01, 10.0 * MATERIAL.s22),
     (0.0, 0.0, -1.0, 0.0, 0.5 * MATERIAL.s22),
     (-0.6, -0.8, 0.0, 0.05, MATERIAL.s00)),
)
RIDGED = dataclasses.replace(MATERIAL, nonlinear=RIDGED_TERMS)
# Points on both sides of every direction with strains of 5–15 %, every n·ε − t at least 1e-3 from
# zero (checked below): the energy is exactly quadratic within a central difference's reach
# (δ ~ 1e-9), so the round-off bound of FD_REL holds as for StVK.
I_STRAINED = (np.array([[1.25, 0.18], [0.18, 0.9]]), np.array([[0.85, -0.15], [-0.15, 1.2]]))


def _ridge_distance(terms: RidgeMembrane, eps: np.ndarray) -> float:
    """Least |n_j·ε − t_j| over the ridges: how far ε is from the nearest kink."""
    return float(np.min(np.abs(eps @ terms.directions.T - terms.knots)))


def test_ridge_membrane_energy_gradient_matches_central_differences():
    for I in I_STRAINED:
        assert _ridge_distance(RIDGED_TERMS, membrane_strain(I)) > 1e-3
        gI, _ = RIDGED.energy_gradient(I, np.zeros((2, 2)))
        scale = np.max(np.abs(gI))
        for i in range(2):
            for j in range(2):
                fd = _central_difference(lambda A: RIDGED.energy_density(A, np.zeros((2, 2))), I, i, j)
                assert abs(fd - gI[i, j]) <= FD_REL * scale, (i, j, fd, gI[i, j])


def test_ridge_membrane_is_the_membrane_and_s_its_linear_model():
    """With a ridge membrane the membrane energy is h ψ(ε) alone (S is not added): against the
    formula written out; ``linear`` is StVK with S; a ridge membrane of the base alone is that
    quadratic (its pulls and constants are StVK's with S = Q)."""
    h = MATERIAL.thickness
    for I in I_STRAINED:
        eps = membrane_strain(I)
        psi = 0.5 * eps @ RIDGED_TERMS.Q @ eps + sum(
            0.5 * c * max(np.dot((n0, n1, n2), eps) - t, 0.0) ** 2 for n0, n1, n2, t, c in RIDGED_TERMS.ridges)
        assert RIDGED.energy_density(I, np.zeros((2, 2))) == pytest.approx(h * psi, rel=ROUND_OFF_REL)
    assert RIDGED.linear == MATERIAL
    assert RIDGED.energy_density(np.eye(2), np.zeros((2, 2))) == 0.0
    quadratic = dataclasses.replace(MATERIAL, nonlinear=RidgeMembrane(RIDGED_TERMS.base))
    for angle in (0.0, 0.4, math.pi / 4, math.pi / 2):
        for stretch in (1.0 + 1e-6, 1.05):
            got, want = quadratic.uniaxial_pull(angle, stretch), MATERIAL.uniaxial_pull(angle, stretch)
            assert got.force_n_per_m == pytest.approx(want.force_n_per_m, rel=PULL_REL)
            assert got.width_ratio == pytest.approx(want.width_ratio, rel=PULL_REL)
    for key, value in MATERIAL.engineering().items():
        assert quadratic.engineering()[key] == pytest.approx(value, rel=SMALL_PULL_REL), key


def test_one_sided_ridges_change_the_tangent_on_their_side_only():
    """A knot-0 ridge adds c n nᵀ where n·ε > 0 and nothing where n·ε < 0; a ridge at a positive
    knot engages past it; the Hessian is the stress's derivative away from the kinks."""
    terms = RIDGED_TERMS
    warp = np.array([0.0, 1e-4, 0.0])
    np.testing.assert_allclose(terms.hessian(warp) - terms.Q, np.diag([0.0, 0.5 * MATERIAL.s11, 0.0]))
    np.testing.assert_allclose(terms.hessian(-warp), terms.Q)
    shear = np.array([0.0, 0.0, 1e-4])
    np.testing.assert_allclose(terms.hessian(-shear) - terms.Q, np.diag([0.0, 0.0, 0.5 * MATERIAL.s22]))
    np.testing.assert_allclose(terms.hessian(shear), terms.Q)
    weft = np.array([0.025, 0.0, 0.0])  # past the weft ridge's 2 % knot, short of the 30° ridge's 3 %
    np.testing.assert_allclose(terms.hessian(weft) - terms.Q, np.diag([5.0 * MATERIAL.s00, 0.0, 0.0]))
    rng = np.random.default_rng(3)
    for eps in rng.uniform(-0.15, 0.15, (40, 3)):
        if _ridge_distance(terms, eps) < 1e-5:
            continue
        step = 1e-7
        fd = np.stack([(terms.stress(eps + step * e) - terms.stress(eps - step * e)) / (2 * step) for e in np.eye(3)], 1)
        np.testing.assert_allclose(terms.hessian(eps), fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_ridge_membrane_is_convex_and_its_largest_tangent_bounds_every_tangent():
    """ψ is convex (midpoints of random segments lie below the chord), and ``largest_tangent(b)``
    lies above the tangent at every strain with ``|ε_d| <= b`` and below at none it need not."""
    terms = RIDGED_TERMS
    rng = np.random.default_rng(4)
    a, b = rng.uniform(-0.2, 0.2, (2, 300, 3))
    assert np.all(terms.energy(0.5 * (a + b)) <= 0.5 * (terms.energy(a) + terms.energy(b)) * (1 + 1e-12))
    for bound in (0.0, 0.015, 0.08):
        upper = terms.largest_tangent(bound)
        eps = rng.uniform(-bound, bound, (500, 3))
        gaps = np.linalg.eigvalsh(upper - terms.hessian(eps))
        assert gaps.min() >= -1e-9 * np.abs(upper).max()
    # A softening ridge: the largest tangent is the stiffest segment reached, not the sum.
    softening = RidgeMembrane((0.0, 0.0, 0.0, 0.0), ((1.0, 0.0, 0.0, 0.0, 2.0e6), (1.0, 0.0, 0.0, 0.01, -1.5e6)))
    assert softening.largest_tangent(0.02)[0, 0] == 2.0e6
    assert softening.hessian(np.array([0.005, 0.0, 0.0]))[0, 0] == 2.0e6
    assert softening.hessian(np.array([0.015, 0.0, 0.0]))[0, 0] == 0.5e6
    # At 0: the base and the one-sided ridges at zero (warp tension, negative shear).
    np.testing.assert_allclose(terms.largest_tangent(0.0) - terms.Q,
                               np.diag([0.0, 0.5 * MATERIAL.s11, 0.5 * MATERIAL.s22]))
    with pytest.raises(ValueError, match="bound must be >= 0"):
        terms.largest_tangent(-0.1)


def test_ridge_uniaxial_tension_is_the_free_width_minimum():
    for axis in (0, 1):
        I, W = RIDGED.uniaxial_tension(axis, 1.15)
        assert I[axis, axis] == pytest.approx(1.15**2)

        def energy(free):
            form = np.diag([1.15**2, 1.0 + 2.0 * free] if axis == 0 else [1.0 + 2.0 * free, 1.15**2])
            return RIDGED.energy_density(form, np.zeros((2, 2)))

        best = minimize_scalar(energy, bounds=(-0.4, 0.1), method="bounded", options={"xatol": 1e-12})
        assert W == pytest.approx(best.fun, rel=MINIMISED_REL)
        # The ridges stiffen both directions at 15 %: above the base's StVK.
        assert W > MATERIAL.uniaxial_tension(axis, 1.15)[1]


def test_a_bad_ridge_membrane_is_refused_naming_what_is_wrong():
    base = RIDGED_TERMS.base
    with pytest.raises(ValueError, match="ridge 0: its direction must be a unit vector"):
        RidgeMembrane(base, ((1.0, 1.0, 0.0, 0.0, 1.0),))
    with pytest.raises(ValueError, match="ridge 1: its knot must be >= 0"):
        RidgeMembrane(base, ((1.0, 0.0, 0.0, 0.0, 1.0), (0.0, 1.0, 0.0, -0.01, 1.0)))
    with pytest.raises(ValueError, match=r"along \[1.0, 0.0, 0.0\] make the energy concave: past knot 0.0"):
        RidgeMembrane(base, ((1.0, 0.0, 0.0, 0.0, -1.0),))
    # A tangent may fall at a knot (softening) as long as it stays >= 0 along its direction.
    RidgeMembrane(base, ((1.0, 0.0, 0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.01, -2.0)))
    with pytest.raises(ValueError, match="past knot 0.01 their tangent is -0.5 Pa"):
        RidgeMembrane(base, ((1.0, 0.0, 0.0, 0.01, -1.5), (1.0, 0.0, 0.0, 0.0, 1.0)))
    with pytest.raises(ValueError, match="ridge 0 knot"):
        RidgeMembrane(base, ((1.0, 0.0, 0.0, float("nan"), 1.0),))
    with pytest.raises(ValueError, match=r"\(n0, n1, n2, knot, stiffness\)"):
        RidgeMembrane(base, ((1.0, 0.0, 0.0, 1.0),))
    with pytest.raises(ValueError, match="positive semi-definite"):
        RidgeMembrane((1.0, 2.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="positive semi-definite"):
        RidgeMembrane((1.0, 0.0, 1.0, -1.0))
    RidgeMembrane((1.0, 1.0, 1.0, 0.0))  # rank one and no shear: semi-definite, accepted
    with pytest.raises(ValueError, match="must be a RidgeMembrane"):
        dataclasses.replace(MATERIAL, nonlinear={"base": base})


def test_a_ridge_material_reads_back_and_old_models_are_refused():
    data = RIDGED.to_dict()
    assert data["nonlinear"]["model"] == RIDGE_MODEL
    assert ShellMaterial.from_dict(json.loads(json.dumps(data))) == RIDGED
    assert ShellMaterial.from_dict(MATERIAL.to_dict()).nonlinear is None
    bad = json.loads(json.dumps(data))
    bad["nonlinear"]["ridges"][2]["knot"] = "tight"
    with pytest.raises(ValueError, match=r"nonlinear.ridges\[2\].knot must be a number"):
        ShellMaterial.from_dict(bad)
    bad = json.loads(json.dumps(data))
    bad["nonlinear"]["ridges"][0]["direction"] = [1.0, 0.0]
    with pytest.raises(ValueError, match=r"nonlinear.ridges\[0\].direction must be a list of 3 numbers"):
        ShellMaterial.from_dict(bad)
    with pytest.raises(ValueError, match="nonlinear.model must be 'green-ridge'"):
        ShellMaterial.from_dict({**data, "nonlinear": {**data["nonlinear"], "model": "ogden"}})
    old = {"model": "green-polynomial", "stress_terms_pa": {}, "stiffening_strain": {}}
    with pytest.raises(ValueError, match="no longer supported: fit the fabric again"):
        ShellMaterial.from_dict({**data, "nonlinear": old})
    # The plugin's keys: the base as s00 … s22 and five numbers a ridge, each read back exactly.
    keys = RIDGED_TERMS.plugin_keys
    assert [float(keys[k]) for k in ("s00", "s01", "s11", "s22")] == list(RIDGED_TERMS.base)
    numbers = [float(v) for v in keys["ridges"].split()]
    assert numbers == [v for ridge in RIDGED_TERMS.ridges for v in ridge]


# A uniaxial pull at 1e-6 strain: its force over the small-strain stiffness times λ − 1 is
# λ (1 + λ)/2 ≈ 1 + 1.5e-6 (Green against engineering strain), and the width contraction is the
# Poisson ratio's to O(strain): 1e-3 holds both with margin.
SMALL_PULL = 1e-6
SMALL_PULL_REL = 1e-3
# Two uniaxial pulls of the same energy by different routes (StVK against a ridge membrane of its
# base alone): each balances its transverse stresses to UNIAXIAL_STRESS_RTOL, ~1e-9 of the pull.
PULL_REL = 1e-7


@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 4, 1.2, math.pi / 2])
def test_uniaxial_pull_at_small_strain_is_the_rotated_compliance(angle):
    stiffness, poisson = MATERIAL.uniaxial_stiffness(angle)
    pull = MATERIAL.uniaxial_pull(angle, 1.0 + SMALL_PULL)
    assert pull.force_n_per_m == pytest.approx(stiffness * SMALL_PULL, rel=SMALL_PULL_REL)
    assert (1.0 - pull.width_ratio) == pytest.approx(poisson * SMALL_PULL, rel=SMALL_PULL_REL)


@pytest.mark.parametrize("angle", [0.0, math.pi / 2])
def test_a_ridge_membranes_small_strain_constants_follow_its_one_sided_tangent(angle):
    """Pulled along weft the ridge membrane meets Q with warp compression (the knot-0 warp ridge
    stays off), pulled along warp it meets Q + ½ s11 e1 e1ᵀ: the closed forms of those tangents."""
    tangent = RIDGED_TERMS.Q + (np.diag([0.0, 0.5 * MATERIAL.s11, 0.0]) if angle else 0.0)
    stiffness, poisson = RIDGED.uniaxial_stiffness(angle)
    other = 1 if angle == 0.0 else 0
    along = 1 - other
    assert stiffness == pytest.approx(MATERIAL.thickness * (tangent[along, along] - tangent[0, 1] ** 2
                                                            / tangent[other, other]), rel=SMALL_PULL_REL)
    assert poisson == pytest.approx(tangent[0, 1] / tangent[other, other], rel=SMALL_PULL_REL)


@pytest.mark.parametrize("axis", [0, 1])
def test_uniaxial_pull_along_a_yarn_is_the_uniaxial_tension(axis):
    """Along weft or warp the pull needs no shear: its force is the derivative of
    :meth:`uniaxial_tension`'s minimum energy (central differences) and its width that minimum's."""
    stretch, step = 1.12, 1e-6
    pull = RIDGED.uniaxial_pull(axis * math.pi / 2, stretch)
    force = (RIDGED.uniaxial_tension(axis, stretch + step)[1] - RIDGED.uniaxial_tension(axis, stretch - step)[1]) / (2 * step)
    I, _ = RIDGED.uniaxial_tension(axis, stretch)
    assert pull.force_n_per_m == pytest.approx(force, rel=FD_REL)
    assert pull.width_ratio == pytest.approx(math.sqrt(I[1 - axis, 1 - axis]), rel=MINIMISED_REL)
    # Both solves balance the transverse stress to ~1e-9 of the stiffest stress (brentq there,
    # Newton here), which leaves the free strain within ~1e-10.
    np.testing.assert_allclose(pull.first_form, I, rtol=0, atol=1e-9)


def test_uniaxial_pull_on_the_bias_is_the_free_minimum():
    """At 45° the pull's free strains (transverse and shear, in the pull's frame) minimise W: an
    independent minimiser over both finds the same energy, and its force is dW/dλ."""
    from scipy.optimize import minimize

    angle, stretch = math.pi / 4, 1.08
    c, s = math.cos(angle), math.sin(angle)
    q = np.array([[c, -s], [s, c]])

    def energy(free, lam=stretch):
        green = np.array([[0.5 * (lam**2 - 1.0), free[1]], [free[1], free[0]]])
        return RIDGED.energy_density(np.eye(2) + 2.0 * q @ green @ q.T, np.zeros((2, 2)))

    pull = RIDGED.uniaxial_pull(angle, stretch)
    best = minimize(energy, np.zeros(2), method="Nelder-Mead", options={"xatol": 1e-12, "fatol": 1e-16,
                                                                         "maxiter": 4000})
    assert RIDGED.energy_density(pull.first_form, np.zeros((2, 2))) == pytest.approx(best.fun, rel=MINIMISED_REL)
    step = 1e-6
    plus = minimize(lambda f: energy(f, stretch + step), best.x, method="Nelder-Mead",
                    options={"xatol": 1e-12, "fatol": 1e-16, "maxiter": 4000}).fun
    minus = minimize(lambda f: energy(f, stretch - step), best.x, method="Nelder-Mead",
                     options={"xatol": 1e-12, "fatol": 1e-16, "maxiter": 4000}).fun
    assert pull.force_n_per_m == pytest.approx((plus - minus) / (2 * step), rel=1e-4)


def test_uniaxial_pull_rejects_bad_input():
    with pytest.raises(ValueError, match="stretch"):
        MATERIAL.uniaxial_pull(0.0, 0.0)
    with pytest.raises(ValueError, match="angle"):
        MATERIAL.uniaxial_pull(float("nan"), 1.1)


def test_a_uniaxial_pull_follows_a_large_poisson_ratio_until_the_width_collapses():
    """A linear StVK membrane with ν = s01/s11 = 1.2 pulled along the weft, no shear coupling: the
    free width's Green strain is −ν times the pulled one (closed form) while it stays above −½; past
    that (e₁ > 1/(2ν)) no width balances the pull, which is said, not extrapolated."""
    h = 1e-3
    knit = ShellMaterial(thickness=h, s00=2.0e6, s01=1.2e6, s11=1.0e6, s22=1.0e5,
                         b00=1.0, b01=0.0, b11=1.0, b22=1.0)
    stretch = 1.3
    e1 = 0.5 * (stretch**2 - 1)
    pull = knit.uniaxial_pull(0.0, stretch)
    assert 0.5 * (pull.first_form[1, 1] - 1) == pytest.approx(-1.2 * e1, rel=1e-9)
    assert pull.force_n_per_m == pytest.approx(stretch * h * (2.0e6 - 1.2e6**2 / 1.0e6) * e1, rel=1e-9)
    with pytest.raises(ValueError, match="the width collapses"):
        knit.uniaxial_pull(0.0, 1.4)  # e1 = 0.48 > 1/2.4


# Random convex ridge membranes for the free-width pull: fans of 3-8 in-plane rays with 1-3 knots
# each below 10 % and tangents up to 30 s00 (falling as well as rising), and a shear pair. 300 of
# them, pulled along weft and warp to 1, 5 and 10 %: the Newton search once cycled between two
# pieces of such a membrane on 2 of the 1800 pulls (a step across a kink lowered W, the step back
# lowered the residual).
RANDOM_MEMBRANES = 300
# W's free-width minimum on the collapse side: the scan's grid of Green strains across the pull.
COLLAPSE_SCAN = np.linspace(-0.49, 0.2, 400)


def test_a_uniaxial_pull_of_any_convex_ridge_membrane_balances_or_the_width_collapses():
    rng = np.random.default_rng(0)
    balanced = 0
    for _ in range(RANDOM_MEMBRANES):
        ridges = [(0.0, 0.0, sign, 0.0, MATERIAL.s22) for sign in (1.0, -1.0)]
        for _ in range(int(rng.integers(3, 9))):
            angle = rng.uniform(0.0, 2.0 * math.pi)
            knots = np.sort(np.concatenate([[0.0], rng.uniform(0.0, 0.1, int(rng.integers(1, 4)))]))
            previous = 0.0
            for knot, tangent in zip(knots, rng.uniform(0.0, 30.0, len(knots)) * MATERIAL.s00):
                ridges.append((math.cos(angle), math.sin(angle), 0.0, float(knot), float(tangent - previous)))
                previous = tangent
        material = dataclasses.replace(MATERIAL, nonlinear=RidgeMembrane((0.0, 0.0, 0.0, 0.0), tuple(ridges)))
        for axis in (0, 1):
            for stretch in (1.01, 1.05, 1.1):
                pulled = 0.5 * (stretch**2 - 1.0)

                def energy(free: float) -> float:
                    green = np.diag([pulled, free] if axis == 0 else [free, pulled])
                    return float(material.energy_density(np.eye(2) + 2.0 * green, np.zeros((2, 2))))

                try:
                    pull = material.uniaxial_pull(axis * math.pi / 2, stretch)
                except ValueError as exc:
                    assert "no free width" in str(exc)
                    # Refused only where W falls all the way to the width's collapse.
                    values = [energy(f) for f in COLLAPSE_SCAN]
                    assert int(np.argmin(values)) == 0, (axis, stretch, ridges)
                    continue
                balanced += 1
                stress = material.energy_gradient(pull.first_form, np.zeros((2, 2)))[0]
                # Against the stress the pull makes in the stiffest direction, as the search judges it.
                scale = H * float(np.abs(material.nonlinear.largest_tangent(pulled)).max()) * pulled
                assert abs(stress[1 - axis, 1 - axis]) <= 1e-6 * scale, (axis, stretch, ridges)
    assert balanced > 0.9 * RANDOM_MEMBRANES * 6


def test_the_satins_fitted_membrane_balances_every_pull():
    """The satin's fitted ridge membrane (its base S zero, all stiffness in the ridges;
    tests/data/satin_shell.json) pulled at five angles from 0.05 to 12 %: every pull balances its
    transverse and shear stresses. A fixed regularisation zigzagged across a kink at the weft's
    1.128 % and gave up (which left `yarnfit validate`'s figures undrawn); there the free strains
    are also W's minimum by an independent minimiser."""
    from scipy.optimize import minimize

    with open(Path(__file__).parent / "data" / "satin_shell.json") as source:
        satin = ShellMaterial.from_dict(json.load(source)["shell"])
    for degrees in (0.0, 30.0, 45.0, 90.0, -45.0):
        for strain in np.linspace(0.0005, 0.12, 40):
            pull = satin.uniaxial_pull(math.radians(degrees), 1.0 + strain)  # raises if it does not balance
            assert pull.force_n_per_m > 0.0 and 0.0 < pull.width_ratio < 1.0
    stretch = 1.0112787274843118
    pull = satin.uniaxial_pull(0.0, stretch)
    pulled = 0.5 * (stretch**2 - 1.0)

    def energy(free):
        return satin.energy_density(np.eye(2) + 2.0 * np.array([[pulled, free[1]], [free[1], free[0]]]),
                                    np.zeros((2, 2)))

    best = minimize(energy, np.zeros(2), method="Nelder-Mead",
                    options={"xatol": 1e-12, "fatol": 1e-16, "maxiter": 4000})
    assert satin.energy_density(pull.first_form, np.zeros((2, 2))) <= best.fun * (1.0 + MINIMISED_REL)
