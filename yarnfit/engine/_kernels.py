"""Numba kernels of the Cosserat rod model: element energies and gradients, Hessian assembly, XPBD
projections and constraint colouring.

Only ``@njit`` code lives here; orchestration is in ``energy.py``, ``xpbd.py`` and
``quasistatic.py``. Every kernel works on the flat arrays of :class:`~yarnfit.engine.model.RodModel`
and writes into output arrays passed by the caller.

Formulas (``docs/design.md`` §4, paper Eq. yarn_energy):

stretch–shear, per edge ``e = (p0, p1, q)`` with rest length ``l0``::

    c = R(q)ᵀ (p1 + offset − p0) / l0 − e3                 (material frame)
    U = l0 [ ½ GA (c1² + c2²) + ½ EA c3² + h |c3|³ / 6 ]     h = A k_tension if c3 > 0 else A k_compression

The cubic term is the exact integral of the nonlinear axial force law ``N(ε) = EA ε + ½ h ε|ε|``,
whose tangent modulus ``dN/dε / A = E + k |ε|`` grows linearly with strain (paper §4.1).

bend–twist, per joint between edges ``a`` and ``b`` with mean rest length ``l̄``::

    Ω = q̄a qb,   s = sign⟨Ω, Ω0⟩,   C = Im(Ω) − s Im(Ω0)
    U = (2 / l̄) (EI1 C1² + EI2 C2² + GJ C3²)

Gradients are taken with respect to node positions and to world-frame rotation vectors ``θ``
acting as ``q ← exp(θ) ⊗ q`` (the "torque" ∂U/∂θ, N·m).
"""

import math

import numpy as np
from numba import njit, prange

from ._quat import (
    cross,
    mat_t_vec,
    mat_vec,
    norm,
    pull_back_block,
    quat_between,
    quat_conj,
    quat_mul,
    quat_normalized,
    quat_rotate,
    quat_rotate_inv,
    quat_rotate_world,
    row3,
    row4,
)

# ---------------------------------------------------------------------------------------------
# Elements
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def axial_force(strain, stretch_stiffness, hardening):
    """Axial force ``N(ε) = EA ε + ½ h ε|ε|`` (N) and its tangent ``dN/dε`` (N)."""
    a = abs(strain)
    return stretch_stiffness * strain + 0.5 * hardening * strain * a, stretch_stiffness + hardening * a


@njit(cache=True)
def element_stress(p0, p1, q, rest_length, shear_stiffness, stretch_stiffness, hard_c, hard_t):
    """Strain and stress of a stretch–shear element.

    Returns ``(c, σ, dN/dε, h)``: the material-frame strain ``c = R(q)ᵀ (p1 − p0) / l0 − e3``, the
    stress resultant ``σ = (GA c1, GA c2, N(c3))`` (N, material frame), the axial tangent (N) and
    the axial hardening ``h`` in use (N, tension or compression by the sign of c3).
    """
    inv_l0 = 1.0 / rest_length
    cm = quat_rotate_inv(q, ((p1[0] - p0[0]) * inv_l0, (p1[1] - p0[1]) * inv_l0, (p1[2] - p0[2]) * inv_l0))
    c3 = cm[2] - 1.0
    hard = hard_t if c3 > 0.0 else hard_c
    n3, tangent = axial_force(c3, stretch_stiffness, hard)
    return (cm[0], cm[1], c3), (shear_stiffness * cm[0], shear_stiffness * cm[1], n3), tangent, hard


@njit(cache=True)
def stretch_shear_element(p0, p1, q, rest_length, shear_stiffness, stretch_stiffness, hard_c, hard_t):
    """Energy and gradient of one stretch–shear element.

    Args:
        p0, p1: end points (m), ``p1`` already shifted by the edge offset.
        q: edge frame (unit quaternion).
        rest_length: l0 (m).
        shear_stiffness: GA (N). stretch_stiffness: EA (N).
        hard_c, hard_t: axial hardening ``A k`` in compression and tension (N).

    Returns:
        ``(U_stretch, U_shear, n, tau)``: energies (J), ``n = ∂U/∂p1 = −∂U/∂p0`` (N, world) and
        ``tau = ∂U/∂θ`` (N·m, world).
    """
    c, stress, _, hard = element_stress(p0, p1, q, rest_length, shear_stiffness, stretch_stiffness, hard_c, hard_t)
    a3 = abs(c[2])
    u_shear = 0.5 * rest_length * shear_stiffness * (c[0] * c[0] + c[1] * c[1])
    u_stretch = rest_length * (0.5 * stretch_stiffness * c[2] * c[2] + hard * a3 * a3 * a3 / 6.0)
    # ∂U/∂p1 = (∂c/∂p1)ᵀ l0 σ = R σ;  ∂U/∂θ = (R σ) × (p1 − p0)
    n = quat_rotate(q, stress)
    tau = cross(n, (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]))
    return u_stretch, u_shear, n, tau


@njit(cache=True)
def _darboux_jacobian_product(w, u, m):
    """``Jᵀ m`` with ``J = ∂v/∂φ = (w² I − w [u]× + u uᵀ) / (2 w²)``, the derivative of
    ``v = u / w`` (``Ω = (w, u) = q̄a qb``) with respect to a turn ``φ`` of ``qb`` expressed in
    ``qa``'s frame (``δw = −½ u·δφ``, ``δu = ½ (w δφ + δφ × u)``)."""
    um = cross(u, m)
    udm = u[0] * m[0] + u[1] * m[1] + u[2] * m[2]
    c = 0.5 / (w * w)
    return (c * (w * w * m[0] + w * um[0] + u[0] * udm),
            c * (w * w * m[1] + w * um[1] + u[1] * udm),
            c * (w * w * m[2] + w * um[2] + u[2] * udm))


