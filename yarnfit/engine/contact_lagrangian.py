"""The quasi-static solver's contact policy: an augmented Lagrangian over sampled constraints.

Each detected pair of edges carries constraints at sample points along both edges (nodes included,
at most :data:`CONTACT_SAMPLE_SPACING` radii apart), each keeping ``ra + rb`` from the other
segment with a multiplier λ (N) and a penalty k (N/m) per pair (the formulation and why it is
smooth: :mod:`yarnfit.engine.quasistatic`). This module owns everything about those constraints
that is not an energy kernel:

- :class:`ContactSet`: one query's pairs, their constraints' layout, multipliers and penalties,
  and the measures of how well they hold (penetration, separation of loaded constraints);
- :class:`ContactLagrangian`: one solve's policy: detecting pairs (with multipliers and penalties
  remembered per pair across queries), when to update the multipliers, and which penalties to
  stiffen when the updates make too little progress.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from . import _contact_kernels
from ._contact_kernels import constraint_measures
from .contact import ContactPairs, ImageMaps, NeighbourList
from .model import RodModel

__all__ = ["CONTACT_SAMPLE_SPACING", "CONTACT_SMOOTHING", "ContactLagrangian", "ContactSet", "contact_potential",
           "exchanged_potential"]

# Contact penalty: each pair starts at EA / (ra + rb) (a yarn under strain ε presses a contact in by
# ~ε of the diameter before the multipliers take the force over). The multiplier iteration removes
# the penetration by a factor ~K / (K + k) per update, K the structure's stiffness at the contact:
# a yarn pressed over a crossing is stiffer than k by ~20 (jersey: 4 % less penetration per
# update). So, as in Bertsekas' method of multipliers, an update that did not cut the worst
# penetration to PENETRATION_PROGRESS of its previous value stiffens the pairs still penetrating
# beyond tolerance tenfold, up to MAX_STIFFENING. Stiffening only at updates, where the iterate is
# balanced: stiffening on any penetration seen mid-solve ratcheted transient overshoots of new
# contacts up to the cap, and Newton then crossed the cap's kinks at every step.
PENETRATION_PROGRESS = 0.25
MAX_STIFFENING = 1e4
# Half-width of the contact ramp's smoothing band, in units of k (ra + rb): the band is ±0.01 % of
# the diameter around λ / k (~1.6e-8 m for a 80 µm yarn), wide against Newton's last corrections
# (~1e-10 m). A touching contact with no multiplier pushes with δ/4 and a lightly loaded one
# rests up to δ/k apart: an unloaded relaxed repeat is then not quite force-free, and the energy
# it releases goes as δ². At 1e-3 the undeformed homogenization sample kept 3e-3 J/m² (3e-6 of a
# 10 % stretch); at 1e-4, 7e-5 J/m², with every relaxation still converging.
CONTACT_SMOOTHING = 1e-4
# Spacing of the contact sample points along an edge, in radii. A crossing between samples is
# seen up to h / 2 off its closest point, which hides h² / (32 r²) of the diameter: 0.2 % here.
CONTACT_SAMPLE_SPACING = 0.25
# Relative allowance on the reach of the constraints (ContactLagrangian.reach) within which pairs
# are queried: the query's distances and the contact kernels' are computed apart, and may differ
# by a few roundings of the coordinates (~1e-19 m), far inside this (~1e-14 m).
REACH_ROUNDING = 1e-6
# Residual below which contact multipliers are first updated: late enough that the forces copied
# into them are close to equilibrium, early enough to spare Newton iterations on a moving target.
# Each update tightens it tenfold (down to the tolerances).
MULTIPLIER_UPDATE_RESIDUAL = 1e-3
# An inner solve that stalls is not waited for: if the imbalance (larger relative force or torque
# residual) has not fallen below STALL_PROGRESS of its best over the STALL_ITERATIONS Newton steps
# before the last STALL_ITERATIONS, the multipliers are updated (and penalties stiffened) anyway,
# as in an inexact method of multipliers. With the penalties too soft for the contacts they hold,
# the inner problem can be too ill-conditioned to balance: HYLC's satin as written (polyester),
# shear +0.4, continuation step 0.875 → 0.9375, crawled at a force imbalance of 2.8e-4 (penetration
# 3 % of the diameter, each step cut by the no-tunnelling cap) and in another run sat at a torque
# imbalance of 1.5e-6 against an update threshold of 1e-7, for 5000 iterations each; one update
# forced after 100 stalled steps let both converge (in 247 and 147 iterations). A converging solve
# halves its imbalance in far fewer than 100 steps, so the rule leaves it alone.
STALL_ITERATIONS = 100
STALL_PROGRESS = 0.5


@dataclass
class ContactSet:
    """Contact pairs of one query with their sampled constraints: pair ``p`` owns constraints
    ``start[p]:start[p + 1]`` (``edge_samples`` points on each of its edges), each with a
    multiplier (N); penalties (N/m: a base value times a remembered stiffening factor) and the sums
    of radii ``radius_sum`` (m) are per pair."""

    pairs: ContactPairs
    edge_samples: np.ndarray
    start: np.ndarray
    multiplier: np.ndarray
    base_stiffness: np.ndarray
    stiffening: np.ndarray
    radius_sum: np.ndarray

    @classmethod
    def none(cls, edge_samples: np.ndarray | None = None) -> "ContactSet":
        """No pairs (``edge_samples`` only travels with the set, to the kernels)."""
        samples = np.zeros(0, dtype=np.int64) if edge_samples is None else edge_samples
        return cls(ContactPairs.empty(), samples, np.zeros(1, dtype=np.int64), np.empty(0), np.empty(0), np.empty(0),
                   np.empty(0))

    def __len__(self) -> int:
        return len(self.pairs)

    @property
    def stiffness(self) -> np.ndarray:
        """Penalty of each pair (N/m)."""
        return self.base_stiffness * self.stiffening

    @property
    def counts(self) -> np.ndarray:
        """Constraints per pair."""
        return np.diff(self.start)

    def per_constraint(self, values: np.ndarray) -> np.ndarray:
        """A per-pair array repeated over each pair's constraints."""
        return np.repeat(values, self.counts)

    def per_pair_any(self, flags: np.ndarray) -> np.ndarray:
        """Pairs with any constraint flagged."""
        if len(self.pairs) == 0:
            return np.zeros(0, dtype=np.bool_)
        return np.add.reduceat(flags.astype(np.int64), self.start[:-1]) > 0

    def per_pair_sum(self, values: np.ndarray) -> np.ndarray:
        if len(self.pairs) == 0:
            return np.zeros(0)
        return np.add.reduceat(values, self.start[:-1])

    def kernel_args(self) -> tuple:
        """``(edge_samples, pairs, rotation, translation, start, multiplier, stiffness, smoothing)``
        as the contact kernels take them (after the model's edge nodes and radii)."""
        return (self.edge_samples, *self.pairs.kernel_args(), self.start, self.multiplier, self.stiffness,
                CONTACT_SMOOTHING)

    def subset(self, which: np.ndarray) -> "ContactSet":
        """The pairs ``which`` selects (indices, ascending) with their constraints, multipliers and
        penalties: the part of the contact potential they contribute."""
        which = np.asarray(which, dtype=np.int64)
        if np.any(np.diff(which) <= 0):
            raise ValueError("subset takes ascending pair indices, each once")
        kept = np.isin(self.per_constraint(np.arange(len(self))), which)  # in pair order, as ``which``
        return ContactSet(self.pairs.subset(which), self.edge_samples,
                          np.concatenate([[0], np.cumsum(self.counts[which])]).astype(np.int64),
                          self.multiplier[kept], self.base_stiffness[which], self.stiffening[which],
                          self.radius_sum[which])

    def missing_from(self, other: "ContactSet", n_edges: int) -> np.ndarray:
        """Indices of this set's pairs (edges and image) that ``other`` does not have."""
        mine = self.pairs.keys(n_edges)
        if len(other.pairs) == 0:
            return np.arange(mine.size)
        theirs = np.sort(other.pairs.keys(n_edges))
        at = np.minimum(np.searchsorted(theirs, mine), theirs.size - 1)
        return np.flatnonzero(theirs[at] != mine)

    def same_constraints(self, other: "ContactSet") -> bool:
        """The same pairs (with images), multipliers and penalties as ``other``: the contact
        potential is then the same function of the positions."""
        return self is other or (
            len(self.pairs) == len(other.pairs)
            and np.array_equal(self.pairs.pairs, other.pairs.pairs)
            and np.array_equal(self.pairs.images, other.pairs.images)
            and np.array_equal(self.multiplier, other.multiplier)
            and np.array_equal(self.stiffness, other.stiffness))

    def with_base_penalties(self) -> "ContactSet":
        """The same pairs and multipliers (copied) with every penalty back at its base value: how
        a frictional load step (:func:`yarnfit.engine.lagged.lagged_solve`) starts from the last
        one's contacts.

        Penalties are a load step's own; the multipliers carry the contact forces on. Carried over,
        the stiffening ratchets: a new pair starts at the largest factor reached so far
        (``_Memory.recall``), so every contact a later Newton step runs into can be far stiffer
        than the step's model knows, and the line search cuts such steps to a sliver. Within a load
        step (its lagged passes) the penalties are kept: its loads do not change; so does a
        frictionless strip's strain, one large solve that needs the stiffening the last reached.
        The measurements behind both: docs/design.md §5, "Penalties are a frictional load step's
        own"."""
        return replace(self, multiplier=self.multiplier.copy(), stiffening=np.ones_like(self.stiffening))

    def measures(self, gap: np.ndarray, force: np.ndarray) -> tuple[float, float]:
        """``(penetration, separation)`` of constraint gaps ``gap`` (m) and normal forces
        ``force`` (N): the deepest overlap, and the widest gap of a constraint still carrying a
        force above the smoothing band, each over the pair's sum of radii (0 without pairs)."""
        if len(self.pairs) == 0:
            return 0.0, 0.0
        return constraint_measures(gap, force, self.start, self.radius_sum, self.stiffness, CONTACT_SMOOTHING)


