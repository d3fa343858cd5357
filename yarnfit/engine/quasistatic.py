"""Quasi-static equilibrium of a rod model: minimise the discrete energy until the residuals are
below tolerance.

Why not XPBD iterations: the fixed point of XPBD pseudo-time stepping is biased towards the soft
side unless the pseudo step is tiny (a tip-loaded cantilever, PL²/EI = 2, 20 edges: v/L = 0.779 at
Δt = 1 and 0.501 at Δt = 0.1 against the discrete minimum 0.467; ``docs/design.md`` §5). The
solver here is a damped Newton method on the exact energy of :mod:`yarnfit.engine.energy`:

- degrees of freedom: free node positions and world rotation vectors of free edge frames
  (``q ← exp(θ) ⊗ q``);
- Hessian: analytic for stretch–shear and contact elements (the closest points' motion
  included), central differences of the analytic gradient for bend–twist elements; assembled
  sparse with the step constraints' rows into a saddle-point system, equilibrated and factorised
  as LDLᵀ with a fill-reducing ordering analysed once per pattern (:mod:`yarnfit.engine.linear`);
  Levenberg–Marquardt damping ``μ diag(H)`` keeps every step a descent direction where the
  Hessian is indefinite or singular (a rod held only by points can spin its frames freely);
- backtracking (Armijo) line search on the total potential, then a few chord steps with the same
  factorisation; a step never brings two segments closer than a tenth of their distance, so yarns
  cannot pass through each other;
- contact: the unilateral constraint ``g ≥ 0`` by an augmented Lagrangian, sampled: points along
  each edge of a pair (nodes included, at most a quarter radius apart) keep ``ra + rb`` from the
  other segment. The closest-point gap of two segments has a kink where they are parallel, and a
  yarn resting along another then stalled Newton at residuals near 1e-3; point-to-segment
  distances are C¹ and spread a line contact over its samples. Each constraint's term is
  ``(M(λ − k g) − M(λ)) / k`` with ``M`` the integral of a C¹ ramp ``m`` (zero below ``−δ``, a
  parabola within ``±δ``, the identity above; ``δ = 10⁻⁴ k (ra + rb)``), so the
  potential is C¹ with a Lipschitz gradient and Newton needs no active set: the normal force is
  ``m(λ − k g) ≥ 0``. With the plain ``max(0, λ − k g)²`` the kink sits within ~1e-10 m of every
  resting contact, Newton's last corrections keep crossing it, and an active set that releases
  pairs turning tensile churned for hundreds of iterations on knits. When the iterate is nearly
  balanced, multipliers take the contact forces (``λ ← m(λ − k g)``), which drives loaded
  contacts to ``g = 0`` exactly (a constraint carrying less than ``δ`` rests up to ``δ / k``
  apart). Friction does no work in a minimisation; the frictionless minimiser is an equilibrium
  of the frictional problem too (zero tangential force is inside every Coulomb cone), and it is
  the reproducible one, which the periodic samples use. A load step that must follow a frictional
  path (a cut strip whose loose yarn ends friction holds) passes lagged friction anchors
  (:mod:`yarnfit.engine.friction`): a convex potential of the slip since the step's start;
- slender rods converge more slowly (Newton's quadratic model misses the quartic stretch energy
  of a rotating edge: L/r = 100 takes ~20 iterations for a large-deflection cantilever, L/r = 1000
  ~100); ``load_steps`` splits strongly nonlinear loads.

Convergence is declared only when the force and torque imbalances (relative to the load scale),
the relative energy change of the last step, the contact penetration and the gap of any contact
still carrying force are all below tolerance.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from . import _contact_kernels, _friction_kernels, _kernels
from .contact import ContactPairs
from .contact_lagrangian import ContactLagrangian, ContactSet, exchanged_potential
from .energy import EnergyTerms, internal_forces
from .friction import FrictionAnchors
from .linear import FactorCache, SingularSystemError, SymmetricSolve
from .model import RodModel, quaternion_d3
from .state import Loads, RodState

# Sufficient-decrease constant of the Armijo line search (the usual 1e-4 of Nocedal & Wright).
ARMIJO_SLOPE = 1e-4
# Chord (lagged-Hessian) steps tried after each accepted Newton step while they decrease the
# potential: each costs one gradient and one back-substitution; on slender rods they cut the
# iteration count by a fifth to a third (cantilever L/r = 100: 32 → 20 iterations).
CHORD_STEPS = 3
# Reach of the line search's contacts beyond the pairs that can push along the Newton step, in
# units of the smallest radius: chord steps after it that move nodes by up to half this (a pair's
# distance changes by at most its two edges' largest node moves) are judged with those contacts,
# and one that moves them further queries the pairs along its own way. Larger holds more pairs in
# every evaluation, smaller queries more often. Five captured lagged solves of the 2 mm twill warp
# strip (5 and 10 %): 2608 Newton iterations at 0.02, 2597 at 0.05, 2540 at 0.2, the last ~20 %
# slower per iteration. Chord steps there moved nodes by 0.01 radii (median), 0.05 (90th
# percentile), 0.12 at most. Stopping chord steps at the allowance instead took the bench's
# 2000-segment crossing 49 iterations against 34.
CHORD_SLACK = 0.05
# Round-off floor of a residual, in units of one rounding of the largest coordinate times the
# stiffness: the strain's subtraction and the sums over a node's elements add a few roundings more.
ROUNDOFF_FACTOR = 10.0
# Levenberg–Marquardt damping follows how well the last step's quadratic model predicted the
# potential (the gain-ratio update of Nielsen 1999, as in Madsen, Nielsen & Tingleff 2004, §3.2):
# a full step with gain ratio ρ (actual over predicted decrease) multiplies μ by
# max(1/3, 1 − (2ρ − 1)³), so a good model lowers μ by up to a third per step and a poor one raises
# it; a step that had to be cut (by a cap or by backtracking) multiplies μ by a factor that starts
# at DAMPING_RAISE and doubles while steps keep being cut. Damping must fall where the model is
# good (μ diag(H), diag(H) ~ EA/l0, swamps the soft bending modes of slender rods) and rise where
# it is not: the older rule (×10 after a step cut below a tenth, ÷10 otherwise) swung μ by two
# decades every few steps between steps that overshot (yarns sagging or sliding onto crossings the
# model did not see: the next step cut to 1/250) and steps damped to nothing. The bench's
# 2000-segment crossing (validation/bench.py) takes 87 iterations with the older rule, 52 with this
# one; the presets' 55-sample fits 2–17 % fewer (satin 1555 → 1284), HYLC's stockinette 28 % fewer
# on its small-strain samples. Paths change, so path-sensitive samples (soft knits) can land on
# other equilibria (docs/design.md §5).
DAMPING_DECREASE_LIMIT = 1.0 / 3.0
DAMPING_RAISE = 2.0
# A step never moves two segments closer by more than this fraction of their current centreline
# distance, so yarns cannot pass through each other between two contact checks.
TUNNELING_FRACTION = 0.9
# A step whose predicted decrease of the potential is below this fraction of it is below the
# potential's round-off: the Armijo test would compare noise.
POTENTIAL_ROUNDOFF = 1e-13
# There Newton steps are taken whole and the imbalance (the larger relative force or torque
# residual) judges the model: a step that did not lower it multiplies the damping by this (a cut
# step raises it too). Contacts resting at the foot of the contact ramp's smoothing band, where
# both their force and their stiffness go to zero, made undamped whole steps hop across the band's
# edge for good: HYLC's stockinette, settled rest state, weft bend at -6.5 /m, cycled between force
# imbalances of 3e-8 and 2e-7 N (6.6e-5 relative) for 29,000 iterations at damping 1e-12.
NOISE_DAMPING = 10.0
# Levenberg–Marquardt damping bounds, relative to diag(H). The floor is far below the Hessian's
# own error (~1e-10 relative); it only regularises exactly singular directions. The start follows
# Madsen, Nielsen & Tingleff (2004, §3.2: μ0 = τ max a_ii with τ = 1e-6 when the start is believed
# close to the solution, 1e-3 or more otherwise): a sample starts from the affine map of its
# relaxed repeat, which its soft modes (loops turning, yarns sliding) are not close to, and from
# 1e-8 its first 4–6 steps were cut while the damping climbed (HYLC's stockinette at 0.1 % shear:
# 1/8 … 1/64 of a step each). Once the iterate is within round-off of a stationary point it is
# close, and the damping restarts from NEAR_DAMPING if it was higher: a step still damped to 1e-5
# there could not resolve a bending residual of 1.7e-8 (tolerance 1e-8), no step lowered the
# imbalance, and the noise rule's raises ratcheted it to the ceiling (solid cotton jersey, weft
# bend 1 /m: 27620 iterations, not converged; 12 with the restart, 9 from 1e-8). Newton iterations
# from the same relaxed repeats, 1e-8 → 1e-4 with the restart: the presets' 5 × 55 samples
# 6788 → 6102, HYLC's stockinette 4101 → 3764, the bench's 2000-segment crossing 41 → 34, the
# presets' relaxations 247 → 232, the twill warp strip 5 → 10 % 1638 → 1552; but the twill weft
# strip's 10 % 531 → 1494 (design notes §5, session 31).
INITIAL_DAMPING = 1e-4
NEAR_DAMPING = 1e-8
MIN_DAMPING = 1e-12
# Ceiling of the damping (and of its raise factor): a step damped this much moves 1e-12 of a
# diagonally scaled gradient step, nothing any more. Without it a run of cut steps (factors 2, 4,
# 8, …) overflowed to inf: HYLC's satin as written, shear −0.4, 2553 iterations.
MAX_DAMPING = 1e12


class ConvergenceWarning(UserWarning):
    """A solver stopped before its residuals met the tolerances."""


@dataclass
class QuasiStaticOptions:
    """Tolerances and limits of :class:`QuasiStaticSolver`.

    Attributes:
        force_tolerance: max |net force| on a free node over the force scale (the largest sum of
            force magnitudes acting on any node, torques counted as τ / l0).
        torque_tolerance: the same for torques on free edge frames.
        energy_tolerance: |ΔΠ| of the last step over max(|Π|, internal energy).
        penetration_tolerance: max contact penetration over (ra + rb).
        max_iterations: Newton iterations per load step.
        load_steps: the loads are applied in this many equal increments, each solved to
            convergence (helps strongly nonlinear problems such as a rod rolled into a ring).
        contact: detect and resolve yarn–yarn contact.
        contact_stiffness: initial augmented-Lagrangian penalty (N/m); default ``EA / (ra + rb)``
            of the stiffer edge of each pair. Pairs still penetrating beyond tolerance at a
            multiplier update that made too little progress are stiffened tenfold (up to 1e4
            times).
        contact_margin: broad-phase margin in units of the smallest radius.
        max_rotation_step: largest frame rotation per iteration (rad).
        fd_relative_step: central-difference step of the bend–twist Hessian (rad); the contact
            Hessian is exact.
    """

    force_tolerance: float = 1e-8
    torque_tolerance: float = 1e-8
    energy_tolerance: float = 1e-12
    penetration_tolerance: float = 1e-5
    max_iterations: int = 300
    load_steps: int = 1
    contact: bool = True
    contact_stiffness: float | None = None
    contact_margin: float = 1.0
    max_rotation_step: float = 1.0
    fd_relative_step: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("force_tolerance", "torque_tolerance", "energy_tolerance", "penetration_tolerance",
                     "contact_margin", "max_rotation_step", "fd_relative_step"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"QuasiStaticOptions.{name} must be a positive finite number, got {value!r}")
        for name in ("max_iterations", "load_steps"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"QuasiStaticOptions.{name} must be a positive integer, got {value!r}")
        stiffness = self.contact_stiffness
        if stiffness is not None and not (isinstance(stiffness, (int, float)) and math.isfinite(stiffness) and stiffness > 0):
            raise ValueError(f"QuasiStaticOptions.contact_stiffness must be positive, got {stiffness!r}")


@dataclass
class Residual:
    """Convergence measures of a quasi-static state (all dimensionless).

    ``separation`` is the largest gap, over the sum of radii, of a contact constraint that still
    carries a force above the smoothing band (its multiplier is not yet up to date; zero at a
    converged state). ``force_floor`` and ``torque_floor`` estimate the smallest imbalance float64
    can resolve for this stiffness and load (positions are known to ``ε |x|``,
    so an edge force only to ``ε |x| EA / l0``), relative to the same scales. A tolerance below the
    floor is unreachable; the floor then takes its place and the result says so.
    """

    force: float
    torque: float
    energy_change: float
    penetration: float
    separation: float = 0.0
    force_floor: float = 0.0
    torque_floor: float = 0.0

    def balanced(self, options: QuasiStaticOptions, slack: float = 0.0) -> bool:
        """Force and torque imbalances within tolerance (or ``slack``, or the round-off floor)."""
        return (self.force <= max(options.force_tolerance, self.force_floor, slack)
                and self.torque <= max(options.torque_tolerance, self.torque_floor, slack))

    def within(self, options: QuasiStaticOptions) -> bool:
        return (
            self.balanced(options)
            and self.energy_change <= options.energy_tolerance
            and self.penetration <= options.penetration_tolerance
            and self.separation <= options.penetration_tolerance
        )

    def __str__(self) -> str:
        text = (
            f"force {self.force:.2e}, torque {self.torque:.2e}, energy change {self.energy_change:.2e}, "
            f"penetration {self.penetration:.2e}"
        )
        if self.separation > 0.0:
            text += f", loaded contact separation {self.separation:.2e}"
        return text + f" (round-off floors: force {self.force_floor:.1e}, torque {self.torque_floor:.1e})"


class LinearConstraints:
    """Linear equality constraints ``A x = A x0`` on node positions, held exactly by every step,
    and edge frames whose spin about their own tangent is held.

    ``matrix`` is ``(m, 3N)`` over the flattened positions (node i, axis k at column ``3i + k``),
    dense or scipy sparse, or None. Rows that only involve pinned nodes or that depend linearly on
    other rows are dropped when the solver uses them. Use them to remove free motions that carry no
    energy (a periodic yarn sliding along itself, a periodic structure translating), or for the
    homogenization constraints.

    ``spin_edges`` lists edges whose frame may not turn about its own ``d3`` in any step. A closed
    or periodic yarn with a straight, isotropic rest shape and no pinned frame can spin all its
    frames about their tangents at no energy; the Newton step is then undetermined along that
    spin, Levenberg–Marquardt damping alone gives it huge rotations, and the rotation cap shrinks
    every step to a fraction (a jersey relaxation took 0.2 of each step and converged linearly).
    Holding one frame per such yarn fixes the gauge without changing the equilibrium; on a yarn
    whose energy does depend on the spin it is a real constraint, and the residual (which it does
    not relax) says so.
    """

    def __init__(self, matrix=None, spin_edges=()):
        self.matrix = None if matrix is None else sp.csr_matrix(matrix, dtype=np.float64)
        if self.matrix is not None and not np.all(np.isfinite(self.matrix.data)):
            raise ValueError("constraint matrix has non-finite entries")
        self.spin_edges = np.unique(np.asarray(spin_edges, dtype=np.int64))

    def __len__(self) -> int:
        return (0 if self.matrix is None else self.matrix.shape[0]) + self.spin_edges.size


@dataclass(frozen=True)
class Progress:
    """What :meth:`QuasiStaticSolver.solve` reports after each iteration (for progress displays
    and recordings). ``position`` is the solver's own array: read it, do not keep or modify it."""

    iteration: int
    residual: Residual
    position: np.ndarray
    potential: float