@njit(cache=True)
def _bend_twist_strain(om, rest_darboux):
    """``C = v(Ω) − v(Ω0)`` with ``v = Im / Re`` (:func:`bend_twist_element`); ``Re Ω ≠ 0``."""
    w, w0 = om[0], rest_darboux[0]
    return (om[1] / w - rest_darboux[1] / w0, om[2] / w - rest_darboux[2] / w0, om[3] / w - rest_darboux[3] / w0)


@njit(cache=True)
def bend_twist_element(qa, qb, rest_darboux, mean_rest_length, bend1, bend2, twist):
    """Energy and gradient of one bend–twist element.

    ``C = v(q̄a qb) − v(Ω0)`` with ``v(Ω) = Im Ω / Re Ω``, which is ``tan(φ/2) n`` for a turn ``φ``
    about ``n`` (the paper's curvature ``(2/l̄) Im/Re``). It is the same for ``Ω`` and ``−Ω``, so no
    sign needs choosing, and it grows without bound as the two frames turn half a turn apart: a
    node cannot fold a rod back on itself (docs/design.md §4).

    Args:
        qa, qb: frames of the two edges (unit quaternions).
        rest_darboux: ``Ω0 = q̄a qb`` in the rest state.
        mean_rest_length: l̄ (m). bend1, bend2: EI1, EI2 (N·m²). twist: GJ (N·m²).

    Returns:
        ``(U_bend, U_twist, tau_b)`` with ``tau_b = ∂U/∂θb = −∂U/∂θa`` (N·m, world); the energies
        are infinite (and ``tau_b`` zero) when the frames are exactly half a turn apart.
    """
    om = quat_mul(quat_conj(qa), qb)
    w = om[0]
    if w == 0.0:
        return math.inf, math.inf, (0.0, 0.0, 0.0)
    k1, k2, k3 = _bend_twist_strain(om, rest_darboux)
    f = 2.0 / mean_rest_length
    u_bend = f * (bend1 * k1 * k1 + bend2 * k2 * k2)
    u_twist = f * twist * k3 * k3
    # m = ∂U/∂C; tau_b = R(qa) Jᵀ m (see _darboux_jacobian_product).
    m = (2.0 * f * bend1 * k1, 2.0 * f * bend2 * k2, 2.0 * f * twist * k3)
    tau_b = quat_rotate(qa, _darboux_jacobian_product(w, (om[1], om[2], om[3]), m))
    return u_bend, u_twist, tau_b


@njit(cache=True)
def _edge_end(pos, edge_nodes, edge_end_rotation, edge_offset, e):
    """End point of edge ``e``: its end node mapped into the edge's tile, ``R x + c``."""
    r = mat_vec(edge_end_rotation[e], row3(pos, edge_nodes[e, 1]))
    return (r[0] + edge_offset[e, 0], r[1] + edge_offset[e, 1], r[2] + edge_offset[e, 2])


@njit(cache=True, inline="always")
def _edge_stretch_shear(pos, quat, rod, e):
    """:func:`stretch_shear_element` of edge ``e`` of the rods ``rod`` bundles at ``pos``, ``quat``."""
    (edge_nodes, edge_end_rotation, edge_offset, edge_rest_length, edge_shear_stiffness, edge_stretch_stiffness,
     edge_hardening, _, _, _, _, _) = rod
    return stretch_shear_element(
        row3(pos, edge_nodes[e, 0]),
        _edge_end(pos, edge_nodes, edge_end_rotation, edge_offset, e),
        row4(quat, e),
        edge_rest_length[e],
        edge_shear_stiffness[e],
        edge_stretch_stiffness[e],
        edge_hardening[e, 0],
        edge_hardening[e, 1],
    )


# ---------------------------------------------------------------------------------------------
# Whole-model energy and gradient
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def rod_energy_gradient(
    pos,
    quat,
    rod,
    node_grad,
    edge_grad,
    node_scale,
    edge_scale,
):
    """Internal rod energy, its gradient, and the magnitude sums used as residual scales, of the
    rods whose rest data ``rod`` bundles (:class:`~yarnfit.engine.model.RodArrays`).

    An edge's end point is its end node mapped by ``edge_end_rotation (E, 3, 3)`` and
    ``edge_offset (E, 3)`` (identity and zero within a tile; the map onto a neighbouring tile for a
    ghost edge); a joint compares its first frame with its second frame turned by
    ``joint_frame_rotation (J, 4)`` (the second edge seen from the first edge's tile).

    Adds into ``node_grad (N, 3)`` (N), ``edge_grad (E, 3)`` (N·m), ``node_scale (N,)`` and
    ``edge_scale (E,)`` (sum of the magnitudes of every contribution, the scale a residual is
    measured against). Returns ``(U_stretch, U_shear, U_bend, U_twist)`` in J.
    """
    (edge_nodes, edge_end_rotation, edge_offset, edge_rest_length, edge_shear_stiffness, edge_stretch_stiffness,
     edge_hardening, joint_edges, joint_frame_rotation, joint_rest_darboux, joint_rest_length, joint_stiffness) = rod
    u_stretch = 0.0
    u_shear = 0.0
    u_bend = 0.0
    u_twist = 0.0
    for e in range(edge_nodes.shape[0]):
        i0 = edge_nodes[e, 0]
        i1 = edge_nodes[e, 1]
        us, uh, n, tau = _edge_stretch_shear(pos, quat, rod, e)
        u_stretch += us
        u_shear += uh
        nn = norm(n)
        n1 = mat_t_vec(edge_end_rotation[e], n)
        for k in range(3):
            node_grad[i0, k] -= n[k]
            node_grad[i1, k] += n1[k]
            edge_grad[e, k] += tau[k]
        node_scale[i0] += nn
        node_scale[i1] += nn
        edge_scale[e] += norm(tau)
    for j in range(joint_edges.shape[0]):
        a = joint_edges[j, 0]
        b = joint_edges[j, 1]
        rho = row4(joint_frame_rotation, j)
        ub, ut, tau_b = bend_twist_element(
            row4(quat, a),
            quat_mul(rho, row4(quat, b)),
            row4(joint_rest_darboux, j),
            joint_rest_length[j],
            joint_stiffness[j, 0],
            joint_stiffness[j, 1],
            joint_stiffness[j, 2],
        )
        u_bend += ub
        u_twist += ut
        tn = norm(tau_b)
        # ρ exp(θ) q = exp(R(ρ) θ) ρ q: a rotation θ of frame b turns the mapped frame by R(ρ) θ.
        tau_own = quat_rotate_inv(rho, tau_b)
        for k in range(3):
            edge_grad[a, k] -= tau_b[k]
            edge_grad[b, k] += tau_own[k]
        edge_scale[a] += tn
        edge_scale[b] += tn
    return u_stretch, u_shear, u_bend, u_twist


