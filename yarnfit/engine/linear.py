"""The quasi-static solver's linear solves: ``M d = b`` for a sparse symmetric ``M`` (the damped
Hessian on the free DOFs), optionally with a few linear constraints ``A d = 0`` (the saddle-point
system ``K = [M Aᵀ; A 0]``, ``K [d; ν] = [b; 0]``).

``K`` is equilibrated (``W K W``, ``W`` diagonal: ``|M_ii|^(-1/2)`` on the free DOFs, whose
stiffnesses differ by up to 1e10 between a slender yarn's positions and rotations, and each
constraint row scaled to a largest entry of 1) and factorised as ``L D Lᵀ`` without pivoting
(QDLDL, the factorisation inside the OSQP solver of Stellato, Banjac, Goulart et al., through its
``qdldl`` binding),
after QDLDL's approximate-minimum-degree ordering. The ordering and the elimination tree (the
symbolic analysis) depend only on the sparsity pattern, and a solve's Hessians keep one as long as
their contact pairs do: :class:`FactorCache` keeps the last analysis over the union of the
patterns seen, and a matrix that fits in it is only refactorised numerically (zeros where a pair
is not touching now). Measured on a HYLC stockinette sample's systems (606 DOFs, 6 constraints):
SuperLU (symmetric mode, MMD ordering, threshold pivoting) 3.6 ms per factorisation, QDLDL with a
new analysis 1.2 ms, a numeric refactorisation of the same pattern 0.36 ms, 1.2 ms on average
with the cache over a solve's changing patterns.

``L D Lᵀ`` without pivoting exists for every quasi-definite ``K`` (``M`` positive definite, as the
damped Hessian is near a stable equilibrium) and is then stable in practice (Vanderbei 1995;
Gill, Saunders & Shinnerl 1996): backward errors of 1e-18 to 1e-13 on the stockinette's systems.
Where it is not:

- a constraint row the ordering eliminates before the DOFs it holds has an exactly zero pivot
  whatever the values (the relaxation's rows that pin one coordinate or one frame's spin: 622 of
  the polyester jersey relaxation's 1420 systems). Such a pattern is factorised by SuperLU in
  symmetric mode instead: one minimum-degree ordering of ``K + Kᵀ``, pivots on the diagonal unless
  one is below :data:`PIVOT_THRESHOLD` of its column. (Regularising the constraints' block with
  −1e-12 instead left HYLC's basket unrelaxed: its solves' backward errors reached 1e-7.)
- an indefinite ``M`` may meet a tiny pivot: each solve checks its normwise backward error and
  falls back to SuperLU with partial pivoting on the unequilibrated system when it exceeds
  :data:`BACKWARD_ERROR`.

Eliminating the constraints by their Schur complement instead (factorising ``M`` alone) fails
here: ``M`` is nearly singular along what the constraints remove (a periodic repeat's rigid
translations), and in-solver directions came out wrong by up to 100 %.
"""

from __future__ import annotations

import numpy as np
import qdldl
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from ._kernels import add_csc

__all__ = ["BACKWARD_ERROR", "PIVOT_THRESHOLD", "UNION_FILL_LIMIT", "FactorCache", "SingularSystemError", "SymmetricSolve",
           "ZeroPivotError"]

# Largest normwise backward error ‖K x − r‖ / (‖K‖ ‖x‖ + ‖r‖) (1-norms) accepted from the
# LDLᵀ factorisation: such an x solves K + δK exactly with ‖δK‖ ≤ 1e-10 ‖K‖, far below the
# error of the finite-difference Hessian (tests/test_hessian.py: 1e-7). QDLDL gives 1e-18–1e-13 on
# the solver's matrices, partial pivoting 1e-19–1e-15; a bad pivot 1e-7 and worse.
BACKWARD_ERROR = 1e-10
# The cached analysis is reused (and extended to the union of the patterns seen) while its pattern
# has at most this many times the entries of the matrix now factorised: pairs that stopped
# touching leave zeros that are still eliminated, and past this their fill costs more than a new
# analysis. Over 400 consecutive systems of three stockinette samples: 1.64 ms per factorisation
# with exact patterns only (312 analyses), 1.26 at 1.1, 1.21 at 1.2 (134), 1.41 at 1.5 and 2.
UNION_FILL_LIMIT = 1.2
# SuperLU's threshold pivoting, for the patterns LDLᵀ without pivoting cannot factorise: a diagonal
# pivot is kept while it is at least this fraction of its column's largest entry (on the
# equilibrated matrix). 0.01 measured fastest on the solver's matrices (1e-1 and 0.5 fill 15–40 %
# more); all three solved them to the same 1e-9.
PIVOT_THRESHOLD = 0.01

