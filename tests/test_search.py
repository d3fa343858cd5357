"""The free-strain quasi-Newton (:mod:`yarnfit.homogenize.search`) on functions whose least point
is known in closed form: a convex quadratic (its minimiser by a linear solve), the same inside a
box (the projected minimiser, by scipy's bounded least squares on its square root), a
backtracking step's parabola, and a kink between two branches (the lower one's end)."""

import numpy as np
import pytest
import scipy.optimize

from yarnfit.homogenize.search import Trial, _shortened, probe_hessian, quasi_newton

# The quadratic's minimiser to this (absolute, in the free strains): the search stops on a step
# below STEP_TOLERANCE, a Newton step on an exact quadratic lands on the minimum at once after
# the BFGS updates have its Hessian.
STEP_TOLERANCE = 1e-10
FREE_ATOL = 1e-8
HESSIAN = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, -0.4], [0.5, -0.4, 2.0]])
CENTRE = np.array([0.03, -0.02, 0.01])


def quadratic(free: np.ndarray) -> Trial:
    """Ū = ½ (x − c)ᵀ H (x − c) + 1 and its slopes, as a solve would report them."""
    offset = np.asarray(free, dtype=np.float64) - CENTRE
    return Trial(np.array(free, dtype=np.float64), None, None, 0.5 * float(offset @ HESSIAN @ offset) + 1.0,
                 HESSIAN @ offset)


def search(bound=None, function=None, probe=1e-3, balanced=lambda trial, w, v: False, balanced_ends=False):
    """The search from 0 on ``function`` (default :func:`quadratic`), probes ``probe`` long:
    ``((trial, failure, hessian), solves)``."""
    function = function or quadratic
    solved = []

    def solve_at(free):
        solved.append(function(free))
        return solved[-1]

    start = solve_at(np.zeros(3))
    hessian, probes = probe_hessian(solve_at, lambda free: True, start, np.full(3, probe))
    current = min([start] + probes, key=lambda trial: trial.energy)
    return quasi_newton(solve_at, lambda free: True, current, hessian, lambda: len(solved), 40, 0.05, STEP_TOLERANCE,
                        balanced, bound=bound, interpolate=True, balanced_ends=balanced_ends), len(solved)


def test_probes_give_a_quadratics_hessian_and_the_search_its_minimum():
    start = quadratic(np.zeros(3))
    hessian, _ = probe_hessian(quadratic, lambda free: True, start, np.full(3, 1e-3))
    np.testing.assert_allclose(hessian, HESSIAN, rtol=1e-12)
    (found, failure, _), solves = search()
    assert failure is None
    np.testing.assert_allclose(found.free, CENTRE, atol=FREE_ATOL)
    assert solves <= 8


def test_a_bounded_search_ends_at_the_boxs_least_point():
    # The least point of a convex quadratic in a box: ½ |L (x − c)|² with H = Lᵀ L, a bounded
    # linear least-squares problem (scipy), independent of the projected Newton steps.
    bound = np.full(3, 0.015)
    (found, failure, _), _ = search(bound)
    assert failure is None
    root = np.linalg.cholesky(HESSIAN).T
    expected = scipy.optimize.lsq_linear(root, root @ CENTRE, bounds=(-bound, bound), tol=1e-14).x
    np.testing.assert_allclose(found.free, expected, atol=FREE_ATOL)
    assert np.all(np.abs(found.free) <= bound)


def test_a_refused_step_is_shortened_to_its_parabolas_least_point():
    current = Trial(np.zeros(1), None, None, 1.0, np.array([-2.0]))
    step = np.array([1.0])
    # Ū(t) = 1 − 2 t + 4 t²: the trial at t = 1 reads 3; the parabola's least point is t = 1/4.
    assert _shortened(current, step, Trial(step, None, None, 3.0, np.zeros(1)))[0] == pytest.approx(0.25)
    # Safeguarded to [0.1, 0.5] of the step, and halved when the trial did not converge.
    assert _shortened(current, step, Trial(step, None, None, 100.0, np.zeros(1)))[0] == pytest.approx(0.1)
    assert _shortened(current, step, Trial(step, None, None, -0.9, np.zeros(1)))[0] == pytest.approx(0.5)
    assert _shortened(current, step, None)[0] == pytest.approx(0.5)


# A quartic's least Ū (scipy's BFGS to round-off) against the search stopped on spent slopes: a
# Newton step promised at most SPENT_DECREASE more, and the quartic term makes the promise a
# near-quadratic's, so what is left is within SPENT_FACTOR of it.
SPENT_DECREASE = 1e-9
SPENT_FACTOR = 10.0


def quartic(free: np.ndarray) -> Trial:
    """Ū = ½ (x − c)ᵀ H (x − c) + 50 Σ (x − c)⁴ + 1 and its slopes: its Hessian changes along the
    way, so the BFGS updates take several steps."""
    offset = np.asarray(free, dtype=np.float64) - CENTRE
    energy = 0.5 * float(offset @ HESSIAN @ offset) + 50.0 * float(np.sum(offset**4)) + 1.0
    return Trial(np.array(free, dtype=np.float64), None, None, energy, HESSIAN @ offset + 200.0 * offset**3)


