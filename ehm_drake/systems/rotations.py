"""Roll-pitch-yaw <-> rotation matrix, Drake's convention: space-fixed
x-y-z, R = Rz(yaw) Ry(pitch) Rx(roll).

Generic in the scalar type (float or AutoDiffXd object arrays); floats take
a `math`-module path, ~20x faster than numpy on scalars, because these run
every time step.
"""

from __future__ import annotations

import math

import numpy as np


def rpy_from_rotation(R):
    """Roll, pitch, yaw of rotation matrix R, for |pitch| < 90 deg."""
    if R.dtype != object:
        return np.array(rpy_from_rotation_list(R.tolist()))
    return _rpy_from_rotation_object(R)


def rpy_from_rotation_list(R) -> list[float]:
    """`rpy_from_rotation` of a float matrix given as nested lists."""
    return [
        math.atan2(R[2][1], R[2][2]),
        math.atan2(-R[2][0], math.hypot(R[0][0], R[1][0])),
        math.atan2(R[1][0], R[0][0]),
    ]


def _rpy_from_rotation_object(R):
    roll = np.arctan2(R[2, 1], R[2, 2])
    pitch = np.arctan2(-R[2, 0], np.sqrt(R[0, 0] * R[0, 0] + R[1, 0] * R[1, 0]))
    yaw = np.arctan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


def rotation_from_rpy(rpy):
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    if np.asarray(rpy).dtype != object:
        r, p, y = (float(a) for a in rpy)
        cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
        cy, sy = math.cos(y), math.sin(y)
    else:
        r, p, y = rpy
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])