_SYMMETRIC = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=PIVOT_THRESHOLD, options=dict(SymmetricMode=True))


@njit(cache=True)
def _equilibrated_upper(m_indptr, m_indices, m_data, at_indptr, at_columns, at_data, weight, n):
    """Upper triangle (CSC, rows sorted, every diagonal entry stored) of ``W K W`` for
    ``K = [M Aᵀ; A 0]``: ``M`` ``(n, n)`` in canonical CSC, ``A`` given by rows (CSR arrays,
    columns sorted), ``weight`` the diagonal of ``W`` ``(n + m,)``. Column j < n is the part of M's
    column j on or above the diagonal; column n + i is A's row i, then a zero diagonal."""
    m = at_indptr.shape[0] - 1
    nnz = m_indptr[n] + n + at_indptr[m] + m  # at most: M's entries, a diagonal each, A, m diagonals
    indptr = np.empty(n + m + 1, dtype=np.int64)
    indices = np.empty(nnz, dtype=np.int64)
    data = np.empty(nnz)
    u = 0
    indptr[0] = 0
    for j in range(n):
        has_diagonal = False
        for k in range(m_indptr[j], m_indptr[j + 1]):
            r = m_indices[k]
            if r > j:
                break
            indices[u] = r
            data[u] = weight[r] * m_data[k] * weight[j]
            u += 1
            if r == j:
                has_diagonal = True
        if not has_diagonal:  # a structural zero on the diagonal: stored, so LDLᵀ sees the entry
            indices[u] = j
            data[u] = 0.0
            u += 1
        indptr[j + 1] = u
    for i in range(m):
        c = n + i
        for k in range(at_indptr[i], at_indptr[i + 1]):
            indices[u] = at_columns[k]
            data[u] = weight[at_columns[k]] * at_data[k] * weight[c]
            u += 1
        indices[u] = c
        data[u] = 0.0
        u += 1
        indptr[c + 1] = u
    return indptr, indices[:u], data[:u]


@njit(cache=True)
def _constraint_weights(indptr, indices, data, weight):
    """Per constraint row (CSR arrays of ``A``), one over its largest entry once its columns are
    scaled by ``weight``: each row of ``W K W`` then has a largest entry of 1."""
    m = indptr.shape[0] - 1
    out = np.ones(m)
    for i in range(m):
        largest = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            largest = max(largest, abs(data[k] * weight[indices[k]]))
        if largest > 0.0:
            out[i] = 1.0 / largest
    return out


@njit(cache=True)
def _symmetric_product(indptr, indices, data, x):
    """``K x`` for the symmetric ``K`` whose upper triangle is the CSC ``(indptr, indices, data)``."""
    out = np.zeros(x.shape[0])
    for j in range(x.shape[0]):
        for k in range(indptr[j], indptr[j + 1]):
            r = indices[k]
            out[r] += data[k] * x[j]
            if r != j:
                out[j] += data[k] * x[r]
    return out


@njit(cache=True)
def _unequilibrated_norm(indptr, indices, data, weight):
    """1-norm (largest absolute column sum) of ``K = W⁻¹ (W K W) W⁻¹`` from the upper triangle of
    ``W K W``."""
    column = np.zeros(weight.shape[0])
    for j in range(weight.shape[0]):
        for k in range(indptr[j], indptr[j + 1]):
            r = indices[k]
            value = abs(data[k]) / (weight[r] * weight[j])
            column[j] += value
            if r != j:
                column[r] += value
    return column.max() if column.shape[0] else 0.0


