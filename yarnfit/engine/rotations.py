"""Frame rotations for orchestration code (NumPy/SciPy, vectorised); the kernels use ``_quat``.

One convention throughout: a quaternion is ``(w, x, y, z)`` (MuJoCo's order and the engine's,
``docs/design.md`` §3), and a world rotation ``R`` turns a frame ``q`` into ``R ⊗ q``. Libraries
that want ``(x, y, z, w)`` (SciPy, Rerun) get it from :func:`xyzw` at the call.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["as_frames", "as_rotations", "quaternion_between", "rotate_frames", "xyzw"]


def xyzw(quaternion: np.ndarray) -> np.ndarray:
    """``(…, 4)`` quaternions ``(w, x, y, z)`` reordered as ``(x, y, z, w)``."""
    return np.asarray(quaternion)[..., [1, 2, 3, 0]]


def as_rotations(quaternion: np.ndarray) -> Rotation:
    """Frames ``(n, 4)`` (w, x, y, z) as SciPy rotations."""
    return Rotation.from_quat(xyzw(quaternion))


def as_frames(rotation: Rotation) -> np.ndarray:
    """SciPy rotations (several) as unit quaternions ``(n, 4)`` (w, x, y, z), C-contiguous."""
    q = rotation.as_quat()
    return np.ascontiguousarray(np.column_stack([q[:, 3], q[:, :3]]))


def rotate_frames(rotation: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """Frames ``quaternion (n, 4)`` turned by world rotations ``rotation`` (``(n, 3, 3)`` or one
    ``(3, 3)``): ``R ⊗ q``, unit quaternions ``(n, 4)``, C-contiguous."""
    return as_frames(Rotation.from_matrix(rotation) * as_rotations(quaternion))


def quaternion_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shortest rotation ``(4,)`` turning the unit vector ``a`` onto the unit vector ``b``
    (opposite vectors: a half turn about the axis perpendicular to ``a`` closest to the basis
    vector least aligned with it)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    w = 1.0 + float(a @ b)
    if w < 1e-12:
        basis = np.eye(3)[int(np.argmin(np.abs(a)))]
        axis = basis - (basis @ a) * a
        return np.concatenate([[0.0], axis / np.linalg.norm(axis)])
    q = np.concatenate([[w], np.cross(a, b)])
    return q / np.linalg.norm(q)
