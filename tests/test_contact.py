"""Yarn–yarn contact: minimum distance, broad phase, self-contact exclusion and Coulomb friction."""

import math

import numpy as np
import pytest

from yarnfit.engine import (
    Loads,
    QuasiStaticOptions,
    QuasiStaticSolver,
    Rod,
    RodMaterial,
    RodModel,
    RodState,
    XPBDOptions,
    XPBDSolver,
    straight_points,
)
from yarnfit.engine._contact_kernels import segment_closest_points, tunneling_step_limit
from yarnfit.engine.contact import ContactPairs, find_pairs, pair_distances
from yarnfit.engine.model import CONTACT_EXCLUSION_FACTOR

# Issue acceptance: pressed rods stop at centreline distance ra + rb within 1 %.
DISTANCE_RTOL = 0.01
MATERIAL = RodMaterial(young_modulus=1e9, poisson_ratio=0.3, density=1000.0)
SPAN = 0.1  # m
N_EDGES = 40


def crossed_rods(radius_a: float, radius_b: float, gap: float) -> RodModel:
    """Rod A along x at z = 0 and rod B along y above it with the given surface gap; each rod is
    pinned at its two end nodes."""
    a = Rod(straight_points(SPAN, N_EDGES, start=(-SPAN / 2, 0, 0)), radius_a, MATERIAL, pinned_nodes=[0, -1])
    b = Rod(straight_points(SPAN, N_EDGES, start=(0, -SPAN / 2, radius_a + radius_b + gap), direction=(0, 1, 0)),
            radius_b, MATERIAL, pinned_nodes=[0, -1])
    return RodModel.from_rods([a, b])


def crossing_distance(model: RodModel, state: RodState) -> float:
    mid = N_EDGES // 2
    return float(np.linalg.norm(state.node_position[model.node_index(1, mid)] - state.node_position[model.node_index(0, mid)]))


