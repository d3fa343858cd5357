"""Numba kernels of the quasi-static solver's lagged Coulomb friction (see :mod:`yarnfit.engine.friction`).

Only ``@njit`` code lives here. An anchor is one sampled contact constraint frozen at the start of a
load step: the relative vector of its two contact points ``r(x) = Σ_m w_m (R_m x_m + t_m)`` over the
pair's four nodes (weights ``(1 − s, s, −(1 − t), −t)``, the pair's tile maps ``R_m, t_m``), a
tangent basis ``T (2, 3)`` of the plane normal to the contact, the tangential slip
``u = T r(x) − u0`` from where the anchor was set, a normal force ``N`` (N) and the friction
coefficient μ. Its energy is ``μ N f(|u|)`` with the smoothed slip ``f`` of Li et al. 2020
(Incremental Potential Contact, §5.1, the mollified ``f0``, shifted to vanish at zero slip):

    f(y) = y² / ε − y³ / (3 ε²)   for y < ε,      f(y) = y − ε / 3   beyond,

C¹ at ε, convex in ``u`` (``f`` is convex and increasing), so the friction force ``μ N f'(|u|)``
grows from zero with slope ``2 μ N / ε`` and saturates at the Coulomb bound ``μ N`` once the
anchor has slipped ``ε``.
"""

import math

import numpy as np
from numba import njit

from ._contact_kernels import _map, _pair_nodes, _pair_points, sample_closest_point
from ._quat import cross, dot, mat_t_vec, normalized, row3


@njit(cache=True)
def _tangent_basis(n, out, k):
    """Write an orthonormal basis of the plane normal to the unit vector ``n`` into
    ``out[k] (2, 3)``."""
    # Cross with the axis least aligned with n: never near-parallel.
    ax = abs(n[0])
    ay = abs(n[1])
    az = abs(n[2])
    if ax <= ay and ax <= az:
        e = (1.0, 0.0, 0.0)
    elif ay <= az:
        e = (0.0, 1.0, 0.0)
    else:
        e = (0.0, 0.0, 1.0)
    t1 = normalized(cross(n, e))
    t2 = cross(n, t1)
    for i in range(3):
        out[k, 0, i] = t1[i]
        out[k, 1, i] = t2[i]


@njit(cache=True, inline="always")
def _weighted_sum(pos, nodes, weight, rotation, translation):
    """``r = Σ_m w_m (R_m x_m + t_m)`` (m) over four nodes ``nodes (4,)`` with weights ``(4,)``
    and maps ``rotation (4, 3, 3)``, ``translation (4, 3)``."""
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    for m in range(4):
        x = _map(rotation[m], translation[m], row3(pos, nodes[m]))
        w = weight[m]
        r0 += w * x[0]
        r1 += w * x[1]
        r2 += w * x[2]
    return r0, r1, r2


@njit(cache=True, inline="always")
def _relative(pos, nodes, weight, rotation, translation, k):
    """The anchor ``k``'s relative vector ``r = Σ_m w_m (R_m x_m + t_m)`` (m)."""
    return _weighted_sum(pos, nodes[k], weight[k], rotation[k], translation[k])


@njit(cache=True)
def anchor_constraints(pos, reference_pos, edge_nodes, edge_samples, pairs, pair_rotation, pair_translation,
                       reference_rotation, reference_translation, constraint_start, force, out_nodes, out_weight,
                       out_rotation, out_translation, out_tangent, out_origin, out_normal_force):
    """Anchor every sampled constraint with a normal force ``force[c] > 0`` (N): its contact points
    and normal at ``pos (N, 3)``, its slip measured from where those points are at
    ``reference_pos (N, 3)`` (m) under the pairs' maps there, ``reference_rotation``,
    ``reference_translation`` (the pair maps' shapes; the current ones unless the tiling itself
    was deformed since). Writes anchors from 0 (outputs sized for every constraint) and returns
    their count."""
    k = 0
    for p in range(pairs.shape[0]):
        nodes = _pair_nodes(edge_nodes, pairs, p)
        a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
        samples_a = edge_samples[pairs[p, 0]]
        samples_b = edge_samples[pairs[p, 1]]
        for c in range(samples_a + samples_b):
            if force[constraint_start[p] + c] <= 0.0:
                continue
            _, _, n = sample_closest_point(c, samples_a, samples_b, a0, a1, b0, b1, out_weight[k])
            for m in range(4):
                out_nodes[k, m] = nodes[m]
                out_rotation[k, m] = pair_rotation[p, m]
                out_translation[k, m] = pair_translation[p, m]
            _tangent_basis(n, out_tangent, k)
            r = _weighted_sum(reference_pos, out_nodes[k], out_weight[k], reference_rotation[p],
                              reference_translation[p])
            for i in range(2):
                out_origin[k, i] = dot(row3(out_tangent[k], i), r)
            out_normal_force[k] = force[constraint_start[p] + c]
            k += 1
    return k


