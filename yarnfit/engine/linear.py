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


class SingularSystemError(RuntimeError):
    """The system is singular to working precision (the caller damps harder)."""


class SymmetricSolve:
    """Factorisation of ``K = [M Aᵀ; A 0]`` for ``matrix`` ``M`` (``(n, n)``, symmetric) and
    ``constraints`` ``A`` (``(m, n)``, full row rank, or ``None``: ``K = M``). Called with ``b``
    ``(n,)``, gives the ``d`` ``(n,)`` of ``K [d; ν] = [b; 0]``. Raises
    :class:`SingularSystemError` when the system is exactly singular. ``pivoted`` says whether the
    partial-pivoting fallback was needed."""

    def __init__(self, matrix: sp.spmatrix, constraints: sp.spmatrix | None = None):
        matrix = sp.csc_matrix(matrix)
        self._n = matrix.shape[0]
        diagonal = np.abs(matrix.diagonal())
        weight = 1.0 / np.sqrt(np.where(diagonal > 0.0, diagonal, 1.0))
        self._n_constraints = 0
        system = matrix
        if constraints is not None and constraints.shape[0] > 0:
            constraints = sp.csr_matrix(constraints)
            self._n_constraints = constraints.shape[0]
            row_max = abs(constraints @ sp.diags(weight)).max(axis=1).toarray().ravel()
            weight = np.concatenate([weight, 1.0 / np.where(row_max > 0.0, row_max, 1.0)])
            system = sp.bmat([[matrix, constraints.T], [constraints, None]], format="csc")
        self.system = system
        self._weight = weight
        self._norm = spla.norm(system, 1)
        self.pivoted = False
        try:
            self._lu = spla.splu(sp.csc_matrix(sp.diags(weight) @ system @ sp.diags(weight)), **_SYMMETRIC)
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