@njit(cache=True)
def stretch_shear_forces(pos, quat, rod, out):
    """The force ``n`` (N, world) each stretch–shear element exerts on its start node, written into
    ``out (E, 3)``: the yarn's tension and shear resultant ``R σ`` carried along the edge (the
    element exerts ``−n``, mapped into the end node's tile, on its end node). Only these elements
    join nodes: a bend–twist element acts on frames alone."""
    for e in range(rod[0].shape[0]):
        _, _, n, _ = _edge_stretch_shear(pos, quat, rod, e)
        for k in range(3):
            out[e, k] = n[k]


# ---------------------------------------------------------------------------------------------
# Hessian: analytic for stretch–shear, central differences of the analytic gradient for bend–twist
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def stretch_shear_hessian(p0, p1, q, rest_length, shear_stiffness, axial_tangent, stress, out):
    """Hessian ``(9, 9)`` of a stretch–shear element over (p0, p1, θ), written into ``out``.

    ``H = (1/l0) Bᵀ D B + H_geo(n)`` with ``B = [−Rᵀ, Rᵀ, Rᵀ[e]×]`` (so ``∂c/∂(p0, p1, θ) = B / l0``),
    ``D = diag(GA, GA, dN/dε)`` and the geometric part of the stress resultant ``n = R σ``:
    ``H[p0, θ] = [n]×``, ``H[p1, θ] = −[n]×``, ``H[θ, θ] = sym([e]×[n]×)`` (the symmetric part is the
    Hessian in the exponential chart). ``axial_tangent`` (dN/dε, N) and ``stress`` (σ, N, material
    frame) come from :func:`element_stress`.
    """
    w, x, y, z = q
    # R(q) columns d1, d2, d3
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r01 = 2.0 * (x * y - w * z)
    r02 = 2.0 * (x * z + w * y)
    r10 = 2.0 * (x * y + w * z)
    r11 = 1.0 - 2.0 * (x * x + z * z)
    r12 = 2.0 * (y * z - w * x)
    r20 = 2.0 * (x * z - w * y)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    ex = p1[0] - p0[0]
    ey = p1[1] - p0[1]
    ez = p1[2] - p0[2]
    # Row k of B: (−d_k, d_k, d_k × e), the directors d_k being the rows of Rᵀ.
    d = ((r00, r10, r20), (r01, r11, r21), (r02, r12, r22))
    stiff = (shear_stiffness, shear_stiffness, axial_tangent)
    inv_l0 = 1.0 / rest_length
    for i in range(9):
        for j in range(9):
            out[i, j] = 0.0
    for kk in range(3):
        dk = d[kk]
        # d_kᵀ [e]× θ = d_k · (e × θ) = (d_k × e) · θ
        ce = cross(dk, (ex, ey, ez))
        row = (-dk[0], -dk[1], -dk[2], dk[0], dk[1], dk[2], ce[0], ce[1], ce[2])
        f = stiff[kk] * inv_l0
        for i in range(9):
            ri = row[i] * f
            for j in range(9):
                out[i, j] += ri * row[j]
    n = quat_rotate(q, (stress[0], stress[1], stress[2]))
    # [n]× entries
    nx = ((0.0, -n[2], n[1]), (n[2], 0.0, -n[0]), (-n[1], n[0], 0.0))
    ex3 = ((0.0, -ez, ey), (ez, 0.0, -ex), (-ey, ex, 0.0))
    for i in range(3):
        for j in range(3):
            out[i, 6 + j] += nx[i][j]
            out[6 + j, i] += nx[i][j]
            out[3 + i, 6 + j] -= nx[i][j]
            out[6 + j, 3 + i] -= nx[i][j]
            en = 0.0
            ne = 0.0
            for m in range(3):
                en += ex3[i][m] * nx[m][j]
                ne += nx[i][m] * ex3[m][j]
            out[6 + i, 6 + j] += 0.5 * (en + ne)


@njit(cache=True)
def _quat_matrix(q, out):
    """Rotation matrix ``(3, 3)`` of unit quaternion ``q`` into ``out``."""
    w, x, y, z = q
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - w * z)
    out[0, 2] = 2.0 * (x * z + w * y)
    out[1, 0] = 2.0 * (x * y + w * z)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - w * x)
    out[2, 0] = 2.0 * (x * z - w * y)
    out[2, 1] = 2.0 * (y * z + w * x)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True)
def _bend_local_gradient(qa, qb, theta_a, theta_b, rest, lbar, b1, b2, t, out):
    _, _, tau_b = bend_twist_element(
        quat_rotate_world(theta_a, qa), quat_rotate_world(theta_b, qb), rest, lbar, b1, b2, t
    )
    for k in range(3):
        out[k] = -tau_b[k]
        out[3 + k] = tau_b[k]


@njit(cache=True)
def _axis(component, length):
    """``length`` times the unit vector of axis ``component``."""
    return (length if component == 0 else 0.0, length if component == 1 else 0.0, length if component == 2 else 0.0)


