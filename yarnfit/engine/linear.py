"""The quasi-static solver's linear solves: ``M d = b`` for a sparse symmetric ``M`` (the damped
Hessian on the free DOFs), optionally with a few linear constraints ``A d = 0`` (the saddle-point
system ``K = [M Aᵀ; A 0]``, ``K [d; ν] = [b; 0]``).

``K`` is equilibrated (``W K W``, ``W`` diagonal: ``|M_ii|^(-1/2)`` on the free DOFs, whose
stiffnesses differ by up to 1e10 between a slender yarn's positions and rotations, and each
constraint row scaled to a largest entry of 1) and factorised by SuperLU in symmetric mode: one
minimum-degree ordering of ``K + Kᵀ`` for rows and columns, pivots on the diagonal unless one is
below :data:`PIVOT_THRESHOLD` of its column (the constraints' zero diagonal block always pivots
off it). SuperLU's default, a column ordering with partial pivoting, destroys the symmetric
ordering and fills in 2–3× as much on the solver's matrices:

- a 9543-DOF knit swatch (no constraints): 1.6e6 against 5.5e5 nonzeros, 53 against 20 ms;
- a 606-DOF periodic stockinette sample with its 6 constraints: 3.4–4.4 against 1.4–2.5 ms.

Eliminating the constraints by their Schur complement instead (factorising ``M`` alone) fails
here: ``M`` is nearly singular along what the constraints remove (a periodic repeat's rigid
translations), and in-solver directions came out wrong by up to 100 %.

Threshold pivoting is not backward stable for every matrix, so each solve checks its normwise
backward error and falls back to partial pivoting when it exceeds :data:`BACKWARD_ERROR`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

__all__ = ["BACKWARD_ERROR", "PIVOT_THRESHOLD", "SingularSystemError", "SymmetricSolve"]

# Largest normwise backward error ‖K x − r‖ / (‖K‖ ‖x‖ + ‖r‖) (1-norms) accepted from the
# symmetric factorisation: such an x solves K + δK exactly with ‖δK‖ ≤ 1e-10 ‖K‖, far below the
# error of the finite-difference Hessian (tests/test_hessian.py: 1e-7). Partial pivoting gives
# 1e-19–1e-15 on the solver's matrices; a bad diagonal pivot 1e-7 and worse.
BACKWARD_ERROR = 1e-10
# A diagonal pivot is kept while it is at least this fraction of its column's largest entry (on
# the equilibrated matrix). 0.01 measured fastest on the solver's matrices (1e-1 and 0.5 fill
# 15–40 % more); all three solved them to the same 1e-9.
PIVOT_THRESHOLD = 0.01

_SYMMETRIC = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=PIVOT_THRESHOLD, options=dict(SymmetricMode=True))


def _saddle_point(matrix: sp.csc_matrix, constraints: sp.spmatrix, weight: np.ndarray):
    """``K = [M Aᵀ; A 0]`` (CSC, canonical when ``M`` is) and the weights extended by each
    constraint row's: one over its largest entry once its columns are weighted."""
    n, m = matrix.shape[0], constraints.shape[0]
    by_column, by_row = sp.csc_matrix(constraints), sp.csr_matrix(constraints)
    by_column.sort_indices()
    by_row.sort_indices()
    row_max = np.zeros(m)
    np.maximum.at(row_max, by_column.indices, np.abs(by_column.data * np.repeat(weight, np.diff(by_column.indptr))))
    weight = np.concatenate([weight, 1.0 / np.where(row_max > 0.0, row_max, 1.0)])
    indptr, indices, data = _stack_saddle_point(matrix.indptr, matrix.indices, matrix.data, by_column.indptr,
                                                by_column.indices, by_column.data, by_row.indptr, by_row.indices,
                                                by_row.data, n)
    system = sp.csc_matrix((data, indices, indptr), shape=(n + m, n + m))
    system.has_canonical_format = matrix.has_canonical_format
    return system, weight


