"""Shell fit: recovery of known materials, weights, Jacobian, indefinite fits, bounds, uncertainty, bad input."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import scipy.optimize

from yarnfit.engine import Residual
from yarnfit.fit import (
    COUPLING_LIMIT,
    DIAGONAL_FLOOR_REL,
    STRETCH_DOMINATED_SHARE,
    IndefiniteFitError,
    design_matrix,
    fit_residual_jacobian,
    fit_shell,
    sample_weights,
    stretch_dominated_notes,
    weighted_residuals,
)
from yarnfit.samples import (BENDING_FAMILIES, FAMILIES, MEMBRANE_FAMILIES, OPTIONAL_FAMILIES, OTHER_BIAS_FAMILIES,
                             SampleResult, SampleSpec)
from yarnfit.shell import PARAMETER_NAMES, ShellMaterial

from fabric_shell import FABRIC as TRUE, H  # a realistic woven

# The acceptance level for recovering a material from its own energies. Exact data come back to
# ~1e-14 (the unit-column design has a condition number ~10), so this fails only for a real error.
RECOVERY_REL = 1e-6
# R² of exact data: SS_res is round-off, (1e-15 W)², against SS_tot ~ W²: 1 − R² ~ 1e-30. 1e-12 is
# loose yet far below what any misfit (a wrong factor, a dropped column) would give.
R2_TOL = 1e-12
# Shell energies and design matrix entries are a few products: a few ulps, with a margin of ~100.
ROUND_OFF_REL = 1e-13
# Coupling-bounded fit against SLSQP on the same problem: SLSQP stops at a cost change of 1e-16
# relative, which leaves parameters uncertain to ~sqrt(1e-16)/(smallest singular value ~0.1) ~ 1e-7.
BOUNDED_REL = 1e-6
# Relative parameter step of the finite-difference Jacobian. The residuals are linear in γ, so any
# step is free of truncation error; 1e-6 keeps the difference well above round-off.
JAC_STEP_REL = 1e-6
# Central-difference round-off: ε·|W|/(δ·|J|) with J δ ~ 1e-6 W gives ~2e-10; 1e-7 leaves 500×.
JAC_REL = 1e-7
# Noisy data: the true value lies within this many standard errors. For a Gaussian estimate a 4σ band
# misses with probability 6e-5 per parameter; with n − p = 12 degrees of freedom (t-distribution)
# about 2e-3, and the seed is fixed, so a failure means a wrong estimate or a wrong error bar.
K_SIGMA = 4.0
# The standard errors must also be informative, not merely large, or the K_SIGMA check could not
# fail: with NOISE_REL below they are 0.01–2 % of the true values (s22, resolved by the weakest
# energies, is the largest); a bound of 5 % makes the K_SIGMA check bite.
MAX_REL_STD_ERROR = 0.05
# Monte-Carlo check of the covariance: the sample standard deviation of N estimates has relative
# error 1/√(2N) = 3.5 % for N = 400; 0.12 is a 3.4σ band.
N_TRIALS = 400
CALIBRATION_REL = 0.12


def fit_linear(*args, **kwargs):
    """The linear (StVK) fit, as the material (quadratic membrane, symmetric bending): these tests
    check its least squares exactly."""
    return fit_shell(*args, membrane="linear", bending="symmetric", **kwargs)
# Energy noise of the noisy-data tests, relative to the group's largest energy (10 J/m² membrane,
# 0.26 J/m² bending). The smallest shear energies are ~1/2500 of the largest membrane energy, so this
# is already ~25 % noise on them; much more and s22 would reach its floor in some trials, truncating
# the scatter the Monte-Carlo test compares with.
NOISE_REL = 1e-4

TRUE_PAPER = ShellMaterial(H, **{**TRUE.parameters, "b01": 0.0})

# Largest parameter of each family: 10 % stretch, I_01 = 0.05 of shear, 200 1/m of curvature.
LARGEST = {
    "weft_stretch": 0.1,
    "warp_stretch": 0.1,
    "biaxial_stretch": 0.1,
    "shear": 0.05,
    "weft_uniaxial": 0.1,
    "warp_uniaxial": 0.1,
    "bias_uniaxial": 0.1,
    "negative_bias_uniaxial": 0.1,
    "weft_bend": 200.0,
    "warp_bend": 200.0,
    "bias_bend": 200.0,
    "saddle_bend": 200.0,
}
PER_FAMILY = 4
# The families every fit needs (the paper's, plus saddles).
CORE_FAMILIES = tuple(f for f in FAMILIES if f not in OPTIONAL_FAMILIES)


def forms(family: str, x: float) -> tuple[np.ndarray, np.ndarray]:
    """(I, II) of one sample: stretch ratio 1 + x, shear I_01 = x, or curvature x (1/m)."""
    I, II = np.eye(2), np.zeros((2, 2))
    if family == "weft_stretch":
        I = np.diag([(1 + x) ** 2, 1.0])
    elif family == "warp_stretch":
        I = np.diag([1.0, (1 + x) ** 2])
    elif family == "biaxial_stretch":
        I = np.diag([(1 + x) ** 2, (1 + x) ** 2])
    elif family == "shear":
        I = np.array([[1.0, x], [x, 1.0]])
    elif family == "weft_uniaxial":  # the homogenizer finds μ; any μ makes a valid membrane sample
        I = np.diag([(1 + x) ** 2, (1 - 0.3 * x) ** 2])
    elif family == "warp_uniaxial":
        I = np.diag([(1 - 0.2 * x) ** 2, (1 + x) ** 2])
    elif family == "bias_uniaxial":  # along 45°, the width contracted as a shear-soft fabric's
        turn = np.sqrt(0.5) * np.array([[1.0, -1.0], [1.0, 1.0]])
        green = np.diag([0.5 * ((1 + x) ** 2 - 1), 0.5 * ((1 - 0.5 * x) ** 2 - 1)])
        I = np.eye(2) + 2.0 * turn @ green @ turn.T
    elif family == "negative_bias_uniaxial":  # its mirror image along −45°
        I = forms("bias_uniaxial", x)[0] * [[1.0, -1.0], [-1.0, 1.0]]
    elif family == "weft_bend":
        II = np.diag([x, 0.0])
    elif family == "warp_bend":
        II = np.diag([0.0, x])
    elif family == "bias_bend":  # cylinder with its curvature direction at 45°
        II = 0.5 * x * np.ones((2, 2))
    else:  # saddle: principal curvatures ±x along the material axes
        II = np.diag([x, -x])
    return I, II


def sample(family, I, II, energy_density, residual, converged, parameter) -> SampleResult:
    """A fit input as the homogenization returns it, ``residual`` its force imbalance."""
    return SampleResult(SampleSpec(family, I, II, parameter), energy_density, converged,
                        Residual(force=residual, torque=0.0, energy_change=0.0, penetration=0.0))


def make_samples(material: ShellMaterial, families=FAMILIES, energy=None) -> list[SampleResult]:
    """PER_FAMILY samples per family with the material's exact energies (or ``energy(family, W)``)."""
    samples = []
    for family in families:
        for x in np.linspace(LARGEST[family] / PER_FAMILY, LARGEST[family], PER_FAMILY):
            I, II = forms(family, x)
            W = material.energy_density(I, II)
            if energy is not None:
                W = energy(family, W)
            samples.append(sample(family, I, II, W, residual=1e-9, converged=True, parameter=x))
    return samples


