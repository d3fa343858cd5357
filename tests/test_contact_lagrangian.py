"""The solver's contact policy on its own: constraint layout, measures, multiplier memory,
update timing and penalty stiffening (yarnfit.engine.contact_lagrangian)."""

from __future__ import annotations

import numpy as np
import pytest

from yarnfit.engine import QuasiStaticOptions, Residual, Rod, RodMaterial, RodModel, straight_points
from yarnfit.engine.contact_lagrangian import (
    CONTACT_SAMPLE_SPACING,
    CONTACT_SMOOTHING,
    MAX_STIFFENING,
    MULTIPLIER_UPDATE_RESIDUAL,
    PENETRATION_PROGRESS,
    STALL_ITERATIONS,
    STALL_PROGRESS,
    ContactLagrangian,
    ContactSet,
    contact_gradient,
    contact_potential,
)
from yarnfit.engine import _contact_kernels

RADIUS = 1e-3  # m
MATERIAL = RodMaterial(young_modulus=1e9, poisson_ratio=0.3, density=1000.0)
# The contact potential summed over pairs in another grouping or order: round-off of a few hundred
# terms of like size (~1e-16 each).
REGROUPED_RTOL = 1e-14


def crossing(overlap: float) -> tuple[RodModel, np.ndarray]:
    """Two 8-edge rods (edges 2r long) crossing at their middles at right angles, their axes
    2r(1 − overlap) apart in z, and the rest positions."""
    along_x = straight_points(16 * RADIUS, 8) - [8 * RADIUS, 0.0, 0.0]
    along_y = along_x[:, [1, 0, 2]] + [0.0, 0.0, 2 * RADIUS * (1.0 - overlap)]
    model = RodModel.from_rods([Rod(along_x, RADIUS, MATERIAL), Rod(along_y, RADIUS, MATERIAL)])
    return model, np.array(model.node_rest_position)


def queried():
    """The 10 %-overlap crossing, default options, its policy and a first query at rest:
    ``(model, position, options, lagrangian, contacts)``."""
    model, position = crossing(0.1)
    options = QuasiStaticOptions()
    lagrangian = ContactLagrangian(model, options)
    return model, position, options, lagrangian, lagrangian.query(position)


def balanced(penetration: float, separation: float = 0.0, force: float = 0.0) -> Residual:
    return Residual(force=force, torque=0.0, energy_change=0.0, penetration=penetration, separation=separation)


def test_constraints_are_laid_out_per_pair_with_the_base_penalty():
    model, position = crossing(0.1)
    lagrangian = ContactLagrangian(model, QuasiStaticOptions())
    # Edges of 2r with samples at most CONTACT_SAMPLE_SPACING r apart, both nodes included.
    assert np.all(lagrangian.edge_samples == 1 + int(np.ceil(2.0 / CONTACT_SAMPLE_SPACING)))
    contacts = lagrangian.query(position)
    assert len(contacts) > 0
    a, b = contacts.pairs.pairs[:, 0], contacts.pairs.pairs[:, 1]
    np.testing.assert_array_equal(contacts.counts, lagrangian.edge_samples[a] + lagrangian.edge_samples[b])
    assert contacts.start[-1] == contacts.counts.sum() and np.all(contacts.multiplier == 0.0)
    np.testing.assert_array_equal(contacts.radius_sum, 2 * RADIUS)
    np.testing.assert_allclose(contacts.stiffness, model.edge_stretch_stiffness[a] / (2 * RADIUS), rtol=1e-15)
    fixed = ContactLagrangian(model, QuasiStaticOptions(contact_stiffness=5.0)).query(position)
    assert np.all(fixed.stiffness == 5.0)
    assert len(ContactLagrangian(model, QuasiStaticOptions(contact=False)).query(position)) == 0


def test_measures_are_the_deepest_overlap_and_the_widest_loaded_gap():
    model, position = crossing(0.1)
    contacts = ContactLagrangian(model, QuasiStaticOptions(contact_stiffness=100.0)).query(position)
    n = contacts.start[-1]
    rsum = 2 * RADIUS
    band = CONTACT_SMOOTHING * 100.0 * rsum  # force of the smoothing band (N)
    gap = np.full(n, 0.5 * rsum)
    force = np.zeros(n)
    gap[0], gap[1], gap[2] = -0.03 * rsum, -0.01 * rsum, 0.02 * rsum
    force[2] = 2.0 * band  # apart yet loaded: counts as separation
    gap[3], force[3] = 0.4 * rsum, 0.5 * band  # within the band: does not
    penetration, separation = contacts.measures(gap, force)
    assert penetration == pytest.approx(0.03, rel=1e-14)
    assert separation == pytest.approx(0.02, rel=1e-14)
    assert ContactSet.none().measures(np.empty(0), np.empty(0)) == (0.0, 0.0)


