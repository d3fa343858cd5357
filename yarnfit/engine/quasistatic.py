"""Quasi-static equilibrium of a rod model: minimise the discrete energy until the residuals are
below tolerance.

Why not XPBD iterations: the fixed point of XPBD pseudo-time stepping is biased towards the soft
side unless the pseudo step is tiny (a tip-loaded cantilever, PL²/EI = 2, 20 edges: v/L = 0.779 at
Δt = 1 and 0.501 at Δt = 0.1 against the discrete minimum 0.467; ``docs/design.md`` §5). The
solver here is a damped Newton method on the exact energy of :mod:`yarnfit.engine.energy`:

- degrees of freedom: free node positions and world rotation vectors of free edge frames
  (``q ← exp(θ) ⊗ q``);
- Hessian: analytic for stretch–shear elements, central differences of the analytic gradient for
  bend–twist and contact elements; assembled sparse and factorised with SuperLU;
  Levenberg–Marquardt damping ``μ diag(H)`` keeps every step a descent direction where the
  Hessian is indefinite;
- backtracking (Armijo) line search on the total potential, then a few chord steps with the same
  factorisation; a step never brings two segments closer than a tenth of their distance, so yarns
  cannot pass through each other;
- slender rods converge more slowly (Newton's quadratic model misses the quartic stretch energy
  of a rotating edge: L/r = 100 takes ~20 iterations for a large-deflection cantilever, L/r = 1000
  ~100); ``load_steps`` splits strongly nonlinear loads;
- contact: the unilateral constraint ``g ≥ 0`` by an augmented Lagrangian (multiplier updates
  drive the penetration below ``penetration_tolerance``). Friction does no work in a minimisation;
  the frictionless minimiser is an equilibrium of the frictional problem too (zero tangential force
  is inside every Coulomb cone), and it is the reproducible one. Frictional paths are for the
  dynamic :class:`~yarnfit.engine.xpbd.XPBDSolver`.

Convergence is declared only when the force and torque imbalances (relative to the load scale),
the relative energy change of the last step and the contact penetration are all below tolerance.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import _contact_kernels, _kernels
from .energy import EnergyTerms, internal_forces
from .model import CONTACT_EXCLUSION_FACTOR, RodModel
from .state import Loads, RodState


# Sufficient-decrease constant of the Armijo line search (the usual 1e-4 of Nocedal & Wright).
ARMIJO_SLOPE = 1e-4
# Chord (lagged-Hessian) steps tried after each accepted Newton step while they decrease the
# potential: each costs one gradient and one back-substitution; on slender rods they cut the
# iteration count by a fifth to a third (cantilever L/r = 100: 32 → 20 iterations).
CHORD_STEPS = 3
# Round-off floor of a residual, in units of one rounding of the largest coordinate times the
# stiffness: the strain's subtraction and the sums over a node's elements add a few roundings more.
ROUNDOFF_FACTOR = 10.0
# A step never moves two segments closer by more than this fraction of their current centreline
# distance, so yarns cannot pass through each other between two contact checks.
TUNNELING_FRACTION = 0.9
# Levenberg–Marquardt damping never drops below this fraction of diag(H): far below the Hessian's
# own finite-difference error (~1e-10 relative), so it never biases a converged Newton step.
MIN_DAMPING = 1e-12


class ConvergenceWarning(UserWarning):
    """A solver stopped before its residuals met the tolerances."""


@dataclass
class QuasiStaticOptions:
    """Tolerances and limits of :class:`QuasiStaticSolver`.

    Attributes:
        force_tolerance: max |net force| on a free node over the force scale (the largest sum of
            force magnitudes acting on any node).
        torque_tolerance: the same for torques on free edge frames.
        energy_tolerance: |ΔΠ| of the last step over max(|Π|, internal energy).
        penetration_tolerance: max contact penetration over (ra + rb).
        max_iterations: Newton iterations per load step.
        load_steps: the loads are applied in this many equal increments, each solved to
            convergence (helps strongly nonlinear problems such as a rod rolled into a ring).
        contact: detect and resolve yarn–yarn contact.
        contact_stiffness: augmented-Lagrangian penalty (N/m); default ``EA / (ra + rb)`` of the
            stiffer edge of each pair (a yarn piece one diameter long pressed end on).
        contact_margin: broad-phase margin in units of the smallest radius.
        max_rotation_step: largest frame rotation per iteration (rad).
        fd_relative_step: central-difference step of the element Hessians (relative to l0; rad).
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
        if self.contact_stiffness is not None and not (math.isfinite(self.contact_stiffness) and self.contact_stiffness > 0):
            raise ValueError(f"QuasiStaticOptions.contact_stiffness must be positive, got {self.contact_stiffness!r}")


