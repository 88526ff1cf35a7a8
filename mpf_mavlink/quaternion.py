"""Unit quaternions (w, x, y, z; Hamilton, w first) and rotation matrices, on plain floats: the
one conversion of each kind, shared by the core's frames (:mod:`mpf_mavlink.core.frames`), the
MAVLink decoders (:mod:`mpf_mavlink.mavlink.codec`) and the simulator.

Quaternions exist only at the MAVLink boundary (ATTITUDE_QUATERNION, SET_ATTITUDE_TARGET,
FOLLOW_TARGET); inside, rotations are matrices. The matrix is ``R_B^N`` (body FRD -> NED) given
by its rows, row-major. A leaf: it imports nothing of the package, so every layer may use it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Rows = tuple[float, float, float, float, float, float, float, float, float]


def rows_of_unit_quat(w: float, x: float, y: float, z: float) -> Rows:
    """The rotation matrix (rows, row-major) of the unit quaternion (w, x, y, z); the caller
    normalises (its own rule for what is too far from unit)."""
    return (
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )  # fmt: skip


def quat_of_rows(r: Sequence[float]) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) with w >= 0 of the rotation matrix whose rows are ``r[0:9]``
    (Shepperd's method: the branch of the largest of the trace and the diagonal, so that the
    divisor is never small)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r[0:9]
    tr = r00 + r11 + r22
    if tr > 0:
        S = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * S, (r21 - r12) / S, (r02 - r20) / S, (r10 - r01) / S
    elif r00 > r11 and r00 > r22:
        S = math.sqrt(1.0 + r00 - r11 - r22) * 2
        w, x, y, z = (r21 - r12) / S, 0.25 * S, (r01 + r10) / S, (r02 + r20) / S
    elif r11 > r22:
        S = math.sqrt(1.0 + r11 - r00 - r22) * 2
        w, x, y, z = (r02 - r20) / S, (r01 + r10) / S, 0.25 * S, (r12 + r21) / S
    else:
        S = math.sqrt(1.0 + r22 - r00 - r11) * 2
        w, x, y, z = (r10 - r01) / S, (r02 + r20) / S, (r12 + r21) / S, 0.25 * S
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / n, x / n, y / n, z / n)


def quat_of_euler(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of ZYX Euler angles (rad): Rz(yaw) Ry(pitch) Rx(roll) as the
    product of the three half-angle rotations (no matrix; w may be negative)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


__all__ = ["Rows", "quat_of_euler", "quat_of_rows", "rows_of_unit_quat"]