@njit(cache=True)
def _slip(pos, nodes, weight, rotation, translation, tangent, origin, k):
    """The anchor ``k``'s tangential slip ``u = T r(x) − u0`` (m)."""
    r = _relative(pos, nodes, weight, rotation, translation, k)
    return dot(row3(tangent[k], 0), r) - origin[k, 0], dot(row3(tangent[k], 1), r) - origin[k, 1]


@njit(cache=True)
def friction_energy_gradient(pos, nodes, weight, rotation, translation, tangent, origin, bound, slip_length,
                             node_grad, node_scale, out_force):
    """Friction energy (J) of all anchors, ``bound[k] = μ N`` (N) each, smoothing length
    ``slip_length`` ε (m). Adds the gradient into ``node_grad (N, 3)`` and force magnitudes into
    ``node_scale``; writes each anchor's friction force magnitude (N) into ``out_force``."""
    energy = 0.0
    eps = slip_length
    for k in range(nodes.shape[0]):
        u0, u1 = _slip(pos, nodes, weight, rotation, translation, tangent, origin, k)
        y = math.sqrt(u0 * u0 + u1 * u1)
        if y < eps:
            energy += bound[k] * (y * y / eps - y * y * y / (3.0 * eps * eps))
            ratio = bound[k] * (2.0 / eps - y / (eps * eps))  # μN f'(y) / y
        else:
            energy += bound[k] * (y - eps / 3.0)
            ratio = bound[k] / y
        out_force[k] = ratio * y
        if ratio * y == 0.0:
            continue
        # ∂E/∂u = ratio u; ∂u/∂x_m = w_m T R_m
        gu = (ratio * u0, ratio * u1)
        world = (tangent[k, 0, 0] * gu[0] + tangent[k, 1, 0] * gu[1],
                 tangent[k, 0, 1] * gu[0] + tangent[k, 1, 1] * gu[1],
                 tangent[k, 0, 2] * gu[0] + tangent[k, 1, 2] * gu[1])
        for m in range(4):
            w = weight[k, m]
            g = mat_t_vec(rotation[k, m], world)
            i = nodes[k, m]
            for j in range(3):
                node_grad[i, j] += w * g[j]
            node_scale[i] += abs(w) * math.sqrt(dot(g, g))
    return energy


@njit(cache=True)
def friction_hessian_coo(pos, nodes, weight, rotation, translation, tangent, origin, bound, slip_length, rows, cols,
                         vals, start):
    """Hessian of the friction energy as COO triplets (144 per anchor) from ``start``; returns the
    new entry count. In slip coordinates it is ``μN (f'/y I + (f'' y − f')/y³ u uᵀ)``, positive
    semidefinite for every y (``2/ε − 2y/ε²`` and ``2/ε − y/ε²`` below ε, ``0`` and ``1/y``
    beyond), so the friction term never spoils a Newton direction."""
    eps = slip_length
    jac = np.empty((2, 12))
    hu = np.empty((2, 2))
    idx = start
    for k in range(nodes.shape[0]):
        u0, u1 = _slip(pos, nodes, weight, rotation, translation, tangent, origin, k)
        y = math.sqrt(u0 * u0 + u1 * u1)
        if y < eps:
            along = 2.0 / eps - y / (eps * eps)
            # (f'' y − f') / y³ = −1 / (ε² y); times u uᵀ it stays bounded as y → 0
            outer = -1.0 / (eps * eps * y) if y > 0.0 else 0.0
        else:
            along = 1.0 / y
            outer = -1.0 / (y * y * y)
        hu[0, 0] = bound[k] * (along + outer * u0 * u0)
        hu[0, 1] = bound[k] * outer * u0 * u1
        hu[1, 0] = hu[0, 1]
        hu[1, 1] = bound[k] * (along + outer * u1 * u1)
        for m in range(4):
            for a in range(2):
                g = mat_t_vec(rotation[k, m], row3(tangent[k], a))
                for j in range(3):
                    jac[a, 3 * m + j] = weight[k, m] * g[j]
        for i in range(12):
            for j in range(12):
                value = 0.0
                for a in range(2):
                    for b in range(2):
                        value += jac[a, i] * hu[a, b] * jac[b, j]
                rows[idx] = 3 * nodes[k, i // 3] + i % 3
                cols[idx] = 3 * nodes[k, j // 3] + j % 3
                vals[idx] = value
                idx += 1
    return idx