@pytest.mark.parametrize("radius_b", [1e-3, 0.5e-3])
def test_pressed_crossed_rods_stop_at_touching_distance(radius_b):
    # Reference: the unilateral constraint holds the centrelines ra + rb apart.
    radius_a = 1e-3
    model = crossed_rods(radius_a, radius_b, gap=0.5 * radius_a)
    loads = Loads.zeros(model)
    mid = model.node_index(1, N_EDGES // 2)
    loads.node_force[mid, 2] = -0.5  # N; bends B (pinned ends, cable action) well below A's top
    result = QuasiStaticSolver(model).solve(RodState.from_model(model), loads)
    assert result.converged
    assert crossing_distance(model, result.state) == pytest.approx(radius_a + radius_b, rel=DISTANCE_RTOL)
    assert len(result.contact_force) > 0 and np.all(result.contact_force > 0)
    # Contact is not idle: A is pushed down, and B sags at least 10 % less than without A.
    assert result.state.node_position[model.node_index(0, N_EDGES // 2), 2] < -0.1 * radius_a
    free = QuasiStaticSolver(model, QuasiStaticOptions(contact=False)).solve(RodState.from_model(model), loads)
    start_height = model.node_rest_position[mid, 2]
    free_sag = start_height - free.state.node_position[mid, 2]
    assert start_height - result.state.node_position[mid, 2] < 0.9 * free_sag


def test_a_large_step_does_not_pass_a_rod_through_another():
    # A load 100× that of the previous test: a single Newton step would carry B far below A; the
    # step limit must stop B on top of A.
    model = crossed_rods(1e-3, 1e-3, gap=0.5e-3)
    loads = Loads.zeros(model)
    ei = MATERIAL.young_modulus * math.pi * 1e-3**4 / 4
    loads.node_force[model.node_index(1, N_EDGES // 2), 2] = -48 * ei / SPAN**3 * 600e-3
    result = QuasiStaticSolver(model).solve(RodState.from_model(model), loads)
    assert result.converged
    mid = N_EDGES // 2
    above = result.state.node_position[model.node_index(1, mid), 2] - result.state.node_position[model.node_index(0, mid), 2]
    assert above == pytest.approx(2e-3, rel=DISTANCE_RTOL)


def test_xpbd_dropped_rod_rests_at_touching_distance():
    # Reference: the XPBD contact projection holds the same minimum distance: a free rod falls under
    # gravity across two parallel pinned rods and settles (damped, with friction so that the impact
    # cannot send it sliding along the supports) at 2r above both.
    radius = 1e-3
    supports = [
        Rod(straight_points(SPAN, N_EDGES, start=(-SPAN / 2, y, 0.0)), radius, MATERIAL, pinned_nodes=[0, -1])
        for y in (-SPAN / 4, SPAN / 4)
    ]
    falling = Rod(straight_points(SPAN, N_EDGES, start=(0.0, -SPAN / 2, 4 * radius), direction=(0, 1, 0)), radius,
                  MATERIAL)
    model = RodModel.from_rods(supports + [falling])
    state = RodState.from_model(model)
    # Small steps (Macklin et al. 2019): with 4 substeps × 10 iterations per ms the supports'
    # bending is unresolved and they sag 200× too far; 50 × 2 resolves it.
    solver = XPBDSolver(model, XPBDOptions(substeps=50, iterations=2, damping=20.0, static_friction=0.5,
                                           kinetic_friction=0.5))
    loads = Loads.zeros(model, gravity=(0.0, 0.0, -9.81))
    crossings = [(model.node_index(0, N_EDGES // 2), model.node_index(2, N_EDGES // 4)),
                 (model.node_index(1, N_EDGES // 2), model.node_index(2, 3 * N_EDGES // 4))]
    for step in range(400):
        solver.step(state, loads, 1e-3)
        if step >= 350:  # resting: the contact distance must hold at every step
            for support, above in crossings:
                distance = np.linalg.norm(state.node_position[above] - state.node_position[support])
                assert distance == pytest.approx(2 * radius, rel=DISTANCE_RTOL)
    # At rest up to XPBD's residual jitter (mm/s; the impact was at 270 mm/s).
    assert np.abs(state.node_velocity).max() < 5e-3


def brute_force_pairs(model, position, margin):
    """All edge pairs whose boxes (inflated by radius + margin/2) overlap, minus same-rod pairs
    sharing a node or closer than the exclusion arc length: the definition, checked for every pair."""
    ends = position[model.edge_nodes]  # (E, 2, 3)
    pad = (model.edge_radius + 0.5 * margin)[:, None]
    lower, upper = ends.min(axis=1) - pad, ends.max(axis=1) + pad
    overlap = np.all((lower[:, None, :] <= upper[None, :, :]) & (lower[None, :, :] <= upper[:, None, :]), axis=2)
    pairs = set()
    for a, b in zip(*np.nonzero(np.triu(overlap, k=1))):
        if model.edge_rod[a] == model.edge_rod[b]:
            shared = set(model.edge_nodes[a]) & set(model.edge_nodes[b])
            gap = max(0.0, abs(model.edge_arc_start[b] - model.edge_arc_start[a]) - model.edge_rest_length[min(a, b)])
            if shared or gap < CONTACT_EXCLUSION_FACTOR * (model.edge_radius[a] + model.edge_radius[b]):
                continue
        pairs.add((int(a), int(b)))
    return pairs


def test_broad_phase_finds_exactly_the_overlapping_pairs():
    # Reference: every pair of edges tested by brute force (O(E²)) on a random tangle of rods.
    rng = np.random.default_rng(2)
    rods = []
    for k in range(12):
        walk = np.cumsum(rng.normal(scale=2e-3, size=(15, 3)), axis=0) + rng.uniform(-6e-3, 6e-3, size=3)
        rods.append(Rod(walk, 5e-4 + 5e-4 * rng.random(), MATERIAL))
    model = RodModel.from_rods(rods)
    x = model.node_rest_position
    margin = 1e-3
    candidates = find_pairs(model, x, margin)
    assert not candidates.images.any()  # not periodic: no images
    found = {tuple(p) for p in candidates.pairs.tolist()}
    assert found == brute_force_pairs(model, x, margin)
    assert len(found) > 100  # a dense tangle, not a trivial case


def test_neighbours_along_a_yarn_never_touch_but_a_folded_yarn_does():
    # A straight yarn whose edges are shorter than its radius has no self pairs; the same yarn bent
    # into a hairpin (legs 3r apart at the tip, U-turn of radius 1.5r) sees its legs as candidates.
    radius = 1e-3
    straight = RodModel.from_rods([Rod(straight_points(0.02, 40), radius, MATERIAL)])
    assert len(find_pairs(straight, straight.node_rest_position, radius)) == 0
    turn = np.linspace(0.0, math.pi, 12)
    leg = np.linspace(0.0, 0.01, 21)[1:]
    hairpin = np.concatenate([
        np.column_stack([leg[::-1], np.full(20, -1.5 * radius), np.zeros(20)]),
        np.column_stack([-1.5 * radius * np.sin(turn), -1.5 * radius * np.cos(turn), np.zeros(12)]),
        np.column_stack([leg, np.full(20, 1.5 * radius), np.zeros(20)]),
    ])
    folded = RodModel.from_rods([Rod(hairpin, radius, MATERIAL)])
    y = folded.node_rest_position
    pairs = find_pairs(folded, y, radius).pairs.tolist()
    legs = [(a, b) for a, b in pairs if y[folded.edge_nodes[a], 0].min() > 2 * radius and y[folded.edge_nodes[b], 0].min() > 2 * radius]
    assert len(legs) > 10


def incline_slide(tan_ratio: float, mu: float = 0.4, duration: float = 0.3) -> tuple[float, float]:
    """A short rod laid across two fixed rails inclined at tan θ = tan_ratio · μ, released under
    gravity with μs = μk = μ. Returns (distance slid down the slope, θ)."""
    theta = math.atan(tan_ratio * mu)
    radius = 1e-3
    down = np.array([math.cos(theta), 0.0, -math.sin(theta)])
    normal = np.array([math.sin(theta), 0.0, math.cos(theta)])
    rails = [
        Rod(straight_points(0.2, 20, start=-0.1 * down + (0.0, y, 0.0), direction=down), radius, MATERIAL,
            pinned_nodes=list(range(21)))
        for y in (-0.01, 0.01)
    ]
    bar = Rod(straight_points(0.04, 8, start=(0.0, -0.02, 0.0) + 2 * radius * normal, direction=(0, 1, 0)), radius,
              MATERIAL)
    model = RodModel.from_rods(rails + [bar])
    state = RodState.from_model(model)
    solver = XPBDSolver(model, XPBDOptions(substeps=10, iterations=4, static_friction=mu, kinetic_friction=mu))
    loads = Loads.zeros(model, gravity=(0.0, 0.0, -9.81))
    nodes = model.rod_nodes(2)
    start = state.node_position[nodes].mean(axis=0)
    dt = 1e-3
    for _ in range(round(duration / dt)):
        solver.step(state, loads, dt)
    return float((state.node_position[nodes].mean(axis=0) - start) @ down), theta


def test_rod_on_an_incline_sticks_below_the_friction_angle():
    # Reference: Coulomb friction holds a body at rest while tan θ < μ.
    slide, theta = incline_slide(0.8)
    free_fall = 0.5 * 9.81 * math.sin(theta) * 0.3**2
    assert abs(slide) < 1e-5 * free_fall


def test_rod_on_an_incline_slides_above_the_friction_angle():
    # Reference: above the friction angle it slides with a = g (sin θ − μk cos θ), s = a t² / 2.
    mu = 0.4
    slide, theta = incline_slide(1.25, mu)
    expected = 0.5 * 9.81 * (math.sin(theta) - mu * math.cos(theta)) * 0.3**2
    # The step starts with static contact and resolves sliding at the substep level: 2 % covers it.
    assert slide == pytest.approx(expected, rel=0.02)


# -- the Newton step's no-tunnelling cap ----------------------------------------------------------

# Kernel's stop: within CCD_CONVERGED (1 %) of the allowed approach, so the step it allows reaches at
# least 98 % of the exact limit on a head-on approach.
CCD_REACH = 0.98
# Distance samples along a step in the brute-force reference.
CCD_SAMPLES = 2001
# The sampled distances are exact to round-off of unit-sized coordinates.
CCD_ROUNDOFF = 1e-12


def _segment_pair(a0, a1, b0, b1):
    """Two free segments with identity maps, as the contact kernels take them."""
    pos = np.array([a0, a1, b0, b1], dtype=np.float64)
    edge_nodes = np.array([[0, 1], [2, 3]])
    pairs = np.array([[0, 1]])
    rotation = np.broadcast_to(np.eye(3), (1, 4, 3, 3)).copy()
    translation = np.zeros((1, 4, 3))
    return pos, edge_nodes, pairs, rotation, translation


def _distance_along(pos, dx, alphas):
    return np.array([segment_closest_points(*(pos + a * dx))[2] for a in alphas])


def test_a_yarn_sliding_along_another_is_not_cut():
    pos, edge_nodes, pairs, rotation, translation = _segment_pair((0, 0, 0), (1, 0, 0), (0, 0, 0.2), (1, 0, 0.2))
    dx = np.zeros((4, 3))
    dx[2:, 0] = 5.0  # b slides 25 distances along a: the distance never changes
    assert tunneling_step_limit(pos, dx, edge_nodes, pairs, rotation, translation, 0.9) == 1.0


def test_a_head_on_approach_stops_at_a_tenth_of_the_distance():
    pos, edge_nodes, pairs, rotation, translation = _segment_pair((0, 0, 0), (1, 0, 0), (0, 0, 0.2), (1, 0, 0.2))
    dx = np.zeros((4, 3))
    dx[2:, 2] = -0.4  # b would pass through a at α = 0.5
    alpha = tunneling_step_limit(pos, dx, edge_nodes, pairs, rotation, translation, 0.9)
    exact = (0.2 - 0.02) / 0.4
    assert CCD_REACH * exact <= alpha <= exact


@pytest.mark.parametrize("seed", range(20))
def test_no_step_brings_a_pair_below_a_tenth_of_its_distance(seed):
    """Random segments and moves against the distance sampled densely along the step (brute force):
    nowhere up to the allowed step is the distance below a tenth of its start."""
    rng = np.random.default_rng(seed)
    pos, edge_nodes, pairs, rotation, translation = _segment_pair(*rng.normal(size=(4, 3)))
    dx = rng.normal(scale=3.0, size=(4, 3))
    alpha = tunneling_step_limit(pos, dx, edge_nodes, pairs, rotation, translation, 0.9)
    start = _distance_along(pos, dx, [0.0])[0]
    along = _distance_along(pos, dx, np.linspace(0.0, alpha, CCD_SAMPLES))
    assert along.min() >= 0.1 * start * (1.0 - CCD_ROUNDOFF)
    assert 0.0 < alpha <= 1.0


@pytest.mark.parametrize("swept", [False, True])
def test_pairs_within_reach_are_the_candidates_whose_segments_come_that_close(swept):
    """``find_pairs(within=w)`` keeps exactly the box candidates whose segments are within
    ra + rb + w at the start, or could be on the way (distance less both edges' largest node
    moves), as computed here pair by pair."""
    model = crossed_rods(1e-3, 1e-3, 0.5e-3)
    position = np.array(model.node_rest_position)
    rng = np.random.default_rng(3)
    end = position + (rng.normal(scale=3e-4, size=position.shape) if swept else 0.0)
    margin = 4e-3
    candidates = find_pairs(model, position, margin, end if swept else None)
    kept = find_pairs(model, position, margin, end if swept else None, within=1e-3)
    distance = pair_distances(model, position, candidates)
    move = np.linalg.norm(end - position, axis=1)
    travel = sum(move[model.edge_nodes[candidates.pairs[:, k]]].max(axis=1) for k in range(2))
    rsum = model.edge_radius[candidates.pairs].sum(axis=1)
    expected = distance - travel <= rsum + 1e-3
    assert 0 < expected.sum() < len(candidates)  # the filter has work to do either way
    np.testing.assert_array_equal(kept.pairs, candidates.pairs[expected])
    np.testing.assert_array_equal(kept.images, candidates.images[expected])
    np.testing.assert_array_equal(kept.translation, candidates.translation[expected])


def test_a_subset_of_pairs_keeps_their_images_and_maps():
    """``ContactPairs.subset`` by a mask or by indices (in the order given) holds the same pairs,
    images, rotations and translations as numpy's indexing of each array (the reference)."""
    rng = np.random.default_rng(11)
    n = 40
    candidates = ContactPairs(rng.integers(0, 100, (n, 2)), rng.integers(-3, 4, (n, 2)),
                              rng.normal(size=(n, 4, 3, 3)), rng.normal(size=(n, 4, 3)))
    mask = rng.random(n) < 0.5
    for which in (mask, rng.permutation(n)[:25], np.zeros(0, dtype=np.int64)):
        kept = candidates.subset(which)
        for name in ("pairs", "images", "rotation", "translation"):
            np.testing.assert_array_equal(getattr(kept, name), getattr(candidates, name)[which])