def contact_potential(model: RodModel, position: np.ndarray, contacts: ContactSet,
                      pairs: np.ndarray | None = None) -> float:
    """The augmented-Lagrangian contact potential (J) of ``contacts`` (their multipliers and
    penalties held fixed), or of its pairs ``pairs`` (indices) alone, at node positions
    ``position`` ``(N, 3)`` (m): the function whose gradient the quasi-static solver balances
    against the rods' forces. The pairs' image maps are taken as ``contacts`` holds them."""
    which = np.arange(len(contacts.pairs)) if pairs is None else np.asarray(pairs, dtype=np.int64)
    if which.size == 0:
        return 0.0
    return float(_contact_kernels.pairs_energy(np.ascontiguousarray(position, dtype=np.float64), model.edge_nodes,
                                               model.edge_radius, *contacts.kernel_args(), which))


def contact_gradient(model: RodModel, position: np.ndarray, contacts: ContactSet) -> np.ndarray:
    """``(N, 3)`` the gradient (N) of :func:`contact_potential` of ``contacts`` at ``position``
    ``(N, 3)`` (m): minus the contact forces on the nodes."""
    position = np.ascontiguousarray(position, dtype=np.float64)
    gradient = np.zeros_like(position)
    if len(contacts.pairs):
        _contact_kernels.contact_energy_gradient(
            position, model.edge_nodes, model.edge_radius, *contacts.kernel_args(), gradient,
            np.zeros(len(position)), np.empty(contacts.start[-1]), np.empty(contacts.start[-1]))
    return gradient