@njit(cache=True)
def _shift(a, d, sign):
    return (a[0] + sign * d[0], a[1] + sign * d[1], a[2] + sign * d[2])


@njit(cache=True)
def _write_local(local, dofs, base, rows, cols, vals):
    """Symmetrise a local Hessian and append it to COO arrays at ``base``."""
    n = dofs.shape[0]
    idx = base
    for i in range(n):
        for j in range(n):
            rows[idx] = dofs[i]
            cols[idx] = dofs[j]
            vals[idx] = 0.5 * (local[i, j] + local[j, i])
            idx += 1
    return idx


@njit(cache=True)
def rod_hessian_coo(
    pos,
    quat,
    rod,
    fd_relative_step,
    rows,
    cols,
    vals,
):
    """Hessian of the internal rod energy (rest data bundled in ``rod``, a
    :class:`~yarnfit.engine.model.RodArrays`) as COO triplets (duplicates summed by the caller).

    Degrees of freedom: node ``i`` owns ``3i..3i+2`` (m), edge ``e`` owns ``3N+3e..3N+3e+2``
    (world rotation vector, rad). Stretch–shear elements are analytic
    (:func:`stretch_shear_hessian`). Bend–twist
    elements are central differences of their analytic gradient (rotations stepped by
    ``fd_relative_step`` rad), symmetrised: the symmetric part of the derivative of the world torque
    is the Hessian in the exponential chart, so only the O(step²) truncation error remains.
    Needs ``81 E + 36 J`` entries; returns the number written.
    """
    (edge_nodes, edge_end_rotation, edge_offset, edge_rest_length, edge_shear_stiffness, edge_stretch_stiffness,
     edge_hardening, joint_edges, joint_frame_rotation, joint_rest_darboux, joint_rest_length, joint_stiffness) = rod
    n_nodes = pos.shape[0]
    local9 = np.empty((9, 9))
    local6 = np.empty((6, 6))
    gp = np.empty(6)
    gm = np.empty(6)
    dofs9 = np.empty(9, dtype=np.int64)
    dofs6 = np.empty(6, dtype=np.int64)
    rho_matrix = np.empty((3, 3))
    zero = (0.0, 0.0, 0.0)
    idx = 0
    for e in range(edge_nodes.shape[0]):
        i0 = edge_nodes[e, 0]
        i1 = edge_nodes[e, 1]
        for k in range(3):
            dofs9[k] = 3 * i0 + k
            dofs9[3 + k] = 3 * i1 + k
            dofs9[6 + k] = 3 * n_nodes + 3 * e + k
        p0 = row3(pos, i0)
        p1 = _edge_end(pos, edge_nodes, edge_end_rotation, edge_offset, e)
        q = row4(quat, e)
        _, stress, tangent, _ = element_stress(p0, p1, q, edge_rest_length[e], edge_shear_stiffness[e],
                                               edge_stretch_stiffness[e], edge_hardening[e, 0], edge_hardening[e, 1])
        stretch_shear_hessian(p0, p1, q, edge_rest_length[e], edge_shear_stiffness[e], tangent, stress, local9)
        pull_back_block(local9, 3, edge_end_rotation[e])
        idx = _write_local(local9, dofs9, idx, rows, cols, vals)
    for j in range(joint_edges.shape[0]):
        a = joint_edges[j, 0]
        b = joint_edges[j, 1]
        qa = row4(quat, a)
        rho = row4(joint_frame_rotation, j)
        qb = quat_mul(rho, row4(quat, b))
        rest = row4(joint_rest_darboux, j)
        lbar = joint_rest_length[j]
        b1 = joint_stiffness[j, 0]
        b2 = joint_stiffness[j, 1]
        t = joint_stiffness[j, 2]
        for k in range(3):
            dofs6[k] = 3 * n_nodes + 3 * a + k
            dofs6[3 + k] = 3 * n_nodes + 3 * b + k
        hr = fd_relative_step
        for col in range(6):
            dp = _axis(col % 3, hr)
            dm = _shift(zero, dp, -1.0)
            if col < 3:
                _bend_local_gradient(qa, qb, dp, zero, rest, lbar, b1, b2, t, gp)
                _bend_local_gradient(qa, qb, dm, zero, rest, lbar, b1, b2, t, gm)
            else:
                _bend_local_gradient(qa, qb, zero, dp, rest, lbar, b1, b2, t, gp)
                _bend_local_gradient(qa, qb, zero, dm, rest, lbar, b1, b2, t, gm)
            for row in range(6):
                local6[row, col] = (gp[row] - gm[row]) * (0.5 / hr)
        # Differentiated with respect to the mapped frame's rotation: pull back by R(ρ).
        _quat_matrix(rho, rho_matrix)
        pull_back_block(local6, 3, rho_matrix)
        idx = _write_local(local6, dofs6, idx, rows, cols, vals)
    return idx