@njit(cache=True)
def _scatter(pattern_indptr, pattern_indices, indptr, indices, data, out):
    """Write the CSC matrix ``(indptr, indices, data)`` into ``out``, laid out as the pattern
    ``(pattern_indptr, pattern_indices)`` (zeros elsewhere); False if an entry is not in it."""
    out[:] = 0.0
    for j in range(pattern_indptr.shape[0] - 1):
        p, end = pattern_indptr[j], pattern_indptr[j + 1]
        for k in range(indptr[j], indptr[j + 1]):
            r = indices[k]
            while p < end and pattern_indices[p] < r:
                p += 1
            if p == end or pattern_indices[p] != r:
                return False
            out[p] = data[k]
    return True


class ZeroPivotError(RuntimeError):
    """LDLᵀ without pivoting met an exactly zero pivot on this pattern."""


class FactorCache:
    """QDLDL's symbolic analysis of the last pattern factorised, reused for every later matrix whose
    entries all lie in it (see the module docstring). One per solve; ``analyses`` and
    ``factorisations`` count the symbolic analyses and the numeric factorisations done."""

    def __init__(self) -> None:
        # The pattern analysed, holding the values of the matrix factorised last.
        self._matrix: sp.csc_matrix | None = None
        self._solver = None
        self._zero_pivot = False
        self.analyses = 0
        self.factorisations = 0

    def factorise(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray):
        """``qdldl.Solver`` holding the LDLᵀ factors of the symmetric matrix whose upper triangle is
        the CSC ``(indptr, indices, data)`` (rows sorted, every diagonal entry stored). Raises
        :class:`ZeroPivotError` on an exactly zero pivot, and at once for every later matrix of a
        pattern that met one: a constraint row eliminated before the DOFs it holds has a zero
        pivot whatever the values (the ordering minimises fill, and a row pinning one coordinate
        or one frame's spin, as the relaxation's do, has the least)."""
        n = indptr.shape[0] - 1
        self.factorisations += 1
        cached = self._matrix
        same_shape = cached is not None and cached.shape[0] == n
        if not (same_shape and cached.indices.shape[0] <= UNION_FILL_LIMIT * indices.shape[0]
                and _scatter(cached.indptr, cached.indices, indptr, indices, data, cached.data)):
            pattern = (indptr, indices)
            if same_shape:
                # The union of the two patterns (entries summed as ones: none cancels).
                union = add_csc(cached.indptr, cached.indices, np.ones(cached.indices.shape[0]), indptr, indices,
                                np.ones(indices.shape[0]))[:2]
                if union[1].shape[0] <= UNION_FILL_LIMIT * indices.shape[0]:
                    pattern = union
            values = np.empty(pattern[1].shape[0])
            _scatter(pattern[0], pattern[1], indptr, indices, data, values)
            # Later matrices of the pattern are scattered into this matrix's values.
            self._matrix = sp.csc_matrix((values, pattern[1], pattern[0]), shape=(n, n))
            self._solver = None
            self._zero_pivot = False
        if self._zero_pivot:
            raise ZeroPivotError("this pattern met a zero pivot before")
        try:
            if self._solver is None:
                self.analyses += 1
                self._solver = qdldl.Solver(self._matrix, upper=True)
            else:
                self._solver.update(self._matrix, upper=True)
        except RuntimeError as error:
            self._zero_pivot = True
            raise ZeroPivotError(str(error)) from None
        return self._solver


class SingularSystemError(RuntimeError):
    """The system is singular to working precision (the caller damps harder)."""