def exchanged_potential(model: RodModel, position: np.ndarray, new: ContactSet, old: ContactSet) -> float:
    """The contact potential (J) of ``new`` less that of ``old`` at ``position``, where both come
    from one solve's memory (the pairs they share carry the same multipliers and penalties, so
    only the pairs one of them lacks count): what a potential assessed with ``old`` gains when
    assessed with ``new`` instead (0 when they hold the same constraints)."""
    if new.same_constraints(old):
        return 0.0
    n_edges = model.n_edges
    return (contact_potential(model, position, new, new.missing_from(old, n_edges))
            - contact_potential(model, position, old, old.missing_from(new, n_edges)))


class _Memory:
    """Multipliers and penalty factors remembered per edge pair across broad-phase queries (a
    pair's constraint count depends only on its edges, so its multipliers keep their layout).

    Multipliers are those of the last stored set; a pair it does not hold has none (a query holds
    every pair that can push, so one it left out was off its ramp and the update zeroes it).
    Penalty factors outlive the set: a pair that drifts out of reach and back keeps its own,
    rather than coming back as a new pair at the stiffest factor reached (the twill warp strip's
    5 % load step, one lagged solve: 873 Newton iterations, 1391 when they were forgotten)."""

    def __init__(self, n_edges: int):
        self._n_edges = n_edges
        self._keys = np.empty(0, dtype=np.int64)
        self._start = np.zeros(1, dtype=np.int64)
        self._multiplier = np.empty(0)
        self._penalty_keys = np.empty(0, dtype=np.int64)
        self._stiffening = np.empty(0)
        self._level = 1.0
        self.multiplier_reach = 0.0

    def recall(self, pairs: ContactPairs, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(multiplier per constraint, stiffening per pair)`` of ``pairs`` laid out by ``start``.
        New pairs start with no multipliers and at the largest stiffening reached so far: the
        penalty a problem needs is set by its loads, which a pair meeting late carries as well as
        the early ones (seed stitch: new pairs at 1× under 10× neighbours sank 5 % in)."""
        multiplier = np.zeros(start[-1])
        stiffening = np.full(len(pairs), self._level)
        if not len(pairs):
            return multiplier, stiffening
        keys = pairs.keys(self._n_edges)
        pos, hit = _lookup(self._penalty_keys, keys)
        stiffening[hit] = self._stiffening[pos[hit]]
        pos, hit = _lookup(self._keys, keys)
        if hit.size:
            counts = start[hit + 1] - start[hit]
            offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
            multiplier[np.repeat(start[hit], counts) + offsets] = self._multiplier[
                np.repeat(self._start[pos[hit]], counts) + offsets]
        return multiplier, stiffening

    def store(self, contacts: ContactSet) -> None:
        """Remember the multipliers of these pairs (the others' are zero) and their penalties."""
        keys = contacts.pairs.keys(self._n_edges)
        order = np.argsort(keys)
        counts = contacts.counts[order]
        self._keys = keys[order]
        self._start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        source = np.repeat(contacts.start[:-1][order], counts) + (
            np.arange(counts.sum()) - np.repeat(self._start[:-1], counts))
        self._multiplier = contacts.multiplier[source]
        kept = np.ones(self._penalty_keys.size, dtype=np.bool_)  # the penalties of pairs this set lacks
        kept[_lookup(self._keys, self._penalty_keys)[1]] = False
        penalty_keys = np.concatenate([self._penalty_keys[kept], self._keys])
        stiffening = np.concatenate([self._stiffening[kept], contacts.stiffening[order]])
        order = np.argsort(penalty_keys)
        self._penalty_keys, self._stiffening = penalty_keys[order], stiffening[order]
        self._level = max(self._level, float(contacts.stiffening.max(initial=1.0)))
        # The farthest a remembered multiplier pushes beyond its ramp's band: λ / k (m).
        self.multiplier_reach = 0.0
        if len(contacts.pairs):
            largest = np.maximum.reduceat(contacts.multiplier, contacts.start[:-1])
            self.multiplier_reach = float(np.max(largest / contacts.stiffness))


def _lookup(sorted_keys: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(position, hits)``: where each of ``keys`` would sit in ``sorted_keys`` (clipped to its
    last entry) and the indices of the keys found there."""
    if sorted_keys.size == 0:
        return np.zeros(keys.size, dtype=np.int64), np.zeros(0, dtype=np.int64)
    pos = np.minimum(np.searchsorted(sorted_keys, keys), sorted_keys.size - 1)
    return pos, np.flatnonzero(sorted_keys[pos] == keys)


class ContactLagrangian:
    """One solve's contact policy (see the module docstring). ``options`` is the solve's
    :class:`~yarnfit.engine.QuasiStaticOptions`: ``contact`` (off: every query is empty),
    ``contact_margin``, ``contact_stiffness``, the penetration tolerance and the force and torque
    tolerances the update threshold tightens to."""

    def __init__(self, model: RodModel, options) -> None:
        self.model = model
        self.options = options
        # Contact sample points per edge, both nodes included, CONTACT_SAMPLE_SPACING radii apart at most.
        self.edge_samples = 1 + np.maximum(
            1, np.ceil(model.edge_rest_length / (CONTACT_SAMPLE_SPACING * model.edge_radius))).astype(np.int64)
        self._margin = options.contact_margin * float(model.edge_radius.min())
        self._memory = _Memory(model.n_edges)
        # Candidates found once and kept while the nodes stay near (a curved tiling's image maps
        # built once per search range with them, rather than at every query).
        self._neighbours = NeighbourList(model, self._margin, ImageMaps(model))
        self.restart()

    def remember(self, contacts: ContactSet) -> None:
        """Start from ``contacts``' multipliers and penalty factors (a previous solve's
        :attr:`~yarnfit.engine.QuasiStaticResult.contacts`): a warm start for a solve that begins
        near that solution, such as the next lagged friction pass or load step."""
        if len(contacts.pairs):
            if len(contacts.edge_samples) != self.model.n_edges:
                raise ValueError(f"contacts of a model with {len(contacts.edge_samples)} edges cannot start a solve of "
                                 f"one with {self.model.n_edges}")
            self._memory.store(contacts)

    def restart(self) -> None:
        """Start a load step: the update threshold back to MULTIPLIER_UPDATE_RESIDUAL (multipliers
        and penalties are kept)."""
        self._threshold = MULTIPLIER_UPDATE_RESIDUAL
        self._last_violation = math.inf
        self._imbalances: list[float] = []

    @property
    def margin(self) -> float:
        """The broad phase's margin (m): no query holds pairs further apart than it."""
        return self._margin

    @property
    def reach(self) -> float:
        """The widest gap (m) at which a constraint can push now: ``(λ + δ) / k`` over the
        remembered multipliers and penalties, ``δ / k`` for a pair met anew (no multiplier)."""
        return (self._memory.multiplier_reach
                + CONTACT_SMOOTHING * 2.0 * float(self.model.edge_radius.max(initial=0.0))) * (1.0 + REACH_ROUNDING)

    def query(self, position: np.ndarray, position_end: np.ndarray | None = None, slack: float = 0.0) -> ContactSet:
        """The pairs that can push at ``position`` (or anywhere on the way to ``position_end``),
        with their remembered multipliers and penalties: those whose segments come within
        :attr:`reach`, or within ``reach + slack`` (m) for moves up to ``slack / 2`` beyond
        (the pair's distance changes by at most its two edges' largest node moves). At most
        within the broad phase's margin."""
        m = self.model
        if not self.options.contact:
            return ContactSet.none(self.edge_samples)
        # Only the pairs some constraint of which can be on its ramp: the others add a constant to
        # the potential and nothing else. They were 99 % of the 2 mm twill strip's pairs within
        # the margin (16536; 190 within the reach), and every kernel ran over them.
        pairs = self._neighbours.query(position, position_end, within=min(self.reach + slack, self._margin))
        counts = self.edge_samples[pairs.pairs].sum(axis=1) if len(pairs) else np.zeros(0, dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        multiplier, stiffening = self._memory.recall(pairs, start)
        edges = pairs.pairs
        radius_sum = m.edge_radius[edges[:, 0]] + m.edge_radius[edges[:, 1]]
        if self.options.contact_stiffness is not None:
            stiffness = np.full(len(pairs), float(self.options.contact_stiffness))
        else:
            ea = np.maximum(m.edge_stretch_stiffness[edges[:, 0]], m.edge_stretch_stiffness[edges[:, 1]])
            stiffness = ea / radius_sum
        return ContactSet(pairs, self.edge_samples, start, multiplier, stiffness, stiffening, radius_sum)

    def due(self, residual) -> bool:
        """Update multipliers once a contact penetrates too far or carries force while apart and
        the iterate (its :class:`~yarnfit.engine.Residual`, one per Newton step) is balanced to the
        current threshold or has stalled (STALL_ITERATIONS)."""
        if max(residual.penetration, residual.separation) <= self.options.penetration_tolerance:
            return False
        if residual.balanced(self.options, slack=self._threshold):
            return True
        imbalances = self._imbalances
        imbalances.append(max(residual.force, residual.torque))
        return (len(imbalances) > 2 * STALL_ITERATIONS
                and min(imbalances[-STALL_ITERATIONS:]) > STALL_PROGRESS * min(imbalances[-2 * STALL_ITERATIONS:-STALL_ITERATIONS]))

    def update(self, contacts: ContactSet, gap: np.ndarray, force: np.ndarray, residual) -> None:
        """λ ← m(λ − k g) for every constraint of ``contacts`` (``force``, N, at gaps ``gap``, m).
        If the worst violation in ``residual`` did not fall to PENETRATION_PROGRESS of the last
        update's, pairs whose gap is beyond tolerance either way get a tenfold penalty (up to
        MAX_STIFFENING). The threshold for the next update tightens tenfold."""
        violation = max(residual.penetration, residual.separation)
        stiffen = violation > PENETRATION_PROGRESS * self._last_violation
        self._last_violation = violation
        contacts.multiplier = force.copy()
        if stiffen and len(contacts.pairs):
            rsum = contacts.per_constraint(contacts.radius_sum)
            off = np.abs(gap) > self.options.penetration_tolerance * rsum
            loaded_or_deep = contacts.per_pair_any(off & ((gap < 0.0) | (force > 0.0)))
            contacts.stiffening = np.where(loaded_or_deep, np.minimum(10.0 * contacts.stiffening, MAX_STIFFENING),
                                           contacts.stiffening)
        self._memory.store(contacts)
        self._imbalances = []
        opt = self.options
        self._threshold = max(0.1 * self._threshold, opt.force_tolerance, opt.torque_tolerance)
