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


def _spd_banded(n: int, rng, band: int = 3) -> sp.csc_matrix:
    """A symmetric positive definite banded matrix (diagonally dominant)."""
    matrix = sp.lil_matrix((n, n))
    for i in range(n):
        matrix[i, i] = 2.0 * band + rng.random()
        for k in range(1, band + 1):
            if i + k < n:
                matrix[i, i + k] = matrix[i + k, i] = rng.uniform(-1.0, 1.0)
    return matrix.tocsc()


def test_factor_cache_reuses_the_analysis_of_a_pattern():
    """Matrices whose entries lie in the pattern analysed last are only refactorised numerically,
    and each solve is still that matrix's own."""
    rng = np.random.default_rng(5)
    cache = linear.FactorCache()
    first = _spd_banded(40, rng)
    constraints = sp.csr_matrix(rng.standard_normal((2, 40)))
    scale = sp.diags(rng.uniform(0.5, 1.5, 40))
    same = sp.csc_matrix(scale @ first @ scale)  # other values, same pattern
    fewer = sp.csc_matrix(sp.triu(first, 2) + sp.tril(first, -2) + sp.diags(first.diagonal()))  # a sub-pattern
    for matrix in (first, same, fewer):
        b = rng.standard_normal(40)
        solve = SymmetricSolve(matrix, constraints, cache)
        _assert_matches_dense(matrix, constraints, b, solve(b))
        assert solve.method == "ldl"
    assert (cache.analyses, cache.factorisations) == (1, 3)


def test_factor_cache_analyses_the_union_of_patterns():
    """A matrix with an entry outside the cached pattern is analysed over the union of both (a new
    contact pair joins the pairs seen so far); the first pattern then fits in it again, until the
    union outgrows UNION_FILL_LIMIT times the matrix factorised."""
    rng = np.random.default_rng(6)
    cache = linear.FactorCache()
    base = _spd_banded(30, rng, band=1)
    coupled = base.tolil()
    coupled[0, 29] = coupled[29, 0] = 0.5  # a new pair
    coupled = coupled.tocsc()
    for matrix in (base, coupled, base):
        b = rng.standard_normal(30)
        _assert_matches_dense(matrix, None, b, SymmetricSolve(matrix, None, cache)(b))
    assert (cache.analyses, cache.factorisations) == (2, 3)
    # A matrix with far fewer entries than the union is analysed on its own pattern, though it fits
    # in the union: the union's fill would cost more.
    diagonal = sp.diags(1.0 + rng.random(30)).tocsc()
    b = rng.standard_normal(30)
    _assert_matches_dense(diagonal, None, b, SymmetricSolve(diagonal, None, cache)(b))
    assert cache.analyses == 3


def test_a_constraint_pinning_one_dof_is_factorised_with_threshold_pivoting():
    """A constraint row that pins one DOF is eliminated first by the fill-reducing ordering and
    meets an exactly zero pivot in LDLᵀ; its pattern is then factorised by SuperLU with threshold
    pivoting, and the cache does not try LDLᵀ on that pattern again."""
    rng = np.random.default_rng(7)
    matrix = _spd_banded(30, rng)
    constraints = sp.csr_matrix(([1.0, 1.0], ([0, 1], [4, 17])), shape=(2, 30))
    cache = linear.FactorCache()
    for _ in range(2):
        b = rng.standard_normal(30)
        solve = SymmetricSolve(matrix, constraints, cache)
        x = solve(b)
        assert solve.method == "threshold"
        _assert_matches_dense(matrix, constraints, b, x)
        assert x[4] == pytest.approx(0.0, abs=DENSE_AGREEMENT) and x[17] == pytest.approx(0.0, abs=DENSE_AGREEMENT)
    assert (cache.analyses, cache.factorisations) == (1, 2)