@njit(cache=True)
def _stack_saddle_point(m_indptr, m_indices, m_data, a_indptr, a_rows, a_data, at_indptr, at_columns, at_data, n):
    """CSC arrays of ``[M Aᵀ; A 0]`` from ``M`` (CSC, ``(n, n)``) and ``A`` given by columns
    (``a_*``, CSC) and by rows (``at_*``, CSR): column j < n is M's column then A's column j (rows
    n + i, below every row of M); column n + i is A's row i."""
    m = at_indptr.shape[0] - 1
    nnz = m_indptr[n] + 2 * a_indptr[n]
    indptr = np.empty(n + m + 1, dtype=np.int32)
    indices = np.empty(nnz, dtype=np.int32)
    data = np.empty(nnz)
    u = 0
    indptr[0] = 0
    for j in range(n):
        for k in range(m_indptr[j], m_indptr[j + 1]):
            indices[u] = m_indices[k]
            data[u] = m_data[k]
            u += 1
        for k in range(a_indptr[j], a_indptr[j + 1]):
            indices[u] = n + a_rows[k]
            data[u] = a_data[k]
            u += 1
        indptr[j + 1] = u
    for i in range(m):
        for k in range(at_indptr[i], at_indptr[i + 1]):
            indices[u] = at_columns[k]
            data[u] = at_data[k]
            u += 1
        indptr[n + i + 1] = u
    return indptr, indices, data


class SingularSystemError(RuntimeError):
    """The system is singular to working precision (the caller damps harder)."""


class SymmetricSolve:
    """Factorisation of ``K = [M Aᵀ; A 0]`` for ``matrix`` ``M`` (``(n, n)``, symmetric) and
    ``constraints`` ``A`` (``(m, n)``, full row rank, or ``None``: ``K = M``). Called with ``b``
    ``(n,)``, gives the ``d`` ``(n,)`` of ``K [d; ν] = [b; 0]``. Raises
    :class:`SingularSystemError` when the system is exactly singular. ``pivoted`` says whether the
    partial-pivoting fallback was needed."""

    def __init__(self, matrix: sp.spmatrix, constraints: sp.spmatrix | None = None):
        matrix = matrix if sp.isspmatrix_csc(matrix) else sp.csc_matrix(matrix)
        self._n = matrix.shape[0]
        diagonal = np.abs(matrix.diagonal())
        weight = 1.0 / np.sqrt(np.where(diagonal > 0.0, diagonal, 1.0))
        self._n_constraints = 0
        system = matrix
        if constraints is not None and constraints.shape[0] > 0:
            system, weight = _saddle_point(matrix, sp.coo_matrix(constraints), weight)
            self._n_constraints = constraints.shape[0]
        self.system = system
        self._weight = weight
        # Column of every stored entry: the system's 1-norm and its equilibration W K W are then
        # sums and products over the stored entries, in the order scipy's (W K) W gives them.
        column = np.repeat(np.arange(system.shape[1]), np.diff(system.indptr))
        self._norm = float(np.bincount(column, weights=np.abs(system.data), minlength=system.shape[1]).max(initial=0.0))
        equilibrated = sp.csc_matrix(((weight[system.indices] * system.data) * weight[column], system.indices,
                                      system.indptr), shape=system.shape)
        self.pivoted = False
        try:
            self._lu = spla.splu(equilibrated, **_SYMMETRIC)
        except RuntimeError:  # a zero pivot even with threshold pivoting
            self._use_pivoted()

    def __call__(self, b: np.ndarray) -> np.ndarray:
        rhs = np.concatenate([b, np.zeros(self._n_constraints)]) if self._n_constraints else b
        if not self.pivoted:
            x = self._weight * self._lu.solve(self._weight * rhs)
            if self.backward_error(x, rhs) <= BACKWARD_ERROR:
                return x[: self._n]
            self._use_pivoted()
        return self._lu.solve(rhs)[: self._n]

    def backward_error(self, x: np.ndarray, rhs: np.ndarray) -> float:
        """Normwise backward error of ``x`` as a solution of ``K x = rhs`` (1-norms)."""
        if not np.all(np.isfinite(x)):
            return np.inf
        denominator = self._norm * float(np.abs(x).sum()) + float(np.abs(rhs).sum())
        residual = float(np.abs(self.system @ x - rhs).sum())
        return residual / denominator if denominator > 0.0 else residual

    def _use_pivoted(self) -> None:
        self.pivoted = True
        try:
            self._lu = spla.splu(self.system)
        except RuntimeError as error:
            raise SingularSystemError(str(error)) from None