def with_energies(samples: list[SampleResult], energies) -> list[SampleResult]:
    return [
        sample(s.family, s.I, s.II, float(u), s.residual.force, s.converged, s.parameter) for s, u in zip(samples, energies)
    ]


def hand_weights(samples: list[SampleResult], thickness: float) -> np.ndarray:
    """w = exp(−½(s/σ)²), s = ‖½(I − Id)‖_F or ‖II‖_F h/2, σ = a quarter of the group's largest s."""
    s = np.array(
        [
            np.sqrt(np.sum((0.5 * (x.I - np.eye(2))) ** 2)) if x.family in MEMBRANE_FAMILIES
            else np.sqrt(np.sum(x.II**2)) * thickness / 2
            for x in samples
        ]
    )
    membrane = np.array([x.family in MEMBRANE_FAMILIES for x in samples])
    sigma = np.where(membrane, 0.25 * s[membrane].max(), 0.25 * s[~membrane].max())
    return np.exp(-0.5 * (s / sigma) ** 2)


def noisy_energies(samples: list[SampleResult], weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Exact energies plus Gaussian noise of variance ∝ 1/w (the model the covariance formula assumes)."""
    exact = np.array([s.energy_density for s in samples])
    membrane = np.array([s.family in MEMBRANE_FAMILIES for s in samples])
    scale = np.where(membrane, exact[membrane].max(), exact[~membrane].max()) * NOISE_REL
    return exact + scale / np.sqrt(weights) * rng.standard_normal(len(samples))


# -- recovery ---------------------------------------------------------------------------------------


def test_full_model_recovers_a_known_material():
    fit = fit_linear(make_samples(TRUE), H, model="full")
    for name in PARAMETER_NAMES:
        assert fit.parameters[name] == pytest.approx(getattr(TRUE, name), rel=RECOVERY_REL), name
        assert getattr(fit.material, name) == fit.parameters[name]
    assert fit.material.thickness == H and fit.model == "full"
    assert set(fit.families) == set(FAMILIES)
    for family, stats in fit.families.items():
        assert stats["r2"] >= 1.0 - R2_TOL, family
        assert stats["relative_rms"] <= R2_TOL, family
        assert stats["samples"] == PER_FAMILY
    assert fit.active_bounds == [] and fit.excluded == []
    assert len(fit.used) == len(FAMILIES) * PER_FAMILY and fit.weights.shape == (len(fit.used),)


def test_paper_model_recovers_a_material_with_b01_zero_without_saddle_samples():
    families = tuple(f for f in FAMILIES if f != "saddle_bend")
    fit = fit_linear(make_samples(TRUE_PAPER, families), H, model="paper")
    assert fit.parameters["b01"] == 0.0 and fit.std_error["b01"] == 0.0
    for name in PARAMETER_NAMES:
        if name != "b01":
            assert fit.parameters[name] == pytest.approx(getattr(TRUE_PAPER, name), rel=RECOVERY_REL), name
    for family, stats in fit.families.items():
        assert stats["r2"] >= 1.0 - R2_TOL, family
    assert "saddle_bend" not in fit.families


def test_paper_model_uses_saddle_samples_when_given():
    fit = fit_linear(make_samples(TRUE_PAPER), H, model="paper")
    assert fit.families["saddle_bend"]["r2"] >= 1.0 - R2_TOL
    assert fit.parameters["b00"] == pytest.approx(TRUE_PAPER.b00, rel=RECOVERY_REL)


def test_design_matrix_reproduces_the_shell_energy():
    samples = make_samples(TRUE)
    D = design_matrix(samples, H)
    gamma = np.array([TRUE.parameters[n] for n in PARAMETER_NAMES])
    W = np.array([s.energy_density for s in samples])
    np.testing.assert_allclose(D @ gamma, W, rtol=ROUND_OFF_REL)
    # Membrane rows have no bending entries and vice versa.
    membrane = np.array([s.family in MEMBRANE_FAMILIES for s in samples])
    assert np.all(D[membrane][:, 4:] == 0.0) and np.all(D[~membrane][:, :4] == 0.0)


def test_weighted_residual_jacobian_matches_central_differences():
    samples = make_samples(TRUE)
    weights, _ = sample_weights(samples, H)
    rng = np.random.default_rng(3)
    # Away from the optimum, with an indefinite-capable parameter set: the residual must not care.
    gamma = np.array([TRUE.parameters[n] for n in PARAMETER_NAMES]) * (1.0 + 0.3 * rng.standard_normal(8))
    r, J = fit_residual_jacobian(gamma, samples, H, weights)
    np.testing.assert_array_equal(r, weighted_residuals(gamma, samples, H, weights))
    assert J.shape == (len(samples), 8)
    for j in range(8):
        step = JAC_STEP_REL * abs(gamma[j])
        plus, minus = gamma.copy(), gamma.copy()
        plus[j] += step
        minus[j] -= step
        fd = (weighted_residuals(plus, samples, H, weights) - weighted_residuals(minus, samples, H, weights)) / (
            plus[j] - minus[j]
        )
        scale = np.max(np.abs(J[:, j]))
        assert scale > 0.0
        np.testing.assert_allclose(fd, J[:, j], rtol=0, atol=JAC_REL * scale, err_msg=PARAMETER_NAMES[j])


# -- weights ----------------------------------------------------------------------------------------


def test_weights_are_gaussian_in_strain_with_a_quarter_of_the_largest_strain_as_width():
    samples = make_samples(TRUE)
    weights, widths = sample_weights(samples, H)
    np.testing.assert_allclose(weights, hand_weights(samples, H), rtol=ROUND_OFF_REL)
    # Hand values: the largest membrane strain is biaxial 10 %: E = 0.105 Id, ‖E‖_F = 0.105 √2; the
    # largest surface strain is the saddle at 200 1/m: ‖II‖_F h/2 = 200 √2 · 1.5e-4.
    assert widths["membrane"] == pytest.approx(0.25 * 0.105 * math.sqrt(2), rel=ROUND_OFF_REL)
    assert widths["bending"] == pytest.approx(0.25 * 200 * math.sqrt(2) * H / 2, rel=ROUND_OFF_REL)
    largest = [
        k
        for k, s in enumerate(samples)
        if s.family in ("biaxial_stretch", "saddle_bend") and s.parameter == LARGEST[s.family]
    ]
    assert len(largest) == 2
    np.testing.assert_allclose(weights[largest], math.exp(-8.0), rtol=ROUND_OFF_REL)

    # An explicit width applies to both groups: weft 10 % (‖E‖ = 0.105) and weft bend 200/m (0.03).
    weights, widths = sample_weights(samples, H, weight_width=0.05)
    assert widths == {"membrane": 0.05, "bending": 0.05}
    weft = [k for k, s in enumerate(samples) if s.family == "weft_stretch"][-1]
    bend = [k for k, s in enumerate(samples) if s.family == "weft_bend"][-1]
    assert weights[weft] == pytest.approx(math.exp(-0.5 * (0.105 / 0.05) ** 2), rel=ROUND_OFF_REL)
    assert weights[bend] == pytest.approx(math.exp(-0.5 * (200 * H / 2 / 0.05) ** 2), rel=ROUND_OFF_REL)


def test_fit_is_the_weighted_least_squares_solution_with_its_covariance():
    # Independent reference: per group, γ = argmin ‖√w (D γ − Ū)‖ by numpy's SVD solver, and
    # cov = σ̂² (Dᵀ W D)⁻¹ with σ̂² = Σ w r² / (n − p), using the hand-computed weights.
    exact = make_samples(TRUE)
    w = hand_weights(exact, H)
    samples = with_energies(exact, noisy_energies(exact, w, np.random.default_rng(11)))
    fit = fit_linear(samples, H, model="full")
    np.testing.assert_allclose(fit.weights, w, rtol=ROUND_OFF_REL)

    D = design_matrix(samples, H)
    u = np.array([s.energy_density for s in samples])
    membrane = np.array([s.family in MEMBRANE_FAMILIES for s in samples])
    # The linear model leaves out the other bias's pulls (an even model cannot follow two biases).
    first_bias = np.array([s.family not in OTHER_BIAS_FAMILIES for s in samples])
    for rows, cols in ((membrane & first_bias, slice(0, 4)), (~membrane, slice(4, 8))):
        A = np.sqrt(w[rows])[:, None] * D[rows][:, cols]
        b = np.sqrt(w[rows]) * u[rows]
        gamma = np.linalg.lstsq(A, b, rcond=None)[0]
        r = A @ gamma - b
        cov = (r @ r) / (len(b) - 4) * np.linalg.inv(A.T @ A)
        names = PARAMETER_NAMES[cols]
        for k, name in enumerate(names):
            # Least squares on well-conditioned 16×4 systems: both solvers agree to ~1e-12.
            assert fit.parameters[name] == pytest.approx(gamma[k], rel=1e-9), name
            assert fit.std_error[name] == pytest.approx(math.sqrt(cov[k, k]), rel=1e-9), name

    # Per-family statistics by hand (unweighted).
    fitted = D @ np.array([fit.parameters[n] for n in PARAMETER_NAMES])
    for family in FAMILIES:
        mask = np.array([s.family == family for s in samples])
        res = fitted[mask] - u[mask]
        r2 = 1 - np.sum(res**2) / np.sum((u[mask] - u[mask].mean()) ** 2)
        assert fit.families[family]["r2"] == pytest.approx(r2, rel=1e-9), family
        assert fit.families[family]["relative_rms"] == pytest.approx(
            np.sqrt(np.mean(res**2)) / np.sqrt(np.mean(u[mask] ** 2)), rel=1e-9
        )
        assert fit.families[family]["r2"] < 1.0  # noise is visible


# -- uncertainty ------------------------------------------------------------------------------------


def test_true_parameters_lie_within_a_few_standard_errors_of_a_noisy_fit():
    exact = make_samples(TRUE)
    w = hand_weights(exact, H)
    fit = fit_linear(with_energies(exact, noisy_energies(exact, w, np.random.default_rng(2024))), H)
    for name in PARAMETER_NAMES:
        true, value, error = getattr(TRUE, name), fit.parameters[name], fit.std_error[name]
        assert 0.0 < error <= MAX_REL_STD_ERROR * abs(true), (name, error)
        assert abs(value - true) <= K_SIGMA * error, (name, value, true, error)


def test_standard_errors_match_the_scatter_of_repeated_noisy_fits():
    exact = make_samples(TRUE)
    w = hand_weights(exact, H)
    rng = np.random.default_rng(7)
    estimates, variances = [], []
    for _ in range(N_TRIALS):
        fit = fit_linear(with_energies(exact, noisy_energies(exact, w, rng)), H)
        estimates.append([fit.parameters[n] for n in PARAMETER_NAMES])
        variances.append([fit.std_error[n] ** 2 for n in PARAMETER_NAMES])
    scatter = np.std(estimates, axis=0, ddof=1)
    predicted = np.sqrt(np.mean(variances, axis=0))  # σ̂² is unbiased, σ̂ is not
    np.testing.assert_allclose(scatter, predicted, rtol=CALIBRATION_REL)


def test_too_few_samples_give_nan_standard_errors_and_strict_json():
    # One sample per family: n = p = 4 in each group, no degrees of freedom left.
    samples = [s for s in make_samples(TRUE, CORE_FAMILIES) if s.parameter in (LARGEST[s.family],)]
    assert len(samples) == len(CORE_FAMILIES)
    fit = fit_linear(samples, H)
    assert all(math.isnan(v) for v in fit.std_error.values())
    for name in PARAMETER_NAMES:
        assert fit.parameters[name] == pytest.approx(getattr(TRUE, name), rel=RECOVERY_REL), name
    quality = fit.quality_dict()
    text = json.dumps(quality, allow_nan=False)  # NaN written as null
    assert json.loads(text)["std_error_pa"]["s00"] is None


# -- indefinite fits, bounds, exclusions, missing families ------------------------------------------


def test_biaxial_energies_far_below_the_uniaxial_sum_give_an_indefinite_membrane():
    # W_biax = (h/2)(s00 + 2 s01 + s11) e² ≈ 0 forces s01 = −(s00 + s11)/2, and
    # (s00 + s11)²/4 > s00 s11 whenever s00 ≠ s11.
    samples = make_samples(TRUE, CORE_FAMILIES, energy=lambda family, W: 1e-3 * W if family == "biaxial_stretch" else W)
    with pytest.raises(IndefiniteFitError, match=r"s01² = .* >= s00·s11 .* biaxial_stretch") as info:
        fit_linear(samples, H, coupling_limit=None)
    assert info.value.family == "biaxial_stretch"
    assert isinstance(info.value, ValueError)
    assert info.value.parameters["s01"] < 0.0


def test_saddle_energies_far_above_the_uniaxial_sum_give_an_indefinite_bending_block():
    # W_saddle = (h³/2)(b00 − 2 b01 + b11) k² ten times the truth forces b01 ≈ −4 (b00 + b11)/2,
    # beyond −√(b00 b11); b22 takes up the bias bends.
    samples = make_samples(TRUE, CORE_FAMILIES,
                           energy=lambda family, W: INDEFINITE_FACTOR[family] * W if family == "saddle_bend" else W)
    with pytest.raises(IndefiniteFitError, match=r"b01² = .* >= b00·b11 .* saddle_bend") as info:
        fit_linear(samples, H, model="full", coupling_limit=None)
    assert info.value.family == "saddle_bend"
    # The paper model cannot be indefinite in bending: b01 = 0.
    fit_linear(samples, H, model="paper", coupling_limit=None)


def reference_bounded_fit(samples, thickness, group_columns, coupling, limit):
    """The same constrained problem solved independently: SLSQP on the unscaled parameters of one
    group, the coupling bound as the explicit inequality ``limit² d0 d1 − c² ≥ 0``."""
    used = [s for s in samples if s.converged]
    weights, _ = sample_weights(used, thickness)
    D = design_matrix(used, thickness)
    target = np.array([s.energy_density for s in used])
    rows = np.array([s.is_membrane for s in used]) == (coupling[0].startswith("s"))
    cols = [PARAMETER_NAMES.index(n) for n in group_columns]
    A = np.sqrt(weights[rows])[:, None] * D[np.ix_(rows, cols)]
    b = np.sqrt(weights[rows]) * target[rows]
    unit = np.linalg.norm(A, axis=0)  # the same problem in unit-scaled columns, for SLSQP's sake
    i0, ic, i1 = (group_columns.index(n) for n in coupling)

    def cost(y):
        r = (A / unit) @ y - b
        return float(r @ r) / float(b @ b)

    def bound(y):
        x = y / unit
        return (limit**2 * x[i0] * x[i1] - x[ic] ** 2) * unit[i0] * unit[i1]

    start = np.linalg.lstsq(A / unit, b, rcond=None)[0]
    start[ic] = np.sign(start[ic]) * 0.5 * limit * np.sqrt(abs(start[i0] * start[i1]) * unit[ic] ** 2 / (unit[i0] * unit[i1]))
    result = scipy.optimize.minimize(cost, start, method="SLSQP", constraints=[{"type": "ineq", "fun": bound}],
                                     bounds=[(0.0, None) if n in ("s00", "s11", "s22", "b00", "b11", "b22") else
                                             (None, None) for n in group_columns],
                                     options={"ftol": 1e-16, "maxiter": 1000})
    assert result.success, result.message
    return dict(zip(group_columns, result.x / unit)), cost(result.x)


# Factors on the coupled family's energies that ask for |ρ| > 1 (see the two tests above).
INDEFINITE_FACTOR = {"biaxial_stretch": 1e-3, "saddle_bend": 10.0}


@pytest.mark.parametrize("family, coupling", [("biaxial_stretch", ("s00", "s01", "s11")),
                                              ("saddle_bend", ("b00", "b01", "b11"))])
def test_a_coupling_the_data_push_past_positive_definite_ends_on_its_bound(family, coupling):
    samples = make_samples(TRUE, CORE_FAMILIES, energy=lambda f, W: INDEFINITE_FACTOR[family] * W if f == family else W)
    fit = fit_linear(samples, H)
    d0, c, d1 = (fit.parameters[n] for n in coupling)
    assert fit.active_bounds == [coupling[1]]
    assert abs(c) / math.sqrt(d0 * d1) == pytest.approx(COUPLING_LIMIT, rel=ROUND_OFF_REL)
    assert fit.material.membrane_positive_definite and fit.material.bending_positive_definite
    assert len(fit.notes) == 1 and family in fit.notes[0] and "positive-definite bound" in fit.notes[0]
    assert fit.quality_dict()["notes"] == fit.notes and fit.quality_dict()["coupling_limit"] == COUPLING_LIMIT

    # An independent solver of the same constrained problem finds the same optimum.
    group = [n for n in PARAMETER_NAMES if n[0] == coupling[0][0]]
    reference, reference_cost = reference_bounded_fit(samples, H, group, coupling, COUPLING_LIMIT)
    for name in group:
        assert fit.parameters[name] == pytest.approx(reference[name], rel=BOUNDED_REL), name
    # The other group is untouched by the bound: exact data, exact recovery.
    other = [n for n in PARAMETER_NAMES if n[0] != coupling[0][0]]
    for name in other:
        assert fit.parameters[name] == pytest.approx(TRUE.parameters[name], rel=RECOVERY_REL), name
    del reference_cost


def test_the_coupling_limit_must_be_a_fraction():
    samples = make_samples(TRUE)
    for bad in (0.0, 1.0, 1.5, -0.5):
        with pytest.raises(ValueError, match="coupling_limit must be in"):
            fit_linear(samples, H, coupling_limit=bad)


def test_a_stiffness_the_data_put_at_zero_is_reported_at_its_floor():
    # Warp stretch carries no energy and neither does the coupling: s11 = 0 in the data.
    soft_warp = ShellMaterial(H, **{**TRUE.parameters, "s11": 0.0, "s01": 0.0})
    fit = fit_linear(make_samples(soft_warp), H)
    # s11 at its floor, and with it the coupling held at zero (nothing to couple to).
    assert fit.active_bounds == ["s11", "s01"]
    assert fit.parameters["s01"] == 0.0 and fit.std_error["s01"] == 0.0
    # The floor is relative to the largest diagonal of the unbounded fit, here s00 to round-off.
    assert fit.parameters["s11"] == pytest.approx(DIAGONAL_FLOOR_REL * TRUE.s00, rel=ROUND_OFF_REL)
    assert fit.material.membrane_positive_definite
    # SS_tot = 0 for warp_stretch (all energies zero) and the floor leaves SS_res > 0: r2 = −inf.
    assert fit.families["warp_stretch"]["r2"] == -math.inf
    assert fit.families["warp_stretch"]["relative_rms"] == math.inf
    assert fit.quality_dict()["active_bounds"] == ["s11", "s01"]
    assert fit.notes == ["s11 at its positive floor: the warp_stretch energies carry no s11 stiffness",
                         "s01 held at 0: s11 at the positive floor"]

    # Shear energies slightly negative (a solver artefact): s22 would be negative, it stops at the
    # floor. (Without the bias pulls, which see shear too.)
    samples = [s for s in make_samples(TRUE, energy=lambda family, W: -1e-3 * W if family == "shear" else W)
               if s.family not in ("bias_uniaxial", "negative_bias_uniaxial")]
    fit = fit_linear(samples, H)
    assert fit.active_bounds == ["s22"]  # s22 is uncoupled: s01 stays free
    assert fit.parameters["s22"] == pytest.approx(DIAGONAL_FLOOR_REL * TRUE.s00, rel=ROUND_OFF_REL)
    assert fit.parameters["s00"] == pytest.approx(TRUE.s00, rel=RECOVERY_REL)


def test_a_uniaxial_family_that_floors_a_stiffness_is_left_out_of_the_linear_fit():
    """A woven's bias pull contracts both thread directions, which its yarns give for nothing and a
    linear membrane charges at the stretch stiffness: with pulls whose energies are 1e-3 of the
    material's (the cotton twill's at 2 % were 1/125 of what its contraction alone costs a linear
    membrane), the least squares bought the difference back with s22 on its floor. The fit leaves
    the family out, says so, and the rest of the samples give the material back exactly."""
    samples = [s for s in make_samples(TRUE, energy=lambda family, W: 1e-3 * W if family == "bias_uniaxial" else W)
               if s.family != "negative_bias_uniaxial"]
    fit = fit_linear(samples, H)
    assert fit.active_bounds == []
    for name, value in TRUE.parameters.items():
        assert fit.parameters[name] == pytest.approx(value, rel=RECOVERY_REL), name
    assert fit.notes[0].startswith("fitted without the bias_uniaxial samples: with them s22 went to the positive floor")
    # Its R² still counts them: the misfit is reported, not hidden.
    assert fit.families["bias_uniaxial"]["r2"] < 0.0
    # The same pulls with their true energies are kept (nothing is floored).
    assert not any("fitted without" in note for note in fit_linear(make_samples(TRUE), H).notes)


def test_non_converged_samples_are_excluded_and_listed():
    good = make_samples(TRUE)
    bad = [
        sample("saddle_bend", *forms("saddle_bend", 300.0), float("nan"), float("nan"), False, 300.0),
        sample("weft_stretch", *forms("weft_stretch", 0.2), 1e9, 0.5, False, 0.2),
    ]
    fit = fit_linear(good[:5] + bad[:1] + good[5:] + bad[1:], H)
    assert len(fit.excluded) == 2 and fit.excluded[0] is bad[0] and fit.excluded[1] is bad[1]
    assert all(u is g for u, g in zip(fit.used, good)) and len(fit.used) == len(good)
    reference = fit_linear(good, H)
    assert fit.parameters == reference.parameters
    # The excluded samples would have changed the weights (larger strains) had they been used.
    np.testing.assert_array_equal(fit.weights, reference.weights)
    listed = fit.quality_dict()["excluded"]
    assert [e["family"] for e in listed] == ["saddle_bend", "weft_stretch"]
    assert listed[0]["energy_density_j_per_m2"] is None


def test_missing_families_are_named():
    without_shear = [s for s in make_samples(TRUE) if s.family != "shear"]
    with pytest.raises(ValueError, match=r"no usable \(converged\) samples for families: shear;"):
        fit_linear(without_shear, H)
    without_saddle = [s for s in make_samples(TRUE) if s.family != "saddle_bend"]
    with pytest.raises(ValueError, match="families: saddle_bend;"):
        fit_linear(without_saddle, H, model="full")
    fit_linear(without_saddle, H, model="paper")
    # A family whose samples all failed counts as missing, and the message says why.
    failed = [
        sample(s.family, s.I, s.II, s.energy_density, s.residual.force, s.family != "weft_bend", s.parameter)
        for s in make_samples(TRUE)
    ]
    with pytest.raises(ValueError, match=r"weft_bend \(4 excluded as not converged\)"):
        fit_linear(failed, H)
    only_membrane = [s for s in make_samples(TRUE) if s.family in MEMBRANE_FAMILIES]
    with pytest.raises(ValueError, match="weft_bend, warp_bend, bias_bend, saddle_bend"):
        fit_linear(only_membrane, H)


def test_undetermined_parameters_are_named():
    # Shear samples at zero strain carry no information about s22 (nor do any others once the bias
    # pulls, which see shear too, are left out).
    samples = [
        sample("shear", np.eye(2), np.zeros((2, 2)), 0.0, 0.0, True, 0.0) if s.family == "shear" else s
        for s in make_samples(TRUE) if s.family not in ("bias_uniaxial", "negative_bias_uniaxial")
    ]
    with pytest.raises(ValueError, match="s22 undetermined"):
        fit_linear(samples, H)
    # Bias bends alone cannot separate b01 from b22 when saddle samples repeat the weft bend.
    samples = [
        sample("saddle_bend", np.eye(2), np.diag([s.parameter, 0.0]), 0.0, 0.0, True, s.parameter)
        if s.family == "saddle_bend" else s
        for s in make_samples(TRUE)
    ]
    with pytest.raises(ValueError, match=r"do not determine b01, b22 separately"):
        fit_linear(samples, H)


def test_quality_dict_is_plain_json():
    fit = fit_linear(make_samples(TRUE), H)
    quality = fit.quality_dict()
    again = json.loads(json.dumps(quality, allow_nan=False))
    assert again == quality
    keys = {"model", "membrane", "bending", "parameters_pa", "std_error_pa", "families", "linear", "strain_range",
            "reference_energy_j_per_m2", "bending_reference_energy_j_per_m2", "residual_stress", "active_bounds",
            "notes", "coupling_limit", "weight_widths", "used", "excluded"}
    assert set(quality) == keys
    assert quality["parameters_pa"] == fit.parameters
    assert len(quality["used"]) == len(fit.used)
    assert quality["used"][0]["weight"] == fit.weights[0]


# -- bad input --------------------------------------------------------------------------------------


def test_bad_fit_arguments():
    samples = make_samples(TRUE)
    with pytest.raises(ValueError, match="model must be one of full, paper, got 'kirchhoff'"):
        fit_linear(samples, H, model="kirchhoff")
    with pytest.raises(ValueError, match=r"thickness must be finite and > 0 \(m\), got -0.0003"):
        fit_linear(samples, -H)
    with pytest.raises(ValueError, match="weight_width must be finite and > 0"):
        fit_linear(samples, H, weight_width=0.0)
    with pytest.raises(ValueError, match="samples is empty"):
        fit_linear([], H)
    with pytest.raises(ValueError, match=r"samples\[1\] must be a SampleResult"):
        fit_linear([samples[0], {"family": "shear"}], H)
    with pytest.raises(ValueError, match="weights must be"):
        weighted_residuals(np.ones(8), samples, H, np.ones(3))
    with pytest.raises(ValueError, match=r"params must have shape \(8,\)"):
        weighted_residuals(np.ones(7), samples, H, np.ones(len(samples)))


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"family": "twist"}, "SampleSpec.family must be one of weft_stretch, .*, got 'twist'"),
        ({"I": np.diag([1.0, -1.0])}, "SampleSpec.I: first fundamental form must be symmetric positive definite"),
        ({"I": np.eye(3)}, r"must have shape \(2, 2\) or \(n, 2, 2\)"),
        ({"I": np.stack([np.eye(2)] * 2)}, r"SampleSpec.I must have shape \(2, 2\)"),
        ({"II": np.array([[1.0, 2.0], [0.0, 1.0]])}, "SampleSpec.II: second fundamental form must be finite and symmetric"),
        ({"II": np.diag([1.0, 0.0])}, "SampleSpec.II must be zero for membrane family weft_stretch"),
        ({"energy_density": float("nan")}, "energy_density must be finite for a converged sample"),
        ({"residual": -1.0}, "SampleResult.residual.force must be >= 0"),
        ({"converged": 1}, "SampleResult.converged must be a bool, got 1"),
        ({"parameter": float("inf")}, "SampleSpec.parameter must be finite"),
        ({"energy_density": "1.0"}, "SampleResult.energy_density must be a real number"),
    ],
)
def test_bad_membrane_samples_are_rejected(changes, message):
    fields = {
        "family": "weft_stretch",
        "I": np.diag([1.21, 1.0]),
        "II": np.zeros((2, 2)),
        "energy_density": 1.0,
        "residual": 1e-9,
        "converged": True,
        "parameter": 0.1,
    }
    with pytest.raises(ValueError, match=message):
        sample(**{**fields, **changes})


def test_bending_samples_must_not_stretch():
    with pytest.raises(ValueError, match="SampleSpec.I must be the identity for bending family bias_bend"):
        sample("bias_bend", np.diag([1.0 + 1e-6, 1.0]), 50.0 * np.ones((2, 2)), 1.0, 0.0, True, 100.0)
    # Round-off in building I = Id is accepted.
    sample("bias_bend", np.diag([1.0 + 1e-15, 1.0]), 50.0 * np.ones((2, 2)), 1.0, 0.0, True, 100.0)
    assert set(BENDING_FAMILIES) | set(MEMBRANE_FAMILIES) == set(FAMILIES)
    assert not set(BENDING_FAMILIES) & set(MEMBRANE_FAMILIES)


def test_sample_arrays_are_read_only_copies():
    I = np.diag([1.21, 1.0])
    result = sample("weft_stretch", I, np.zeros((2, 2)), 1.0, 0.0, True, 0.1)
    I[0, 0] = 5.0
    assert result.I[0, 0] == 1.21
    with pytest.raises(ValueError):
        result.I[0, 0] = 2.0


def test_a_uniaxial_sample_that_pulls_its_yarns_is_noted():
    """A free-width pull whose rods store at least STRETCH_DOMINATED_SHARE of Ū in stretch gets a
    note naming it, its share and its width; one that bends its yarns, a pure stretch (fixed width)
    and a sample without a known share get none."""
    I, II = forms("warp_uniaxial", 0.02)
    residual = Residual(force=1e-10, torque=0.0, energy_change=0.0, penetration=0.0)
    jammed = SampleResult(SampleSpec("warp_uniaxial", I, II, 0.02), 6.8, True, residual, stretch_share=0.98)
    notes = stretch_dominated_notes([jammed])
    assert len(notes) == 1 and "warp_uniaxial sample at 2 %" in notes[0] and "98 %" in notes[0]
    assert f"width {1 - 0.2 * 0.02:.3f}" in notes[0] and "warp stiffness is the yarn's" in notes[0]
    bending = dataclasses.replace(jammed, stretch_share=STRETCH_DOMINATED_SHARE * 0.99)
    unknown = dataclasses.replace(jammed, stretch_share=math.nan)
    I, II = forms("warp_stretch", 0.02)
    fixed_width = SampleResult(SampleSpec("warp_stretch", I, II, 0.02), 6.8, True, residual, stretch_share=0.98)
    assert stretch_dominated_notes([bending, unknown, fixed_width]) == []


@pytest.mark.parametrize("share", [math.nan, 0.0, 0.42, 1.0])
def test_the_stretch_share_reads_back_and_bad_ones_are_refused(share):
    I, II = forms("weft_uniaxial", 0.05)
    result = SampleResult(SampleSpec("weft_uniaxial", I, II, 0.05), 1.0, True,
                          Residual(1e-10, 0.0, 0.0, 0.0), stretch_share=share)
    data = json.loads(json.dumps(result.to_dict()))
    back = SampleResult.from_dict(data)
    assert back.stretch_share == pytest.approx(share, nan_ok=True)
    del data["stretch_share"]  # a file written before the share was kept
    assert math.isnan(SampleResult.from_dict(data).stretch_share)
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="stretch_share must lie in"):
            dataclasses.replace(result, stretch_share=bad)


def test_a_uniaxial_samples_slopes_read_back_and_other_families_have_none():
    I, II = forms("weft_uniaxial", 0.05)
    result = SampleResult(SampleSpec("weft_uniaxial", I, II, 0.05), 1.0, True,
                          Residual(1e-10, 0.0, 0.0, 0.0), pull_slope=42.5, across_slope=-1.5)
    data = json.loads(json.dumps(result.to_dict()))
    back = SampleResult.from_dict(data)
    assert (back.pull_slope, back.across_slope) == (42.5, -1.5)
    del data["pull_slope_n_per_m"], data["across_slope_n_per_m"]  # a file written before they were kept
    assert math.isnan(SampleResult.from_dict(data).pull_slope)
    assert math.isnan(SampleResult.from_dict(data).across_slope)
    I, II = forms("weft_stretch", 0.05)
    for name in ("pull_slope", "across_slope"):
        with pytest.raises(ValueError, match=f"{name} is only defined for a uniaxial family"):
            SampleResult(SampleSpec("weft_stretch", I, II, 0.05), 1.0, True, Residual(1e-10, 0.0, 0.0, 0.0),
                         **{name: 1.0})
