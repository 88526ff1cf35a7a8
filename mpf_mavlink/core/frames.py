"""Frame conventions: NED inertial, FRD body, ZYX Euler angles, quaternions (w, x, y, z).

Quaternions exist only at the MAVLink boundary; everything inside uses rotation matrices.
``R_B^N`` (body FRD -> NED) is what MAVLink's ATTITUDE_QUATERNION / SET_ATTITUDE_TARGET ``q``
encodes (Hamilton convention, w first). Geodetic helpers wrap pymap3d (WGS-84).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from mpf_mavlink.core.so3 import Mat3, Vec3, rot_x, rot_y, rot_z
from mpf_mavlink.quaternion import quat_of_rows, rows_of_unit_quat


def quat_wxyz_to_matrix(q: ArrayLike) -> Mat3:
    """Unit quaternion (w, x, y, z) -> rotation matrix R_B^N. Normalises q; rejects zero norm."""
    w, x, y, z = np.asarray(q, float).tolist()
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"quaternion {(w, x, y, z)} has no direction")
    r = rows_of_unit_quat(w / n, x / n, y / n, z / n)
    return np.array([r[0:3], r[3:6], r[6:9]])


def matrix_to_quat_wxyz(R: ArrayLike) -> tuple[float, float, float, float]:
    """Rotation matrix R_B^N -> unit quaternion (w, x, y, z) with w >= 0 (Shepperd's method:
    :func:`mpf_mavlink.quaternion.quat_of_rows`)."""
    return quat_of_rows(np.asarray(R, dtype=float).ravel().tolist())


def euler_to_matrix(roll: float, pitch: float, yaw: float) -> Mat3:
    """ZYX (yaw, pitch, roll) Euler angles (rad) -> R_B^N = Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def matrix_to_euler(R: ArrayLike) -> tuple[float, float, float]:
    """R_B^N -> ZYX Euler angles (roll, pitch, yaw) in rad; yaw in (-pi, pi]."""
    R = np.asarray(R, dtype=float)
    pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    roll = math.atan2(R[2, 1], R[2, 2])
    yaw = math.atan2(R[1, 0], R[0, 0])
    return roll, pitch, yaw


def wind_frame_from_velocity(v_air_ned: ArrayLike, roll_ref: float = 0.0) -> Mat3:
    """Wind frame R_W^I whose w1 is along the air-relative velocity (NED, m/s).

    The roll about w1 does not matter to the MPF law (its command is independent of it);
    we choose w2 horizontal (right of w1) rotated by ``roll_ref`` so the frame is well defined
    for any non-vertical velocity.
    """
    v = np.asarray(v_air_ned, dtype=float)
    n = float(np.linalg.norm(v))
    if n < 1e-6:
        raise ValueError("air-relative velocity is zero: the wind frame is undefined")
    w1 = v / n
    down = np.array([0.0, 0.0, 1.0])
    w2 = np.cross(down, w1)
    if np.linalg.norm(w2) < 1e-9:
        w2 = np.array([0.0, 1.0, 0.0])
    w2 /= np.linalg.norm(w2)
    w3 = np.cross(w1, w2)
    if roll_ref:
        c, s = math.cos(roll_ref), math.sin(roll_ref)
        w2, w3 = c * w2 + s * w3, -s * w2 + c * w3
    return np.column_stack([w1, w2, w3])


def geodetic_to_ned(
    lat_deg: float, lon_deg: float, alt_m: float, lat0_deg: float, lon0_deg: float, alt0_m: float
) -> Vec3:
    """WGS-84 geodetic position -> local NED (m) about an origin (pymap3d: exact, not a
    flat-earth approximation)."""
    import pymap3d

    n, e, d = pymap3d.geodetic2ned(lat_deg, lon_deg, alt_m, lat0_deg, lon0_deg, alt0_m)
    return np.array([float(n), float(e), float(d)])


def ned_to_geodetic(
    ned: ArrayLike, lat0_deg: float, lon0_deg: float, alt0_m: float
) -> tuple[float, float, float]:
    """Local NED (m) about an origin -> WGS-84 (lat deg, lon deg, alt m)."""
    import pymap3d

    n, e, d = np.asarray(ned, float).tolist()
    lat, lon, alt = pymap3d.ned2geodetic(n, e, d, lat0_deg, lon0_deg, alt0_m)
    return float(lat), float(lon), float(alt)