@dataclass
class Residual:
    """Convergence measures of a quasi-static state (all dimensionless).

    ``force_floor`` and ``torque_floor`` estimate the smallest imbalance float64 can resolve for
    this stiffness and load (positions are known to ``ε |x|``, so an edge force only to
    ``ε |x| EA / l0``), relative to the same scales. A tolerance below the floor is unreachable; the
    floor then takes its place and the result says so.
    """

    force: float
    torque: float
    energy_change: float
    penetration: float
    force_floor: float = 0.0
    torque_floor: float = 0.0

    def within(self, options: QuasiStaticOptions) -> bool:
        return (
            self.force <= max(options.force_tolerance, self.force_floor)
            and self.torque <= max(options.torque_tolerance, self.torque_floor)
            and self.energy_change <= options.energy_tolerance
            and self.penetration <= options.penetration_tolerance
        )

    def __str__(self) -> str:
        text = (
            f"force {self.force:.2e}, torque {self.torque:.2e}, energy change {self.energy_change:.2e}, "
            f"penetration {self.penetration:.2e}"
        )
        return text + f" (round-off floors: force {self.force_floor:.1e}, torque {self.torque_floor:.1e})"


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
        contact_pairs: ``(P, 2)`` edge pairs touching at the end.
        contact_force: ``(P,)`` their normal forces (N).
        history: the residual of every iteration.
    """

    state: RodState
    converged: bool
    iterations: int
    energy: EnergyTerms
    residual: Residual
    contact_pairs: np.ndarray
    contact_force: np.ndarray
    history: list = field(default_factory=list)


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
        self._min_radius = float(model.edge_radius.min())
        # Axial stiffness seen by each node (N/m) and carried by each edge (N), for round-off floors.
        edge_stiffness = np.maximum(model.edge_stretch_stiffness, model.edge_shear_stiffness)
        self._node_stiffness = np.zeros(n)
        np.add.at(self._node_stiffness, model.edge_nodes.ravel(), np.repeat(edge_stiffness / model.edge_rest_length, 2))
        self._edge_stiffness = edge_stiffness

    # -- public -------------------------------------------------------------------------------

    def solve(
        self,
        state: RodState,
        loads: Loads | None = None,
        callback: Callable[[int, Residual], None] | None = None,
    ) -> QuasiStaticResult:
        """Equilibrium of ``state`` under ``loads``. Warns :class:`ConvergenceWarning` when the
        tolerances are not met within the iteration limit; ``callback(iteration, residual)`` is
        called after every iteration (for progress displays)."""
        model, opt = self.model, self.options
        state.check(model)
        loads = loads if loads is not None else Loads.zeros(model)
        loads.check(model)
        work = _Work(
            position=np.array(state.node_position, dtype=np.float64),
            quaternion=np.array(state.edge_quaternion, dtype=np.float64),
        )
        history: list[Residual] = []
        total_iterations = 0
        converged = False
        for step in range(1, opt.load_steps + 1):
            step_loads = loads.scaled(step / opt.load_steps)
            converged, iterations = self._solve_step(work, step_loads, history, callback, total_iterations)
            total_iterations += iterations
        residual = history[-1]
        result_state = RodState(
            node_position=work.position,
            edge_quaternion=work.quaternion,
            node_velocity=np.zeros_like(work.position),
            edge_angular_velocity=np.zeros((model.n_edges, 3)),
        )
        forces = internal_forces(model, work.position, work.quaternion)
        external = -float(np.sum(loads.total_node_force(model) * (work.position - model.node_rest_position)))
        external -= work.moment_work
        stretch, shear, bend, twist = forces.terms
        terms = EnergyTerms(stretch=stretch, shear=shear, bend=bend, twist=twist, external=external)
        touching = work.contact_force > 0.0
        if not converged:
            warnings.warn(
                f"quasi-static solve did not converge in {total_iterations} iterations: {residual} "
                f"(tolerances: force {opt.force_tolerance:.1e}, torque {opt.torque_tolerance:.1e}, "
                f"energy {opt.energy_tolerance:.1e}, penetration {opt.penetration_tolerance:.1e})",
                ConvergenceWarning,
                stacklevel=2,
            )
        return QuasiStaticResult(
            state=result_state,
            converged=converged,
            iterations=total_iterations,
            energy=terms,
            residual=residual,
            contact_pairs=work.pairs[touching],
            contact_force=work.contact_force[touching],
            history=history,
        )

    # -- one load step ------------------------------------------------------------------------

    def _solve_step(self, work, loads, history, callback, iteration_base) -> tuple[bool, int]:
        opt = self.options
        node_force = loads.total_node_force(self.model)
        moment = np.asarray(loads.edge_moment)
        damping = 1e-8  # initial Levenberg–Marquardt damping, relative to diag(H)
        energy_change = 0.0
        for it in range(opt.max_iterations + 1):
            ev = self._evaluate(work, node_force, moment)
            residual = ev.residual(energy_change)
            history.append(residual)
            if callback is not None:
                callback(iteration_base + it, residual)
            if residual.within(opt):
                return True, it
            if it == opt.max_iterations:
                return False, it
            balanced = (ev.force_residual <= max(opt.force_tolerance, ev.force_floor)
                        and ev.torque_residual <= max(opt.torque_tolerance, ev.torque_floor))
            if balanced and ev.penetration > opt.penetration_tolerance:
                # Augmented-Lagrangian update: the current contact forces become the multipliers.
                self._update_multipliers(work)
                energy_change = 0.0
                continue
            direction, solve, damping = self._newton_direction(work, ev, damping)
            if direction is None:
                return False, it
            alpha, energy_change, damping = self._line_search(work, ev, direction, solve, node_force, moment, damping)
            if alpha == 0.0:
                # No decrease is possible any more; report the residuals of the current state.
                ev = self._evaluate(work, node_force, moment)
                history.append(ev.residual(energy_change))
                return history[-1].within(opt), it + 1
        return False, opt.max_iterations

    # -- evaluation ---------------------------------------------------------------------------

    def _detect(self, position: np.ndarray, position_end: np.ndarray | None = None) -> np.ndarray:
        """Candidate contact pairs near ``position`` or anywhere on the way to ``position_end``."""
        m = self.model
        if not self.options.contact:
            return np.empty((0, 2), dtype=np.int64)
        end = position if position_end is None else np.ascontiguousarray(position_end)
        return _contact_kernels.broad_phase(
            position, end, m.edge_nodes, m.edge_offset, m.edge_radius, m.edge_rod, m.edge_arc_start,
            m.edge_rest_length, m.rod_length, m.rod_closed, self._node_free,
            self.options.contact_margin * self._min_radius, CONTACT_EXCLUSION_FACTOR,
        )

    def _pair_stiffness(self, pairs: np.ndarray) -> np.ndarray:
        m = self.model
        if len(pairs) == 0:
            return np.empty(0)
        if self.options.contact_stiffness is not None:
            return np.full(len(pairs), float(self.options.contact_stiffness))
        ea = np.maximum(m.edge_stretch_stiffness[pairs[:, 0]], m.edge_stretch_stiffness[pairs[:, 1]])
        return ea / (m.edge_radius[pairs[:, 0]] + m.edge_radius[pairs[:, 1]])

    def _evaluate(self, work: "_Work", node_force: np.ndarray, moment: np.ndarray) -> "_Evaluation":
        """Detect contacts at the current iterate and assess it."""
        m = self.model
        work.pairs = self._detect(work.position)
        work.multiplier = work.multipliers_of(work.pairs, m.n_edges)
        work.stiffness = self._pair_stiffness(work.pairs)
        ev = self._assess(work.position, work.quaternion, work.moment_work, work.pairs, work.multiplier,
                          work.stiffness, node_force, moment)
        work.contact_force = ev.contact_force
        return ev

    def _assess(self, position, quaternion, moment_work, pairs, multiplier, stiffness, node_force, moment):
        """Potential, gradient and residuals of a configuration for a fixed set of contact pairs."""
        m = self.model
        forces = internal_forces(m, position, quaternion)
        node_gradient = forces.node_gradient - node_force
        edge_gradient = forces.edge_gradient - moment
        node_scale = forces.node_scale + np.linalg.norm(node_force, axis=1)
        edge_scale = forces.edge_scale + np.linalg.norm(moment, axis=1)
        gap = np.empty(len(pairs))
        contact_force = np.empty(len(pairs))
        contact_energy = 0.0
        penetration = 0.0
        if len(pairs):
            contact_energy = _contact_kernels.contact_energy_gradient(
                position, m.edge_nodes, m.edge_offset, m.edge_radius, pairs, multiplier, stiffness,
                node_gradient, node_scale, gap, contact_force,
            )
            rsum = m.edge_radius[pairs[:, 0]] + m.edge_radius[pairs[:, 1]]
            penetration = float(np.max(-gap / rsum, initial=0.0))
        force_scale = float(node_scale.max(initial=0.0))
        torque_scale = float(edge_scale.max(initial=0.0))
        net_force = np.linalg.norm(node_gradient[self._node_free], axis=1).max(initial=0.0)
        net_torque = np.linalg.norm(edge_gradient[~m.edge_pinned], axis=1).max(initial=0.0)
        internal = sum(forces.terms)
        potential = (
            internal + contact_energy - float(np.sum(node_force * (position - m.node_rest_position))) - moment_work
        )
        roundoff = ROUNDOFF_FACTOR * np.finfo(float).eps * float(np.abs(position).max(initial=0.0))
        force_floor = roundoff * float(self._node_stiffness.max(initial=0.0))
        torque_floor = roundoff * float(self._edge_stiffness.max(initial=0.0))
        return _Evaluation(
            pairs=pairs,
            gradient=np.concatenate([node_gradient.ravel(), edge_gradient.ravel()]),
            potential=potential,
            internal=internal,
            force_residual=net_force / force_scale if force_scale > 0 else 0.0,
            torque_residual=net_torque / torque_scale if torque_scale > 0 else 0.0,
            force_floor=force_floor / force_scale if force_scale > 0 else 0.0,
            torque_floor=torque_floor / torque_scale if torque_scale > 0 else 0.0,
            penetration=penetration,
            contact_force=contact_force,
        )

    def _update_multipliers(self, work: "_Work") -> None:
        work.remember_multipliers(work.contact_force.copy(), self.model.n_edges)

    # -- Newton step --------------------------------------------------------------------------

    def _hessian(self, work: "_Work", pairs: np.ndarray) -> sp.csc_matrix:
        m, opt = self.model, self.options
        n_entries = 81 * m.n_edges + 36 * m.n_joints + 144 * len(pairs)
        rows = np.empty(n_entries, dtype=np.int64)
        cols = np.empty(n_entries, dtype=np.int64)
        vals = np.empty(n_entries)
        count = _kernels.rod_hessian_coo(
            work.position, work.quaternion, m.edge_nodes, m.edge_offset, m.edge_rest_length, m.edge_shear_stiffness,
            m.edge_stretch_stiffness, m.edge_hardening, m.joint_edges, m.joint_rest_darboux, m.joint_rest_length,
            m.joint_stiffness, opt.fd_relative_step, rows, cols, vals,
        )
        if len(pairs):
            count = _contact_kernels.contact_hessian_coo(
                work.position, m.edge_nodes, m.edge_offset, m.edge_radius, pairs, work.multiplier, work.stiffness,
                opt.fd_relative_step, rows, cols, vals, count,
            )
        r = self._dof_map[rows[:count]]
        c = self._dof_map[cols[:count]]
        keep = (r >= 0) & (c >= 0)
        n_free = self._free.size
        return sp.csc_matrix((vals[:count][keep], (r[keep], c[keep])), shape=(n_free, n_free))

    def _newton_direction(self, work, ev, damping):
        """Levenberg–Marquardt direction on the free DOFs and the factorised matrix's solve;
        ``(None, None, damping)`` when no descent direction is found."""
        if self._free.size == 0:
            return None, None, damping
        hessian = self._hessian(work, ev.pairs)
        g = ev.gradient[self._free]
        diag = hessian.diagonal()
        floor = 1e-12 * max(float(np.abs(diag).max(initial=0.0)), 1e-300)
        scale = sp.diags(np.maximum(np.abs(diag), floor))
        for _ in range(20):
            try:
                lu = spla.splu((hessian + damping * scale).tocsc())
                d = -lu.solve(g)
            except RuntimeError:  # exactly singular: damp harder
                damping *= 100.0
                continue
            if np.all(np.isfinite(d)) and float(g @ d) < 0.0:
                return d, lu.solve, damping
            damping *= 100.0
        return None, None, damping

    def _split(self, free_step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Free-DOF vector → node displacements ``(N, 3)`` and frame rotations ``(E, 3)``."""
        m = self.model
        full = np.zeros(3 * (m.n_nodes + m.n_edges))
        full[self._free] = free_step
        return full[: 3 * m.n_nodes].reshape(-1, 3), full[3 * m.n_nodes :].reshape(-1, 3)

    def _line_search(self, work, ev, direction, solve, node_force, moment, damping):
        """Backtracking Armijo line search along ``direction``, then chord steps; moves ``work`` and
        returns ``(step length, relative potential change, damping)`` (step length 0: no decrease
        was found)."""
        m, opt = self.model, self.options
        dx, dtheta = self._split(direction)
        alpha_max = 1.0
        rot = float(np.linalg.norm(dtheta, axis=1).max(initial=0.0))
        if rot > opt.max_rotation_step:
            alpha_max = opt.max_rotation_step / rot
        pairs, multiplier, stiffness = ev.pairs, work.multiplier, work.stiffness
        if opt.contact:
            # Pairs that may touch anywhere along the step, and a cap so that none passes through another.
            pairs = self._detect(work.position, work.position + alpha_max * dx)
            multiplier = work.multipliers_of(pairs, m.n_edges)
            stiffness = self._pair_stiffness(pairs)
            if len(pairs):
                alpha_max *= _contact_kernels.tunneling_step_limit(
                    work.position, alpha_max * dx, m.edge_nodes, m.edge_offset, pairs, TUNNELING_FRACTION
                )

        def assess(point):
            return self._assess(*point, pairs, multiplier, stiffness, node_force, moment)

        def moved(point, step_x, step_theta):
            position, quaternion, moment_work = point
            return (position + step_x, _rotate_frames(quaternion, step_theta),
                    moment_work + float(np.sum(moment * step_theta)))

        start_point = (work.position, work.quaternion, work.moment_work)
        start = assess(start_point).potential
        g_dot_d = float(ev.gradient[self._free] @ direction)
        scale = max(abs(start), abs(ev.internal), 1e-300)

        def acceptable(trial, alpha):
            # Below round-off of the potential the Armijo test is noise; Newton steps are then
            # accepted whole (the gradient, not the energy, measures progress there).
            return abs(alpha * g_dot_d) < 1e-13 * scale or trial <= start + ARMIJO_SLOPE * alpha * g_dot_d

        def accept(point, trial, alpha, damping):
            if hasattr(trial, "potential"):
                trial = trial.potential
            work.position, work.quaternion, work.moment_work = point
            change = abs(trial - start) / max(abs(trial), abs(start), abs(ev.internal), 1e-300)
            return alpha, change, damping

        point = moved(start_point, alpha_max * dx, alpha_max * dtheta)
        trial = assess(point)
        if acceptable(trial.potential, alpha_max):
            return accept(*self._chord_steps(point, trial, solve, assess, moved), alpha_max,
                          max(damping / 10.0, MIN_DAMPING))
        alpha = 0.5 * alpha_max
        while alpha > 1e-12 * alpha_max:
            point = moved(start_point, alpha * dx, alpha * dtheta)
            trial = assess(point).potential
            if acceptable(trial, alpha):
                return accept(point, trial, alpha, damping * 10.0 if alpha < 0.5 * alpha_max else damping)
            alpha *= 0.5
        return 0.0, 0.0, damping * 100.0


    def _chord_steps(self, point, trial, solve, assess, moved):
        """Further steps with the same factorisation while each decreases the potential."""
        for _ in range(CHORD_STEPS):
            g = trial.gradient[self._free]
            step = -solve(g)
            slope = float(g @ step)
            if not np.all(np.isfinite(step)) or slope >= 0.0:
                break
            cx, ctheta = self._split(step)
            if float(np.linalg.norm(ctheta, axis=1).max(initial=0.0)) > self.options.max_rotation_step:
                break
            candidate = moved(point, cx, ctheta)
            result = assess(candidate)
            if result.potential > trial.potential + ARMIJO_SLOPE * slope:
                break
            point, trial = candidate, result
        return point, trial


