"""Coulomb friction for the quasi-static solver, lagged as in Incremental Potential Contact.

A minimiser has no friction path of its own: friction does no work it could minimise. Li et al.
2020 (IPC, §5) make it one for a time step by freezing, at the step's start, each contact's normal
force ``N``, its tangent plane and its contact points, and adding the dissipation potential
``μ N f(|u|)`` of the tangential slip ``u`` since the start (:mod:`yarnfit.engine._friction_kernels`
gives ``f``): a convex term whose minimiser sticks a contact while its tangential force is below
``μ N`` and lets it slide at ``μ N`` beyond. A quasi-static load step is such a step with
displacements for velocities. The frozen quantities are then refreshed from the solution and the
step solved again (IPC's lagged iterations) until the normal forces settle:
:func:`yarnfit.engine.lagged.lagged_solve`.

Each sampled contact constraint carrying force becomes one :class:`FrictionAnchors` entry, so a
line contact's friction is spread over its samples as its normal force is.

What it cannot represent: static friction above kinetic (one μ), and friction on contacts that
appear during a step (they are anchored only at the next lag); a contact that opens keeps its
frozen force for the rest of the pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _contact_kernels, _friction_kernels
from .contact import ContactPairs
from .contact_lagrangian import ContactSet
from .model import RodModel

__all__ = ["FRICTION_SLIP", "FrictionAnchors", "anchor_contacts", "constraint_forces"]

# Slip ε (in sums of radii ra + rb) at which a contact's friction reaches the Coulomb bound μ N;
# below it the contact sticks elastically with stiffness 2 μ N / ε. The model has no tangential
# contact compliance of its own, so ε is numerical: small against the slips a strain step makes
# (a 1 % step moves crossings a repeat apart by ~1 µm; ε is 0.2 µm for a 100 µm-thick yarn pair),
# large enough that the stick stiffness stays within a few orders of the yarns' own. Measured
# (session 32): the cotton twill's cut warp strip (1819 nodes) at 2 % pulls at 814.80 N/m with
# this ε and 815.11 N/m with half of it (0.04 %).
FRICTION_SLIP = 1e-3


@dataclass(frozen=True)
class FrictionAnchors:
    """Contact constraints frozen for friction (``K`` anchors).

    Attributes:
        nodes: ``(K, 4)`` the pair's nodes ``(a0, a1, b0, b1)``.
        weight: ``(K, 4)`` weights of the relative vector ``r = Σ_m w_m (R_m x_m + t_m)`` from the
            point on b to the point on a.
        rotation, translation: ``(K, 4, 3, 3)``, ``(K, 4, 3)`` m: the nodes' tile maps.
        tangent: ``(K, 2, 3)`` orthonormal basis of the contact's tangent plane.
        origin: ``(K, 2)`` m: ``T r`` where the slip is measured from.
        bound: ``(K,)`` N: ``μ N``, the largest friction force of each anchor.
        slip_length: ε (m), the slip at which an anchor's friction reaches its bound.
    """

    nodes: np.ndarray
    weight: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    tangent: np.ndarray
    origin: np.ndarray
    bound: np.ndarray
    slip_length: float

    def __len__(self) -> int:
        return len(self.bound)

    def kernel_args(self) -> tuple:
        """``(nodes, weight, rotation, translation, tangent, origin, bound, slip_length)`` as the
        friction kernels take them."""
        return (self.nodes, self.weight, self.rotation, self.translation, self.tangent, self.origin, self.bound,
                self.slip_length)

    def subset(self, which: np.ndarray) -> "FrictionAnchors":
        """The anchors ``which`` selects (a boolean mask or indices)."""
        return FrictionAnchors(self.nodes[which], self.weight[which], self.rotation[which], self.translation[which],
                               self.tangent[which], self.origin[which], self.bound[which], self.slip_length)

    def transformed(self, matrix: np.ndarray) -> "FrictionAnchors":
        """The anchors with their nodes' tile maps where they are when the whole tiled
        configuration is mapped by the linear ``matrix`` (``(3, 3)``): the translations map, the
        rotations, tangent planes and origins stay (the slip is still measured from the same
        reference). Only for maps that turn nothing, as
        :meth:`~yarnfit.engine.contact.ContactPairs.transformed`: a periodic sample whose free
        strain changes within a frictional load step."""
        matrix = np.asarray(matrix, dtype=np.float64)
        if matrix.shape != (3, 3):
            raise ValueError(f"matrix must be (3, 3), got {matrix.shape}")
        return FrictionAnchors(self.nodes, self.weight, self.rotation,
                               np.ascontiguousarray(self.translation @ matrix.T), self.tangent, self.origin,
                               self.bound, self.slip_length)

    def energy_gradient(self, position: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Friction energy (J) at node positions ``position (N, 3)``, its gradient ``(N, 3)``
        (N) and each anchor's friction force magnitude ``(K,)`` (N)."""
        gradient = np.zeros_like(position)
        force = np.empty(len(self))
        energy = _friction_kernels.friction_energy_gradient(position, *self.kernel_args(), gradient,
                                                            np.zeros(len(position)), force)
        return float(energy), gradient, force


