"""The free-strain quasi-Newton (:mod:`yarnfit.homogenize.search`) on functions whose least point
is known in closed form: a convex quadratic (its minimiser by a linear solve), the same inside a
box (the projected minimiser, by scipy's bounded least squares on its square root), and a
backtracking step's parabola."""

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