def test_multipliers_are_remembered_per_pair_across_queries():
    model, position = crossing(0.1)
    lagrangian = ContactLagrangian(model, QuasiStaticOptions())
    first = lagrangian.query(position)
    n = first.start[-1]
    force = np.arange(1.0, n + 1.0)
    lagrangian.update(first, np.zeros(n), force, balanced(0.0))
    # A query that finds the same pairs in another order gets each pair's own multipliers back.
    again = lagrangian.query(position + 1e-6)
    for p, key in enumerate(again.pairs.keys(model.n_edges)):
        q = int(np.flatnonzero(first.pairs.keys(model.n_edges) == key)[0])
        np.testing.assert_array_equal(again.multiplier[again.start[p]:again.start[p + 1]],
                                      force[first.start[q]:first.start[q + 1]])


def test_updates_wait_for_balance_and_tighten_tenfold():
    model, position, options, lagrangian, contacts = queried()
    n = contacts.start[-1]
    deep = 10 * options.penetration_tolerance
    assert not lagrangian.due(balanced(deep, force=2 * MULTIPLIER_UPDATE_RESIDUAL))  # not balanced yet
    assert not lagrangian.due(balanced(0.5 * options.penetration_tolerance))  # nothing to correct
    assert lagrangian.due(balanced(deep, force=0.5 * MULTIPLIER_UPDATE_RESIDUAL))
    lagrangian.update(contacts, np.zeros(n), np.zeros(n), balanced(deep))
    assert not lagrangian.due(balanced(deep, force=0.5 * MULTIPLIER_UPDATE_RESIDUAL))
    assert lagrangian.due(balanced(deep, force=0.05 * MULTIPLIER_UPDATE_RESIDUAL))
    lagrangian.restart()  # a new load step starts from the first threshold again
    assert lagrangian.due(balanced(deep, force=0.5 * MULTIPLIER_UPDATE_RESIDUAL))


def test_a_stalled_inner_solve_updates_without_balance():
    model, position, options, lagrangian, contacts = queried()
    n = contacts.start[-1]
    deep = 10 * options.penetration_tolerance
    unbalanced = 1.0  # far above the update threshold: only a stall can make an update due
    # An imbalance that keeps halving is progress: no update however long it takes.
    for k in range(5 * STALL_ITERATIONS):
        assert not lagrangian.due(balanced(deep, force=unbalanced * STALL_PROGRESS ** (k / (STALL_ITERATIONS - 1))))
    lagrangian.restart()
    # A flat imbalance is a stall: due after two windows of STALL_ITERATIONS steps, not before.
    for _ in range(2 * STALL_ITERATIONS):
        assert not lagrangian.due(balanced(deep, force=unbalanced))
    assert lagrangian.due(balanced(deep, force=unbalanced))
    # An update starts the count again; nothing to correct is never due.
    lagrangian.update(contacts, np.zeros(n), np.zeros(n), balanced(deep))
    assert not lagrangian.due(balanced(deep, force=unbalanced))
    for _ in range(3 * STALL_ITERATIONS):
        assert not lagrangian.due(balanced(0.5 * options.penetration_tolerance, force=unbalanced))


def test_penalties_stiffen_only_where_updates_stall():
    model, position, options, lagrangian, contacts = queried()
    n = contacts.start[-1]
    rsum = 2 * RADIUS
    gap = np.full(n, 0.5 * rsum)  # every pair apart and unloaded ...
    gap[contacts.start[0]] = -10 * options.penetration_tolerance * rsum  # ... but the first, too deep
    # The first update has no previous violation to compare with: it counts as progress.
    lagrangian.update(contacts, gap, np.zeros(n), balanced(1e-3))
    assert np.all(contacts.stiffening == 1.0)
    # Cut to PENETRATION_PROGRESS exactly is progress enough; above it is a stall.
    lagrangian.update(contacts, gap, np.zeros(n), balanced(PENETRATION_PROGRESS * 1e-3))
    assert np.all(contacts.stiffening == 1.0)
    lagrangian.update(contacts, gap, np.zeros(n), balanced(PENETRATION_PROGRESS * 1e-3))
    assert contacts.stiffening[0] == 10.0 and np.all(contacts.stiffening[1:] == 1.0)
    for _ in range(10):
        lagrangian.update(contacts, gap, np.zeros(n), balanced(PENETRATION_PROGRESS * 1e-3))
    assert contacts.stiffening[0] == MAX_STIFFENING
    # A pair met later starts at the stiffest level reached (its load is the same problem's); a
    # pair met before keeps its own factor. The second rod (nodes 9–17) moved by one edge crosses
    # the next edge of the first, and leaves the edge it crossed before.
    n_edges = model.n_edges
    own = dict(zip(contacts.pairs.keys(n_edges).tolist(), contacts.stiffening.tolist()))
    shifted = position.copy()
    shifted[9:, 0] += 2 * RADIUS
    later = lagrangian.query(shifted)
    later_keys = later.pairs.keys(n_edges).tolist()
    new = np.array([key not in own for key in later_keys])
    assert new.any() and (~new).any() and not set(own) <= set(later_keys)
    assert np.all(later.stiffening[new] == MAX_STIFFENING)
    assert [s for s, key in zip(later.stiffening, later_keys) if key in own] == [own[k] for k in later_keys if k in own]
    # Updated there, the pairs it left out lose their multipliers (they were out of reach) but not
    # their penalties: back at rest, every pair has its own factor again.
    lagrangian.update(later, np.full(later.start[-1], 0.5 * rsum), np.zeros(later.start[-1]), balanced(0.0))
    back = lagrangian.query(position)
    assert sorted(back.pairs.keys(n_edges).tolist()) == sorted(own)
    assert [own[k] for k in back.pairs.keys(n_edges).tolist()] == back.stiffening.tolist()
    assert np.all(back.multiplier == 0.0)


