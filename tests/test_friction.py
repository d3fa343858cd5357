"""The quasi-static solver's lagged Coulomb friction (yarnfit.engine.friction): the kernels'
values against the smoothed Coulomb law and derivatives against central differences, and a rod
pressed onto another and dragged: sliding, its jaw holds μ N; stuck, less, growing with the drag."""

import dataclasses

import numpy as np
import pytest

from yarnfit.engine import Loads, QuasiStaticOptions, QuasiStaticSolver, Rod, RodMaterial, RodModel, RodState
from yarnfit.engine import _friction_kernels
from yarnfit.engine.friction import FrictionAnchors, anchor_contacts
from yarnfit.engine.lagged import in_halves, lagged_solve

# Central differences of a smooth function at step 1e-7 of a 1e-4 m scale: truncation ~1e-10 and
# round-off ~1e-9 relative to the largest entry.
DIFFERENCE_TOLERANCE = 1e-6

YARN = RodMaterial(young_modulus=3e9, poisson_ratio=0.3, density=1380.0)
RADIUS = 1e-4


def _random_anchors(rng, n_nodes=8, n_anchors=5, slip_length=2e-5):
    rotations = []
    for _ in range(n_anchors * 4):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        rotations.append(q * np.sign(np.linalg.det(q)))
    tangent = np.empty((n_anchors, 2, 3))
    for k in range(n_anchors):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        tangent[k] = q[:, :2].T
    s, t = rng.uniform(size=n_anchors), rng.uniform(size=n_anchors)
    return FrictionAnchors(
        nodes=rng.integers(0, n_nodes, size=(n_anchors, 4)),
        weight=np.stack([1 - s, s, -(1 - t), -t], axis=1),
        rotation=np.array(rotations).reshape(n_anchors, 4, 3, 3),
        translation=rng.normal(scale=1e-4, size=(n_anchors, 4, 3)),
        tangent=tangent,
        origin=rng.normal(scale=1e-4, size=(n_anchors, 2)),
        bound=rng.uniform(0.1, 1.0, size=n_anchors),
        slip_length=slip_length,
    )


@pytest.mark.parametrize("slip_length", [1e-2, 3e-5], ids=["sticking", "sliding"])
def test_friction_gradient_and_hessian_match_central_differences(slip_length):
    """Every anchor within its slip length (ε 1 cm) and every one beyond it (ε 30 µm, slips
    ~0.2 mm): both branches of the smoothed slip."""
    rng = np.random.default_rng(3)
    anchors = _random_anchors(rng, slip_length=slip_length)
    position = rng.normal(scale=1e-4, size=(8, 3))
    energy, gradient, _ = anchors.energy_gradient(position)
    h = 1e-11  # m: 1e-7 of the positions' 1e-4 m scale
    numeric = np.zeros(24)
    for i in range(24):
        plus, minus = position.copy(), position.copy()
        plus.flat[i] += h
        minus.flat[i] -= h
        numeric[i] = (anchors.energy_gradient(plus)[0] - anchors.energy_gradient(minus)[0]) / (2 * h)
    assert np.abs(numeric - gradient.ravel()).max() <= DIFFERENCE_TOLERANCE * np.abs(gradient).max()

    n = 144 * len(anchors)
    rows, cols, vals = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.empty(n)
    count = _friction_kernels.friction_hessian_coo(position, *anchors.kernel_args(), rows, cols, vals, 0)
    hessian = np.zeros((24, 24))
    np.add.at(hessian, (rows[:count], cols[:count]), vals[:count])
    numeric = np.zeros((24, 24))
    for i in range(24):
        plus, minus = position.copy(), position.copy()
        plus.flat[i] += h
        minus.flat[i] -= h
        numeric[:, i] = (anchors.energy_gradient(plus)[1].ravel() - anchors.energy_gradient(minus)[1].ravel()) / (2 * h)
    assert np.abs(numeric - hessian).max() <= DIFFERENCE_TOLERANCE * np.abs(hessian).max()
    assert np.linalg.eigvalsh(hessian).min() >= -1e-12 * np.abs(hessian).max()
    assert energy >= 0.0


