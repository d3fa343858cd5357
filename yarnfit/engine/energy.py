"""The discrete rod energy and its gradient, evaluated independently of any solver.

``energy`` and ``energy_gradient`` are the reference every solver is checked against: the
quasi-static solver minimises exactly this function, and the XPBD projections are tested to move
along its gradient.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from . import _kernels
from ._quat import quat_log, quat_mul
from .model import RodModel
from .state import Loads, RodState


@dataclass(frozen=True)
class EnergyTerms:
    """Energy split by term (J).

    ``external`` is the potential of the loads, ``−Σ f·(x − X)`` over nodes (weight included)
    minus the work of the edge moments.
    """

    stretch: float = 0.0
    shear: float = 0.0
    bend: float = 0.0
    twist: float = 0.0
    external: float = 0.0

    @property
    def internal(self) -> float:
        """Elastic energy stored in the rods (J)."""
        return self.stretch + self.shear + self.bend + self.twist

    @property
    def total(self) -> float:
        """Total potential energy ``internal + external`` (J)."""
        return self.internal + self.external

    def as_dict(self) -> dict:
        return {**asdict(self), "internal": self.internal, "total": self.total}


@dataclass
class InternalForces:
    """Internal energy terms, gradient and per-entity residual scales of one configuration."""

    terms: tuple  # (stretch, shear, bend, twist), J
    node_gradient: np.ndarray  # (N, 3), N
    edge_gradient: np.ndarray  # (E, 3), N·m
    node_scale: np.ndarray  # (N,), N: sum of magnitudes of the contributions
    edge_scale: np.ndarray  # (E,), N·m


def internal_forces(model: RodModel, position: np.ndarray, quaternion: np.ndarray) -> InternalForces:
    """Internal energy, gradient and residual scales (no validation; for solvers)."""
    node_gradient = np.zeros((model.n_nodes, 3))
    edge_gradient = np.zeros((model.n_edges, 3))
    node_scale = np.zeros(model.n_nodes)
    edge_scale = np.zeros(model.n_edges)
    terms = _kernels.rod_energy_gradient(position, quaternion, model.arrays, node_gradient, edge_gradient,
                                         node_scale, edge_scale)
    return InternalForces(terms, node_gradient, edge_gradient, node_scale, edge_scale)


def element_forces(model: RodModel, position: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """``(E, 3)`` the force (N, world) each edge's stretch–shear element exerts on the edge's start
    node, ``∂U/∂p1 = −∂U/∂p0``: the yarn's tension along the edge plus its shear resultant (the
    element pulls its end node with the opposite force, mapped into the end node's tile). These
    are the only rod forces between nodes, so the rods' force across any cut is their sum over the
    edges the cut crosses."""
    out = np.empty((model.n_edges, 3))
    _kernels.stretch_shear_forces(np.ascontiguousarray(position, dtype=np.float64),
                                  np.ascontiguousarray(quaternion, dtype=np.float64), model.arrays, out)
    return out


def edge_rotation_from_rest(model: RodModel, quaternion: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Rotation vectors ``log(q q̄_rest)`` of the frames of ``edges`` from their rest frames,
    ``(len(edges), 3)`` rad (principal branch, angle ≤ π)."""
    rest = model.edge_rest_quaternion
    out = np.empty((len(edges), 3))
    for k, e in enumerate(edges):
        r = rest[e]
        out[k] = quat_log(quat_mul(tuple(quaternion[e]), (r[0], -r[1], -r[2], -r[3])))
    return out


def external_potential(model: RodModel, state: RodState, loads: Loads) -> float:
    """``−Σ f·(x − X) − Σ M·θ`` (J), with ``X`` the rest positions and ``θ = log(q q̄_rest)`` the
    rotation of each loaded edge frame from its rest frame.

    Edge moments are dead loads about fixed world axes; in general 3D motion their work depends on
    the path. The expression above is their potential while each loaded frame turns about the
    moment's own axis by less than π (then its gradient is exactly ``−M``, the dead load the
    gradient and the solvers use). The quasi-static solver integrates moment work along its path,
    so a full turn (a rod rolled into a ring) is accounted for there.
    """
    force = loads.total_node_force(model)
    value = -float(np.sum(force * (state.node_position - model.node_rest_position)))
    loaded = np.flatnonzero(np.any(loads.edge_moment != 0.0, axis=1))
    if loaded.size:
        rotation = edge_rotation_from_rest(model, state.edge_quaternion, loaded)
        value -= float(np.sum(loads.edge_moment[loaded] * rotation))
    return value


def energy(model: RodModel, state: RodState, loads: Loads | None = None) -> EnergyTerms:
    """Discrete energy of ``state`` split by term (paper Eq. yarn_energy plus load potential).

    Raises ``ValueError`` for a state that does not match the model, non-finite values or
    non-unit quaternions.
    """
    return energy_gradient(model, state, loads)[0]


def energy_gradient(
    model: RodModel, state: RodState, loads: Loads | None = None
) -> tuple[EnergyTerms, np.ndarray, np.ndarray]:
    """Energy terms and the gradient of the total energy.

    Returns ``(terms, node_gradient (N, 3) in N, edge_gradient (E, 3) in N·m)``; the edge
    gradient is the derivative with respect to world-frame rotation vectors ``θ`` acting as
    ``q ← exp(θ) ⊗ q``. Pinned nodes and frames are included (their gradient is the reaction).
    """
    state.check(model)
    if loads is not None:
        loads.check(model)
    forces = internal_forces(model, state.node_position, state.edge_quaternion)
    external = 0.0
    node_gradient = forces.node_gradient
    edge_gradient = forces.edge_gradient
    if loads is not None:
        external = external_potential(model, state, loads)
        node_gradient = node_gradient - loads.total_node_force(model)
        edge_gradient = edge_gradient - loads.edge_moment
    stretch, shear, bend, twist = forces.terms
    terms = EnergyTerms(stretch=stretch, shear=shear, bend=bend, twist=twist, external=external)
    return terms, node_gradient, edge_gradient