def test_a_query_holds_every_pair_that_can_push():
    # A query keeps only the pairs within the constraints' reach, (λ + δ) / k: the others add a
    # constant to the potential and nothing else. Against a query out to the broad phase's margin,
    # at a configuration where some pairs are loaded, some slack and some far: the same pairs
    # push with the same forces, the potentials differ by the left-out pairs' constant only.
    model, position, options, lagrangian, contacts = queried()
    n = contacts.start[-1]
    rsum = 2 * RADIUS
    assert lagrangian.reach == pytest.approx(CONTACT_SMOOTHING * rsum, rel=1e-5)  # nothing remembered
    force = np.linspace(0.0, 5.0, n)
    lagrangian.update(contacts, np.zeros(n), force, balanced(1e-3))
    largest = np.maximum.reduceat(force, contacts.start[:-1]) / contacts.stiffness
    assert lagrangian.reach == pytest.approx(largest.max() + CONTACT_SMOOTHING * rsum, rel=1e-5)
    assert lagrangian.reach < 0.01 * lagrangian.margin  # the test separates the two sets
    # The second rod lifted to within half the reach of the first, and a quarter of a radius:
    # still pushing, then out of reach but inside the margin.
    for lift, pushing in ((0.5 * lagrangian.reach, True), (0.25 * RADIUS, False)):
        moved = position.copy()
        moved[9:, 2] += 0.2 * RADIUS + lift  # the 10 % overlap first
        narrow = lagrangian.query(moved)
        wide = lagrangian.query(moved, slack=lagrangian.margin)
        assert len(wide) > len(narrow) and (len(narrow) > 0) == pushing
        results = []
        for each in (narrow, wide):
            gradient = np.zeros((model.n_nodes, 3))
            gap, each_force = np.empty(each.start[-1]), np.empty(each.start[-1])
            energy = _contact_kernels.contact_energy_gradient(moved, model.edge_nodes, model.edge_radius,
                                                              *each.kernel_args(), gradient, np.zeros(model.n_nodes),
                                                              gap, each_force)
            results.append((energy, gradient, each.per_pair_sum(each_force)))
        (energy_n, gradient_n, pushes_n), (energy_w, gradient_w, pushes_w) = results
        left_out = wide.missing_from(narrow, model.n_edges)
        assert np.all(pushes_w[left_out] == 0.0) and (pushes_n.max(initial=0.0) > 0.0) == pushing
        np.testing.assert_array_equal(gradient_n, gradient_w)
        constant = contact_potential(model, moved, wide, left_out)
        assert energy_w == pytest.approx(energy_n + constant, rel=REGROUPED_RTOL, abs=1e-30)


def test_a_new_load_step_keeps_the_multipliers_at_base_penalties():
    model, position, options, lagrangian, contacts = queried()
    n = contacts.start[-1]
    gap = np.full(n, -10 * options.penetration_tolerance * 2 * RADIUS)  # every constraint too deep
    force = np.linspace(1.0, 2.0, n)
    for _ in range(2):  # the second update stalls: every pair stiffens tenfold
        lagrangian.update(contacts, gap, force, balanced(1e-3))
    assert np.all(contacts.stiffening == 10.0)
    fresh = contacts.with_base_penalties()
    assert np.all(fresh.stiffening == 1.0) and np.array_equal(fresh.stiffness, fresh.base_stiffness)
    assert np.array_equal(fresh.multiplier, force) and np.array_equal(fresh.pairs.pairs, contacts.pairs.pairs)
    # A copy: the step it starts updates its own multipliers, not the last step's record.
    fresh.multiplier[0] = -1.0
    assert contacts.multiplier[0] == force[0] and np.all(contacts.stiffening == 10.0)
    # A solve starting from it recalls those multipliers, and pairs it meets later start at base
    # penalties too: the stiffest level reached is the new step's own (the second rod moved by
    # three edges crosses other edges of the first).
    step = ContactLagrangian(model, options)
    step.remember(fresh)
    again = step.query(position)
    assert np.array_equal(again.pairs.pairs, fresh.pairs.pairs) and np.array_equal(again.multiplier, fresh.multiplier)
    assert np.all(again.stiffening == 1.0)
    shifted = position.copy()
    shifted[9:, 0] += 6 * RADIUS
    later = step.query(shifted)
    known = set(fresh.pairs.keys(model.n_edges).tolist())
    assert any(key not in known for key in later.pairs.keys(model.n_edges).tolist())
    assert np.all(later.stiffening == 1.0)


