"""pymavlink messages <-> plain typed values (frozen dataclasses, SI units, NED / FRD, radians).

Decoders never raise: a message with a non-finite or absurd field returns ``None`` so that
malformed MAVLink can neither crash the loop nor put a NaN into the state. Encoders refuse
(``ValueError``) to put a non-finite number on the wire.

The attitude decoders (one per control step) compute the matrices of
:func:`mpf_mavlink.core.frames.euler_to_matrix` / :func:`~mpf_mavlink.core.frames.quat_wxyz_to_matrix` in
scalar arithmetic (same conventions; tests hold them to those functions).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mpf_mavlink.mavlink import dialect as _d
from mpf_mavlink.mavlink.modes import (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    Flavour,
    arduplane_mode_from_name,
    is_armed,
    px4_mode_from_name,
)

# Plausibility bounds. Anything beyond them is corruption, a unit bug or a spoof, not flight.
MAX_SPEED_M_S = 200.0  # any velocity component or norm (fixed-wing UAV, wind)
MAX_RATE_RAD_S = 50.0  # ~2900 deg/s, far beyond any airframe
MAX_ANGLE_RAD = 2.0 * math.pi + 1e-3
MAX_LOCAL_POS_M = 1.0e6  # 1000 km from the EKF origin
MIN_ALT_M, MAX_ALT_M = -1000.0, 50000.0
MAX_ACCEL_M_S2 = 200.0  # ~20 g
QUAT_NORM_TOL = 0.1  # |q| must be within 1 +- 0.1 (a float32 unit quaternion is within 1e-6)

# SET_ATTITUDE_TARGET type_mask bits (common.xml ATTITUDE_TARGET_TYPEMASK)
TM_BODY_ROLL_RATE_IGNORE = 1
TM_BODY_PITCH_RATE_IGNORE = 2
TM_BODY_YAW_RATE_IGNORE = 4
TM_THRUST_BODY_SET = 32
TM_THROTTLE_IGNORE = 64
TM_ATTITUDE_IGNORE = 128

#: PX4 offboard body rates: quaternion ignored, the three rates and thrust used.
TYPE_MASK_PX4_RATES = TM_ATTITUDE_IGNORE  # 128
#: ArduPlane GUIDED attitude: roll and pitch from the quaternion, thrust used, yaw left to
#: ArduPlane. ArduPlane's handler (ArduPlane/GCS_MAVLink_Plane.cpp,
#: handle_set_attitude_target) inverts the mask and takes each Euler angle whose rate bit is
#: clear, or all three when the attitude bit is clear; a forced yaw is written straight to the
#: rudder (Attitude.cpp, calc_nav_yaw_coordinated), bypassing its yaw damper and rudder mix
#: (KFF_RDDRMIX), so a yaw of 0 pins the rudder at neutral through every turn. With the
#: attitude bit set and the yaw-rate bit set (132) roll and pitch are forced and the rudder
#: stays ArduPlane's own coordinated-turn output, as in its other modes. ArduPlane never reads
#: the body rates.
TYPE_MASK_ARDUPLANE_ATTITUDE = TM_ATTITUDE_IGNORE | TM_BODY_YAW_RATE_IGNORE  # 132

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_GET_HOME_POSITION = 410
MAV_CMD_DO_REPOSITION = 192

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
ARM_FORCE_MAGIC = 21196  # param2 that forces arming/disarming (PX4 and ArduPilot)


def _ro(a: Iterable[float]) -> np.ndarray:
    arr = np.array(list(a), dtype=float)
    arr.setflags(write=False)
    return arr


def _finite(*vals: float) -> bool:
    try:
        return all(math.isfinite(float(v)) for v in vals)
    except (TypeError, ValueError):
        return False


def _t_rx(msg: Any) -> float | None:
    t = getattr(msg, "_timestamp", None)
    return float(t) if isinstance(t, (int, float)) and math.isfinite(t) else None


# ---------------------------------------------------------------------------------------------
# Samples
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class AttitudeSample:
    t_boot_s: float  # s, autopilot time since boot (time_boot_ms / 1000)
    R_B_N: np.ndarray  # 3x3, body FRD -> NED rotation
    rates_frd: np.ndarray  # rad/s, body angular velocity (p, q, r) in FRD
    source: str = "ATTITUDE"  # "ATTITUDE" or "ATTITUDE_QUATERNION"


@dataclass(frozen=True, eq=False)
class LocalPositionSample:
    t_boot_s: float  # s, time since boot
    pos_ned: np.ndarray  # m, position about the EKF origin, NED
    vel_ned: np.ndarray  # m/s, ground velocity, NED


@dataclass(frozen=True, eq=False)
class GlobalPositionSample:
    t_boot_s: float  # s, time since boot
    lat_deg: float  # deg, WGS-84
    lon_deg: float  # deg, WGS-84
    alt_amsl_m: float  # m, above mean sea level
    rel_alt_m: float  # m, above home
    vel_ned: np.ndarray  # m/s, ground velocity, NED
    heading_rad: float | None  # rad in [0, 2pi), None if unknown (hdg = UINT16_MAX)
    src_system: int = 0  # MAVLink system id of the sender (a target can also send this)


@dataclass(frozen=True)
class VfrHudSample:
    airspeed_m_s: float  # m/s, indicated/true airspeed as the autopilot reports it
    groundspeed_m_s: float  # m/s
    throttle_frac: float  # 0..1 (VFR_HUD.throttle is in percent)
    heading_rad: float  # rad, [0, 2pi)
    alt_amsl_m: float  # m
    climb_m_s: float  # m/s, positive up
    t_rx_s: float | None = None  # s, receive/log time (VFR_HUD carries no timestamp)


@dataclass(frozen=True, eq=False)
class WindSample:
    wind_ned: np.ndarray  # m/s, velocity of the air mass in NED (the direction it blows TOWARD)
    source: str  # "WIND" (ArduPilot) or "WIND_COV" (PX4)
    t_boot_s: float | None = None  # s, WIND_COV.time_usec / 1e6; WIND has no timestamp
    t_rx_s: float | None = None  # s, receive/log time


@dataclass(frozen=True, eq=False)
class HomeSample:
    lat_deg: float  # deg, WGS-84 geodetic origin
    lon_deg: float  # deg
    alt_amsl_m: float  # m
    pos_ned: np.ndarray  # m, home in the local NED frame


@dataclass(frozen=True)
class HeartbeatSample:
    type: int  # MAV_TYPE
    autopilot: int  # MAV_AUTOPILOT (3 ArduPilot, 12 PX4)
    base_mode: int  # MAV_MODE_FLAG bits
    custom_mode: int  # autopilot-specific mode (see modes.py)
    system_status: int  # MAV_STATE
    armed: bool  # MAV_MODE_FLAG_SAFETY_ARMED
    src_system: int = 0  # sender system id
    src_component: int = 0  # sender component id
    t_rx_s: float | None = None  # s, receive/log time


@dataclass(frozen=True)
class CommandAckSample:
    command: int  # MAV_CMD
    result: int  # MAV_RESULT (0 accepted)
    accepted: bool  # result == MAV_RESULT_ACCEPTED
    result_name: str  # e.g. "MAV_RESULT_DENIED"
    src_system: int = 0


@dataclass(frozen=True, eq=False)
class FollowTargetSample:
    t_s: float  # s, FOLLOW_TARGET.timestamp / 1000 (sender's clock)
    lat_deg: float  # deg
    lon_deg: float  # deg
    alt_amsl_m: float  # m
    vel_ned: np.ndarray | None  # m/s, None if not estimated
    acc_ned: np.ndarray | None  # m/s^2, None if not estimated
    R_B_N: np.ndarray | None  # target attitude, None if not estimated
    rates_frd: np.ndarray | None  # rad/s, None if not estimated
    position_cov: np.ndarray  # m^2 (as sent; zeros = unknown)
    est_capabilities: int  # bits: 0 pos, 1 vel, 2 acc, 3 attitude + rates (0 = unknown)
    src_system: int = 0


@dataclass(frozen=True)
class AttitudeTargetSample:
    """ATTITUDE_TARGET (#83): the setpoint the autopilot is using, stamped (PX4) when it
    received it. The bridge finds its own setpoint in it to measure its loop delay."""

    t_boot_s: float  # s, autopilot time since boot (time_boot_ms / 1000)
    rates_frd: tuple[float, float, float]  # rad/s, body rate setpoint (p, q, r)
    thrust: float  # 0..1
    type_mask: int


# ---------------------------------------------------------------------------------------------
# Decoders (return None on anything non-finite or absurd)
# ---------------------------------------------------------------------------------------------
def _ro3(a: float, b: float, c: float) -> np.ndarray:
    arr = np.array((a, b, c))
    arr.setflags(write=False)
    return arr


def _ro33(rows: tuple) -> np.ndarray:
    arr = np.array(rows)
    arr.setflags(write=False)
    return arr


def decode_attitude(msg: Any) -> AttitudeSample | None:
    # Hot path (one per control step): scalar arithmetic only. A NaN fails every comparison,
    # so the bound checks also reject non-finite values.
    try:
        r, p, y = float(msg.roll), float(msg.pitch), float(msg.yaw)
        wx, wy, wz = float(msg.rollspeed), float(msg.pitchspeed), float(msg.yawspeed)
        t = float(msg.time_boot_ms) * 1e-3
    except (AttributeError, TypeError, ValueError):
        return None
    A, W = MAX_ANGLE_RAD, MAX_RATE_RAD_S
    if not (-A <= r <= A and -A <= p <= A and -A <= y <= A):
        return None
    if not (-W <= wx <= W and -W <= wy <= W and -W <= wz <= W):
        return None
    # R = Rz(yaw) Ry(pitch) Rx(roll) (frames.euler_to_matrix), products grouped as that
    # matrix product rounds them: (Rz Ry) first, then times Rx.
    cr, sr = math.cos(r), math.sin(r)
    cp, sp = math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    a00, a02 = cy * cp, cy * sp  # Rz Ry = [[cy cp, -sy, cy sp], [sy cp, cy, sy sp], [-sp, 0, cp]]
    a10, a12 = sy * cp, sy * sp
    R = _ro33(
        (
            (a00, a02 * sr - sy * cr, a02 * cr + sy * sr),
            (a10, a12 * sr + cy * cr, a12 * cr - cy * sr),
            (-sp, cp * sr, cp * cr),
        )
    )
    return AttitudeSample(t, R, _ro3(wx, wy, wz), "ATTITUDE")


def _quat_to_matrix(q: Sequence[float]) -> np.ndarray | None:
    if len(q) != 4:
        return None
    try:
        w, x, y, z = float(q[0]), float(q[1]), float(q[2]), float(q[3])
    except (TypeError, ValueError):
        return None
    n2 = w * w + x * x + y * y + z * z  # NaN/inf: the bound below fails
    n = math.sqrt(n2) if n2 < math.inf else math.inf
    if not abs(n - 1.0) <= QUAT_NORM_TOL:
        return None
    # frames.quat_wxyz_to_matrix, scalar (same operations, same rounding)
    w, x, y, z = w / n, x / n, y / n, z / n
    return _ro33(
        (
            (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
        )
    )


def decode_attitude_quaternion(msg: Any) -> AttitudeSample | None:
    try:
        q = (float(msg.q1), float(msg.q2), float(msg.q3), float(msg.q4))  # w, x, y, z
        wx, wy, wz = float(msg.rollspeed), float(msg.pitchspeed), float(msg.yawspeed)
        t = float(msg.time_boot_ms) * 1e-3
    except (AttributeError, TypeError, ValueError):
        return None
    W = MAX_RATE_RAD_S
    if not (-W <= wx <= W and -W <= wy <= W and -W <= wz <= W):
        return None
    R = _quat_to_matrix(q)
    if R is None:
        return None
    return AttitudeSample(t, R, _ro3(wx, wy, wz), "ATTITUDE_QUATERNION")


def decode_local_position_ned(msg: Any) -> LocalPositionSample | None:
    try:
        x, y, z = float(msg.x), float(msg.y), float(msg.z)
        vx, vy, vz = float(msg.vx), float(msg.vy), float(msg.vz)
        t = float(msg.time_boot_ms) * 1e-3
    except (AttributeError, TypeError, ValueError):
        return None
    P = MAX_LOCAL_POS_M  # a NaN fails the comparisons, an inf exceeds the bounds
    if not (-P <= x <= P and -P <= y <= P and -P <= z <= P):
        return None
    if not math.hypot(vx, vy, vz) <= MAX_SPEED_M_S:
        return None
    return LocalPositionSample(t, _ro3(x, y, z), _ro3(vx, vy, vz))


def _geodetic_ok(lat: float, lon: float, alt: float) -> bool:
    if not _finite(lat, lon, alt) or abs(lat) > 90.0 or abs(lon) > 180.0:
        return False
    if lat == 0.0 and lon == 0.0:  # what autopilots send before a fix, never a real position
        return False
    return MIN_ALT_M <= alt <= MAX_ALT_M


def decode_global_position_int(msg: Any) -> GlobalPositionSample | None:
    try:
        lat, lon = msg.lat * 1e-7, msg.lon * 1e-7  # degE7 -> deg
        alt, rel = msg.alt * 1e-3, msg.relative_alt * 1e-3  # mm -> m
        vel = (msg.vx * 1e-2, msg.vy * 1e-2, msg.vz * 1e-2)  # cm/s -> m/s
        hdg = int(msg.hdg)
        t = float(msg.time_boot_ms) * 1e-3
        src = int(msg.get_srcSystem()) if hasattr(msg, "get_srcSystem") else 0
    except (AttributeError, TypeError, ValueError):
        return None
    if not _geodetic_ok(lat, lon, alt) or not _finite(rel, *vel):
        return None
    if math.hypot(*vel) > MAX_SPEED_M_S:
        return None
    heading = None if hdg == 65535 or hdg > 36000 else math.radians(hdg * 1e-2) % (2 * math.pi)
    return GlobalPositionSample(t, lat, lon, alt, rel, _ro(vel), heading, src)


def decode_vfr_hud(msg: Any) -> VfrHudSample | None:
    try:
        a, g = float(msg.airspeed), float(msg.groundspeed)
        thr, hdg = float(msg.throttle), float(msg.heading)
        alt, climb = float(msg.alt), float(msg.climb)
    except (AttributeError, TypeError, ValueError):
        return None
    if not _finite(a, g, thr, hdg, alt, climb):
        return None
    if not (
        0.0 <= a <= MAX_SPEED_M_S and 0.0 <= g <= MAX_SPEED_M_S and abs(climb) <= MAX_SPEED_M_S
    ):
        return None
    if not (0.0 <= thr <= 100.0) or not (MIN_ALT_M <= alt <= MAX_ALT_M):
        return None
    return VfrHudSample(
        a, g, thr / 100.0, math.radians(hdg) % (2 * math.pi), alt, climb, _t_rx(msg)
    )


def decode_wind(msg: Any) -> WindSample | None:
    """ArduPilot WIND: direction the wind comes FROM (deg), speed (m/s), speed_z (m/s, NED down).

    ArduPilot sends ``speed = |wind|`` (the 3-D norm, despite the XML saying "ground plane") and
    ``direction = atan2(-wind_e, -wind_n)``; we undo exactly that:
    horizontal = sqrt(speed^2 - speed_z^2), wind_n = -h cos(dir), wind_e = -h sin(dir).
    """
    try:
        d, s, sz = float(msg.direction), float(msg.speed), float(msg.speed_z)
    except (AttributeError, TypeError, ValueError):
        return None
    if not _finite(d, s, sz) or not (0.0 <= s <= MAX_SPEED_M_S) or abs(sz) > MAX_SPEED_M_S:
        return None
    if abs(d) > 720.0:
        return None
    h = math.sqrt(max(s * s - sz * sz, 0.0))
    dr = math.radians(d)
    return WindSample(_ro((-h * math.cos(dr), -h * math.sin(dr), sz)), "WIND", None, _t_rx(msg))


def decode_wind_cov(msg: Any) -> WindSample | None:
    """PX4 WIND_COV: wind_x north, wind_y east, wind_z down (m/s, air-mass velocity).

    MAVLink defines NaN as "unknown" per field: an unknown vertical wind is taken as 0 m/s,
    an unknown horizontal component rejects the sample.
    """
    try:
        wx, wy, wz = float(msg.wind_x), float(msg.wind_y), float(msg.wind_z)
        t = float(msg.time_usec) * 1e-6
    except (AttributeError, TypeError, ValueError):
        return None
    if math.isnan(wz):
        wz = 0.0
    if not _finite(wx, wy, wz) or math.sqrt(wx * wx + wy * wy + wz * wz) > MAX_SPEED_M_S:
        return None
    return WindSample(_ro((wx, wy, wz)), "WIND_COV", t, _t_rx(msg))


def decode_home_position(msg: Any) -> HomeSample | None:
    try:
        lat, lon, alt = msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3
        pos = (float(msg.x), float(msg.y), float(msg.z))
    except (AttributeError, TypeError, ValueError):
        return None
    if not _geodetic_ok(lat, lon, alt) or not _finite(*pos):
        return None
    if max(abs(v) for v in pos) > MAX_LOCAL_POS_M:
        return None
    return HomeSample(lat, lon, alt, _ro(pos))


def decode_heartbeat(msg: Any) -> HeartbeatSample | None:
    try:
        hb = HeartbeatSample(
            type=int(msg.type),
            autopilot=int(msg.autopilot),
            base_mode=int(msg.base_mode),
            custom_mode=int(msg.custom_mode),
            system_status=int(msg.system_status),
            armed=is_armed(msg),
            src_system=int(msg.get_srcSystem()) if hasattr(msg, "get_srcSystem") else 0,
            src_component=int(msg.get_srcComponent()) if hasattr(msg, "get_srcComponent") else 0,
            t_rx_s=_t_rx(msg),
        )
    except (AttributeError, TypeError, ValueError):
        return None
    return hb


def decode_command_ack(msg: Any) -> CommandAckSample | None:
    try:
        cmd, res = int(msg.command), int(msg.result)
        src = int(msg.get_srcSystem()) if hasattr(msg, "get_srcSystem") else 0
    except (AttributeError, TypeError, ValueError):
        return None
    entry = _d.enums.get("MAV_RESULT", {}).get(res)
    name = entry.name if entry is not None else f"MAV_RESULT({res})"
    return CommandAckSample(cmd, res, res == _d.MAV_RESULT_ACCEPTED, name, src)


FT_POS, FT_VEL, FT_ACC, FT_ATT = 1, 2, 4, 8


def decode_follow_target(msg: Any) -> FollowTargetSample | None:
    """FOLLOW_TARGET (#144). Fields are used when their est_capabilities bit is set; with
    est_capabilities == 0 ("unknown") a field is used when it is not all zeros (zero = unknown).
    A sample without a position is rejected: it cannot define a moving path."""
    try:
        caps = int(msg.est_capabilities)
        lat, lon, alt = msg.lat * 1e-7, msg.lon * 1e-7, float(msg.alt)
        vel = [float(v) for v in msg.vel]
        acc = [float(v) for v in msg.acc]
        q = [float(v) for v in msg.attitude_q]
        rates = [float(v) for v in msg.rates]
        cov = [float(v) for v in msg.position_cov]
        t = float(msg.timestamp) * 1e-3
        src = int(msg.get_srcSystem()) if hasattr(msg, "get_srcSystem") else 0
    except (AttributeError, TypeError, ValueError):
        return None

    def present(bit: int, vals: list[float]) -> bool:
        return bool(caps & bit) if caps else any(v != 0.0 for v in vals)

    if not present(FT_POS, [lat, lon]) or not _geodetic_ok(lat, lon, alt):
        return None
    if not _finite(*cov):
        return None
    vel_a = acc_a = R = rates_a = None
    if present(FT_VEL, vel):
        if not _finite(*vel) or math.sqrt(sum(v * v for v in vel)) > MAX_SPEED_M_S:
            return None
        vel_a = _ro(vel)
    if present(FT_ACC, acc):
        if not _finite(*acc) or math.sqrt(sum(v * v for v in acc)) > MAX_ACCEL_M_S2:
            return None
        acc_a = _ro(acc)
    if present(FT_ATT, q + rates):
        R = _quat_to_matrix(q)
        if R is None or not _finite(*rates) or max(abs(v) for v in rates) > MAX_RATE_RAD_S:
            return None
        rates_a = _ro(rates)
    return FollowTargetSample(t, lat, lon, alt, vel_a, acc_a, R, rates_a, _ro(cov), caps, src)


def decode_attitude_target(msg: Any) -> AttitudeTargetSample | None:
    try:
        t = float(msg.time_boot_ms) * 1e-3
        rates = (float(msg.body_roll_rate), float(msg.body_pitch_rate), float(msg.body_yaw_rate))
        thrust, tm = float(msg.thrust), int(msg.type_mask)
    except (AttributeError, TypeError, ValueError):
        return None
    if not _finite(t, thrust, *rates) or max(abs(v) for v in rates) > MAX_RATE_RAD_S:
        return None
    return AttitudeTargetSample(t, rates, thrust, tm)


_DECODERS: dict[str, Callable[[Any], Any]] = {
    "ATTITUDE": decode_attitude,
    "ATTITUDE_QUATERNION": decode_attitude_quaternion,
    "LOCAL_POSITION_NED": decode_local_position_ned,
    "GLOBAL_POSITION_INT": decode_global_position_int,
    "VFR_HUD": decode_vfr_hud,
    "WIND": decode_wind,
    "WIND_COV": decode_wind_cov,
    "HOME_POSITION": decode_home_position,
    "HEARTBEAT": decode_heartbeat,
    "COMMAND_ACK": decode_command_ack,
    "FOLLOW_TARGET": decode_follow_target,
    "ATTITUDE_TARGET": decode_attitude_target,
}
DECODED_TYPES = frozenset(_DECODERS)


def decode(msg: Any) -> Any:
    """Dispatch on ``msg.get_type()``; None for unhandled types or rejected content. Never raises."""
    try:
        fn = _DECODERS.get(msg.get_type())
        return fn(msg) if fn is not None else None
    except Exception:  # noqa: BLE001 - a decoder bug must not take the loop down
        return None


# ---------------------------------------------------------------------------------------------
# Encoders (raise ValueError rather than send a non-finite or out-of-range value)
# ---------------------------------------------------------------------------------------------
def _check_ids(time_boot_ms: int, target_sys: int, target_comp: int) -> int:
    if not (0 <= int(target_sys) <= 255 and 0 <= int(target_comp) <= 255):
        raise ValueError(f"target ids out of range: {target_sys}/{target_comp}")
    if not isinstance(time_boot_ms, (int, np.integer)) or time_boot_ms < 0:
        raise ValueError(f"time_boot_ms must be a non-negative integer, got {time_boot_ms!r}")
    return int(time_boot_ms) & 0xFFFFFFFF  # uint32 on the wire; wraps after 49.7 days


def _check_finite(name: str, vals: Sequence[float], bound: float) -> list[float]:
    out = [float(v) for v in vals]
    if not _finite(*out):
        raise ValueError(f"refusing to encode non-finite {name}: {tuple(vals)}")
    if any(abs(v) > bound for v in out):
        raise ValueError(f"refusing to encode {name} beyond +-{bound}: {tuple(vals)}")
    return out


def _check_thrust(thrust: float) -> float:
    (t,) = _check_finite("thrust", [thrust], 1.0)
    return t


def encode_set_attitude_target_rates(
    mav: Any,
    time_boot_ms: int,
    target_sys: int,
    target_comp: int,
    p: float,
    q: float,
    r: float,
    thrust: float,
) -> Any:
    """PX4 offboard body rates: SET_ATTITUDE_TARGET, type_mask 128 (attitude ignored).

    p, q, r: rad/s about FRD body axes; thrust: 0..1 (must be sent: with "throttle ignore"
    PX4's fixed-wing rate controller gets zero throttle). The quaternion field is the identity
    (w, x, y, z) = (1, 0, 0, 0) because a NaN there could be taken for a real value by others.
    """
    t_ms = _check_ids(time_boot_ms, target_sys, target_comp)
    pf, qf, rf, thr = float(p), float(q), float(r), float(thrust)
    W = MAX_RATE_RAD_S  # a NaN fails the comparisons; the checkers then say what is wrong
    if not (-W <= pf <= W and -W <= qf <= W and -W <= rf <= W):
        _check_finite("body rates", (p, q, r), MAX_RATE_RAD_S)
    if not -1.0 <= thr <= 1.0:
        _check_thrust(thrust)
    return mav.set_attitude_target_encode(
        t_ms, target_sys, target_comp, TYPE_MASK_PX4_RATES, [1.0, 0.0, 0.0, 0.0], pf, qf, rf, thr
    )


def encode_set_attitude_target_quat(
    mav: Any,
    time_boot_ms: int,
    target_sys: int,
    target_comp: int,
    q_wxyz: Sequence[float],
    thrust: float,
    body_rates: Sequence[float] = (0.0, 0.0, 0.0),
) -> Any:
    """ArduPlane GUIDED attitude: SET_ATTITUDE_TARGET, type_mask 132 (see
    :data:`TYPE_MASK_ARDUPLANE_ATTITUDE`).

    ArduPlane takes roll and pitch from q and leaves the rudder to its own coordinated-turn
    output (the yaw of q is not used). Bit 64 (throttle ignore) clear: thrust 0..1 is used (only
    if TRIM_THROTTLE > 1). ArduPlane never reads body rates; ``body_rates`` (rad/s) are carried
    for logs and other receivers only.
    ``q_wxyz`` is (w, x, y, z), R_B^N; it is normalised, and zero/non-finite is refused.
    """
    t_ms = _check_ids(time_boot_ms, target_sys, target_comp)
    qv = _check_finite("quaternion", q_wxyz, 10.0)
    if len(qv) != 4:
        raise ValueError(f"quaternion must have 4 components (w, x, y, z), got {len(qv)}")
    n = math.sqrt(sum(v * v for v in qv))
    if n < 1e-6:
        raise ValueError("refusing to encode a zero quaternion")
    qv = [v / n for v in qv]
    rates = _check_finite("body rates", body_rates, MAX_RATE_RAD_S)
    thr = _check_thrust(thrust)
    return mav.set_attitude_target_encode(
        t_ms, target_sys, target_comp, TYPE_MASK_ARDUPLANE_ATTITUDE, qv, *rates, thr
    )


def encode_set_mode(
    mav: Any, target_sys: int, target_comp: int, flavour: Flavour | str, mode: str | int | tuple
) -> Any:
    """COMMAND_LONG MAV_CMD_DO_SET_MODE, param1 = 1 (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED).

    PX4: param2 = main mode, param3 = sub mode; ``mode`` is a name ('OFFBOARD', 'AUTO.LOITER')
    or a (main, sub) tuple. ArduPlane: param2 = mode number; ``mode`` is a name ('GUIDED') or int.
    """
    flavour = Flavour(flavour)
    _check_ids(0, target_sys, target_comp)
    if flavour is Flavour.PX4:
        if isinstance(mode, str):
            main, sub = px4_mode_from_name(mode)
        elif isinstance(mode, tuple) and len(mode) == 2:
            main, sub = int(mode[0]), int(mode[1])
        else:
            raise ValueError(f"PX4 mode must be a name or (main, sub), got {mode!r}")
        p2, p3 = float(main), float(sub)
    elif flavour is Flavour.ARDUPILOT:
        if isinstance(mode, str):
            num = arduplane_mode_from_name(mode)
        elif isinstance(mode, int):
            num = mode
        else:
            raise ValueError(f"ArduPlane mode must be a name or a number, got {mode!r}")
        if not 0 <= num <= 255:
            raise ValueError(f"ArduPlane mode number out of range: {num}")
        p2, p3 = float(num), 0.0
    else:
        raise ValueError("cannot encode a mode change for an unknown autopilot flavour")
    return mav.command_long_encode(
        target_sys, target_comp, MAV_CMD_DO_SET_MODE, 0,
        float(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), p2, p3, 0.0, 0.0, 0.0, 0.0,
    )  # fmt: skip


def encode_arm(
    mav: Any, target_sys: int, target_comp: int, arm: bool = True, force: bool = False
) -> Any:
    """COMMAND_LONG MAV_CMD_COMPONENT_ARM_DISARM: param1 1 arm / 0 disarm, param2 21196 forces."""
    _check_ids(0, target_sys, target_comp)
    return mav.command_long_encode(
        target_sys, target_comp, MAV_CMD_COMPONENT_ARM_DISARM, 0,
        1.0 if arm else 0.0, float(ARM_FORCE_MAGIC) if force else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    )  # fmt: skip


def encode_companion_heartbeat(mav: Any, system_status: int | None = None) -> Any:
    """HEARTBEAT of a companion computer: MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID,
    so that autopilots and GCSs do not mistake us for a vehicle."""
    status = _d.MAV_STATE_ACTIVE if system_status is None else int(system_status)
    return mav.heartbeat_encode(
        _d.MAV_TYPE_ONBOARD_CONTROLLER, _d.MAV_AUTOPILOT_INVALID, 0, 0, status
    )


def encode_set_message_interval(
    mav: Any, target_sys: int, target_comp: int, msg_id: int, rate_hz: float
) -> Any:
    """COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL: param1 message id, param2 interval (us);
    ``rate_hz`` <= 0 stops the stream (interval -1)."""
    _check_ids(0, target_sys, target_comp)
    if not math.isfinite(rate_hz):
        raise ValueError(f"message rate must be finite, got {rate_hz!r}")
    interval = -1.0 if rate_hz <= 0 else 1e6 / rate_hz
    return mav.command_long_encode(
        target_sys, target_comp, MAV_CMD_SET_MESSAGE_INTERVAL, 0,
        float(msg_id), interval, 0.0, 0.0, 0.0, 0.0, 0.0,
    )  # fmt: skip


def encode_request_data_stream(
    mav: Any, target_sys: int, target_comp: int, stream_id: int, rate_hz: int
) -> Any:
    """REQUEST_DATA_STREAM (deprecated in common, still ArduPilot's SRn mechanism): one stream
    group (MAV_DATA_STREAM_*) at ``rate_hz`` (integer Hz, 0 stops it)."""
    _check_ids(0, target_sys, target_comp)
    hz = max(0, min(int(round(rate_hz)), 0xFFFF))
    return mav.request_data_stream_encode(
        target_sys, target_comp, int(stream_id), hz, 1 if hz else 0
    )


def encode_request_message(mav: Any, target_sys: int, target_comp: int, msg_id: int) -> Any:
    """COMMAND_LONG MAV_CMD_REQUEST_MESSAGE: param1 the message id, sent once."""
    _check_ids(0, target_sys, target_comp)
    return mav.command_long_encode(
        target_sys, target_comp, MAV_CMD_REQUEST_MESSAGE, 0,
        float(msg_id), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    )  # fmt: skip


def encode_get_home_position(mav: Any, target_sys: int, target_comp: int) -> Any:
    """COMMAND_LONG MAV_CMD_GET_HOME_POSITION (older autopilots' way to ask for HOME_POSITION)."""
    _check_ids(0, target_sys, target_comp)
    return mav.command_long_encode(
        target_sys, target_comp, MAV_CMD_GET_HOME_POSITION, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    )


def encode_do_reposition(
    mav: Any,
    target_sys: int,
    target_comp: int,
    lat_deg: float,
    lon_deg: float,
    alt_amsl_m: float,
    radius_m: float,
    counter_clockwise: bool,
) -> Any:
    """COMMAND_INT MAV_CMD_DO_REPOSITION (frame MAV_FRAME_GLOBAL, AMSL): ArduPlane in GUIDED
    makes it its guided waypoint, a loiter of ``radius_m`` (param3) about it, counter-clockwise
    when param4 is non-zero (ArduPlane/GCS_MAVLink_Plane.cpp, handle_command_int_do_reposition;
    in GUIDED it leaves the forced attitude alone)."""
    _check_ids(0, target_sys, target_comp)
    if not _geodetic_ok(lat_deg, lon_deg, alt_amsl_m) or not (0.0 < radius_m < 1e5):
        raise ValueError(
            f"bad reposition target {lat_deg!r}, {lon_deg!r}, {alt_amsl_m!r} m, radius {radius_m!r} m"
        )
    return mav.command_int_encode(
        target_sys, target_comp, _d.MAV_FRAME_GLOBAL, MAV_CMD_DO_REPOSITION, 0, 0,
        -1.0, 0.0, float(radius_m), 1.0 if counter_clockwise else 0.0,
        int(round(lat_deg * 1e7)), int(round(lon_deg * 1e7)), float(alt_amsl_m),
    )  # fmt: skip