def test_a_search_asked_every_step_stops_at_spent_slopes():
    from yarnfit.homogenize.search import promised_decrease

    def run(balanced_ends):
        spent = lambda trial, w, v: promised_decrease(trial, w, v) <= SPENT_DECREASE
        (found, failure, _), solves = search(function=quartic, probe=1e-2, balanced=spent, balanced_ends=balanced_ends)
        assert failure is None
        return found, solves

    least = scipy.optimize.minimize(lambda x: quartic(x).energy, np.zeros(3), jac=lambda x: quartic(x).slopes,
                                    method="BFGS", options={"gtol": 1e-13}).fun
    stopped, early = run(True)
    walked, late = run(False)
    assert early < late
    assert 0.0 <= stopped.energy - least <= SPENT_FACTOR * SPENT_DECREASE
    assert walked.energy - least <= SPENT_FACTOR * SPENT_DECREASE


# A kink in one free strain, at the scale of the plain weave's bias pull at 1 % (250 g/m²): Ū =
# KINK_FLOOR + ½ k (x − c)² on its lower branch while x < KINK_AT (the pull's own energy, which the
# free strain only modulates; its slope there −0.76 J/m², its curvature 7600), and above it
# another branch KINK_JUMP higher whose slope points back (KINK_BACK): the least Ū is where the
# lower branch ends, Ū(KINK_AT). Its energy tolerance, as the bias search's (SEARCH_ENERGY_RTOL).
KINK_FLOOR, KINK_CURVATURE, KINK_CENTRE = 0.1, 7600.0, -0.0077
KINK_AT, KINK_JUMP, KINK_BACK = -0.0078, 0.005, 1.3
KINK_ENERGY_RTOL = 1e-3


def kinked(free: np.ndarray) -> Trial:
    """Ū and its slope on the branch ``free`` (1,) lands on (:data:`KINK_AT`)."""
    x = float(free[0])
    energy = KINK_FLOOR + 0.5 * KINK_CURVATURE * (x - KINK_CENTRE) ** 2
    slope = KINK_CURVATURE * (x - KINK_CENTRE)
    if x >= KINK_AT:
        energy, slope = energy + KINK_JUMP + KINK_BACK * (x - KINK_AT), slope + KINK_BACK
    return Trial(np.array(free, dtype=np.float64), None, None, energy, np.array([slope]))


def test_a_search_between_two_branches_ends_at_the_kink_when_asked():
    def run(kink_energy_rtol):
        solved = []

        def solve_at(free):
            solved.append(kinked(free))
            return solved[-1]

        start = solve_at(np.zeros(1))
        hessian, probes = probe_hessian(solve_at, lambda free: True, start, np.full(1, 1e-3))
        current = min([start] + probes, key=lambda trial: trial.energy)
        return quasi_newton(solve_at, lambda free: True, current, hessian, lambda: len(solved), 40, 0.05,
                            STEP_TOLERANCE, lambda trial, w, v: False, kink_energy_rtol=kink_energy_rtol)

    least = kinked(np.array([KINK_AT - 1e-15])).energy
    found, failure, _ = run(KINK_ENERGY_RTOL)
    assert failure is None
    # On the lower branch, short of its end by no more than the energy tolerance allows (its
    # slope there 0.76 J/m²: 1.3e-4), Ū within the tolerance of the least.
    slope = KINK_CURVATURE * (KINK_CENTRE - KINK_AT)
    assert 0.0 < KINK_AT - found.free[0] <= KINK_ENERGY_RTOL * least / slope
    assert 0.0 <= found.energy - least <= KINK_ENERGY_RTOL * least
    # Without it the search does not settle: its slope never vanishes at the kink.
    _, failure, _ = run(None)
    assert failure is not None


def test_a_kink_needs_a_branch_above_that_points_back_and_nothing_left_to_gain():
    from yarnfit.homogenize.search import kink_minimum

    hessian = np.diag([4.0, 4.0])
    lower = Trial(np.array([0.0, 0.0]), None, None, 1.0, np.array([-0.1, 0.0]))
    upper = Trial(np.array([1e-4, 0.0]), None, None, 1.1, np.array([0.2, 0.0]))
    assert kink_minimum([upper, lower], hessian, 0.05, KINK_ENERGY_RTOL) is lower
    # The other trial on the same branch (within the tolerance): no kink, the slopes decide.
    same = upper._replace(energy=1.0 + 0.5 * KINK_ENERGY_RTOL)
    assert kink_minimum([same, lower], hessian, 0.05, KINK_ENERGY_RTOL) is None
    # Its slope not pointing back, or the lower one's not towards it: no kink between them.
    assert kink_minimum([upper._replace(slopes=np.array([-0.2, 0.0])), lower], hessian, 0.05,
                        KINK_ENERGY_RTOL) is None
    assert kink_minimum([upper, lower._replace(slopes=np.array([0.1, 0.0]))], hessian, 0.05,
                        KINK_ENERGY_RTOL) is None
    # Too far apart for what Ū may still fall towards it (0.1 × 0.02 > 1e-3 of Ū).
    far = upper._replace(free=np.array([0.02, 0.0]))
    assert kink_minimum([far, lower], hessian, 0.05, KINK_ENERGY_RTOL) is None
    # A slope across the gap that a Newton step would still gain from (½ 0.2² / 4 = 5e-3 of Ū).
    across = lower._replace(slopes=np.array([-0.1, 0.2]))
    assert kink_minimum([upper, across], hessian, 0.05, KINK_ENERGY_RTOL) is None
