"""XPBD time stepper for rod models: Kugelstadt & Schömer stretch–shear and bend–twist constraints
with compliance, hard unilateral yarn–yarn contact and position-based static/kinetic friction.

Each substep of length h predicts positions and frames (symplectic Euler), resets the
multipliers, projects every constraint ``iterations`` times (Gauss–Seidel colour by colour; the
constraints of one colour in parallel threads when ``parallel`` is set, on one thread otherwise:
the result is the same) and recovers velocities from the position change. This is
the dynamic engine; for equilibria use :class:`~yarnfit.engine.quasistatic.QuasiStaticSolver`,
whose answer does not depend on a step size (``docs/design.md`` §5).

Stiffness needs iterations: Gauss–Seidel resolves a stiff rod's bending only with enough
substeps × iterations, and an under-resolved rod behaves softer than it is (a 0.1 m, r = 1 mm,
E = 1 GPa rod pinned at both ends sags 200× too far at 4 × 10 per ms; 50 × 2 resolves it). Prefer
many substeps with one or two iterations each (Macklin et al. 2019, "Small steps in physics
simulation").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from . import _contact_kernels, _kernels
from .contact import ContactPairs, find_pairs
from .model import RodModel
from .state import Loads, RodState


@dataclass
class XPBDOptions:
    """Settings of :class:`XPBDSolver`.

    Attributes:
        substeps: substeps per :meth:`XPBDSolver.step`.
        iterations: constraint sweeps per substep.
        damping: linear velocity damping rate (1/s); velocities decay by ``exp(−damping h)``.
        contact: resolve yarn–yarn contact.
        static_friction: μs; tangential slip is cancelled while it needs less than μs λn.
        kinetic_friction: μk; sliding contacts lose up to μk times the normal impulse.
        contact_margin: broad-phase margin in units of the smallest radius (pairs are found once
            per substep from the swept boxes of the prediction).
        parallel: project the constraints of one colour in parallel threads (the result is the same
            as on one thread, only faster on several cores).
    """

    substeps: int = 1
    iterations: int = 10
    damping: float = 0.0
    contact: bool = True
    static_friction: float = 0.0
    kinetic_friction: float = 0.0
    contact_margin: float = 1.0
    parallel: bool = False

    def __post_init__(self) -> None:
        for name in ("substeps", "iterations"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"XPBDOptions.{name} must be a positive integer, got {value!r}")
        for name in ("damping", "static_friction", "kinetic_friction", "contact_margin"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"XPBDOptions.{name} must be a finite number >= 0, got {value!r}")


@dataclass
class StepInfo:
    """What the last :meth:`XPBDSolver.step` did: contact pairs checked and touching."""

    candidate_pairs: int
    touching_pairs: int


class XPBDSolver:
    """Extended position-based dynamics for a :class:`RodModel` (see module docstring)."""

    def __init__(self, model: RodModel, options: XPBDOptions | None = None):
        if model.curved:
            # The projections map ghost-edge ends by translation only (their rotation and the
            # frame transport across tile borders live in the quasi-static path).
            raise ValueError("XPBDSolver steps flat models only; use QuasiStaticSolver on a curved tiling")
        self.model = model
        self.options = options or XPBDOptions()
        self._node_inv_mass = np.ascontiguousarray(model.node_inv_mass)
        self._edge_inv_inertia = np.ascontiguousarray(model.edge_inv_inertia)
        # A frame of rotational inertia I is a 4D quaternion particle of mass 4I (q̇ = ½ ω q).
        self._edge_inv_qmass = 0.25 * self._edge_inv_inertia
        self._prev_position = np.empty((model.n_nodes, 3))
        self._prev_quaternion = np.empty((model.n_edges, 4))
        self._lam_edge = np.zeros((model.n_edges, 3))
        self._lam_joint = np.zeros((model.n_joints, 3))
        self._min_radius = float(model.edge_radius.min())
        self._coloring = _color_constraints(model)

    def step(self, state: RodState, loads: Loads | None, dt: float) -> StepInfo:
        """Advance ``state`` in place by ``dt`` seconds."""
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"time step must be positive and finite, got {dt!r}")
        model, opt = self.model, self.options
        state.check(model)
        loads = loads if loads is not None else Loads.zeros(model)
        loads.check(model)
        accel = np.asarray(loads.gravity)[None, :] + loads.node_force / model.node_mass[:, None]
        torque = np.ascontiguousarray(loads.edge_moment, dtype=np.float64)
        h = dt / opt.substeps
        inv_h2 = 1.0 / (h * h)
        x, q = state.node_position, state.edge_quaternion
        v, w = state.node_velocity, state.edge_angular_velocity
        info = StepInfo(0, 0)
        for _ in range(opt.substeps):
            _kernels.predict(x, q, v, w, self._node_inv_mass, self._edge_inv_inertia, accel, torque, h,
                             self._prev_position, self._prev_quaternion)
            self._lam_edge[:] = 0.0
            self._lam_joint[:] = 0.0
            pairs = self._detect(self._prev_position, x)
            lam_normal = np.zeros(len(pairs))
            lam_tangent = np.zeros(len(pairs))
            for _ in range(opt.iterations):
                self._project_rods(x, q, inv_h2)
                if len(pairs):
                    _contact_kernels.project_contacts(
                        x, self._prev_position, self._node_inv_mass, model.edge_nodes, model.edge_radius,
                        *pairs.kernel_args(), lam_normal, lam_tangent, opt.static_friction,
                    )
            _kernels.update_velocities(x, q, v, w, self._node_inv_mass, self._edge_inv_inertia,
                                       self._prev_position, self._prev_quaternion, h, opt.damping)
            if len(pairs) and opt.kinetic_friction > 0.0:
                _contact_kernels.apply_kinetic_friction(x, v, self._node_inv_mass, model.edge_nodes,
                                                        *pairs.kernel_args(), lam_normal, opt.kinetic_friction, h)
            info = StepInfo(len(pairs), int(np.count_nonzero(lam_normal > 0.0)))
        return info

    # -- internals ----------------------------------------------------------------------------

    def _detect(self, start: np.ndarray, end: np.ndarray) -> ContactPairs:
        if not self.options.contact:
            return ContactPairs.empty()
        return find_pairs(self.model, start, self.options.contact_margin * self._min_radius, end)

    def _project_rods(self, x: np.ndarray, q: np.ndarray, inv_h2: float) -> None:
        args = (x, q, self._node_inv_mass, self._edge_inv_qmass, self.model.arrays, self._lam_edge, self._lam_joint,
                inv_h2, *self._coloring)
        if self.options.parallel:
            _kernels.project_rods(*args)
            return
        # The same sweep on one thread (its result does not depend on the thread count).
        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            _kernels.project_rods(*args)
        finally:
            numba.set_num_threads(threads)


def _color_constraints(model: RodModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Constraint orders grouped by colour: ``(edge_order, edge_color_start, joint_order,
    joint_color_start)``. A stretch–shear constraint writes its two nodes and its frame; a
    bend–twist constraint writes two frames."""
    n = model.n_nodes
    edge_resources = np.concatenate([model.edge_nodes, n + np.arange(model.n_edges)[:, None]], axis=1)
    edge_colors = _kernels.greedy_coloring(np.ascontiguousarray(edge_resources), n + model.n_edges)
    joint_colors = _kernels.greedy_coloring(np.ascontiguousarray(model.joint_edges), model.n_edges)

    def group(colors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(colors, kind="stable").astype(np.int64)
        counts = np.bincount(colors, minlength=1) if colors.size else np.zeros(1, dtype=np.int64)
        return order, np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    return (*group(edge_colors), *group(joint_colors))
