"""Quaternion and small-vector helpers for the Numba kernels.

Only ``@njit`` code lives here. Quaternions are 4-tuples ``(w, x, y, z)``; vectors are 3-tuples;
rigid maps are 3×3 arrays.
Working on tuples instead of small arrays keeps the hot loops free of heap allocation.

Conventions (``docs/design.md`` §4):

- ``R(q) v = q (0, v) q̄`` rotates material (body) coordinates into world coordinates, so the
  edge directors are ``d_k = R(q) e_k`` and ``d3`` is the edge tangent.
- A world-frame rotation vector ``θ`` acts by left multiplication: ``q' = exp(θ) ⊗ q``; angular
  velocities and the solver's rotational degrees of freedom use this convention.
"""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def quat_mul(a, b):
    """Hamilton product ``a ⊗ b`` of two 4-tuples."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@njit(cache=True)
def quat_conj(q):
    return (q[0], -q[1], -q[2], -q[3])


@njit(cache=True)
def quat_dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


@njit(cache=True)
def quat_normalized(q):
    inv = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv)


@njit(cache=True)
def quat_rotate(q, v):
    """``R(q) v`` for a unit quaternion ``q`` (body to world)."""
    w, x, y, z = q
    # v + 2 w (u × v) + 2 u × (u × v), u = (x, y, z)
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    return (
        v[0] + w * tx + (y * tz - z * ty),
        v[1] + w * ty + (z * tx - x * tz),
        v[2] + w * tz + (x * ty - y * tx),
    )


@njit(cache=True)
def quat_rotate_inv(q, v):
    """``R(q)ᵀ v`` for a unit quaternion ``q`` (world to body)."""
    return quat_rotate((q[0], -q[1], -q[2], -q[3]), v)


@njit(cache=True)
def quat_exp(theta):
    """Unit quaternion of the rotation vector ``theta`` (axis times angle, radians)."""
    angle2 = theta[0] * theta[0] + theta[1] * theta[1] + theta[2] * theta[2]
    if angle2 < 1e-16:
        # Taylor series of cos(a/2) and sin(a/2)/a, exact to round-off for a < 1e-8.
        s = 0.5 - angle2 / 48.0
        return (1.0 - angle2 / 8.0, s * theta[0], s * theta[1], s * theta[2])
    angle = math.sqrt(angle2)
    s = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), s * theta[0], s * theta[1], s * theta[2])


@njit(cache=True)
def quat_rotate_world(theta, q):
    """``exp(theta) ⊗ q``: rotate the frame ``q`` by the world-frame rotation vector ``theta``."""
    return quat_normalized(quat_mul(quat_exp(theta), q))


@njit(cache=True)
def quat_log(q):
    """Rotation vector of a unit quaternion, principal branch (angle in [0, π])."""
    w = q[0]
    if w < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
        w = -w
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if s < 1e-12:
        # angle = 2 atan2(s, w) ≈ 2 s / w for small s.
        f = 2.0 / w
    else:
        f = 2.0 * math.atan2(s, w) / s
    return (f * q[1], f * q[2], f * q[3])


@njit(cache=True)
def quat_between(a, b):
    """Minimal rotation taking unit vector ``a`` onto unit vector ``b``."""
    d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if d < -1.0 + 1e-12:
        # Antiparallel: rotate by π about any axis perpendicular to a.
        if abs(a[0]) < 0.9:
            axis = cross(a, (1.0, 0.0, 0.0))
        else:
            axis = cross(a, (0.0, 1.0, 0.0))
        axis = normalized(axis)
        return (0.0, axis[0], axis[1], axis[2])
    c = cross(a, b)
    return quat_normalized((1.0 + d, c[0], c[1], c[2]))


@njit(cache=True)
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True)
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True)
def normalized(a):
    inv = 1.0 / math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    return (a[0] * inv, a[1] * inv, a[2] * inv)


@njit(cache=True)
def row3(arr, i):
    """Row ``i`` of an ``(n, 3)`` array as a tuple."""
    return (arr[i, 0], arr[i, 1], arr[i, 2])


@njit(cache=True)
def row4(arr, i):
    """Row ``i`` of an ``(n, 4)`` array as a tuple."""
    return (arr[i, 0], arr[i, 1], arr[i, 2], arr[i, 3])


@njit(cache=True)
def mat_vec(m, v):
    """``m v`` for a 3×3 array ``m`` (a rigid map's rotation)."""
    return (m[0, 0] * v[0] + m[0, 1] * v[1] + m[0, 2] * v[2],
            m[1, 0] * v[0] + m[1, 1] * v[1] + m[1, 2] * v[2],
            m[2, 0] * v[0] + m[2, 1] * v[1] + m[2, 2] * v[2])


@njit(cache=True)
def mat_t_vec(m, v):
    """``mᵀ v``: a gradient or correction at a mapped point, pulled back to the node."""
    return (m[0, 0] * v[0] + m[1, 0] * v[1] + m[2, 0] * v[2],
            m[0, 1] * v[0] + m[1, 1] * v[1] + m[2, 1] * v[2],
            m[0, 2] * v[0] + m[1, 2] * v[1] + m[2, 2] * v[2])


@njit(cache=True)
def pull_back_block(local, start, m):
    """``local ← Tᵀ local T`` in place, T the identity except the 3×3 ``m`` on rows and columns
    ``start..start+2``: a Hessian over a mapped point ``m x + t`` pulled back to ``x``."""
    n = local.shape[0]
    tmp = np.empty(3)
    for i in range(n):  # columns: local[i, block] ← local[i, block] m
        for c in range(3):
            tmp[c] = local[i, start] * m[0, c] + local[i, start + 1] * m[1, c] + local[i, start + 2] * m[2, c]
        for c in range(3):
            local[i, start + c] = tmp[c]
    for j in range(n):  # rows: local[block, j] ← mᵀ local[block, j]
        for r in range(3):
            tmp[r] = m[0, r] * local[start, j] + m[1, r] * local[start + 1, j] + m[2, r] * local[start + 2, j]
        for r in range(3):
            local[start + r, j] = tmp[r]