@dataclass
class QuasiStaticResult:
    """Outcome of :meth:`QuasiStaticSolver.solve`.

    Attributes:
        state: the equilibrium configuration (velocities zero).
        converged: every residual met its tolerance.
        iterations: Newton iterations over all load steps.
        energy: energy split by term at the returned state (J); ``external`` includes the work of
            edge moments integrated along the solution path.
        residual: the residuals at the returned state.
        contact_pairs: the edge pairs touching at the end (with the image of their second edge).
        contact_force: ``(P,)`` their normal forces (N, summed over each pair's samples).
        reaction_force: ``(N, 3)`` the force (N) each pinned node's support exerts on it, ``∂Π/∂x``
            of the total potential (rods, contacts and loads): what holds the node where it is;
            zero on free nodes. A tensile test's jaw force is the sum over the jaw's nodes.
        reaction_moment: ``(E, 3)`` the moment (N·m, world frame) each pinned frame's support
            exerts on it, ``∂Π/∂θ``; zero on free frames.
        history: the residual of every iteration.
        contacts: the contact constraints of every pair within the broad phase's margin at the
            returned state, with their multipliers and penalties: the contact potential the
            returned state balances (see
            :func:`~yarnfit.engine.contact_lagrangian.contact_potential`; the pairs out of reach
            add only a constant). The margin rather than the pairs that can push, so that a solve
            started from them (the next lagged friction pass) recalls the penalties of the pairs
            near contact too: recalled as new pairs, at the stiffest factor reached, they took
            the twill warp strip's 5 % load step 1399 Newton iterations against 873.
    """

    state: RodState
    converged: bool
    iterations: int
    energy: EnergyTerms
    residual: Residual
    contact_pairs: ContactPairs
    contact_force: np.ndarray
    reaction_force: np.ndarray
    reaction_moment: np.ndarray
    history: list = field(default_factory=list)
    contacts: ContactSet = field(default_factory=ContactSet.none)