# ---------------------------------------------------------------------------------------------
# XPBD projections (Kugelstadt & Schömer 2016 with compliance, docs/design.md §4)
# ---------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def project_stretch_shear_one(
    e,
    pos,
    quat,
    node_inv_mass,
    edge_inv_qmass,
    edge_nodes,
    edge_offset,
    edge_rest_length,
    edge_shear_stiffness,
    edge_stretch_stiffness,
    edge_hardening,
    lam,
    inv_dt2,
):
    """One XPBD projection of the stretch–shear constraint of edge ``e``.

    ``lam (E, 3)`` holds the accumulated multipliers of the step (material frame, scaled by Δt²).
    Per material component k: ``Δλ_k = −(c_k + α̃_k λ_k) / (W + α̃_k)``, ``W = (w0 + w1)/l0² + 4 wq``,
    ``α̃_k = 1 / (Δt² l0 K_k)``; then ``g = R Δλ``, ``Δp0 = −(w0/l0) g``, ``Δp1 = (w1/l0) g``,
    ``Δq = −2 wq (0, g) ⊗ q ⊗ ē3`` (renormalised). The axial component uses the tangent compliance
    of the nonlinear force law: the residual ``Δt² ∂U/∂c3 + λ = 0`` is driven to zero by Newton
    steps (``c3`` becomes ``N(c3) / N'(c3)`` and ``K3`` becomes ``N'(c3)``), which reduces to the
    linear update when the hardening is zero.

    Inlined into the sweep loops: a Numba call passes each of its 13 arrays as a 7-word struct,
    which made a projection 40 % slower than the work it does.
    """
    i0 = edge_nodes[e, 0]
    i1 = edge_nodes[e, 1]
    w0 = node_inv_mass[i0]
    w1 = node_inv_mass[i1]
    wq = edge_inv_qmass[e]
    l0 = edge_rest_length[e]
    weight = (w0 + w1) / (l0 * l0) + 4.0 * wq
    if weight == 0.0:
        return
    q = row4(quat, e)
    inv_l0 = 1.0 / l0
    ev = (
        (pos[i1, 0] + edge_offset[e, 0] - pos[i0, 0]) * inv_l0,
        (pos[i1, 1] + edge_offset[e, 1] - pos[i0, 1]) * inv_l0,
        (pos[i1, 2] + edge_offset[e, 2] - pos[i0, 2]) * inv_l0,
    )
    c = quat_rotate_inv(q, ev)
    # Shear (linear): alpha = 1 / (l0 GA).
    alpha_shear = inv_dt2 / (l0 * edge_shear_stiffness[e])
    d0 = -(c[0] + alpha_shear * lam[e, 0]) / (weight + alpha_shear)
    d1 = -(c[1] + alpha_shear * lam[e, 1]) / (weight + alpha_shear)
    # Stretch (nonlinear): effective constraint ψ'/ψ'' and tangent compliance 1 / ψ''.
    c3 = c[2] - 1.0
    hard = edge_hardening[e, 1] if c3 > 0.0 else edge_hardening[e, 0]
    force, tangent = axial_force(c3, edge_stretch_stiffness[e], hard)
    alpha_stretch = inv_dt2 / (l0 * tangent)
    d2 = -(force / tangent + alpha_stretch * lam[e, 2]) / (weight + alpha_stretch)
    lam[e, 0] += d0
    lam[e, 1] += d1
    lam[e, 2] += d2
    g = quat_rotate(q, (d0, d1, d2))
    f0 = w0 * inv_l0
    f1 = w1 * inv_l0
    for k in range(3):
        pos[i0, k] -= f0 * g[k]
        pos[i1, k] += f1 * g[k]
    if wq > 0.0:
        # Δq = −2 wq (0, g) ⊗ q ⊗ ē3
        t = quat_mul(quat_mul((0.0, g[0], g[1], g[2]), q), (0.0, 0.0, 0.0, -1.0))
        qn = quat_normalized((q[0] - 2.0 * wq * t[0], q[1] - 2.0 * wq * t[1], q[2] - 2.0 * wq * t[2], q[3] - 2.0 * wq * t[3]))
        for k in range(4):
            quat[e, k] = qn[k]


@njit(cache=True, inline="always")
def project_bend_twist_one(
    j, quat, edge_inv_qmass, joint_edges, joint_rest_darboux, joint_rest_length, joint_stiffness, lam, inv_dt2
):
    """One XPBD projection of the bend–twist constraint of joint ``j`` (``lam (J, 3)``).

    ``C = v(q̄a qb) − v(Ω0)`` (:func:`bend_twist_element`), per component
    ``Δλ_k = −(C_k + α̃_k λ_k) / (4 (wa + wb) |J_k|² + α̃_k)`` with ``α̃_k = l̄ / (4 K_k Δt²)`` and
    ``J = ∂C/∂φ``; then each frame turns by ``±4 w R(qa) Jᵀ Δλ`` (world; a frame of inertia I is a
    quaternion particle of mass 4I), applied as ``q ← (q + ½ (0, δθ) q) / |·|``. Frames half a turn
    apart are left alone. Inlined into the sweep loops like :func:`project_stretch_shear_one`.
    """
    a = joint_edges[j, 0]
    b = joint_edges[j, 1]
    wa = edge_inv_qmass[a]
    wb = edge_inv_qmass[b]
    if wa + wb == 0.0:
        return
    qa = row4(quat, a)
    qb = row4(quat, b)
    rest = row4(joint_rest_darboux, j)
    om = quat_mul(quat_conj(qa), qb)
    w = om[0]
    if w == 0.0:
        return
    u = (om[1], om[2], om[3])
    strain = _bend_twist_strain(om, rest)
    scale_a = joint_rest_length[j] * 0.25 * inv_dt2
    delta = [0.0, 0.0, 0.0]
    for k in range(3):
        # Row k of J = (w² I − w [u]× + u uᵀ) / (2 w²) is Jᵀ e_k.
        row = _darboux_jacobian_product(w, u, _axis(k, 1.0))
        alpha = scale_a / joint_stiffness[j, k]
        c = strain[k]
        weight = 4.0 * (wa + wb) * (row[0] * row[0] + row[1] * row[1] + row[2] * row[2])
        delta[k] = -(c + alpha * lam[j, k]) / (weight + alpha)
        lam[j, k] += delta[k]
    turn = quat_rotate(qa, _darboux_jacobian_product(w, u, (delta[0], delta[1], delta[2])))
    for edge, q, sign in ((a, qa, -4.0 * wa), (b, qb, 4.0 * wb)):
        if sign != 0.0:
            t = quat_mul((0.0, 0.5 * sign * turn[0], 0.5 * sign * turn[1], 0.5 * sign * turn[2]), q)
            n = quat_normalized((q[0] + t[0], q[1] + t[1], q[2] + t[2], q[3] + t[3]))
            for k in range(4):
                quat[edge, k] = n[k]