def test_each_anchor_follows_the_smoothed_coulomb_law():
    """Force μ N (2 y / ε − y² / ε²) below the slip length ε, μ N beyond, y = |T r(x) − u0|
    computed here from the anchors' definition."""
    rng = np.random.default_rng(5)
    anchors = _random_anchors(rng, n_anchors=40, slip_length=1.5e-4)
    position = rng.normal(scale=1e-4, size=(8, 3))
    mapped = np.einsum("kmij,kmj->kmi", anchors.rotation, position[anchors.nodes]) + anchors.translation
    relative = np.einsum("km,kmi->ki", anchors.weight, mapped)
    y = np.linalg.norm(np.einsum("kai,ki->ka", anchors.tangent, relative) - anchors.origin, axis=1)
    eps = anchors.slip_length
    expected = anchors.bound * np.where(y < eps, 2 * y / eps - (y / eps) ** 2, 1.0)
    assert 0 < np.count_nonzero(y < eps) < len(y)
    assert np.allclose(anchors.energy_gradient(position)[2], expected, rtol=1e-12)


def _dragged_rod(press: float):
    """Rod A along x, every node pinned; rod B half as long lying along it on top (centrelines 2r
    apart), pressed onto it by ``press`` (N) spread over its nodes but the first, which is held
    (the jaw) at the height of the contact. Sliding along its own axis, every sampled contact's
    normal stays vertical, so the whole press is the contacts' normal force throughout. B is
    stiff (E 1e4 times a polyester fibre's) so that it slides as one piece: its compression
    between the jaw and its far end, P L / (2 EA), is 3e-6 of the drag at most."""
    n_edges, length = 10, 2e-3
    a = Rod(np.column_stack([np.linspace(-length, length, 2 * n_edges + 1), np.zeros(2 * n_edges + 1),
                             np.zeros(2 * n_edges + 1)]), RADIUS, YARN, pinned_nodes=range(2 * n_edges + 1),
            pinned_frames=range(2 * n_edges))
    b = Rod(np.column_stack([np.linspace(-length / 2, length / 2, n_edges + 1), np.zeros(n_edges + 1),
                             np.full(n_edges + 1, 2 * RADIUS)]), RADIUS, YARN, pinned_nodes=[0])
    model = RodModel.from_rods([a, b])
    loads = Loads.zeros(model)
    jaw = 2 * n_edges + 1
    loads.node_force[jaw + 1:, 2] = -press / n_edges
    return model, loads, jaw


def _drag(drag_slips: float, press: float = 1.0, mu: float = 0.3):
    """Drag B's jaw ``drag_slips`` slip lengths along B, the lagged normal forces settled to
    round-off; returns the jaw's pull (N), its vertical reaction (N) and the lagged solve."""
    model, loads, jaw = _dragged_rod(press)
    solver = QuasiStaticSolver(model, QuasiStaticOptions(force_tolerance=1e-10, torque_tolerance=1e-10))
    rest = solver.solve(RodState.from_model(model), loads)
    assert rest.converged
    slip_length = 1e-3 * 2 * RADIUS
    moved = rest.state.node_position.copy()
    moved[jaw, 0] += drag_slips * slip_length
    guess = RodState(moved, rest.state.edge_quaternion, np.zeros_like(moved), np.zeros((model.n_edges, 3)))
    lagged = lagged_solve(solver, guess, rest.state.node_position, mu, slip_length=slip_length,
                          anchors_from=(rest.state.node_position, rest.contacts), loads=loads, tolerance=LAG_SETTLED)
    assert lagged.settled and lagged.result.converged
    return lagged.result.reaction_force[jaw, 0], lagged.result.reaction_force[jaw, 2], lagged


# Lagged passes are run until the anchored normal force changes by less than this: the friction
# bound is then the solution's own to round-off.
LAG_SETTLED = 1e-9


# The contacts' normals are not quite vertical: B sags between its nodes under the press and rounds
# over A's samples at its ends (the anchors' tangent planes tilt by up to 0.014 rad, measured), so
# the normal forces push B along x by ~1e-3 of their sum (1.25e-3 measured sliding) and their
# magnitudes exceed their vertical parts by ~1e-4; the friction forces, saturated, lean out of x by
# as much. Each anchor's own force is checked against its bound to round-off.
TILT_TOLERANCE = 2e-3