@dataclass
class _Evaluation:
    """Potential, gradient (full DOF vector) and residual measures of one configuration; contact
    forces (N) and gaps (m) per sampled constraint."""

    gradient: np.ndarray
    potential: float
    internal: float
    contact_force: np.ndarray
    contact_gap: np.ndarray
    residual: Residual


class _RodHessian:
    """The rods' Hessian triplets (``81 E + 36 J``, written in the same order at every iterate),
    the fixed CSC pattern over the free DOFs they fill and where each lands (set on first use)."""

    def __init__(self, model: RodModel) -> None:
        count = 81 * model.n_edges + 36 * model.n_joints
        self.rows = np.empty(count, dtype=np.int64)
        self.cols = np.empty(count, dtype=np.int64)
        self.vals = np.empty(count)
        self.indptr: np.ndarray | None = None
        self.indices: np.ndarray | None = None
        self.slot: np.ndarray | None = None
        self.data: np.ndarray | None = None


@dataclass
class _Work:
    """Mutable iterate of a solve: configuration, path-integrated moment work (J), and the
    contacts of the last evaluation with their forces."""

    position: np.ndarray
    quaternion: np.ndarray
    moment_work: float = 0.0
    contacts: ContactSet = field(default_factory=ContactSet.none)
    # The line search's swept contacts when the iterate lies on its segment (no chord step): a
    # superset of the pairs near it, which the next evaluation uses instead of a new search.
    swept: ContactSet | None = None
    # The line search's evaluation at that iterate with those contacts: the next evaluation is the
    # same numbers, so it is taken over rather than computed again.
    swept_evaluation: _Evaluation | None = None
    contact_force: np.ndarray = field(default_factory=lambda: np.empty(0))
    # Full gradient (every DOF, pinned ones included) of the last evaluation: the solve always
    # ends on an evaluation at the returned state, so this gives the reactions there.
    gradient: np.ndarray = field(default_factory=lambda: np.empty(0))
    # The symbolic analysis of the Newton systems' sparsity pattern, reused while the contact
    # pairs (hence the pattern) stay within it.
    factors: FactorCache = field(default_factory=FactorCache)

    @property
    def point(self) -> tuple[np.ndarray, np.ndarray, float]:
        return self.position, self.quaternion, self.moment_work


