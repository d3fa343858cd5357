"""The fitted shell in the yarn strip's own test: a strip of the shell's membrane, clamped by two
jaws and pulled quasi-statically, read as the yarn strip is read (issue 14's acceptance, like for
like).

Why: a strip held by its jaws is not a free pull. A woven's bias strip, cut 8 × 6 repeats, has its
ends held unsheared by the jaws and its middle sheared more than their travel (the twill's middle
strains 1.6–1.8 times it, the satin's nearly twice): its middle's pull at its strain is not what a
long strip pulled free (:meth:`yarnfit.shell.ShellMaterial.uniaxial_pull`) gives at that strain.
The shell pulled between the same jaws is: if the shell summarises its yarns, it reproduces the
jaws' constraint as the yarns do.

The model: the strip's gauge ``G × W`` (m, between the jaws' inner edges; x along the pull, y
across, centred on the strip's middle as :class:`yarnfit.validate.strip.Swatch` is), meshed with
linear triangles whose edges follow the yarns (:func:`strip_mesh`: a mesh whose edges do not lie
along a nearly inextensible yarn locks, since a constant-strain triangle cannot shear without
stretching every direction but its own edges'); the membrane energy ``Π = Σ h A ψ(E)`` of the
material's Green strain ``E`` in its weft/warp frame (``h`` the thickness, ``A`` a triangle's
reference area, ``ψ`` :meth:`~yarnfit.shell.ShellMaterial.membrane_energy`), in plane (no bending,
no wrinkling: a bias strip's compression across it is carried in plane); the nodes at or beyond
either jaw's inner edge held, the ``+x`` jaw moved ``strain × G`` along x. Each strain is reached
in load steps of at most :data:`STRAIN_STEP` (the yarn strip's friction step), each a Newton solve
on the total-Lagrangian stiffness (material and geometric parts), warm-started from the last state
stretched affinely between the jaws, stopped on the free nodes' force imbalance
(:data:`FORCE_RTOL` of the jaws' pull) and reporting it.

What is read, as :mod:`yarnfit.validate.strip` reads the yarn strip: the jaws' pull over the whole
width; the middle half of the width's pull across planes over the middle half of the gauge (the
mean over that region of the traction on reference planes across x, ``(F S N)_x``, per reference
width); the middle's strain between two extensometer marks; the middle half's width ratio between
two transverse marks; the width at mid-length. Cut yarn ends at a strip's long sides, which carry
little, the shell does not have: the middle half is read where they matter least.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import scipy.sparse
from numba import njit

from ..engine.linear import FactorCache, SingularSystemError, SymmetricSolve
from ..shell import ShellMaterial
from .strip import EXTENSOMETER_SPAN, MARK_BAND, between_marks
from .swatch import UniformReading, read_curve

# Rows of triangles across the strip's width, or node spacings along its gauge where it is shorter
# than wide (a bias mesh's rows are half a cell apart): the middle of shell_strip_limit's three
# meshes (12, 24 and 48 rows: see its docstring for the convergence they give;
# tests/test_shell_strip.py checks it on a woven-like membrane).
ROWS_ACROSS = 24
# Largest jaw travel per load step (strain): as the yarn strip's frictional steps
# (yarnfit.engine.lagged.FRICTION_STRAIN_STEP), so the two curves are read between steps as fine.
STRAIN_STEP = 0.005
# A load step has converged when every free node's force imbalance is below this fraction of the
# jaws' pull (N): the pull is what is read, and 1e-8 of it is far below any reading's precision
# while far above round-off (a satin's bias pull is ~1e-5 of the stresses its yarns could carry;
# the imbalance's round-off is ~1e-16 of those).
FORCE_RTOL = 1e-8
# ... or below this multiple of the stiffest node's stiffness (the Hessian's largest diagonal
# entry, N/m) times the largest displacement (m): the imbalance's round-off floor (a displacement's
# last digits through the stiffest yarn), which a near-mechanism's pull can fall below (the twill's
# linear fit, shear stiffness ~1e-12 of its yarns', pulls ~1e-11 N at 2 %). Newton's imbalances
# stall at 1e-16 … 1e-14 of that product.
FORCE_ROUNDOFF = 1e-13
# Newton iterations per load step before a step is reported unconverged. A membrane with a
# piecewise-quadratic energy converges in a few once its kinks are crossed (the wovens' 8 x 6 bias
# strips: 8-16 a step on average, the backtracking carrying them across the kinks); where a strip
# has slack regions it converges slowly: the satin's 2 x 5 bias strip, whose corners beyond the
# yarns running clamp to clamp are compressed both ways (no stiffness but its yarns' one-sided
# ridges, 1e5 times its shear's), takes up to 801 at 0.2 % on 48 rows, 497 on 24 (session 50;
# stopped at 100, its readings were within 6e-5 of the converged ones and its edges' width within
# 2e-3). An iteration costs ~20 ms on 48 rows (3085 nodes).
MAX_NEWTON = 1000
# Backtracking: the step is halved until the energy falls (Armijo, this fraction of the linear
# decrease) or it is this small, then the Hessian is shifted (it can be indefinite where the strip
# is compressed across).
ARMIJO = 1e-4
LEAST_STEP = 1e-6
# Angles (degrees from weft) whose yarns the two kinds of mesh follow: 0 / 90 (yarns along the strip and
# across it: square cells split on a diagonal) and ±45 (yarns at ±45°: rows half a cell apart,
# shifted half a cell, so the edges run along x and both diagonals).
ALIGNED_ANGLES = (0.0, 90.0, -90.0)
BIAS_ANGLES = (45.0, -45.0)


@dataclass(frozen=True)
class StripMesh:
    """A shell strip's reference mesh, in the strip frame (x along the pull, y across, centred).

    Attributes:
        rest: ``(n, 2)`` node positions at rest (m).
        triangles: ``(m, 3)`` node indices, counter-clockwise.
        moving, fixed: node indices held by the ``+x`` and ``−x`` jaws.
        gauge, width: the gauge between the jaws' inner edges and the width (m).
    """

    rest: np.ndarray
    triangles: np.ndarray
    moving: np.ndarray
    fixed: np.ndarray
    gauge: float
    width: float


@dataclass(frozen=True)
class ShellStripState:
    """One load step of a shell strip.

    Attributes:
        strain: the jaws' travel over the gauge.
        force_n_per_m: the moving jaw's pull over the whole reference width (N/m).
        middle_force_n_per_m: the middle half of the width's pull over the middle half of the gauge
            per reference width (N/m).
        mid_strain: the middle's strain between the extensometer marks.
        middle_compression_ratio: the middle half's width ratio between the transverse marks.
        compression_ratio: the width at mid-length over the initial width.
        imbalance_n: the largest free-node force imbalance at the end of the solve (N).
        iterations: Newton iterations of the step.
        converged: whether the imbalance fell below :data:`FORCE_RTOL` of the jaws' pull (or its
            round-off floor, :data:`FORCE_ROUNDOFF`).
    """

    strain: float
    force_n_per_m: float
    middle_force_n_per_m: float
    mid_strain: float
    middle_compression_ratio: float
    compression_ratio: float
    imbalance_n: float
    iterations: int
    converged: bool


@dataclass(frozen=True)
class ShellStripCurve:
    """A shell strip pulled through its load steps (:func:`pull_shell_strip`), rest first:
    ``rows`` the mesh's rows across, or the three meshes it was extrapolated from
    (:func:`shell_strip_limit`; ``nodes`` then the finest's)."""

    angle_deg: float
    gauge: float
    width: float
    nodes: int
    states: tuple[ShellStripState, ...]
    rows: tuple[int, ...] = (ROWS_ACROSS,)

    @property
    def converged(self) -> bool:
        return all(state.converged for state in self.states)

    def at_strain(self, strain: float) -> ShellStripState:
        """The state whose jaw strain is ``strain`` (one of the strains it was pulled to)."""
        for state in self.states:
            if math.isclose(state.strain, strain, rel_tol=1e-9, abs_tol=1e-15):
                return state
        raise ValueError(f"the shell strip was not pulled to {strain!r}")

    def uniform_curve(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The middle's strain, pull (N/m), width ratio and converged flag ``(n,)`` each through
        every load step, as :func:`yarnfit.validate.swatch.uniform_curve` gives a yarn strip's."""
        columns = [(s.mid_strain, s.middle_force_n_per_m, s.middle_compression_ratio, s.converged)
                   for s in self.states]
        strain, force, width, converged = (np.array(column) for column in zip(*columns))
        return strain, force, width, converged.astype(bool)

    def read(self, strains: Sequence[float]) -> list[UniformReading | None]:
        """The middle's pull and width at each of the middle's ``strains``, read off its load
        steps as a yarn strip's (:func:`yarnfit.validate.swatch.read_curve`)."""
        return read_curve(*self.uniform_curve(), "steps", strains)


def strip_mesh(angle_deg: float, gauge: float, width: float, rows: int = ROWS_ACROSS) -> StripMesh:
    """The mesh of a strip pulled at ``angle_deg`` from weft (one of :data:`ALIGNED_ANGLES` or
    :data:`BIAS_ANGLES`), ``gauge × width`` (m) between its jaws, ``rows`` rows of triangles
    across (across the gauge's length instead where the strip is shorter than wide), cells as near
    square as the gauge allows. Its edges lie along the yarns (see the
    module docstring); the jaws hold the nodes at or beyond their inner edges ``x = ±gauge/2``
    (a bias mesh's shifted rows end in a half cell at each jaw)."""
    for value, what in ((gauge, "gauge"), (width, "width")):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{what} must be a positive length in m, got {value!r}")
    if not (isinstance(rows, (int, np.integer)) and rows >= 2):
        raise ValueError(f"rows must be an integer of at least 2, got {rows!r}")
    bias = any(math.isclose(angle_deg, a) for a in BIAS_ANGLES)
    if not bias and not any(math.isclose(angle_deg, a) for a in ALIGNED_ANGLES):
        raise ValueError(f"a shell strip's mesh follows its yarns at {', '.join(f'{a:g}' for a in ALIGNED_ANGLES)}"
                         f" or {', '.join(f'{a:g}' for a in BIAS_ANGLES)}°, got {angle_deg!r}")
    # Row spacing dy; cell length a along x (a bias cell is two rows high, a = 2 dy, so its
    # diagonals run at 45°).
    # ``rows`` counts the cells across the shorter side (a 2 × 5 cm strip, 2 cm between its jaws,
    # gets as many along as a long one gets across).
    if width > gauge:
        rows = max(rows, round(rows * width / gauge))
    dy = width / rows
    cell = 2.0 * dy if bias else dy
    columns = max(1, round(gauge / cell))
    cell = gauge / columns
    if bias:
        dy = 0.5 * cell  # the diagonals at exactly 45°: rows follow the cells along x
        rows = max(2, round(width / dy))
        dy = width / rows
    xs, index, count = [], [], 0
    for j in range(rows + 1):
        x = np.arange(columns + 1) * cell
        if bias and j % 2 == 1:  # shifted half a cell, a node at each jaw's edge
            x = np.concatenate([[0.0], (np.arange(columns) + 0.5) * cell, [gauge]])
        index.append(np.arange(len(x)) + count)
        xs.append(x)
        count += len(x)
    rest = np.concatenate([np.column_stack([x - 0.5 * gauge, np.full(len(x), j * dy - 0.5 * width)])
                           for j, x in enumerate(xs)])
    triangles = []
    for j in range(rows):
        triangles.extend(_zip_rows(index[j], index[j + 1], rest))
    triangles = np.array(triangles, dtype=np.int64)
    slack = 1e-9 * gauge
    moving = np.flatnonzero(rest[:, 0] >= 0.5 * gauge - slack)
    fixed = np.flatnonzero(rest[:, 0] <= -0.5 * gauge + slack)
    return StripMesh(rest=rest, triangles=triangles, moving=moving, fixed=fixed, gauge=gauge, width=width)


def _zip_rows(low: np.ndarray, high: np.ndarray, rest: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (counter-clockwise) between two rows of nodes (``rest (n, 2)``), each sorted by
    x, both starting and ending at the same x: each triangle advances one row by a node, the row
    whose advance makes the shorter new edge across (the lower row on a tie). Two unshifted rows
    give squares split on one diagonal; a row shifted half a cell gives edges along x and both
    diagonals, and half cells whose edges run across at its ends."""
    i, j, triangles = 0, 0, []
    while i < len(low) - 1 or j < len(high) - 1:
        advance_low = j == len(high) - 1 or (
            i < len(low) - 1 and np.linalg.norm(rest[low[i + 1]] - rest[high[j]])
            <= np.linalg.norm(rest[low[i]] - rest[high[j + 1]]) * (1.0 + 1e-12))
        if advance_low:
            triangles.append((int(low[i]), int(low[i + 1]), int(high[j])))
            i += 1
        else:
            triangles.append((int(low[i]), int(high[j + 1]), int(high[j])))
            j += 1
    return triangles


class _Membrane:
    """The strip's membrane energy over its mesh: energy, nodal gradient and stiffness (material
    and geometric parts) at nodal displacements ``u (n, 2)`` (m), the material's Green strain taken
    in its weft/warp frame. The kinematics and the assembly are the kernels below; the law is the
    material's (:meth:`~yarnfit.shell.ShellMaterial.membrane_law`). ``free`` are the DOFs the jaws
    do not hold, and the stiffness is assembled into a pattern fixed at construction."""

    def __init__(self, material: ShellMaterial, mesh: StripMesh, angle_deg: float):
        self.material, self.mesh = material, mesh
        c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
        # Material coordinates of the strip frame's reference points: the pull direction u is
        # (c, s) in weft/warp coordinates, across it v = (−s, c) (as cut_swatch turns a strip).
        self.to_material = np.array([[c, -s], [s, c]])
        rest = mesh.rest @ self.to_material.T
        t = np.ascontiguousarray(mesh.triangles, dtype=np.int64)
        self.triangles = t
        edges = np.stack([rest[t[:, 1]] - rest[t[:, 0]], rest[t[:, 2]] - rest[t[:, 0]]], axis=2)  # (m, 2, 2)
        self.area = 0.5 * np.linalg.det(edges)
        if np.any(self.area <= 0.0):
            raise ValueError("the strip's mesh has a degenerate or inverted triangle")
        inverse = np.linalg.inv(edges)  # rows: ∂(barycentric 1, 2)/∂X
        # Shape-function gradients in material coordinates, (m, 3, 2).
        self.gradient_of_shape = np.ascontiguousarray(
            np.concatenate([-inverse.sum(axis=1, keepdims=True), inverse], axis=1))
        self.h = material.thickness
        # The middle region middle_traction averages over: triangles by their centroid.
        centroid = mesh.rest[t].mean(axis=1)
        self._middle = (np.abs(centroid[:, 0]) <= 0.25 * mesh.gauge) & (np.abs(centroid[:, 1]) <= 0.25 * mesh.width)
        held = np.zeros(2 * len(mesh.rest), dtype=bool)
        for nodes in (mesh.moving, mesh.fixed):
            held[2 * nodes] = held[2 * nodes + 1] = True
        self.free = np.flatnonzero(~held)
        # The stiffness's pattern (CSC, symmetric): each local entry's slot, and the slots of the
        # free block.
        n = held.shape[0]
        dofs = (2 * t[:, :, None] + np.arange(2)[None, None, :]).reshape(len(t), 6)
        rows, cols = np.tile(dofs, (1, 6)).ravel(), np.repeat(dofs, 6, axis=1).ravel()
        keys, self._slot = np.unique(cols * n + rows, return_inverse=True)
        row, col = keys % n, keys // n
        self._pattern = (row, np.searchsorted(col, np.arange(n + 1)), n)
        in_free = ~held[row] & ~held[col]
        renumber = np.cumsum(~held) - 1
        self._free_entries = np.flatnonzero(in_free)
        free_col = renumber[col[in_free]]
        self._free_pattern = (renumber[row[in_free]], np.searchsorted(free_col, np.arange(len(self.free) + 1)),
                              len(self.free))

    def kinematics(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(F, ε)`` per triangle at nodal displacements ``u (n, 2)`` (m): ``F = ∂x/∂X`` (current
        strip frame from material frame) ``(m, 2, 2)`` and the Voigt Green strain ``(m, 3)``
        (:func:`_strip_strains`)."""
        F, eps = np.empty((len(self.area), 2, 2)), np.empty((len(self.area), 3))
        _strip_strains(np.ascontiguousarray(u, dtype=np.float64), self.triangles, self.gradient_of_shape,
                       self.to_material, F, eps)
        return F, eps

    def energy(self, u: np.ndarray) -> float:
        return float(self.h * np.dot(self.area, self.material.membrane_law(self.kinematics(u)[1], 0)[0]))

    def first_piola(self, F: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """``h F S`` (N/m) per triangle ``(m, 2, 2)``: the first Piola–Kirchhoff stress resultant,
        ``S`` the second Piola–Kirchhoff stress in material coordinates (the gradient's kernel,
        :func:`_strip_gradient`, forms the same per triangle)."""
        sigma = self.material.membrane_stress(eps)
        S = np.stack([np.stack([sigma[:, 0], sigma[:, 2]], axis=1), np.stack([sigma[:, 2], sigma[:, 1]], axis=1)],
                     axis=1)
        return self.h * np.einsum("mij,mjk->mik", F, S)

    def gradient(self, u: np.ndarray) -> np.ndarray:
        """``∂Π/∂u (n, 2)`` (N)."""
        F, eps = self.kinematics(u)
        out = np.zeros((len(u), 2))
        _strip_gradient(self.triangles, self.gradient_of_shape, self.h * self.area, F,
                        self.material.membrane_law(eps, 1)[1], out)
        return out

    def stiffness(self, u: np.ndarray) -> scipy.sparse.csc_matrix:
        """``∂²Π/∂u²`` ``(2n, 2n)``, the material part ``h A Bᵀ D B`` and the geometric part
        ``h A (gₐᵀ S g_b) Id`` (:func:`_strip_stiffness`)."""
        row, indptr, n = self._pattern
        return scipy.sparse.csc_matrix((self._stiffness_values(u), row, indptr), shape=(n, n))

    def free_stiffness(self, u: np.ndarray) -> scipy.sparse.csc_matrix:
        """:meth:`stiffness`'s block on :attr:`free`."""
        row, indptr, n = self._free_pattern
        return scipy.sparse.csc_matrix((self._stiffness_values(u)[self._free_entries], row, indptr), shape=(n, n))

    def _stiffness_values(self, u: np.ndarray) -> np.ndarray:
        F, eps = self.kinematics(u)
        _, stress, tangent = self.material.membrane_law(eps, 2)
        local = np.empty((len(F), 6, 6))
        _strip_stiffness(self.gradient_of_shape, self.h * self.area, F, stress, np.ascontiguousarray(tangent), local)
        return np.bincount(self._slot, weights=local.ravel(), minlength=len(self._pattern[0]))

    def middle_traction(self, u: np.ndarray) -> float:
        """The mean over the middle region (half the gauge by half the width, triangles by their
        centroid, area-weighted) of the pull across reference planes normal to x, ``(P N)_x`` with
        ``N`` the strip's x in material coordinates (N/m)."""
        inner = self._middle
        traction = self.first_piola(*self.kinematics(u))[:, 0, :] @ self.to_material[:, 0]
        return float(np.dot(self.area[inner], traction[inner]) / self.area[inner].sum())


@njit(cache=True)
def _strip_strains(u, triangles, gradient_of_shape, to_material, F, eps):
    """Per triangle of ``triangles (m, 3)``, from nodal displacements ``u (n, 2)`` (m): the
    deformation gradient ``F = Rᵀ + D`` into ``F (m, 2, 2)`` and the Voigt Green strain into
    ``eps (m, 3)``, formed from the displacement gradient ``D = Σₐ uₐ gₐᵀ`` as
    ``½ (R D + (R D)ᵀ + Dᵀ D)`` (``R`` = ``to_material``, ``gₐ`` = ``gradient_of_shape (m, 3, 2)``):
    from positions, ``½ (FᵀF − Id)`` loses the digits of a gauge-long coordinate over a cell, which
    a satin's stiff yarns turn into a force imbalance above the bias pull's tolerance."""
    R = to_material
    for m in range(triangles.shape[0]):
        d00 = d01 = d10 = d11 = 0.0
        for a in range(3):
            node = triangles[m, a]
            g0, g1 = gradient_of_shape[m, a, 0], gradient_of_shape[m, a, 1]
            d00 += u[node, 0] * g0
            d01 += u[node, 0] * g1
            d10 += u[node, 1] * g0
            d11 += u[node, 1] * g1
        rd00 = R[0, 0] * d00 + R[0, 1] * d10
        rd01 = R[0, 0] * d01 + R[0, 1] * d11
        rd10 = R[1, 0] * d00 + R[1, 1] * d10
        rd11 = R[1, 0] * d01 + R[1, 1] * d11
        eps[m, 0] = rd00 + 0.5 * (d00 * d00 + d10 * d10)
        eps[m, 1] = rd11 + 0.5 * (d01 * d01 + d11 * d11)
        eps[m, 2] = rd01 + rd10 + d00 * d01 + d10 * d11
        F[m, 0, 0] = R[0, 0] + d00
        F[m, 0, 1] = R[1, 0] + d01
        F[m, 1, 0] = R[0, 1] + d10
        F[m, 1, 1] = R[1, 1] + d11


@njit(cache=True)
def _strip_gradient(triangles, gradient_of_shape, weight, F, stress, out):
    """``∂Π/∂u`` added into ``out (n, 2)`` (N): per triangle ``weight (m,)`` (``h A``, m³) times
    ``F S gₐ`` at each of its nodes, ``S`` the second Piola–Kirchhoff stress from its Voigt
    ``stress (m, 3)`` (Pa)."""
    for m in range(triangles.shape[0]):
        s00, s11, s01 = stress[m, 0], stress[m, 1], stress[m, 2]
        p00 = weight[m] * (F[m, 0, 0] * s00 + F[m, 0, 1] * s01)
        p01 = weight[m] * (F[m, 0, 0] * s01 + F[m, 0, 1] * s11)
        p10 = weight[m] * (F[m, 1, 0] * s00 + F[m, 1, 1] * s01)
        p11 = weight[m] * (F[m, 1, 0] * s01 + F[m, 1, 1] * s11)
        for a in range(3):
            g0, g1 = gradient_of_shape[m, a, 0], gradient_of_shape[m, a, 1]
            out[triangles[m, a], 0] += p00 * g0 + p01 * g1
            out[triangles[m, a], 1] += p10 * g0 + p11 * g1


@njit(cache=True)
def _strip_stiffness(gradient_of_shape, weight, F, stress, tangent, local):
    """Each triangle's ``6 × 6`` stiffness into ``local (m, 6, 6)`` (DOF ``2 a + k``: node ``a``'s
    coordinate ``k``): ``weight (Bᵀ D B + (gₐᵀ S g_b) Id)``, ``B (3, 6)`` the Voigt strain's
    derivative (rows δE00, δE11, 2 δE01), ``D`` = ``tangent (m, 3, 3)``, ``S`` from ``stress``."""
    B = np.empty((3, 6))
    for m in range(F.shape[0]):
        for a in range(3):
            g0, g1 = gradient_of_shape[m, a, 0], gradient_of_shape[m, a, 1]
            for k in range(2):
                B[0, 2 * a + k] = g0 * F[m, k, 0]
                B[1, 2 * a + k] = g1 * F[m, k, 1]
                B[2, 2 * a + k] = g1 * F[m, k, 0] + g0 * F[m, k, 1]
        s00, s11, s01 = stress[m, 0], stress[m, 1], stress[m, 2]
        for i in range(6):
            for j in range(6):
                value = 0.0
                for p in range(3):
                    row = tangent[m, p, 0] * B[0, j] + tangent[m, p, 1] * B[1, j] + tangent[m, p, 2] * B[2, j]
                    value += B[p, i] * row
                if i % 2 == j % 2:
                    ga0, ga1 = gradient_of_shape[m, i // 2, 0], gradient_of_shape[m, i // 2, 1]
                    gb0, gb1 = gradient_of_shape[m, j // 2, 0], gradient_of_shape[m, j // 2, 1]
                    value += ga0 * (s00 * gb0 + s01 * gb1) + ga1 * (s01 * gb0 + s11 * gb1)
                local[m, i, j] = weight[m] * value


def pull_shell_strip(material: ShellMaterial, angle_deg: float, gauge: float, width: float,
                     strains: Sequence[float], *, rows: int = ROWS_ACROSS, strain_step: float = STRAIN_STEP,
                     progress: Callable[[str], None] | None = None) -> ShellStripCurve:
    """Pull a strip of ``material``'s membrane, cut at ``angle_deg`` from weft, ``gauge × width``
    (m) between its jaws, to each of ``strains`` (ascending, > 0) in load steps of at most
    ``strain_step`` (see the module docstring). Every load step is kept (``states``, rest first).
    A step that does not converge is kept and flagged, and reported through ``progress``."""
    strains = [float(e) for e in strains]
    if not strains or any(not (math.isfinite(e) and e > 0) for e in strains) or strains != sorted(strains):
        raise ValueError(f"strains must be positive and ascending, got {strains!r}")
    if not (math.isfinite(strain_step) and strain_step > 0):
        raise ValueError(f"strain_step must be positive, got {strain_step!r}")
    material.check_positive_definite()
    mesh = strip_mesh(angle_deg, gauge, width, rows)
    membrane = _Membrane(material, mesh, angle_deg)
    u = np.zeros_like(mesh.rest)  # displacements (m): the unknowns, see _Membrane.kinematics
    states = [_read(membrane, u, 0.0, 0.0, 0, True)]
    reached, before = 0.0, None
    for target in strains:
        steps = max(1, math.ceil((target - reached) / strain_step - 1e-9))
        for k in range(1, steps + 1):
            strain = reached + (target - reached) * k / steps
            previous = states[-1].strain
            # Warm start: the last two equilibria extrapolated to this strain (the first step: the
            # rest state stretched affinely between the jaws, which move apart symmetrically, the
            # strip's middle staying at x = 0).
            if before is None:
                guess = u.copy()
                guess[:, 0] = mesh.rest[:, 0] * strain
            else:
                guess = u + (u - before[1]) * (strain - previous) / (previous - before[0])
            before, u = (previous, u), guess
            u[mesh.moving] = (0.5 * strain * gauge, 0.0)
            u[mesh.fixed] = (-0.5 * strain * gauge, 0.0)
            u, imbalance, iterations, converged = _solve(membrane, u)
            state = _read(membrane, u, strain, imbalance, iterations, converged)
            if not converged and progress is not None:
                progress(f"shell strip at {100 * strain:.3g} %: not converged (imbalance {imbalance:.3g} N after "
                         f"{iterations} Newton iterations)")
            states.append(state)
        reached = target
    return ShellStripCurve(angle_deg=float(angle_deg), gauge=float(gauge), width=float(width), nodes=len(mesh.rest),
                           states=tuple(states), rows=(int(rows),))


def shell_strip_limit(material: ShellMaterial, angle_deg: float, gauge: float, width: float,
                      strains: Sequence[float], *, rows: int = ROWS_ACROSS,
                      progress: Callable[[str], None] | None = None) -> ShellStripCurve:
    """The shell strip in the limit of a fine mesh: pulled on ``rows / 2``, ``rows`` and ``2 rows``
    rows (:func:`pull_shell_strip`), each reading of each load step extrapolated by Richardson at
    the order the three meshes show (:func:`richardson_limit`). Why: a strip held by its jaws
    shears in regions bounded by the yarns through the jaws' corners, and the strain jumps across
    those lines, which a triangle mesh resolves to first order in its cell: a woven's bias strip's
    middle pull falls 5–9 % from 24 to 48 rows and half that again to 96 (the satin's and twill's
    8 × 6 bias strips, ``docs/design.md`` §8); where the strip stiffens, faster: the cotton
    jersey's 2 × 5 cm weft strip at 10 % pulls 525 / 286 / 213 / 192 N/m on 12 / 24 / 48 / 96 rows,
    order 1.7, and ``2 fine − coarse`` from 24 and 48 rows (140 N/m) overshot the limit those
    meshes show (181 N/m from 12 / 24 / 48 rows, 182 from 24 / 48 / 96) by 23 %.
    ``imbalance_n`` is the largest of the three, ``iterations`` their sum, ``converged`` all."""
    if not (isinstance(rows, (int, np.integer)) and rows >= 4 and rows % 2 == 0):
        raise ValueError(f"rows must be an even integer of at least 4 (the coarsest mesh has rows / 2), got {rows!r}")
    curves = [pull_shell_strip(material, angle_deg, gauge, width, strains, rows=n, progress=progress)
              for n in (rows // 2, rows, 2 * rows)]
    fields = ("force_n_per_m", "middle_force_n_per_m", "mid_strain", "middle_compression_ratio", "compression_ratio")
    states = []
    for triple in zip(*(curve.states for curve in curves)):
        states.append(ShellStripState(
            strain=triple[-1].strain,
            **{name: richardson_limit(*(getattr(state, name) for state in triple)) for name in fields},
            imbalance_n=max(state.imbalance_n for state in triple),
            iterations=sum(state.iterations for state in triple),
            converged=all(state.converged for state in triple)))
    fine = curves[-1]
    return ShellStripCurve(angle_deg=fine.angle_deg, gauge=fine.gauge, width=fine.width, nodes=fine.nodes,
                           states=tuple(states), rows=(rows // 2, rows, 2 * rows))


def richardson_limit(coarse: float, middle: float, fine: float) -> float:
    """The limit of a reading on three meshes each of half the last's cell, at the order they show:
    with ``d₁ = coarse − middle`` and ``d₂ = middle − fine`` of one sign and ``r = d₁ / d₂``, the
    error falls as ``h^p`` with ``2^p = r`` and the limit is ``fine − d₂ / (r − 1)``. Where they
    show an order below 1 (``r < 2``) or do not converge monotonically, ``2 fine − middle``: first
    order, the least a mesh's error can have here (the strain's jumps across lines through the
    jaws' corners, resolved to first order), so a slow or noisy triple is not extrapolated further
    than first order would."""
    d1, d2 = coarse - middle, middle - fine
    if d1 * d2 > 0.0 and abs(d1) >= 2.0 * abs(d2):
        return fine - d2 / (d1 / d2 - 1.0)
    return 2.0 * fine - middle


def _jaw_pull(membrane: _Membrane, gradient: np.ndarray) -> float:
    """The moving jaw's pull (N): the x sum of ∂Π/∂u over its nodes."""
    return float(gradient[membrane.mesh.moving, 0].sum())


def _solve(membrane: _Membrane, u: np.ndarray) -> tuple[np.ndarray, float, int, bool]:
    """Newton on the free dofs from displacements ``u`` with backtracking on the energy, shifting
    the Hessian where its step does not descend; ``(u, imbalance (N), iterations, converged)``.
    The Newton systems are solved by :class:`yarnfit.engine.linear.SymmetricSolve` (equilibrated
    LDLᵀ on a fill-reducing ordering, its analysis kept across the solve's systems, which share one
    pattern)."""
    free = membrane.free
    flat = u.ravel().copy()
    cache = FactorCache()
    for iteration in range(MAX_NEWTON + 1):
        gradient = membrane.gradient(flat.reshape(-1, 2))
        g = gradient.ravel()[free]
        imbalance = float(np.abs(g).max()) if len(g) else 0.0
        if imbalance <= FORCE_RTOL * abs(_jaw_pull(membrane, gradient)):
            return flat.reshape(-1, 2), imbalance, iteration, True
        # The stiffness is assembled only for a step (or the round-off floor it sets).
        K = membrane.free_stiffness(flat.reshape(-1, 2))
        diagonal = float(np.abs(K.diagonal()).max())
        if imbalance <= FORCE_ROUNDOFF * diagonal * float(np.abs(flat).max()):
            return flat.reshape(-1, 2), imbalance, iteration, True
        if iteration == MAX_NEWTON:
            break
        energy = membrane.energy(flat.reshape(-1, 2))
        shift = 0.0
        for _ in range(60):
            try:
                shifted = K if shift == 0.0 else K + shift * scipy.sparse.identity(len(free), format="csc")
                step = -SymmetricSolve(shifted, cache=cache)(g)
            except SingularSystemError:  # singular: shift it
                step = None
            if step is not None and np.all(np.isfinite(step)) and float(g @ step) < 0.0:
                accepted = _backtrack(membrane, flat, free, step, g, energy)
                if accepted is not None:
                    flat = accepted
                    break
            shift = max(1e-12 * diagonal, 10.0 * shift)
        else:
            break
    gradient = membrane.gradient(flat.reshape(-1, 2))
    g = gradient.ravel()[free]
    return flat.reshape(-1, 2), float(np.abs(g).max()), MAX_NEWTON, False


def _backtrack(membrane: _Membrane, flat: np.ndarray, free: np.ndarray, step: np.ndarray, g: np.ndarray,
               energy: float) -> np.ndarray | None:
    """The Newton step halved until the energy falls by Armijo's fraction of its linear decrease
    (or, where that decrease is below the energy's round-off, until the imbalance falls); None
    below :data:`LEAST_STEP`."""
    slope = float(g @ step)
    roundoff = 1e-14 * abs(energy)
    imbalance = float(np.abs(g).max())
    alpha = 1.0
    while alpha >= LEAST_STEP:
        trial = flat.copy()
        trial[free] += alpha * step
        change = membrane.energy(trial.reshape(-1, 2)) - energy
        if change <= ARMIJO * alpha * slope and change < 0.0:
            return trial
        if abs(change) <= roundoff:
            trial_g = membrane.gradient(trial.reshape(-1, 2)).ravel()[free]
            if float(np.abs(trial_g).max()) < imbalance:
                return trial
        alpha *= 0.5
    return None


def _read(membrane: _Membrane, u: np.ndarray, strain: float, imbalance: float, iterations: int,
          converged: bool) -> ShellStripState:
    mesh = membrane.mesh
    gradient = membrane.gradient(u)
    x = mesh.rest + u
    rest3 = np.column_stack([mesh.rest, np.zeros(len(mesh.rest))])
    now3 = np.column_stack([x, np.zeros(len(x))])
    inner_across = np.abs(mesh.rest[:, 1]) <= 0.25 * mesh.width
    inner_along = np.abs(mesh.rest[:, 0]) <= 0.25 * mesh.gauge
    mid_strain = between_marks(rest3, now3, 0, 0.0, 0.5 * EXTENSOMETER_SPAN * mesh.gauge, MARK_BAND * mesh.gauge,
                               inner_across) - 1.0
    middle_width = between_marks(rest3, now3, 1, 0.0, 0.25 * mesh.width, MARK_BAND * mesh.width, inner_along)
    return ShellStripState(
        strain=float(strain),
        force_n_per_m=_jaw_pull(membrane, gradient) / mesh.width,
        middle_force_n_per_m=membrane.middle_traction(u),
        mid_strain=float(mid_strain),
        middle_compression_ratio=float(middle_width),
        compression_ratio=_mid_width(mesh, x) / mesh.width,
        imbalance_n=float(imbalance),
        iterations=int(iterations),
        converged=bool(converged),
    )


def _mid_width(mesh: StripMesh, x: np.ndarray) -> float:
    """The width (m) at mid-length: where the strip's long sides (its first and last rows) cross
    the plane halfway between the jaws, interpolated along each side's edges."""
    ys = []
    for side in (mesh.rest[:, 1].min(), mesh.rest[:, 1].max()):
        nodes = np.flatnonzero(np.isclose(mesh.rest[:, 1], side))
        nodes = nodes[np.argsort(x[nodes, 0])]
        ys.append(float(np.interp(0.0, x[nodes, 0], x[nodes, 1])))
    return ys[1] - ys[0]