def test_a_sliding_rod_pulls_its_jaw_with_the_coulomb_force():
    """Dragged 20 slip lengths, every contact slides: the jaw holds μ N exactly, N the contacts'
    normal force (the press plus what the jaw holds down: vertical balance of B)."""
    press, mu = 1.0, 0.3
    pull, lift, lagged = _drag(20.0, press, mu)
    normal = lagged.anchors.bound.sum() / mu
    assert normal == pytest.approx(press - lift, rel=TILT_TOLERANCE)
    _, gradient, force = lagged.anchors.energy_gradient(lagged.result.state.node_position)
    jaw = len(gradient) - 11  # B's first node (see _dragged_rod)
    assert gradient[jaw:, 0].sum() == pytest.approx(mu * normal, rel=TILT_TOLERANCE)
    assert pull == pytest.approx(mu * normal, rel=TILT_TOLERANCE)
    assert np.allclose(force, lagged.anchors.bound, rtol=1e-12)


def test_a_stuck_rod_holds_less_than_the_coulomb_force_and_more_the_further_it_is_dragged():
    """Dragged within the slip length, the contacts stick: B's slip decays from the jaw along it
    (shear lag between its axial stiffness and the contacts' stick stiffness 2 μ N / ε), and
    the jaw's pull, below μ N, grows with the drag; B's horizontal balance puts the contacts'
    friction forces (all along x: they lie along B) equal to the pull."""
    mu = 0.3
    pulls = []
    for drag_slips in (0.1, 0.3):
        pull, lift, lagged = _drag(drag_slips, mu=mu)
        _, gradient, force = lagged.anchors.energy_gradient(lagged.result.state.node_position)
        assert pull < lagged.anchors.bound.sum()
        assert np.all(force < lagged.anchors.bound)
        jaw = len(gradient) - 11  # B's first node (see _dragged_rod)
        assert gradient[jaw:, 0].sum() == pytest.approx(pull, rel=TILT_TOLERANCE)
        pulls.append(pull)
    assert 0.0 < pulls[0] < pulls[1]


def test_anchors_refuse_bad_input():
    model, loads, _ = _dragged_rod(1e-3)
    rest = QuasiStaticSolver(model).solve(RodState.from_model(model), loads)
    x = rest.state.node_position
    with pytest.raises(ValueError, match="friction coefficient"):
        anchor_contacts(model, x, rest.contacts, x, -0.1)
    with pytest.raises(ValueError, match="slip length"):
        anchor_contacts(model, x, rest.contacts, x, 0.3, slip_length=0.0)
    with pytest.raises(ValueError, match="reference"):
        anchor_contacts(model, x, rest.contacts, x[:-1], 0.3)
    assert len(anchor_contacts(model, x, rest.contacts, x, 0.0)) == 0
    assert len(anchor_contacts(model, x, rest.contacts, x, 0.3)) > 0


# A warm start changes the path to the equilibrium, not the equilibrium: both solves stop within
# the penetration tolerance (1e-5 of the radius sum, 2e-9 m here) of the constraint surface, so
# their nodes may differ by that much (1.9e-10 m measured).
WARM_START_ATOL = 1e-5 * 2 * RADIUS


def test_a_solve_warm_started_from_the_last_multipliers_lands_on_the_same_equilibrium_in_fewer_iterations():
    """The pressed rod's jaw moved a little (a load step): solved from the rest solution's contact
    multipliers (``solve(contacts=...)``, how lagged passes and load steps start) it reaches the
    equilibrium the solve from zero multipliers does, with fewer Newton iterations (measured 4
    against 8: no multiplier update pushes the residual back up)."""
    model, loads, jaw = _dragged_rod(1.0)
    solver = QuasiStaticSolver(model, QuasiStaticOptions(force_tolerance=1e-10, torque_tolerance=1e-10))
    rest = solver.solve(RodState.from_model(model), loads)
    moved = rest.state.node_position.copy()
    moved[jaw, 0] += 0.05 * RADIUS
    guess = RodState(moved, rest.state.edge_quaternion, np.zeros_like(moved), np.zeros((model.n_edges, 3)))
    cold = solver.solve(guess, loads)
    warm = solver.solve(guess, loads, contacts=rest.contacts)
    assert cold.converged and warm.converged
    assert np.allclose(warm.state.node_position, cold.state.node_position, rtol=0.0, atol=WARM_START_ATOL)
    assert warm.iterations < cold.iterations