class _Damping:
    """Levenberg–Marquardt damping μ (relative to diag(H)) of one load step and its update rule
    (DAMPING_DECREASE_LIMIT, DAMPING_RAISE)."""

    def __init__(self) -> None:
        self.value = INITIAL_DAMPING
        self._raise = DAMPING_RAISE
        self._near = False

    def reached_roundoff(self) -> None:
        """The iterate is within round-off of a stationary point: from the first such step on, the
        damping starts again from NEAR_DAMPING if it was higher."""
        if not self._near:
            self._near = True
            self.value = min(self.value, NEAR_DAMPING)

    def succeeded(self, gain: float) -> None:
        """A full Newton step was taken; ``gain`` is its actual over its predicted decrease."""
        factor = 1.0 - (2.0 * min(max(gain, 0.0), 1.0) - 1.0) ** 3
        self.value = max(self.value * max(DAMPING_DECREASE_LIMIT, factor), MIN_DAMPING)
        self._raise = DAMPING_RAISE

    def failed(self) -> None:
        """The step had to be cut: the model reached too far."""
        self.raise_by(self._raise)
        self._raise = min(2.0 * self._raise, MAX_DAMPING)

    def harden(self) -> None:
        """No descent direction or no decrease at all: damp much harder."""
        self.raise_by(100.0)

    def raise_by(self, factor: float) -> None:
        self.value = min(self.value * factor, MAX_DAMPING)


