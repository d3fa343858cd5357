"""The orchestration helpers of yarnfit.engine.rotations against the kernels' quaternion algebra."""

from __future__ import annotations

import math

import numpy as np
import pytest

from yarnfit.engine._quat import quat_mul, quat_rotate
from yarnfit.engine.rotations import quaternion_between, rotate_frames, xyzw

# Products of a few unit quaternions and 3×3 rotations: a few ulps.
ROUND_OFF = 1e-14


def test_rotate_frames_is_the_world_rotation_on_the_left():
    rng = np.random.default_rng(3)
    q = rng.standard_normal((5, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    angle = 0.7
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # +angle about z
    r = np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])
    turned = rotate_frames(rotation, q)
    for k in range(5):
        expected = np.array(quat_mul(tuple(r), tuple(q[k])))
        # q and −q are one rotation: compare up to sign.
        sign = 1.0 if expected @ turned[k] >= 0 else -1.0
        np.testing.assert_allclose(sign * turned[k], expected, rtol=0.0, atol=ROUND_OFF)
    # One matrix per frame as well as one for all.
    np.testing.assert_allclose(np.abs(rotate_frames(np.stack([rotation] * 5), q)), np.abs(turned), atol=ROUND_OFF)


@pytest.mark.parametrize("b", [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.6, 0.0, 0.8), (0.0, 0.0, -1.0), (0.0, -1.0, 0.0)])
def test_quaternion_between_turns_a_onto_b(b):
    a = np.array([0.0, 0.0, 1.0])
    b = np.array(b)
    q = quaternion_between(a, b)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=ROUND_OFF)
    np.testing.assert_allclose(quat_rotate(tuple(q), tuple(a)), b, rtol=0.0, atol=ROUND_OFF)


def test_xyzw_reorders():
    np.testing.assert_array_equal(xyzw(np.array([1.0, 2.0, 3.0, 4.0])), [2.0, 3.0, 4.0, 1.0])