@njit(cache=True, parallel=True)
def project_rods(
    pos,
    quat,
    node_inv_mass,
    edge_inv_qmass,
    rod,
    lam_edge,
    lam_joint,
    inv_dt2,
    edge_order,
    edge_color_start,
    joint_order,
    joint_color_start,
):
    """One Gauss–Seidel sweep over every stretch–shear and bend–twist constraint of the rods whose
    rest data ``rod`` bundles (:class:`~yarnfit.engine.model.RodArrays`), colour by colour.

    Constraints of one colour share no node and no edge frame (see :func:`greedy_coloring`), so a
    colour is a set of independent projections, run in parallel threads; colours run one after
    another. The result does not depend on the number of threads: on one, this is the serial sweep
    in colour order.
    """
    (edge_nodes, edge_end_rotation, edge_offset, edge_rest_length, edge_shear_stiffness, edge_stretch_stiffness,
     edge_hardening, joint_edges, joint_frame_rotation, joint_rest_darboux, joint_rest_length, joint_stiffness) = rod
    for c in range(edge_color_start.shape[0] - 1):
        start = edge_color_start[c]
        for k in prange(edge_color_start[c + 1] - start):
            project_stretch_shear_one(
                edge_order[start + k], pos, quat, node_inv_mass, edge_inv_qmass, edge_nodes, edge_offset,
                edge_rest_length, edge_shear_stiffness, edge_stretch_stiffness, edge_hardening, lam_edge, inv_dt2,
            )
    for c in range(joint_color_start.shape[0] - 1):
        start = joint_color_start[c]
        for k in prange(joint_color_start[c + 1] - start):
            project_bend_twist_one(
                joint_order[start + k], quat, edge_inv_qmass, joint_edges, joint_rest_darboux, joint_rest_length,
                joint_stiffness, lam_joint, inv_dt2,
            )


@njit(cache=True)
def greedy_coloring(resources, n_resources):
    """Colour constraints so that no two of one colour share a resource.

    ``resources (C, k)`` lists the resources (node or frame ids, ``-1`` for none) each constraint
    writes. Returns ``colors (C,)``. Greedy first-fit over at most 64 colours, tracked as a bit
    mask per resource.
    """
    n = resources.shape[0]
    colors = np.empty(n, dtype=np.int64)
    used = np.zeros(n_resources, dtype=np.uint64)
    for c in range(n):
        forbidden = np.uint64(0)
        for k in range(resources.shape[1]):
            r = resources[c, k]
            if r >= 0:
                forbidden |= used[r]
        color = 0
        while (forbidden >> np.uint64(color)) & np.uint64(1):
            color += 1
        if color >= 64:
            raise ValueError("constraint colouring needs more than 64 colours")
        colors[c] = color
        bit = np.uint64(1) << np.uint64(color)
        for k in range(resources.shape[1]):
            r = resources[c, k]
            if r >= 0:
                used[r] |= bit
    return colors


# ---------------------------------------------------------------------------------------------
# Time integration helpers (XPBD prediction and velocity update)
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def predict(pos, quat, vel, omega, node_inv_mass, edge_inv_inertia, node_accel, edge_torque, dt, prev_pos, prev_quat):
    """Symplectic Euler prediction of positions and frames; stores the step's start state."""
    for i in range(pos.shape[0]):
        for k in range(3):
            prev_pos[i, k] = pos[i, k]
        if node_inv_mass[i] > 0.0:
            for k in range(3):
                vel[i, k] += dt * node_accel[i, k]
                pos[i, k] += dt * vel[i, k]
    for e in range(quat.shape[0]):
        for k in range(4):
            prev_quat[e, k] = quat[e, k]
        if edge_inv_inertia[e] > 0.0:
            for k in range(3):
                omega[e, k] += dt * edge_inv_inertia[e] * edge_torque[e, k]
            theta = (dt * omega[e, 0], dt * omega[e, 1], dt * omega[e, 2])
            qn = quat_rotate_world(theta, row4(quat, e))
            for k in range(4):
                quat[e, k] = qn[k]


@njit(cache=True)
def update_velocities(pos, quat, vel, omega, node_inv_mass, edge_inv_inertia, prev_pos, prev_quat, dt, damping):
    """Velocities from the position change of the step, then linear damping ``exp(−damping dt)``."""
    decay = math.exp(-damping * dt)
    inv_dt = 1.0 / dt
    for i in range(pos.shape[0]):
        for k in range(3):
            vel[i, k] = (pos[i, k] - prev_pos[i, k]) * inv_dt * decay if node_inv_mass[i] > 0.0 else 0.0
    for e in range(quat.shape[0]):
        if edge_inv_inertia[e] > 0.0:
            dq = quat_mul(row4(quat, e), quat_conj(row4(prev_quat, e)))
            sgn = 1.0 if dq[0] >= 0.0 else -1.0
            # ω ≈ 2 Im(q q̄_prev) / dt (shortest arc)
            for k in range(3):
                omega[e, k] = 2.0 * sgn * dq[k + 1] * inv_dt * decay
        else:
            for k in range(3):
                omega[e, k] = 0.0


@njit(cache=True)
def rotate_frames(quat, theta, out):
    """``out[e] = exp(theta[e]) ⊗ quat[e]`` for frames ``(E, 4)`` and rotation vectors ``(E, 3)``."""
    for e in range(quat.shape[0]):
        qn = quat_rotate_world(row3(theta, e), row4(quat, e))
        for k in range(4):
            out[e, k] = qn[k]


@njit(cache=True)
def align_frames(quat, d3, tangent, out):
    """``out[e]``: frame ``quat[e]`` ``(E, 4)`` turned by the minimal rotation taking its third
    director ``d3[e]`` onto the unit ``tangent[e]`` ``(E, 3)``, normalised."""
    for e in range(quat.shape[0]):
        q = quat_mul(quat_between(row3(d3, e), row3(tangent, e)), row4(quat, e))
        length = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        for k in range(4):
            out[e, k] = q[k] / length


