"""The quasi-static solver's symmetric saddle-point solves against dense LAPACK solves."""

import numpy as np
import pytest
import scipy.sparse as sp

from yarnfit.engine import linear
from yarnfit.engine.linear import SingularSystemError, SymmetricSolve

# Agreement with the dense solve of the same system: both are backward stable, and the systems
# below have condition numbers under ~1e6, so 1e-9 leaves three orders for their conditioning.
DENSE_AGREEMENT = 1e-9


def _dense_kkt_solution(matrix, constraints, b):
    m = 0 if constraints is None else constraints.shape[0]
    dense = matrix.toarray()
    if m:
        a = constraints.toarray()
        dense = np.block([[dense, a.T], [a, np.zeros((m, m))]])
    return np.linalg.solve(dense, np.concatenate([b, np.zeros(m)]))[: matrix.shape[0]]


def _assert_matches_dense(matrix, constraints, b, x) -> None:
    ref = _dense_kkt_solution(matrix, constraints, b)
    assert np.linalg.norm(x - ref) <= DENSE_AGREEMENT * np.linalg.norm(ref)


def _indefinite_banded(n: int, rng) -> sp.csc_matrix:
    """A symmetric, indefinite, banded matrix whose diagonal spans six orders (as positions and
    rotations of a slender yarn do)."""
    scale = 10.0 ** rng.uniform(-3, 3, n)
    off = rng.standard_normal((n, 4))
    matrix = sp.diags([np.sign(rng.standard_normal(n)) * (4.0 + rng.random(n))], [0], shape=(n, n)).tolil()
    for k in range(1, 5):
        for i in range(n - k):
            matrix[i, i + k] = matrix[i + k, i] = 0.5 * off[i, k - 1]
    s = sp.diags(np.sqrt(scale))
    return sp.csc_matrix(s @ matrix.tocsc() @ s)


def test_unconstrained_indefinite_matches_dense():
    rng = np.random.default_rng(1)
    matrix = _indefinite_banded(80, rng)
    b = rng.standard_normal(80)
    solve = SymmetricSolve(matrix)
    x = solve(b)
    _assert_matches_dense(matrix, None, b, x)
    assert not solve.pivoted


def test_constraints_along_a_null_space():
    """A periodic chain's stiffness is singular along its rigid translation; the dense constraint
    row that removes it makes the saddle-point system regular (a Schur complement of M alone could
    not be formed)."""
    rng = np.random.default_rng(2)
    n = 60
    k = 1.0 + rng.random(n)  # spring i joins node i and i + 1 (mod n)
    matrix = sp.lil_matrix((n, n))
    for i in range(n):
        j = (i + 1) % n
        matrix[i, i] += k[i]
        matrix[j, j] += k[i]
        matrix[i, j] -= k[i]
        matrix[j, i] -= k[i]
    matrix = matrix.tocsc()
    constraints = sp.csr_matrix(np.ones((1, n)) / n)
    b = rng.standard_normal(n)
    b -= b.mean()
    solve = SymmetricSolve(matrix, constraints)
    x = solve(b)
    _assert_matches_dense(matrix, constraints, b, x)
    assert abs(x.sum()) <= DENSE_AGREEMENT * np.abs(x).sum()


def test_several_dense_constraint_rows():
    rng = np.random.default_rng(3)
    matrix = _indefinite_banded(90, rng)
    constraints = sp.csr_matrix(rng.standard_normal((5, 90)))
    b = rng.standard_normal(90)
    solve = SymmetricSolve(matrix, constraints)
    x = solve(b)
    _assert_matches_dense(matrix, constraints, b, x)
    assert np.abs(constraints @ x).max() <= DENSE_AGREEMENT * np.abs(x).max()


def test_zero_diagonal_is_pivoted_off():
    matrix = sp.csc_matrix(np.array([[0.0, 2.0, 0.0], [2.0, 0.0, 1.0], [0.0, 1.0, 3.0]]))
    b = np.array([1.0, -1.0, 2.0])
    x = SymmetricSolve(matrix)(b)
    np.testing.assert_allclose(matrix @ x, b, rtol=0, atol=1e-14)


def test_falls_back_to_partial_pivoting(monkeypatch):
    # No backward error is accepted: every solve must come from the partial-pivoting fallback.
    monkeypatch.setattr(linear, "BACKWARD_ERROR", -1.0)
    rng = np.random.default_rng(4)
    matrix = _indefinite_banded(50, rng)
    constraints = sp.csr_matrix(rng.standard_normal((2, 50)))
    b = rng.standard_normal(50)
    solve = SymmetricSolve(matrix, constraints)
    x = solve(b)
    assert solve.pivoted
    _assert_matches_dense(matrix, constraints, b, x)


def test_singular_system_raises():
    matrix = sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(SingularSystemError):
        SymmetricSolve(matrix)(np.array([1.0, 0.0]))
