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


def search(bound=None):
    solved = []

    def solve_at(free):
        solved.append(quadratic(free))
        return solved[-1]

    start = solve_at(np.zeros(3))
    hessian, probes = probe_hessian(solve_at, lambda free: True, start, np.full(3, 1e-3))
    current = min([start] + probes, key=lambda trial: trial.energy)
    return quasi_newton(solve_at, lambda free: True, current, hessian, lambda: len(solved), 40, 0.05, STEP_TOLERANCE,
                        lambda trial, w, v: False, bound=bound, interpolate=True), len(solved)


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