def test_a_warm_start_refuses_another_models_contacts():
    model, loads, _ = _dragged_rod(1.0)
    rest = QuasiStaticSolver(model).solve(RodState.from_model(model), loads)
    straight = np.column_stack([np.linspace(0, 1e-3, 4), np.zeros(4), np.zeros(4)])
    other = RodModel.from_rods([Rod(straight, RADIUS, YARN)])
    with pytest.raises(ValueError, match="edges"):
        QuasiStaticSolver(other).solve(RodState.from_model(other), contacts=rest.contacts)


def test_a_load_step_starts_from_the_last_multipliers_at_base_penalties():
    """``lagged_solve`` is a new load step: its first pass starts from the multipliers of
    ``anchors_from`` with their penalties back at base (``ContactSet.with_base_penalties``), and
    each later pass from the contacts the pass before it reached, penalties included."""
    model, loads, jaw = _dragged_rod(1.0)
    solver = QuasiStaticSolver(model, QuasiStaticOptions(force_tolerance=1e-10, torque_tolerance=1e-10))
    rest = solver.solve(RodState.from_model(model), loads)
    stiffened = dataclasses.replace(rest.contacts, stiffening=np.full_like(rest.contacts.stiffening, 100.0))
    moved = rest.state.node_position.copy()
    moved[jaw, 0] += 3e-3 * 2 * RADIUS
    guess = RodState(moved, rest.state.edge_quaternion, np.zeros_like(moved), np.zeros((model.n_edges, 3)))
    started, reached = [], []
    solve = solver.solve

    def recording(*args, contacts=None, **kwargs):
        started.append(contacts)
        reached.append(solve(*args, contacts=contacts, **kwargs))
        return reached[-1]

    solver.solve = recording
    lagged = lagged_solve(solver, guess, rest.state.node_position, 0.3,
                          anchors_from=(rest.state.node_position, stiffened), loads=loads, tolerance=LAG_SETTLED)
    assert lagged.result.converged and lagged.passes == len(started) >= 2
    assert np.all(started[0].stiffening == 1.0) and np.array_equal(started[0].multiplier, rest.contacts.multiplier)
    assert np.all(stiffened.stiffening == 100.0)  # the caller's record is left alone
    assert all(later is before.contacts for later, before in zip(started[1:], reached))


def test_a_load_step_that_fails_is_taken_in_halves_and_halves_again():
    # A step is accepted when it spans at most a quarter: one from 0 to 1 is taken as four
    # quarters after the whole and both halves failed; every step tried is returned for its cost.
    def take(start, low, high):
        return (start, low, high)

    def accepted(step):
        return step[2] - step[1] <= 0.25

    path, tried = in_halves(take, accepted, lambda step: f"at {step[2]:g}", "rest", 0.0, 1.0, halvings=2)
    assert [(low, high) for _, low, high in path] == [(0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 1.0)]
    assert [start for start, _, _ in path] == ["rest", "at 0.25", "at 0.5", "at 0.75"]
    assert [(low, high) for _, low, high in tried] == [(0.0, 1.0), (0.0, 0.5), (0.0, 0.25), (0.25, 0.5),
                                                       (0.5, 1.0), (0.5, 0.75), (0.75, 1.0)]
    # One halving fewer: the halves fail too, and the path is the whole step, not accepted.
    path, tried = in_halves(take, accepted, lambda step: step[2], "rest", 0.0, 1.0, halvings=1)
    assert path == [("rest", 0.0, 1.0)] and len(tried) == 2
    # Accepted at once: one step.
    assert in_halves(take, lambda step: True, lambda step: step[2], "rest", 0.0, 1.0) == ([("rest", 0.0, 1.0)],) * 2
    # A second half that fails ends the path on it, after the first half that held.
    path, _ = in_halves(take, lambda step: step[2] <= 0.5, lambda step: step[2], "rest", 0.0, 1.0, halvings=1)
    assert path == [("rest", 0.0, 0.5), (0.5, 0.5, 1.0)]