@dataclass
class _Evaluation:
    pairs: np.ndarray
    gradient: np.ndarray
    potential: float
    internal: float
    force_residual: float
    torque_residual: float
    force_floor: float
    torque_floor: float
    penetration: float
    contact_force: np.ndarray

    def residual(self, energy_change: float) -> Residual:
        return Residual(self.force_residual, self.torque_residual, energy_change, self.penetration,
                        self.force_floor, self.torque_floor)


@dataclass
class _Work:
    """Mutable iterate of a solve: configuration, path-integrated moment work, and the contact
    pairs with their multipliers (remembered by edge pair across broad-phase queries)."""

    position: np.ndarray
    quaternion: np.ndarray
    moment_work: float = 0.0
    pairs: np.ndarray = field(default_factory=lambda: np.empty((0, 2), dtype=np.int64))
    multiplier: np.ndarray = field(default_factory=lambda: np.empty(0))
    stiffness: np.ndarray = field(default_factory=lambda: np.empty(0))
    contact_force: np.ndarray = field(default_factory=lambda: np.empty(0))
    known_keys: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    known_multipliers: np.ndarray = field(default_factory=lambda: np.empty(0))

    def multipliers_of(self, pairs: np.ndarray, n_edges: int) -> np.ndarray:
        """Remembered multipliers of ``pairs`` (0 for pairs never updated)."""
        multiplier = np.zeros(len(pairs))
        if self.known_keys.size and len(pairs):
            keys = pairs[:, 0] * n_edges + pairs[:, 1]
            pos = np.minimum(np.searchsorted(self.known_keys, keys), self.known_keys.size - 1)
            hit = self.known_keys[pos] == keys
            multiplier[hit] = self.known_multipliers[pos[hit]]
        return multiplier

    def remember_multipliers(self, multiplier: np.ndarray, n_edges: int) -> None:
        """Store ``multiplier`` for the current pairs (forgetting pairs no longer detected)."""
        keys = self.pairs[:, 0] * n_edges + self.pairs[:, 1]
        order = np.argsort(keys)
        self.known_keys = keys[order]
        self.known_multipliers = multiplier[order]


def _rotate_frames(quaternion: np.ndarray, theta: np.ndarray) -> np.ndarray:
    out = np.empty_like(quaternion)
    _kernels.rotate_frames(quaternion, theta, out)
    return out
