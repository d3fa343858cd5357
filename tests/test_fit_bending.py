"""The signed bending (:class:`yarnfit.shell.SignedBending`) and its fit (``fit_shell(bending=
"signed")``): its energy's gradient, continuity and convexity; the exact recovery of a signed
material from its own energies; the convexity-bounded fit against an independent constrained
minimiser of the same weighted least squares; and when the material keeps the symmetric bending."""

from __future__ import annotations


import numpy as np
import pytest
import scipy.optimize

from yarnfit.fit import fit_shell, sample_weights, signed_design_matrix
from yarnfit.samples import sample_design
from yarnfit.shell import SIGNED_BENDING_PARAMETERS, ShellMaterial, SignedBending

from fabric_shell import FABRIC, H
from test_fit_nonlinear import LEVELS, RANGES, RECOVERY_REL, samples_of

# Central differences of a quadratic per quadrant, step GRADIENT_STEP (1/m) at curvatures ~100 /m
# and stiffnesses ~1e5 Pa: round-off ~1e-16 · 1e9 / (1e-5 · 1e7) = 1e-9 relative, and on an axis,
# where the step straddles the sides, (b00_pos − b00_neg) h/4 ~ 0.1 against moments ~1e6. 1e-7 of
# the largest moment fails any wrong term (a missing factor 2 on b01, the side picked by the wrong
# sign: O(1)).
GRADIENT_STEP = 1e-5
GRADIENT_RTOL = 1e-7
# Our bounded solve stops at round-off (BOUNDED_SOLVE_TOLERANCE); scipy's SLSQP at ftol 1e-15 on
# the unit-scaled problem ends a little above it (the jersey: 6e-5 relative, its point 1e-5 outside
# a quadrant's bound). Ours must not be above SLSQP's by more than round-off.
COST_REL = 1e-9
# A jersey's bends (cotton jersey's unbounded signed fit, N·m over h³): its warp bends away from
# the face for free, its coupling far beyond what that allows, as the presets' are.
JERSEY = SignedBending(b00_pos=4.6e-7 / H**3, b00_neg=2.6e-6 / H**3, b01=-2.0e-6 / H**3,
                       b11_pos=4.6e-6 / H**3, b11_neg=2.4e-12 / H**3, b22=5.3e-7 / H**3)
# A woven's: each side of weft and warp up to twice the other's (the twill's fit), convex.
WOVEN = SignedBending(b00_pos=FABRIC.b00, b00_neg=0.6 * FABRIC.b00, b01=FABRIC.b01, b11_pos=0.7 * FABRIC.b11,
                      b11_neg=1.3 * FABRIC.b11, b22=FABRIC.b22)


def signed(bending: SignedBending) -> ShellMaterial:
    return ShellMaterial(H, **FABRIC.parameters, signed_bending=bending)


def test_the_moment_is_the_energys_gradient_on_every_side():
    rng = np.random.default_rng(5)
    kap = rng.normal(scale=100.0, size=(200, 3))
    kap[:20, 0] = 0.0  # on an axis: the sides meet there with one slope
    step = GRADIENT_STEP
    for k in range(3):
        delta = np.zeros(3)
        delta[k] = step
        numeric = (WOVEN.energy(kap + delta) - WOVEN.energy(kap - delta)) / (2.0 * step)
        np.testing.assert_allclose(WOVEN.moment(kap)[:, k], numeric, rtol=GRADIENT_RTOL,
                                   atol=GRADIENT_RTOL * np.abs(numeric).max())


def test_convex_exactly_when_every_quadrant_is_positive_definite():
    assert WOVEN.positive_definite and not JERSEY.positive_definite
    assert "b01² = " in JERSEY.problems()[0]
    # Convex: along random lines the slope never falls (it is continuous and rises on every piece).
    rng = np.random.default_rng(8)
    t = np.linspace(-1.0, 1.0, 2001)
    for _ in range(50):
        start, direction = rng.normal(scale=50.0, size=3), rng.normal(scale=100.0, size=3)
        points = start + t[:, None] * direction
        slope = WOVEN.moment(points) @ direction
        assert np.all(np.diff(slope) >= -1e-9 * np.abs(slope).max())
    # ... and not when a quadrant is indefinite: the jersey's slope falls on some line.
    falls = False
    for _ in range(50):
        start, direction = rng.normal(scale=50.0, size=3), rng.normal(scale=100.0, size=3)
        slope = JERSEY.moment(start + t[:, None] * direction) @ direction
        falls |= bool(np.any(np.diff(slope) < 0.0))
    assert falls


def test_the_material_carries_it_and_its_file_round_trips():
    material = signed(WOVEN)
    II = np.array([[-30.0, 5.0], [5.0, 12.0]])
    kap = np.array([-30.0, 12.0, 10.0])
    assert material.energy_density(np.eye(2), II) == pytest.approx(H**3 * float(WOVEN.energy(kap)), rel=1e-14)
    assert material.linear.signed_bending is None
    assert material.energy_density(np.eye(2), II) != pytest.approx(material.linear.energy_density(np.eye(2), II))
    _, moment = material.energy_gradient(np.eye(2), II)
    m = H**3 * WOVEN.moment(kap)
    np.testing.assert_allclose(moment, [[m[0], m[2]], [m[2], m[1]]], rtol=1e-14)
    again = ShellMaterial.from_dict(material.to_dict())
    assert again.signed_bending == WOVEN
    data = material.to_dict()
    data["signed_bending_pa"] = {**data["signed_bending_pa"], "b00_side": 1.0}
    with pytest.raises(ValueError, match="b00_side"):
        ShellMaterial.from_dict(data)
    with pytest.raises(ValueError, match="signed bending not convex"):
        signed(JERSEY).check_positive_definite()