@njit(cache=True)
def assemble_csc(rows, cols, vals, count, dof_map, n_free):
    """Sum the first ``count`` COO triplets over full DOFs into a CSC matrix over the free DOFs
    (``dof_map``: full DOF → free index, −1 for a pinned one), in canonical form: row indices
    sorted within each column, duplicates summed in the order they were written, every diagonal
    entry stored (zero if none was written) and no explicit zero off the diagonal.

    One stable counting sort by row, then a sweep over the rows in order that appends each
    triplet to its column (so every column's rows come out sorted, and a duplicate lands next to
    the entry it adds to): O(count + n_free). Returns ``(indptr (n_free + 1,), indices, data,
    diagonal (n_free,))``, ``diagonal[j]`` the position of entry (j, j)."""
    # Triplets kept (their free indices, row −1 for a dropped one), counted per row and per column
    # (each column also holds its diagonal).
    mapped_row = np.empty(count, dtype=np.int64)
    mapped_column = np.empty(count, dtype=np.int64)
    row_start = np.zeros(n_free + 1, dtype=np.int64)
    column_room = np.ones(n_free + 1, dtype=np.int64)
    column_room[0] = 0
    for k in range(count):
        i = dof_map[rows[k]]
        j = dof_map[cols[k]]
        if j < 0:
            i = -1
        mapped_row[k] = i
        mapped_column[k] = j
        if i >= 0:
            row_start[i + 1] += 1
            column_room[j + 1] += 1
    for i in range(n_free):
        row_start[i + 1] += row_start[i]
        column_room[i + 1] += column_room[i]
    # Stable counting sort by row: each row's (column, value) in written order.
    by_row_column = np.empty(row_start[n_free], dtype=np.int64)
    by_row_value = np.empty(row_start[n_free])
    fill = row_start[:n_free].copy()
    for k in range(count):
        i = mapped_row[k]
        if i >= 0:
            by_row_column[fill[i]] = mapped_column[k]
            by_row_value[fill[i]] = vals[k]
            fill[i] += 1
    # Sweep the rows in order, appending to the columns (room for every triplet of a column).
    room_indices = np.empty(column_room[n_free], dtype=np.int64)
    room_data = np.empty(column_room[n_free])
    end = column_room[:n_free].copy()
    for i in range(n_free):
        # The diagonal entry first: a zero that the written (i, i) triplets then add to.
        room_indices[end[i]] = i
        room_data[end[i]] = 0.0
        end[i] += 1
        for t in range(row_start[i], row_start[i + 1]):
            j = by_row_column[t]
            e = end[j]
            if e > column_room[j] and room_indices[e - 1] == i:  # a duplicate of the last entry
                room_data[e - 1] += by_row_value[t]
            else:
                room_indices[e] = i
                room_data[e] = by_row_value[t]
                end[j] = e + 1
    # Compact the columns, dropping sums that cancelled off the diagonal.
    indptr = np.zeros(n_free + 1, dtype=np.int64)
    indices = np.empty(column_room[n_free], dtype=np.int64)
    data = np.empty(column_room[n_free])
    diagonal = np.empty(n_free, dtype=np.int64)
    n = 0
    for j in range(n_free):
        for t in range(column_room[j], end[j]):
            row = room_indices[t]
            if row == j:
                diagonal[j] = n
            elif room_data[t] == 0.0:
                continue
            indices[n] = row
            data[n] = room_data[t]
            n += 1
        indptr[j + 1] = n
    return indptr, indices[:n], data[:n], diagonal


@njit(cache=True)
def csc_slots(rows, cols, count, dof_map, n_free):
    """A fixed CSC pattern over the free DOFs for the first ``count`` COO triplets over full DOFs
    (``dof_map`` as :func:`assemble_csc`), every diagonal entry included, and where each triplet
    adds to: ``(indptr (n_free + 1,), indices, slot (count,))``, ``slot[k]`` the position of
    triplet k's entry (−1 for a triplet on a pinned DOF). For triplets whose positions never
    change (the rods'), so that :func:`scatter_add` assembles their values without sorting."""
    indptr, indices, _, _ = assemble_csc(rows, cols, np.ones(count), count, dof_map, n_free)
    slot = np.full(count, -1, dtype=np.int64)
    for k in range(count):
        i = dof_map[rows[k]]
        j = dof_map[cols[k]]
        if i < 0 or j < 0:
            continue
        lo, hi = indptr[j], indptr[j + 1]
        while lo < hi:  # binary search of row i in column j
            mid = (lo + hi) // 2
            if indices[mid] < i:
                lo = mid + 1
            else:
                hi = mid
        slot[k] = lo
    return indptr, indices, slot