class SymmetricSolve:
    """Factorisation of ``K = [M Aᵀ; A 0]`` for ``matrix`` ``M`` (``(n, n)``, symmetric) and
    ``constraints`` ``A`` (``(m, n)``, full row rank, or ``None``: ``K = M``), through ``cache``
    (a :class:`FactorCache` shared by a solve's systems; a private one if ``None``). Called with
    ``b`` ``(n,)``, gives the ``d`` ``(n,)`` of ``K [d; ν] = [b; 0]``. Raises
    :class:`SingularSystemError` when the system is exactly singular.

    ``method`` says which factorisation solved it: ``"ldl"`` (QDLDL), ``"threshold"`` (SuperLU in
    symmetric mode with threshold pivoting, where LDLᵀ met a zero pivot) or ``"partial"`` (SuperLU
    with partial pivoting on the unequilibrated system, where either gave a backward error above
    :data:`BACKWARD_ERROR`); ``pivoted`` whether it came to the last.

    LDLᵀ factors live in the cache and are overwritten by its next factorisation: a solve is valid
    until its cache factorises another matrix (the Newton step's direction and chord steps use it
    before the next step's Hessian is factorised)."""

    def __init__(self, matrix: sp.spmatrix, constraints: sp.spmatrix | None = None,
                 cache: FactorCache | None = None):
        matrix = matrix if sp.isspmatrix_csc(matrix) else sp.csc_matrix(matrix)
        if not matrix.has_canonical_format:
            matrix = matrix.copy()
            matrix.sum_duplicates()
        self._n = matrix.shape[0]
        diagonal = np.abs(matrix.diagonal())
        weight = 1.0 / np.sqrt(np.where(diagonal > 0.0, diagonal, 1.0))
        if constraints is not None and constraints.shape[0] > 0:
            by_row = constraints if sp.isspmatrix_csr(constraints) else sp.csr_matrix(constraints)
            if not by_row.has_canonical_format:
                by_row = by_row.copy()
                by_row.sum_duplicates()
            weight = np.concatenate([weight, _constraint_weights(by_row.indptr, by_row.indices, by_row.data, weight)])
            a_indptr, a_indices, a_data = by_row.indptr, by_row.indices, by_row.data
        else:
            a_indptr, a_indices, a_data = np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
        self._weight = weight
        # Everything below works on these arrays: the caller may change its matrix afterwards.
        self._upper = _equilibrated_upper(matrix.indptr, matrix.indices, matrix.data, a_indptr, a_indices, a_data,
                                          weight, self._n)
        self._norm = float(_unequilibrated_norm(*self._upper, weight))
        self.method = "ldl"
        try:
            self._factors = (cache if cache is not None else FactorCache()).factorise(*self._upper)
        except ZeroPivotError:
            self.method = "threshold"
            try:
                self._factors = spla.splu(self._full(equilibrated=True), **_SYMMETRIC)
            except RuntimeError:  # a zero pivot even with threshold pivoting
                self._use_pivoted()

    @property
    def pivoted(self) -> bool:
        """Whether the partial-pivoting fallback was needed."""
        return self.method == "partial"

    @property
    def size(self) -> int:
        """Rows of ``K``: free DOFs plus constraints."""
        return self._weight.shape[0]

    def __call__(self, b: np.ndarray) -> np.ndarray:
        m = self.size - self._n
        rhs = np.concatenate([b, np.zeros(m)]) if m else np.asarray(b, dtype=np.float64)
        if not self.pivoted:
            weighted = self._weight * rhs
            y = self._factors.solve(weighted)
            x = self._weight * y
            # K x − r = W⁻¹ (W K W y − W r) with x = W y.
            residual = (_symmetric_product(*self._upper, y) - weighted) / self._weight
            if self._backward_error(x, rhs, residual) <= BACKWARD_ERROR:
                return x[: self._n]
            self._use_pivoted()
        return self._factors.solve(rhs)[: self._n]

    def _backward_error(self, x: np.ndarray, rhs: np.ndarray, residual: np.ndarray) -> float:
        """Normwise backward error of ``x`` as a solution of ``K x = rhs`` (1-norms), ``residual``
        being ``K x − rhs``."""
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(residual))):
            return np.inf
        denominator = self._norm * float(np.abs(x).sum()) + float(np.abs(rhs).sum())
        error = float(np.abs(residual).sum())
        return error / denominator if denominator > 0.0 else error

    def _full(self, equilibrated: bool) -> sp.csc_matrix:
        """``W K W`` (``equilibrated``) or ``K`` itself, ``W⁻¹ (W K W) W⁻¹``, in full (CSC)."""
        indptr, indices, data = self._upper
        if not equilibrated:
            column = np.repeat(np.arange(self.size), np.diff(indptr))
            data = data / (self._weight[indices] * self._weight[column])
        upper = sp.csc_matrix((data, indices, indptr), shape=(self.size, self.size))
        return sp.csc_matrix(upper + upper.T - sp.diags(upper.diagonal()))

    def _use_pivoted(self) -> None:
        self.method = "partial"
        try:
            self._factors = spla.splu(self._full(equilibrated=False))
        except RuntimeError as error:
            raise SingularSystemError(str(error)) from None