def test_a_signed_material_is_recovered_from_its_own_energies():
    fit = fit_shell(samples_of(signed(WOVEN)), H)
    assert fit.bending == "signed"
    got = fit.material.signed_bending
    for name in SIGNED_BENDING_PARAMETERS:
        assert getattr(got, name) == pytest.approx(getattr(WOVEN, name), rel=RECOVERY_REL), name
    for family in ("weft_bend", "warp_bend", "bias_bend", "saddle_bend"):
        assert fit.families[family]["relative_rms"] <= RECOVERY_REL, family
        # ... which the symmetric bending fitted to the same samples is not.
        assert fit.linear_families[family]["relative_rms"] > 100 * RECOVERY_REL or family == "bias_bend", family


def weighted_bends(samples):
    """The fit's bends as the signed fit sees them: ``(A, b)`` with ``√w`` applied, J/m²."""
    bends = [s for s in samples if not s.is_membrane and np.any(s.II != 0.0)]
    weights, _ = sample_weights([s for s in samples if not s.is_membrane], H)
    w = np.array([weight for s, weight in zip([s for s in samples if not s.is_membrane], weights)
                  if np.any(s.II != 0.0)])
    return np.sqrt(w)[:, None] * signed_design_matrix(bends, H), np.sqrt(w) * np.array([s.energy_density for s in bends])


@pytest.mark.parametrize("bending", [WOVEN, JERSEY], ids=["convex", "jersey"])
def test_the_convex_fit_is_the_constrained_least_squares_optimum(bending):
    """Against scipy's SLSQP on the same weighted least squares with the four quadrants'
    convexity as constraints (|b01| <= 0.99 √(b00_a b11_b)), from the symmetric fit: no convex
    signed bending fits the bends better than ours."""
    samples = samples_of(signed(bending))
    fit = fit_shell(samples, H)
    candidate = fit.signed_fit  # the jersey's material keeps the symmetric bending: still fitted
    assert candidate.positive_definite
    A, b = weighted_bends(samples)
    scale = np.linalg.norm(A, axis=0)
    As = A / scale

    def cost(x):
        r = As @ x - b
        return float(r @ r)

    ours = cost(np.array([getattr(candidate, n) for n in SIGNED_BENDING_PARAMETERS]) * scale)
    limit = 0.99

    def quadrant(a, c):
        return lambda x: limit**2 * (x[a] / scale[a]) * (x[c] / scale[c]) - (x[2] / scale[2]) ** 2

    start = np.array([FABRIC.b00, FABRIC.b00, 0.0, FABRIC.b11, FABRIC.b11, FABRIC.b22]) * scale
    theirs = scipy.optimize.minimize(cost, start, jac=lambda x: 2.0 * As.T @ (As @ x - b), method="SLSQP",
                                     bounds=[(0.0, None)] * 2 + [(None, None)] + [(0.0, None)] * 3,
                                     constraints=[{"type": "ineq", "fun": quadrant(a, c)} for a in (0, 1) for c in (3, 4)],
                                     options={"ftol": 1e-15, "maxiter": 2000})
    # (SLSQP may stop on "positive directional derivative for linesearch" at the optimum: its line
    # search at the precision limit. Its cost is what is compared.)
    assert ours <= theirs.fun * (1.0 + COST_REL) + 1e-30
    # ... and the symmetric fit is among the signed one's candidates: it fits no better.
    symmetric = fit.linear
    as_signed = [symmetric.b00, symmetric.b00, symmetric.b01, symmetric.b11, symmetric.b11, symmetric.b22]
    assert ours <= cost(np.array(as_signed) * scale) * (1.0 + COST_REL)


def test_the_jerseys_bends_leave_a_mode_without_stiffness_and_keep_the_symmetric_bending():
    fit = fit_shell(samples_of(signed(JERSEY)), H)
    assert fit.bending == "symmetric" and fit.material.signed_bending is None
    assert any("signed bending not used: its b22 at the positive floor" in note for note in fit.notes)


def test_bends_of_one_sign_fit_no_signed_bending():
    positive = [spec for spec in sample_design(RANGES, LEVELS)
                if spec.is_membrane or spec.family == "bias_bend" or spec.parameter >= 0.0]
    fit = fit_shell(samples_of(FABRIC, specs=positive), H)
    assert fit.material.signed_bending is None and fit.bending == "symmetric"
    assert any(note.startswith("signed bending not fitted: no bend with weight strains b00_neg") for note in fit.notes)
    with pytest.raises(ValueError, match="bending must be one of signed, symmetric"):
        fit_shell(samples_of(FABRIC), H, bending="one-sided")


def test_the_builtin_hinge_share_covers_the_stiffer_sides_and_refuses_a_non_convex_bending():
    from yarnfit.mujoco.split import builtin_bending_rigidity

    upper = WOVEN.upper
    expected = H**3 * max(float(np.linalg.eigvalsh(upper[:2, :2])[-1]), 2.0 * upper[2, 2])
    assert builtin_bending_rigidity(signed(WOVEN)) == pytest.approx(expected, rel=1e-14)
    assert builtin_bending_rigidity(signed(WOVEN)) > builtin_bending_rigidity(FABRIC)  # warp_neg is stiffer
    with pytest.raises(ValueError, match="signed bending not convex"):
        builtin_bending_rigidity(signed(JERSEY))