@njit(cache=True)
def assemble_node_blocks(rows, cols, vals, count, dof_map, n_free, n_nodes):
    """Sum the first ``count`` COO triplets into a CSC matrix over the free DOFs (``dof_map`` as
    :func:`assemble_csc`; rows sorted within each column, duplicates summed, zeros kept, no
    diagonal added) when they come as the contact and friction Hessians write them: in groups of
    144, each a 12 × 12 block over the positions of four nodes written row-major (entry (i, j) of
    group g at ``144 g + 12 i + j``, on DOFs ``3 n[i // 3] + i % 3`` and ``3 n[j // 3] + j % 3``).
    Sorts each group's sixteen 3 × 3 node blocks instead of its 144 entries (counting sort by the
    column's node, insertion sort by the row's within a column): O(count + nodes). Returns
    ``(indptr (n_free + 1,), indices, data)``."""
    n_blocks = 16 * (count // 144)
    block_row = np.empty(n_blocks, dtype=np.int64)
    block_col = np.empty(n_blocks, dtype=np.int64)
    block_source = np.empty(n_blocks, dtype=np.int64)
    column_start = np.zeros(n_nodes + 1, dtype=np.int64)
    for g in range(count // 144):
        base = 144 * g
        for a in range(4):
            for b in range(4):
                k = 16 * g + 4 * a + b
                block_row[k] = rows[base + 36 * a] // 3
                block_col[k] = cols[base + 3 * b] // 3
                block_source[k] = base + 36 * a + 3 * b
                column_start[block_col[k] + 1] += 1
    for n in range(n_nodes):
        column_start[n + 1] += column_start[n]
    order = np.empty(n_blocks, dtype=np.int64)
    fill = column_start[:n_nodes].copy()
    for k in range(n_blocks):
        order[fill[block_col[k]]] = k
        fill[block_col[k]] += 1
    indptr = np.zeros(n_free + 1, dtype=np.int64)
    indices = np.empty(9 * n_blocks, dtype=np.int64)
    data = np.empty(9 * n_blocks)
    u = 0
    for n in range(n_nodes):
        lo, hi = column_start[n], column_start[n + 1]
        for t in range(lo + 1, hi):  # the column's blocks by row node (a few each)
            k = order[t]
            s = t
            while s > lo and block_row[order[s - 1]] > block_row[k]:
                order[s] = order[s - 1]
                s -= 1
            order[s] = k
        for c in range(3):
            j = dof_map[3 * n + c]
            if j < 0:
                continue
            t = lo
            while t < hi:
                row_node = block_row[order[t]]
                run = t
                while run < hi and block_row[order[run]] == row_node:
                    run += 1
                for r in range(3):
                    i = dof_map[3 * row_node + r]
                    if i < 0:
                        continue
                    value = 0.0
                    for q in range(t, run):
                        value += vals[block_source[order[q]] + 12 * r + c]
                    indices[u] = i
                    data[u] = value
                    u += 1
                t = run
            indptr[j + 1] = u
    for j in range(n_free):  # the frames' columns, after the nodes', have no entry
        indptr[j + 1] = max(indptr[j + 1], indptr[j])
    return indptr, indices[:u], data[:u]


@njit(cache=True)
def scatter_add(slot, vals, count, out):
    """``out`` zeroed, then ``out[slot[k]] += vals[k]`` for the first ``count`` triplets (those with
    ``slot[k] < 0`` dropped), in the order written."""
    out[:] = 0.0
    for k in range(count):
        if slot[k] >= 0:
            out[slot[k]] += vals[k]


@njit(cache=True)
def add_csc(a_indptr, a_indices, a_data, b_indptr, b_indices, b_data):
    """The sum of two square CSC matrices of one shape, each canonical (rows sorted, no
    duplicates), the first with every diagonal entry stored, in the same form as
    :func:`assemble_csc` returns (no explicit zero off the diagonal): ``(indptr, indices, data,
    diagonal)``."""
    n = a_indptr.shape[0] - 1
    indptr = np.empty(n + 1, dtype=np.int64)
    indices = np.empty(a_indptr[n] + b_indptr[n], dtype=np.int64)
    data = np.empty(a_indptr[n] + b_indptr[n])
    diagonal = np.empty(n, dtype=np.int64)
    u = 0
    indptr[0] = 0
    for j in range(n):
        p, p_end = a_indptr[j], a_indptr[j + 1]
        q, q_end = b_indptr[j], b_indptr[j + 1]
        while p < p_end or q < q_end:
            if q == q_end or (p < p_end and a_indices[p] < b_indices[q]):
                row, value = a_indices[p], a_data[p]
                p += 1
            elif p == p_end or b_indices[q] < a_indices[p]:
                row, value = b_indices[q], b_data[q]
                q += 1
            else:
                row, value = a_indices[p], a_data[p] + b_data[q]
                p += 1
                q += 1
            if row == j:
                diagonal[j] = u
            elif value == 0.0:
                continue
            indices[u] = row
            data[u] = value
            u += 1
        indptr[j + 1] = u
    return indptr, indices[:u], data[:u], diagonal


@njit(cache=True)
def plus_row_norms(scale, rows):
    """``scale + |rows|`` row by row (``(N,)`` and ``(N, 3)``)."""
    out = np.empty(scale.shape[0])
    for i in range(scale.shape[0]):
        out[i] = scale[i] + math.sqrt(rows[i, 0] ** 2 + rows[i, 1] ** 2 + rows[i, 2] ** 2)
    return out


@njit(cache=True)
def residual_scales(node_scale, edge_scale, edge_nodes, rest_length):
    """``(force scale, torque scale)``: the largest of the nodes' force scales and the edges'
    torque scales over their rest lengths, and the largest of the edges' torque scales and their
    end nodes' larger force scale times their rest lengths (0 for none; NaN if any scale is)."""
    force = 0.0
    torque = 0.0
    finite = True
    for i in range(node_scale.shape[0]):
        finite &= node_scale[i] == node_scale[i]
        force = max(force, node_scale[i])
    for e in range(edge_scale.shape[0]):
        finite &= edge_scale[e] == edge_scale[e]
        force = max(force, edge_scale[e] / rest_length[e])
        ends = max(node_scale[edge_nodes[e, 0]], node_scale[edge_nodes[e, 1]])
        torque = max(torque, edge_scale[e], ends * rest_length[e])
    if not finite:
        return math.nan, math.nan
    return force, torque


@njit(cache=True)
def largest_row_norm(rows, mask):
    """Largest ``|rows[i]|`` over the rows with ``mask[i]`` (0 if none)."""
    largest = 0.0
    for i in range(rows.shape[0]):
        if mask[i]:
            largest = max(largest, rows[i, 0] ** 2 + rows[i, 1] ** 2 + rows[i, 2] ** 2)
    return math.sqrt(largest)
