"""The quasi-static solver's step control: the Levenberg–Marquardt damping update and the spin
gauge it holds on its own (docs/design.md §6)."""

import numpy as np
import pytest

from yarnfit.engine import Loads, QuasiStaticSolver, Rod, RodMaterial, RodModel, RodState, straight_points
from yarnfit.engine.quasistatic import (
    DAMPING_DECREASE_LIMIT,
    DAMPING_RAISE,
    INITIAL_DAMPING,
    MIN_DAMPING,
    NEAR_DAMPING,
    NOISE_DAMPING,
    LinearConstraints,
    _Damping,
)

YARN = RodMaterial(young_modulus=3e9, poisson_ratio=0.3, density=1380.0)
RADIUS = 1e-4


def test_damping_follows_the_gain_ratio():
    damping = _Damping()
    assert damping.value == INITIAL_DAMPING
    damping.succeeded(1.0)  # the model predicted the decrease: damp a third as much
    assert damping.value == pytest.approx(INITIAL_DAMPING * DAMPING_DECREASE_LIMIT)
    damping.succeeded(0.5)  # half of it: keep
    assert damping.value == pytest.approx(INITIAL_DAMPING * DAMPING_DECREASE_LIMIT)
    damping.succeeded(0.0)  # none of it: double
    assert damping.value == pytest.approx(2.0 * INITIAL_DAMPING * DAMPING_DECREASE_LIMIT)


def test_cut_steps_raise_the_damping_faster_and_faster_until_one_is_taken_whole():
    damping = _Damping()
    damping.failed()
    damping.failed()
    damping.failed()
    assert damping.value == pytest.approx(INITIAL_DAMPING * DAMPING_RAISE * (2 * DAMPING_RAISE) * (4 * DAMPING_RAISE))
    damping.succeeded(1.0)
    raised = damping.value
    damping.failed()
    assert damping.value == pytest.approx(raised * DAMPING_RAISE)


def test_the_damping_restarts_near_once_the_iterate_reaches_round_off():
    """The first step in the round-off regime brings a damping still up from the cold start
    down to NEAR_DAMPING (a damped step there could not resolve a soft residual, and the noise
    rule's raises ratcheted); later ones leave the noise rule alone, and a lower damping is kept."""
    damping = _Damping()
    assert INITIAL_DAMPING > NEAR_DAMPING
    damping.reached_roundoff()
    assert damping.value == NEAR_DAMPING
    damping.raise_by(NOISE_DAMPING)
    damping.reached_roundoff()
    assert damping.value == pytest.approx(NEAR_DAMPING * NOISE_DAMPING)
    low = _Damping()
    for _ in range(30):
        low.succeeded(1.0)
    floor = low.value
    assert floor < NEAR_DAMPING
    low.reached_roundoff()
    assert low.value == floor


def test_damping_never_falls_below_its_floor():
    damping = _Damping()
    for _ in range(100):
        damping.succeeded(1.0)
    assert damping.value == MIN_DAMPING


def _rod(y, **kwargs):
    return Rod(straight_points(0.01, 20, start=(0.0, y, 0.0)), RADIUS, YARN, **kwargs)


def test_spin_gauge_is_held_only_where_the_spin_costs_nothing():
    bent = straight_points(0.01, 20, start=(0.0, 0.004, 0.0))
    bent[:, 2] = 1e-3 * np.sin(bent[:, 0] * 300.0)
    model = RodModel.from_rods([
        _rod(0.0, pinned_nodes=[0, -1]),  # free frames, straight: a gauge
        _rod(0.001, pinned_nodes=[0, -1], pinned_frames=[0]),  # a frame pinned
        _rod(0.002, pinned_nodes=[0, -1]),  # a moment on one of its edges (below)
        _rod(0.003, pinned_nodes=[0, -1]),  # its spin held by the caller
        Rod(bent, RADIUS, YARN, pinned_nodes=[0, -1]),  # curved rest shape: the spin is real
        Rod(bent + (0.0, 0.002, 0.0), RADIUS, YARN, pinned_nodes=[0, -1], straight=True),  # bent, straight rest
    ])
    moment = np.zeros((model.n_edges, 3))
    moment[model.edge_index(2, 5)] = (0.0, 0.0, 1e-6)
    held = np.array([model.edge_index(3, 7)])
    gauge = QuasiStaticSolver(model)._spin_gauge(held, moment)
    assert gauge.tolist() == [model.edge_index(0, 0), model.edge_index(5, 0)]


def test_holding_the_spin_gauge_does_not_move_the_equilibrium():
    # Two straight yarns crossing, frames free: the solver holds each one's first frame. Holding
    # another frame instead (the caller's choice) gives the same positions.
    model = RodModel.from_rods([
        Rod(straight_points(0.004, 16, start=(-0.002, 0.0, 0.0)), RADIUS, YARN, pinned_nodes=[0, -1]),
        Rod(straight_points(0.004, 16, start=(0.0, -0.002, 2.2 * RADIUS), direction=(0.0, 1.0, 0.0)), RADIUS, YARN,
            pinned_nodes=[0, -1]),
    ])
    loads = Loads.zeros(model)
    loads.node_force[model.rod_nodes(1), 2] = -1e-3
    solver = QuasiStaticSolver(model)
    first = solver.solve(RodState.from_model(model), loads)
    middle = solver.solve(RodState.from_model(model), loads,
                          constraints=LinearConstraints(spin_edges=[model.edge_index(0, 8), model.edge_index(1, 8)]))
    assert first.converged and middle.converged
    assert len(first.contact_force) > 0
    np.testing.assert_allclose(first.state.node_position, middle.state.node_position, rtol=0.0, atol=1e-12)


def test_damping_stays_finite_under_a_long_run_of_cut_steps():
    # Each cut doubles the raise factor: 2, 4, 8, ... would overflow after ~45 cuts without a ceiling.
    from yarnfit.engine.quasistatic import MAX_DAMPING

    damping = _Damping()
    with np.errstate(over="raise"):
        for _ in range(2000):
            damping.failed()
        damping.harden()
    assert damping.value == MAX_DAMPING
    damping.succeeded(1.0)
    assert damping.value == pytest.approx(MAX_DAMPING * DAMPING_DECREASE_LIMIT)
