"""The quasi-static solver against an independent minimiser of the same discrete energy.

Reference: scipy's BFGS on ``energy(...).total`` with its exact gradient from ``energy_gradient``,
over free node positions and unnormalised 4-vectors ``u`` with frames ``q = u / |u|`` (chain rule:
``∂U/∂u = (I − q qᵀ) g_q / |u|`` with the tangential quaternion gradient ``g_q = 2 (0, τ) ⊗ q``,
τ the torque-like gradient). Nothing of the Newton solver (Hessian, line search, rotation chart)
is used by the reference.
"""

import numpy as np
import pytest
from scipy.optimize import minimize

from yarnfit.engine import (
    Loads,
    QuasiStaticOptions,
    QuasiStaticSolver,
    Rod,
    RodMaterial,
    RodModel,
    RodState,
    energy,
    energy_gradient,
    straight_points,
)

# Acceptance of the issue: relative energy error below 1e-4 and positions within 1e-4 L.
ENERGY_RTOL = 1e-4
POSITION_ATOL_PER_LENGTH = 1e-4
# The reference itself must be converged far below those: BFGS is asked for a largest gradient
# component below 1e-10 of the largest applied force (N, or N·m per m of rod for frames) and must
# reach 1e-7, which bounds its own position error at ~1e-7 of the load-induced displacement.
REFERENCE_GTOL = 1e-10
REFERENCE_ACCEPT = 1e-7
# Newton polish of the BFGS result (below) and its central-difference step, relative to the
# largest coordinate: round-off ε/h ~ 1e-10 and truncation h² ~ 1e-12 of the Hessian entries.
REFERENCE_NEWTON_STEPS = 5
REFERENCE_FD_STEP = 1e-6


def _quat_mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def scipy_equilibrium(model: RodModel, loads: Loads, start: RodState) -> RodState:
    load_scale = float(np.linalg.norm(loads.total_node_force(model), axis=1).max())
    free_nodes = np.flatnonzero(~model.node_pinned)
    free_edges = np.flatnonzero(~model.edge_pinned)
    n_pos = 3 * free_nodes.size

    def unpack(z):
        s = start.copy()
        s.node_position[free_nodes] = z[:n_pos].reshape(-1, 3)
        u = z[n_pos:].reshape(-1, 4)
        s.edge_quaternion[free_edges] = u / np.linalg.norm(u, axis=1, keepdims=True)
        return s, u

    def fun(z):
        s, u = unpack(z)
        terms, node_gradient, edge_gradient = energy_gradient(model, s, loads)
        grad_u = np.empty_like(u)
        for k, e in enumerate(free_edges):
            q = s.edge_quaternion[e]
            g_q = 2.0 * _quat_mul((0.0, *edge_gradient[e]), q)
            grad_u[k] = (g_q - q * (q @ g_q)) / np.linalg.norm(u[k])
        return terms.total, np.concatenate([node_gradient[free_nodes].ravel(), grad_u.ravel()])

    z = np.concatenate([start.node_position[free_nodes].ravel(), start.edge_quaternion[free_edges].ravel()])
    result = minimize(fun, z, jac=True, method="BFGS", options={"gtol": REFERENCE_GTOL * load_scale, "maxiter": 100000})
    z = result.x
    _, grad = fun(z)
    # BFGS can stop on "precision loss" (no decrease its line search can see in float64) short of
    # the gradient asked for (the rod pinned at both ends: 1.8e-7 of the load). Newton steps on a
    # central-difference Hessian of the same gradient finish the job, pseudo-inverted because the
    # quaternions' norms are free directions of z.
    for _ in range(REFERENCE_NEWTON_STEPS):
        if np.abs(grad).max() < REFERENCE_ACCEPT * load_scale:
            break
        h = REFERENCE_FD_STEP * max(1.0, float(np.abs(z).max()))
        hessian = np.column_stack([(fun(z + h * e)[1] - fun(z - h * e)[1]) / (2 * h) for e in np.eye(z.size)])
        z = z - np.linalg.lstsq(0.5 * (hessian + hessian.T), grad, rcond=1e-12)[0]
        _, grad = fun(z)
    assert np.abs(grad).max() < REFERENCE_ACCEPT * load_scale, f"reference did not converge: {result.message}"
    return unpack(z)[0]


def compare(model: RodModel, loads: Loads, length: float) -> None:
    start = RodState.from_model(model)
    ours = QuasiStaticSolver(model, QuasiStaticOptions(contact=False)).solve(start, loads)
    assert ours.converged
    reference = scipy_equilibrium(model, loads, start)
    e_ours = energy(model, ours.state, loads).total
    e_ref = energy(model, reference, loads).total
    assert abs(e_ours - e_ref) <= ENERGY_RTOL * abs(e_ref)
    assert np.abs(ours.state.node_position - reference.node_position).max() <= POSITION_ATOL_PER_LENGTH * length
    # The solver reports the same energy as energy() for forces only.
    assert ours.energy.total == pytest.approx(e_ours, rel=1e-12)


def test_clamped_curved_rod_with_hardening_under_tip_force_and_gravity():
    # A clamped helical arc (curved and twisted rest shape, nonlinear stretch) under a 3D tip force
    # and its weight: large rotations (the tip moves by a third of the arc length) and a few percent
    # of axial strain, so bending, twisting, hardening stretch and shear are all active.
    t = np.linspace(0.0, 1.2, 7)
    points = np.column_stack([0.05 * np.sin(t), 0.05 * (1 - np.cos(t)), 0.01 * t])
    mat = RodMaterial(5e6, 0.3, 1.5e3, hardening_tension=4e7, hardening_compression=1e7)
    model = RodModel.from_rods([Rod(points, 4e-3, mat, pinned_nodes=[0], pinned_frames=[0])])
    loads = Loads.zeros(model, gravity=(0.0, 0.0, -9.81))
    loads.node_force[-1] = (6.0, -0.4, 0.3)
    compare(model, loads, length=0.06)


def test_rod_pinned_at_both_ends_under_lateral_loads():
    # Points pinned at both ends (frames free): a bent, stretched rod with a free twist mode.
    mat = RodMaterial(2e6, 0.4, 1e3)
    model = RodModel.from_rods([Rod(straight_points(0.1, 6), 5e-3, mat, pinned_nodes=[0, -1])])
    loads = Loads.zeros(model)
    loads.node_force[2] = (0.0, 0.4, -1.0)
    loads.node_force[4] = (0.0, -0.2, -0.6)
    compare(model, loads, length=0.1)


def test_two_rods_and_a_closed_loop():
    # Several rods in one model, one of them a closed loop held at one node and one frame.
    mat = RodMaterial(3e6, 0.3, 1e3)
    angle = np.linspace(0.0, 2 * np.pi, 7)[:-1]
    loop = np.column_stack([0.02 * np.cos(angle), 0.02 * np.sin(angle), np.zeros(6)])
    rods = [
        Rod(loop, 3e-3, mat, closed=True, pinned_nodes=[0], pinned_frames=[0]),
        Rod(straight_points(0.05, 4, start=(0.0, 0.0, 0.05)), 3e-3, mat, pinned_nodes=[0], pinned_frames=[0]),
    ]
    model = RodModel.from_rods(rods)
    loads = Loads.zeros(model)
    loads.node_force[3] = (0.01, 0.0, 0.02)
    loads.node_force[-1] = (0.0, 0.01, -0.01)
    compare(model, loads, length=0.05)