class QuasiStaticSolver:
    """Newton solver for the static equilibrium of a :class:`RodModel` (see module docstring)."""

    def __init__(self, model: RodModel, options: QuasiStaticOptions | None = None):
        self.model = model
        self.options = options or QuasiStaticOptions()
        n, e = model.n_nodes, model.n_edges
        free = np.concatenate([np.repeat(~model.node_pinned, 3), np.repeat(~model.edge_pinned, 3)])
        self._free = np.flatnonzero(free)
        self._dof_map = np.full(3 * (n + e), -1, dtype=np.int64)
        self._dof_map[self._free] = np.arange(self._free.size)
        self._node_free = ~model.node_pinned
        self._edge_free = ~model.edge_pinned
        # A step never moves a node further than the model's reach (one tile of a periodic model,
        # the rest configuration's extent otherwise): a Newton step beyond it means the quadratic
        # model has failed, and the contact search along it would have to map that many tiles (a
        # HYLC satin at r = 1 mm, in a halved continuation step, proposed a step that overflowed
        # the image count).
        if model.periodic:
            tiles = np.linalg.norm(model.lattice, axis=1)
            self._max_displacement = float(tiles[tiles > 0.0].min())
        else:
            rest = model.node_rest_position
            self._max_displacement = max(float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0))),
                                         float(model.edge_rest_length.max(initial=0.0)))
        # Axial stiffness seen by each node (N/m) and carried by each edge (N), for round-off floors.
        edge_stiffness = np.maximum(model.edge_stretch_stiffness, model.edge_shear_stiffness)
        self._constraint = None
        self._constraint_dense = None
        self._least_squares_multiplier = None
        self._spin_edges = np.empty(0, dtype=np.int64)
        self._friction: FrictionAnchors | None = None
        self._rod_hessian = _RodHessian(model)
        node_stiffness = np.zeros(n)
        np.add.at(node_stiffness, model.edge_nodes.ravel(), np.repeat(edge_stiffness / model.edge_rest_length, 2))
        self._largest_node_stiffness = float(node_stiffness.max(initial=0.0))
        self._largest_edge_stiffness = float(edge_stiffness.max(initial=0.0))

    def _set_constraints(self, constraints: LinearConstraints | None) -> None:
        """Restrict ``constraints`` to the free DOFs (rotations have zero columns), drop empty and
        dependent rows, and prepare the projection used to measure residuals."""
        self._constraint = None
        self._constraint_dense = None
        self._least_squares_multiplier = None
        self._spin_edges = np.empty(0, dtype=np.int64)
        if constraints is None:
            return
        m = self.model
        spin = constraints.spin_edges
        if spin.size and (spin.min() < 0 or spin.max() >= m.n_edges):
            raise ValueError(f"spin_edges must be edge indices in [0, {m.n_edges}), got {spin.min()}..{spin.max()}")
        self._spin_edges = spin[~m.edge_pinned[spin]]
        matrix = constraints.matrix
        if matrix is None or matrix.shape[0] == 0:
            return
        n_nodes = m.n_nodes
        if matrix.shape[1] != 3 * n_nodes:
            raise ValueError(f"constraint matrix must have {3 * n_nodes} columns (3 per node), got {matrix.shape[1]}")
        free_nodes = self._free[self._free < 3 * n_nodes]
        reduced = sp.lil_matrix((matrix.shape[0], self._free.size))
        reduced[:, : free_nodes.size] = matrix.tocsc()[:, free_nodes]
        dense = reduced.toarray()
        # Keep a maximal independent set of rows (pivoted QR of the transpose).
        _, r, pivot = scipy.linalg.qr(dense.T, mode="economic", pivoting=True)
        tolerance = 1e-12 * max(abs(r[0, 0]), 1e-300) if r.size else 0.0
        rank = int(np.count_nonzero(np.abs(np.diag(r)) > tolerance))
        if rank == 0:
            return
        rows = np.sort(pivot[:rank])
        self._constraint = sp.csr_matrix(dense[rows])
        # The residual's projection g − Aᵀ(AAᵀ)⁻¹Ag runs at every assessment: keep A dense (a few
        # rows) with (AAᵀ)⁻¹A beside it, two small dense products instead of sparse ones and a solve.
        self._constraint_dense = np.ascontiguousarray(dense[rows])
        gram = scipy.linalg.cho_factor(dense[rows] @ dense[rows].T)
        self._least_squares_multiplier = scipy.linalg.cho_solve(gram, dense[rows])

    def _spin_gauge(self, held: np.ndarray, moment: np.ndarray) -> np.ndarray:
        """The first edge of every rod whose frames can all turn about their own tangents at no
        energy, and none of whose frames is held already (see :class:`LinearConstraints`).

        Turning every frame of a rod by the same angle about its own d3 (``q ← q ⊗ r_z``) turns
        each joint's ``q̄0 q1`` by a conjugation about z and each edge's strain ``Rᵀ(e/l0 − d3)``
        about z: the energy cannot change when the rod's sections are isotropic (EI1 = EI2; GA is
        one number) and its rest Darboux vectors have no bending part (straight, twisted or not),
        no frame is pinned and no edge carries a moment. Contacts act on nodes only. The Newton
        matrix is then singular along that spin and Levenberg–Marquardt damping alone lets steps
        turn the frames by radians (the bench's crossing bundle: 0.3–5 rad, steps cut by the
        rotation cap); holding one frame's spin removes the gauge and not the equilibrium.
        """
        m = self.model
        gauge = []
        for rod in range(m.n_rods):
            edges = m.rod_edges(rod)
            joints = slice(int(m.rod_joint_start[rod]), int(m.rod_joint_start[rod + 1]))
            first, stop = edges.start, edges.stop
            if stop == first or np.any(m.edge_pinned[edges]) or np.any((held >= first) & (held < stop)):
                continue
            if np.any(moment[edges] != 0.0):
                continue
            stiffness = m.joint_stiffness[joints]
            if np.any(stiffness[:, 0] != stiffness[:, 1]) or np.any(m.joint_rest_darboux[joints, 1:3] != 0.0):
                continue
            gauge.append(first)
        return np.array(gauge, dtype=np.int64)

    def _step_constraints(self, quaternion: np.ndarray) -> sp.csr_matrix | None:
        """Rows every step must satisfy with zero right-hand side: the position constraints and,
        for each spin-held edge, ``d3 · θ = 0`` on its rotation at the current frames."""
        blocks = [] if self._constraint is None else [self._constraint]
        if self._spin_edges.size:
            n_spin = self._spin_edges.size
            d3 = quaternion_d3(quaternion[self._spin_edges])
            dofs = 3 * self.model.n_nodes + 3 * self._spin_edges[:, None] + np.arange(3)
            blocks.append(sp.csr_matrix((d3.ravel(), (np.repeat(np.arange(n_spin), 3), self._dof_map[dofs].ravel())),
                                        shape=(n_spin, self._free.size)))
        if not blocks:
            return None
        return blocks[0] if len(blocks) == 1 else sp.vstack(blocks).tocsr()

    def _project(self, free_gradient: np.ndarray) -> np.ndarray:
        """The part of a free-DOF gradient the constraints do not balance (``g − Aᵀμ``, μ least
        squares)."""
        if self._constraint is None:
            return free_gradient
        mu = self._least_squares_multiplier @ free_gradient
        return free_gradient - self._constraint_dense.T @ mu

    # -- public -------------------------------------------------------------------------------

    def solve(
        self,
        state: RodState,
        loads: Loads | None = None,
        callback: Callable[[Progress], None] | None = None,
        constraints: LinearConstraints | None = None,
        friction: FrictionAnchors | None = None,
        contacts: ContactSet | None = None,
    ) -> QuasiStaticResult:
        """Equilibrium of ``state`` under ``loads`` (and ``constraints``, which ``state`` must
        satisfy), with the lagged ``friction`` anchors' potential added when given
        (:mod:`yarnfit.engine.friction`). ``contacts``: a previous solve's
        :attr:`QuasiStaticResult.contacts` whose multipliers and penalties this one starts from,
        for a ``state`` near that solution (default: every multiplier from zero). Warns
        :class:`ConvergenceWarning` when the tolerances are not met within the iteration limit;
        ``callback(progress)`` is called after every iteration with a :class:`Progress`."""
        model, opt = self.model, self.options
        state.check(model)
        loads = loads if loads is not None else Loads.zeros(model)
        loads.check(model)
        if friction is not None and len(friction) and int(friction.nodes.max()) >= model.n_nodes:
            raise ValueError(f"friction anchors name node {int(friction.nodes.max())}; the model has {model.n_nodes}")
        self._friction = friction if friction is not None and len(friction) else None
        self._set_constraints(constraints)
        self._spin_edges = np.union1d(self._spin_edges, self._spin_gauge(self._spin_edges, loads.edge_moment))
        work = _Work(
            position=np.array(state.node_position, dtype=np.float64),
            quaternion=np.array(state.edge_quaternion, dtype=np.float64),
        )
        lagrangian = ContactLagrangian(model, opt)
        if contacts is not None:
            lagrangian.remember(contacts)
        history: list[Residual] = []
        total_iterations = 0
        converged = False
        for step in range(1, opt.load_steps + 1):
            step_loads = loads.scaled(step / opt.load_steps)
            converged, iterations = self._solve_step(work, lagrangian, step_loads, history, callback, total_iterations)
            total_iterations += iterations
        residual = history[-1]
        forces = internal_forces(model, work.position, work.quaternion)
        external = -float(np.sum(loads.total_node_force(model) * (work.position - model.node_rest_position)))
        stretch, shear, bend, twist = forces.terms
        terms = EnergyTerms(stretch=stretch, shear=shear, bend=bend, twist=twist, external=external - work.moment_work)
        if not converged:
            warnings.warn(
                f"quasi-static solve did not converge in {total_iterations} iterations: {residual} "
                f"(tolerances: force {opt.force_tolerance:.1e}, torque {opt.torque_tolerance:.1e}, "
                f"energy {opt.energy_tolerance:.1e}, penetration {opt.penetration_tolerance:.1e})",
                ConvergenceWarning,
                stacklevel=2,
            )
        pair_force = work.contacts.per_pair_sum(work.contact_force)
        touching = pair_force > 0.0
        n3 = 3 * model.n_nodes
        reaction_force = np.where(model.node_pinned[:, None], work.gradient[:n3].reshape(-1, 3), 0.0)
        reaction_moment = np.where(model.edge_pinned[:, None], work.gradient[n3:].reshape(-1, 3), 0.0)
        return QuasiStaticResult(
            state=RodState(
                node_position=work.position,
                edge_quaternion=work.quaternion,
                node_velocity=np.zeros_like(work.position),
                edge_angular_velocity=np.zeros((model.n_edges, 3)),
            ),
            converged=converged,
            iterations=total_iterations,
            energy=terms,
            residual=residual,
            contact_pairs=work.contacts.pairs.subset(touching),
            contact_force=pair_force[touching],
            reaction_force=reaction_force,
            reaction_moment=reaction_moment,
            history=history,
            contacts=lagrangian.query(work.position, slack=lagrangian.margin) if opt.contact else work.contacts,
        )

    # -- one load step ------------------------------------------------------------------------

    def _solve_step(self, work, lagrangian: ContactLagrangian, loads, history, callback, iteration_base) -> tuple[bool, int]:
        opt = self.options
        node_force = loads.total_node_force(self.model)
        moment = np.asarray(loads.edge_moment)
        damping = _Damping()
        energy_change = 0.0
        # Augmented Lagrangian: multipliers are updated when the inner problem is solved to the
        # policy's threshold (tightening per update), and never twice without a Newton step.
        lagrangian.restart()
        stepped = True
        for it in range(opt.max_iterations + 1):
            ev = self._evaluate(work, lagrangian, node_force, moment, energy_change)
            history.append(ev.residual)
            if callback is not None:
                callback(Progress(iteration_base + it, ev.residual, work.position, ev.potential))
            if ev.residual.within(opt):
                return True, it
            if it == opt.max_iterations:
                return False, it
            if stepped and lagrangian.due(ev.residual):
                lagrangian.update(work.contacts, ev.contact_gap, work.contact_force, ev.residual)
                energy_change = 0.0
                stepped = False
                continue
            stepped = True
            direction, solve, curvature = self._newton_direction(work, ev, damping)
            if direction is None:
                return False, it
            alpha, energy_change = self._line_search(work, lagrangian, ev, direction, solve, curvature, node_force,
                                                     moment, damping)
            if alpha == 0.0:
                # No decrease is possible any more; report the residuals of the current state.
                ev = self._evaluate(work, lagrangian, node_force, moment, 0.0)
                history.append(ev.residual)
                return ev.residual.within(opt), it + 1
        return False, opt.max_iterations

    # -- evaluation ---------------------------------------------------------------------------

    def _evaluate(self, work: _Work, lagrangian: ContactLagrangian, node_force, moment, energy_change) -> _Evaluation:
        """Detect contacts at the current iterate and assess it. After a line search that ended on
        its own segment, its swept pairs are those contacts: every pair within reach of a point on
        the segment is among them, and a pair out of reach adds no force (only its multipliers'
        constant, the same at every point the potential is compared at)."""
        if work.swept is not None and work.swept_evaluation is not None:
            work.contacts = work.swept
            ev = work.swept_evaluation
            ev = dataclasses.replace(ev, residual=dataclasses.replace(ev.residual, energy_change=energy_change))
        else:
            work.contacts = work.swept if work.swept is not None else lagrangian.query(work.position)
            ev = self._assess(work.point, work.contacts, node_force, moment, energy_change)
        work.swept = work.swept_evaluation = None
        work.contact_force = ev.contact_force
        work.gradient = ev.gradient
        return ev

    def _assess(self, point, contacts: ContactSet, node_force, moment, energy_change=0.0) -> _Evaluation:
        """Potential, gradient and residuals of a configuration for a fixed set of contacts."""
        m = self.model
        position, quaternion, moment_work = point
        forces = internal_forces(m, position, quaternion)
        node_gradient = forces.node_gradient - node_force
        edge_gradient = forces.edge_gradient - moment
        node_scale = _kernels.plus_row_norms(forces.node_scale, node_force)
        edge_scale = _kernels.plus_row_norms(forces.edge_scale, moment)
        n_pairs = len(contacts.pairs)
        gap = np.empty(contacts.start[-1])
        contact_force = np.empty(contacts.start[-1])
        contact_energy = 0.0
        if n_pairs:
            contact_energy = _contact_kernels.contact_energy_gradient(
                position, m.edge_nodes, m.edge_radius, *contacts.kernel_args(), node_gradient,
                node_scale, gap, contact_force,
            )
        friction_energy = 0.0
        if self._friction is not None:
            friction_energy = _friction_kernels.friction_energy_gradient(
                position, *self._friction.kernel_args(), node_gradient, node_scale, np.empty(len(self._friction)))
        # A torque τ on an edge is carried by forces τ / l0 on its nodes, and a force F on a node
        # makes torques F l0 on its edges: each scale includes the other's equivalent, so that
        # pure-moment and pure-force problems have meaningful scales for both residuals.
        force_scale, torque_scale = _kernels.residual_scales(node_scale, edge_scale, m.edge_nodes, m.edge_rest_length)
        gradient = np.concatenate([node_gradient.ravel(), edge_gradient.ravel()])
        unbalanced = gradient
        if self._constraint is not None:
            unbalanced = np.zeros_like(gradient)
            unbalanced[self._free] = self._project(gradient[self._free])
        n3 = 3 * m.n_nodes
        net_node = unbalanced[:n3].reshape(-1, 3)
        net_edge = unbalanced[n3:].reshape(-1, 3)
        net_force = float(_kernels.largest_row_norm(net_node, self._node_free))
        net_torque = float(_kernels.largest_row_norm(net_edge, self._edge_free))
        roundoff = ROUNDOFF_FACTOR * np.finfo(float).eps * float(np.abs(position).max(initial=0.0))
        penetration, separation = contacts.measures(gap, contact_force)

        def relative(value: float, scale: float) -> float:
            return value / scale if scale > 0.0 else 0.0

        residual = Residual(
            force=relative(net_force, force_scale),
            torque=relative(net_torque, torque_scale),
            energy_change=energy_change,
            penetration=penetration,
            separation=separation,
            force_floor=relative(roundoff * self._largest_node_stiffness, force_scale),
            torque_floor=relative(roundoff * self._largest_edge_stiffness, torque_scale),
        )
        internal = sum(forces.terms)
        potential = (
            internal + contact_energy + friction_energy
            - float(np.sum(node_force * (position - m.node_rest_position))) - moment_work
        )
        return _Evaluation(
            gradient=gradient,
            potential=potential,
            internal=internal,
            contact_force=contact_force,
            contact_gap=gap,
            residual=residual,
        )

    # -- Newton step --------------------------------------------------------------------------

    def _hessian(self, work: _Work) -> tuple[sp.csc_matrix, np.ndarray]:
        """Hessian of the potential on the free DOFs at the current iterate (CSC, canonical, every
        diagonal entry stored: the damping goes there) and the positions of its diagonal entries."""
        m, opt = self.model, self.options
        c = work.contacts
        friction = self._friction
        n_free = self._free.size
        # The rods' triplets land where they did last time: summed into their fixed pattern
        # without sorting (a sixth of the twill warp strip's Newton iteration went to sorting them).
        rods = self._rod_hessian
        count = _kernels.rod_hessian_coo(work.position, work.quaternion, m.arrays, opt.fd_relative_step, rods.rows,
                                         rods.cols, rods.vals)
        if rods.slot is None:
            rods.indptr, rods.indices, rods.slot = _kernels.csc_slots(rods.rows, rods.cols, count, self._dof_map,
                                                                      n_free)
            rods.data = np.empty(rods.indices.size)
        _kernels.scatter_add(rods.slot, rods.vals, count, rods.data)
        # The contacts' and the friction anchors' triplets, whose pattern changes with the pairs.
        n_anchors = 0 if friction is None else len(friction)
        n_entries = 144 * (len(c.pairs) + n_anchors)
        rows = np.empty(n_entries, dtype=np.int64)
        cols = np.empty(n_entries, dtype=np.int64)
        vals = np.empty(n_entries)
        count = 0
        if len(c.pairs):
            count = _contact_kernels.contact_hessian_coo(
                work.position, m.edge_nodes, m.edge_radius, *c.kernel_args(),
                rows, cols, vals, count,
            )
        if friction is not None:
            count = _friction_kernels.friction_hessian_coo(work.position, *friction.kernel_args(), rows, cols, vals,
                                                           count)
        pairs = _kernels.assemble_node_blocks(rows, cols, vals, count, self._dof_map, n_free, m.n_nodes)
        indptr, indices, data, diagonal = _kernels.add_csc(rods.indptr, rods.indices, rods.data, *pairs)
        hessian = sp.csc_matrix((data, indices.astype(np.int32), indptr.astype(np.int32)), shape=(n_free, n_free))
        hessian.has_canonical_format = True
        return hessian, diagonal

    def _newton_direction(self, work: _Work, ev: _Evaluation, damping: _Damping):
        """Levenberg–Marquardt direction d on the free DOFs, the factorised matrix's solve and the
        model's curvature ``dᵀ H d`` along d (undamped H); ``(None, None, 0)`` when no descent
        direction is found. Raises ``damping`` until the matrix is regular and d descends."""
        if self._free.size == 0:
            return None, None, 0.0
        hessian, on_diagonal = self._hessian(work)
        g = ev.gradient[self._free]
        diag = hessian.data[on_diagonal].copy()
        floor = 1e-12 * max(float(np.abs(diag).max(initial=0.0)), 1e-300)
        scale = np.maximum(np.abs(diag), floor)
        a = self._step_constraints(work.quaternion)
        for _ in range(20):
            # Damped in place (the solve keeps its own arrays) and undamped again for the curvature.
            hessian.data[on_diagonal] = diag + damping.value * scale
            try:
                solve = SymmetricSolve(hessian, a, work.factors)
                d = solve(-g)
            except SingularSystemError:  # exactly singular: damp harder
                damping.harden()
                continue
            finally:
                hessian.data[on_diagonal] = diag
            if np.all(np.isfinite(d)) and float(g @ d) < 0.0:
                with np.errstate(over="ignore", invalid="ignore"):  # a step beyond every cap
                    curvature = float(d @ (hessian @ d))
                return d, solve, curvature
            damping.harden()
        return None, None, 0.0

    def _split(self, free_step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Free-DOF vector → node displacements ``(N, 3)`` and frame rotations ``(E, 3)``."""
        m = self.model
        full = np.zeros(3 * (m.n_nodes + m.n_edges))
        full[self._free] = free_step
        return full[: 3 * m.n_nodes].reshape(-1, 3), full[3 * m.n_nodes :].reshape(-1, 3)

    def _moved(self, point, moment, step_x: np.ndarray, step_theta: np.ndarray):
        position, quaternion, moment_work = point
        return (position + step_x, _rotate_frames(quaternion, step_theta),
                moment_work + float(np.sum(moment * step_theta)))

    def _line_search(self, work, lagrangian: ContactLagrangian, ev, direction, solve, curvature, node_force, moment,
                     damping: _Damping):
        """Backtracking Armijo line search along ``direction``, then chord steps; moves ``work``,
        updates ``damping`` from the step (``curvature`` is the model's ``dᵀ H d``) and returns
        ``(step length, relative potential change)`` (step length 0: no decrease was found)."""
        m, opt = self.model, self.options
        dx, dtheta = self._split(direction)
        alpha_max = 1.0
        rot = float(np.linalg.norm(dtheta, axis=1).max(initial=0.0))
        if rot > opt.max_rotation_step:
            alpha_max = opt.max_rotation_step / rot
        reach = alpha_max * float(np.linalg.norm(dx, axis=1).max(initial=0.0))
        if reach > self._max_displacement:
            alpha_max *= self._max_displacement / reach
        contacts = work.contacts
        slack = math.inf  # no contacts: chord steps go as far as they decrease the potential
        if opt.contact:
            # Pairs that may push anywhere along the step or within a chord step's allowance of
            # its end, and a cap so that none passes through another.
            slack = min(CHORD_SLACK * float(m.edge_radius.min()), max(0.0, lagrangian.margin - lagrangian.reach))
            contacts = lagrangian.query(work.position, work.position + alpha_max * dx, slack=slack)
            if len(contacts.pairs):
                alpha_max *= _contact_kernels.tunneling_step_limit(
                    work.position, alpha_max * dx, m.edge_nodes, *contacts.pairs.kernel_args(), TUNNELING_FRACTION,
                )

        def assess(point):
            return self._assess(point, contacts, node_force, moment)

        # The current iterate's potential with the swept contacts: the evaluation's own, corrected
        # by the pairs only one of the two sets has. Most sweeps add pairs, and assessing the
        # iterate again was a fifth of a stockinette sample's evaluations.
        start = ev.potential + exchanged_potential(m, work.position, contacts, work.contacts)
        g_dot_d = float(ev.gradient[self._free] @ direction)
        scale = max(abs(start), abs(ev.internal), 1e-300)

        def below_roundoff(alpha: float) -> bool:
            # The step's predicted decrease is below the potential's round-off: Armijo compares noise.
            return abs(alpha * g_dot_d) < POTENTIAL_ROUNDOFF * scale

        def acceptable(trial: float, alpha: float) -> bool:
            return below_roundoff(alpha) or trial <= start + ARMIJO_SLOPE * alpha * g_dot_d

        def accept(point, trial: _Evaluation, alpha: float, on_segment: bool = True):
            work.position, work.quaternion, work.moment_work = point
            work.swept = contacts if on_segment and opt.contact else None
            work.swept_evaluation = trial if work.swept is not None else None
            change = abs(trial.potential - start) / max(abs(trial.potential), abs(start), abs(ev.internal), 1e-300)
            return alpha, change

        point = self._moved(work.point, moment, alpha_max * dx, alpha_max * dtheta)
        trial = assess(point)
        if below_roundoff(alpha_max):
            # The step is taken whole, and the imbalance judges the model instead (see NOISE_DAMPING).
            damping.reached_roundoff()
            if _imbalance(trial) >= _imbalance(ev):
                damping.raise_by(NOISE_DAMPING)
            else:
                damping.succeeded(1.0)
            return accept(point, trial, alpha_max)
        if acceptable(trial.potential, alpha_max):
            if alpha_max < 1.0:
                damping.failed()
            else:
                predicted = -(g_dot_d + 0.5 * curvature)
                gain = 1.0 if below_roundoff(1.0) or not predicted > 0.0 else (start - trial.potential) / predicted
                damping.succeeded(gain)
            whole = point
            point, trial = self._chord_steps(point, trial, solve, contacts, lagrangian, node_force, moment, slack)
            return accept(point, trial, alpha_max, on_segment=point is whole)
        damping.failed()
        alpha = 0.5 * alpha_max
        while alpha > 1e-12 * alpha_max:
            point = self._moved(work.point, moment, alpha * dx, alpha * dtheta)
            trial = assess(point)
            if acceptable(trial.potential, alpha):
                return accept(point, trial, alpha)
            alpha *= 0.5
        damping.harden()
        return 0.0, 0.0

    def _chord_steps(self, point, trial: _Evaluation, solve, contacts: ContactSet, lagrangian: ContactLagrangian,
                     node_force, moment, slack: float):
        """Further steps with the same factorisation while each decreases the potential.

        ``contacts`` hold every pair that can push within ``slack / 2`` (m) of ``point``'s nodes
        (``inf`` without contact): a step that would move a node further looks again along its own
        way, and the potential it is compared with gains the pairs found and loses those left
        (none of which can push at the point it starts from: only their constants differ)."""
        start = point[0]
        for _ in range(CHORD_STEPS):
            g = trial.gradient[self._free]
            step = -solve(g)
            slope = float(g @ step)
            if not np.all(np.isfinite(step)) or slope >= 0.0:
                break
            cx, ctheta = self._split(step)
            if (float(np.linalg.norm(ctheta, axis=1).max(initial=0.0)) > self.options.max_rotation_step
                    or float(np.linalg.norm(cx, axis=1).max(initial=0.0)) > self._max_displacement):
                break
            candidate = self._moved(point, moment, cx, ctheta)
            current = trial.potential
            if math.sqrt(_contact_kernels.largest_squared_move(start, candidate[0])) > 0.5 * slack:
                along = lagrangian.query(point[0], candidate[0], slack=slack)
                current += exchanged_potential(self.model, point[0], along, contacts)
                contacts, start = along, candidate[0]
            result = self._assess(candidate, contacts, node_force, moment)
            if result.potential > current + ARMIJO_SLOPE * slope:
                break
            point, trial = candidate, result
        return point, trial


def _imbalance(evaluation: _Evaluation) -> float:
    """The larger of the relative force and torque imbalances of an evaluation."""
    return max(evaluation.residual.force, evaluation.residual.torque)


def _rotate_frames(quaternion: np.ndarray, theta: np.ndarray) -> np.ndarray:
    out = np.empty_like(quaternion)
    _kernels.rotate_frames(quaternion, theta, out)
    return out