def test_the_potential_of_some_pairs_adds_up_to_the_whole():
    # A swept query finds pairs a query at the start does not: the solver corrects the start's
    # potential by the pairs one set lacks (pairs_energy over those alone) instead of assessing it
    # again. The parts must add up to the kernel's whole, and missing_from must name exactly the
    # pairs the other set lacks.
    model, position, options, lagrangian, at_rest = queried()
    moved = position + np.array([0.0, 0.0, 3.0 * RADIUS]) * (np.arange(model.n_nodes) >= model.n_nodes // 2)[:, None]
    swept = lagrangian.query(position, moved)
    swept.multiplier = np.linspace(0.0, 2.0, swept.start[-1])  # loaded constraints, not only zeros
    assert len(swept) > len(at_rest) > 0
    n = model.n_edges
    missing = swept.missing_from(at_rest, n)
    have = set(at_rest.pairs.keys(n).tolist())
    assert [int(k) for k in swept.pairs.keys(n)[missing]] == [k for k in swept.pairs.keys(n).tolist() if k not in have]
    assert at_rest.missing_from(swept, n).size == 0 and at_rest.missing_from(ContactSet.none(), n).size == len(at_rest)
    rest = np.setdiff1d(np.arange(len(swept)), missing)
    gap, force = np.empty(swept.start[-1]), np.empty(swept.start[-1])
    whole = _contact_kernels.contact_energy_gradient(position, model.edge_nodes, model.edge_radius,
                                                     *swept.kernel_args(), np.zeros((model.n_nodes, 3)),
                                                     np.zeros(model.n_nodes), gap, force)
    parts = contact_potential(model, position, swept, missing) + contact_potential(model, position, swept, rest)
    assert parts == pytest.approx(whole, rel=REGROUPED_RTOL) and whole != 0.0
    assert contact_potential(model, position, swept) == pytest.approx(whole, rel=REGROUPED_RTOL)


def test_a_subset_of_pairs_is_their_part_of_the_potential():
    # ContactSet.subset keeps each chosen pair's constraints, multipliers and penalties: its
    # potential is contact_potential over those pairs, and two complementary subsets' gradients
    # add up to the whole set's (cut_forces sums the pull of some pairs this way).
    model, position, options, lagrangian, at_rest = queried()
    moved = position + np.array([0.0, 0.0, 3.0 * RADIUS]) * (np.arange(model.n_nodes) >= model.n_nodes // 2)[:, None]
    swept = lagrangian.query(position, moved)
    swept.multiplier = np.linspace(0.0, 2.0, swept.start[-1])
    swept.stiffening = np.linspace(1.0, 3.0, len(swept))
    assert len(swept) >= 4
    some = np.arange(1, len(swept), 3)
    others = np.setdiff1d(np.arange(len(swept)), some)

    def gradient(contacts: ContactSet) -> tuple[float, np.ndarray]:
        out = np.zeros((model.n_nodes, 3))
        energy = _contact_kernels.contact_energy_gradient(
            position, model.edge_nodes, model.edge_radius, *contacts.kernel_args(), out, np.zeros(model.n_nodes),
            np.empty(contacts.start[-1]), np.empty(contacts.start[-1]))
        np.testing.assert_array_equal(contact_gradient(model, position, contacts), out)
        return energy, out

    part = swept.subset(some)
    assert len(part) == len(some) and np.array_equal(part.counts, swept.counts[some])
    np.testing.assert_array_equal(part.stiffness, swept.stiffness[some])
    energy, part_gradient = gradient(part)
    assert energy == pytest.approx(contact_potential(model, position, swept, some), rel=REGROUPED_RTOL)
    whole_energy, whole_gradient = gradient(swept)
    assert whole_energy != 0.0
    np.testing.assert_allclose(part_gradient + gradient(swept.subset(others))[1], whole_gradient,
                               rtol=REGROUPED_RTOL, atol=REGROUPED_RTOL * np.abs(whole_gradient).max())
    assert len(swept.subset(np.zeros(0, dtype=np.int64))) == 0
    with pytest.raises(ValueError, match="ascending"):
        swept.subset(some[::-1])
