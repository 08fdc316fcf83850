"""Small vector algebra on the per-frame hot paths.

``np.cross`` spends most of its time normalising axes (~20 us a call for two 3-vectors); the per-frame human COM
estimator called it ~8 times a frame, the robot plant's sensors at the state rate. :func:`cross` gives the same
result from three products, for single vectors or stacks of them.
"""

from __future__ import annotations

import numpy as np


_NEXT, _AFTER = np.array([1, 2, 0]), np.array([2, 0, 1])
"""The coordinates after each one, cyclically (x -> y, z): the stacked cross product's index takes."""


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of 3-vectors, (3,) or (..., 3) (broadcast like ``np.cross`` over the leading axes)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.ndim == 1 and b.ndim == 1:
        return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
    return a.take(_NEXT, axis=-1) * b.take(_AFTER, axis=-1) - a.take(_AFTER, axis=-1) * b.take(_NEXT, axis=-1)


def skew_rows(r: np.ndarray) -> np.ndarray:
    """(k, 3, 3) cross-product matrices [r_i]x of the rows of ``r`` (k, 3): [r_i]x w = r_i x w."""
    S = np.zeros((len(r), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -r[:, 2], r[:, 1], -r[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = r[:, 2], -r[:, 1], r[:, 0]
    return S


def xyzw_from_wxyz(q_wxyz: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) in MuJoCo's order (w, x, y, z) as Pinocchio's and ROS's (x, y, z, w)."""
    return np.asarray(q_wxyz, dtype=float)[..., [1, 2, 3, 0]]


def pose_xyzw_from_wxyz(pose: np.ndarray) -> np.ndarray:
    """A MuJoCo free joint's pose (7,) (position, quaternion w x y z) in ROS's order (position, x y z w): one take,
    for the driver's 500 Hz state."""
    return pose.take(_POSE_XYZW)


_POSE_XYZW = np.array([0, 1, 2, 4, 5, 6, 3])


def wxyz_from_xyzw(q_xyzw: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) in Pinocchio's and ROS's order (x, y, z, w) as MuJoCo's (w, x, y, z)."""
    return np.asarray(q_xyzw, dtype=float)[..., [3, 0, 1, 2]]


def pitch_deg(q_xyzw: np.ndarray) -> float:
    """The pitch [deg] of a body whose orientation is the quaternion ``q_xyzw`` (x, y, z, w): how far its z axis
    leans toward +x about y (forward positive, REP-103), 0 upright."""
    x, y, z, w = np.asarray(q_xyzw, dtype=float)
    r02, r22 = 2.0 * (x * z + w * y), 1.0 - 2.0 * (x * x + y * y)      # the rotation matrix's (0, 2) and (2, 2)
    return float(np.degrees(np.arctan2(r02, r22)))