def constraint_forces(model: RodModel, position: np.ndarray, contacts: ContactSet) -> np.ndarray:
    """Normal force (N) of each sampled constraint of ``contacts`` at ``position (N, 3)``."""
    force = np.zeros(contacts.start[-1])
    if len(contacts.pairs):
        _contact_kernels.contact_energy_gradient(
            position, model.edge_nodes, model.edge_radius, *contacts.kernel_args(), np.zeros_like(position),
            np.zeros(len(position)), np.empty(contacts.start[-1]), force)
    return force


def anchor_contacts(model: RodModel, position: np.ndarray, contacts: ContactSet, reference: np.ndarray,
                    coefficient: float, slip_length: float | None = None,
                    reference_pairs: ContactPairs | None = None) -> FrictionAnchors:
    """Anchor the loaded constraints of ``contacts`` at ``position (N, 3)`` (m): their contact
    points, tangent planes and normal forces there, their slip measured from where those contact
    points are at ``reference (N, 3)`` (the load step's start). ``coefficient`` μ; ``slip_length``
    ε (m), by default :data:`FRICTION_SLIP` of the mean sum of radii. ``reference_pairs``:
    ``contacts.pairs`` with the tile maps they had at ``reference``, for a periodic sample whose
    tiling was deformed since (its images moved with the macroscopic strain: measured with today's
    maps, a pair across a tile border would slip by the change of a period); default: today's."""
    if not (math.isfinite(coefficient) and coefficient >= 0.0):
        raise ValueError(f"friction coefficient must be finite and non-negative, got {coefficient!r}")
    position = np.ascontiguousarray(position, dtype=np.float64)
    reference = np.ascontiguousarray(reference, dtype=np.float64)
    if reference.shape != position.shape:
        raise ValueError(f"reference positions have shape {reference.shape}, positions {position.shape}")
    if slip_length is None:
        slip_length = FRICTION_SLIP * 2.0 * float(np.mean(model.edge_radius))
    if not (math.isfinite(slip_length) and slip_length > 0.0):
        raise ValueError(f"slip length must be finite and positive, got {slip_length!r}")
    force = constraint_forces(model, position, contacts)
    n = int(np.count_nonzero(force > 0.0)) if coefficient > 0.0 else 0
    nodes = np.empty((n, 4), dtype=np.int64)
    weight = np.empty((n, 4))
    rotation = np.empty((n, 4, 3, 3))
    translation = np.empty((n, 4, 3))
    tangent = np.empty((n, 2, 3))
    origin = np.empty((n, 2))
    normal = np.empty(n)
    if reference_pairs is None:
        reference_pairs = contacts.pairs
    elif reference_pairs.rotation.shape != contacts.pairs.rotation.shape or not np.array_equal(
            reference_pairs.pairs, contacts.pairs.pairs):
        raise ValueError("reference_pairs must be the contacts' own pairs with the maps they had at the reference")
    if n:
        written = _friction_kernels.anchor_constraints(
            position, reference, model.edge_nodes, contacts.edge_samples, *contacts.pairs.kernel_args(),
            reference_pairs.rotation, reference_pairs.translation, contacts.start, force, nodes, weight, rotation,
            translation, tangent, origin, normal)
        assert written == n
    return FrictionAnchors(nodes, weight, rotation, translation, tangent, origin, coefficient * normal,
                           float(slip_length))
