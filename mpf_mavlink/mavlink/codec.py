"""pymavlink messages <-> plain typed values (frozen dataclasses, SI units, NED / FRD, radians).

Decoders never raise: a message with a non-finite or absurd field returns ``None`` so that
malformed MAVLink can neither crash the loop nor put a NaN into the state. Encoders refuse
(``ValueError``) to put a non-finite number on the wire.

The attitude decoders (one per control step) compute the matrices of
:func:`mpf_mavlink.core.frames.euler_to_matrix` in scalar arithmetic (same conventions; tests
hold them to it) and, of a quaternion, :func:`mpf_mavlink.quaternion.rows_of_unit_quat` (the
conversion :func:`~mpf_mavlink.core.frames.quat_wxyz_to_matrix` uses).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, fields
from typing import Any, TypeVar

import numpy as np

from mpf_mavlink.mavlink.modes import (
    is_armed,
)
from mpf_mavlink.mavlink.pymav import dialect as _d
from mpf_mavlink.mavlink.wire_limits import (
    MAX_ACCEL_M_S2,
    MAX_ALT_M,
    MAX_ANGLE_RAD,
    MAX_LOCAL_POS_M,
    MAX_RATE_RAD_S,
    MAX_SPEED_M_S,
    MIN_ALT_M,
    QUAT_NORM_TOL,
    _finite,
    _geodetic_ok,
)
from mpf_mavlink.quaternion import rows_of_unit_quat

_T = TypeVar("_T")


# Read-only float64 arrays made from packed doubles: np.frombuffer over immutable bytes is
# read-only already, at a fifth of the cost of np.array + setflags (the values are the same).
_PACK3 = struct.Struct("3d").pack
_PACK9 = struct.Struct("9d").pack
_frombuffer = np.frombuffer
# the 3x3 straight from the bytes (np.ndarray(shape, dtype, buffer)): one call instead of
# frombuffer, then a reshape, with the dtype an object rather than ``float`` to look up
_ndarray, _F64, _SHAPE33 = np.ndarray, np.dtype(np.float64), (3, 3)


def _ro(a: Iterable[float]) -> np.ndarray:
    vals = [float(v) for v in a]
    return _frombuffer(struct.pack(f"{len(vals)}d", *vals))


def _frozen_maker(cls: type[_T]) -> Callable[..., _T]:
    """A constructor of the frozen dataclass ``cls`` taking every field, in order: it stores
    them in the instance's ``__dict__``, where the generated ``__init__`` sets each through
    ``object.__setattr__`` (frozen) at 2-3 times the cost, on the path of every sample. Made
    as dataclasses makes its ``__init__``: from the field names (identifiers)."""
    names = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    stores = "".join(f"    d[{n!r}] = {n}\n" for n in names)
    head = f"def make({', '.join(names)}):\n    o = new(cls)\n    d = o.__dict__\n"
    source = f"{head}{stores}    return o\n"
    scope: dict[str, Any] = {"new": object.__new__, "cls": cls}
    exec(source, scope)  # noqa: S102
    make: Callable[..., _T] = scope["make"]
    return make


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
    # m^2/s^2, WIND_COV.var_horiz: the autopilot's variance of its horizontal wind estimate
    # (None: not sent, zero, NaN or negative: MAVLink's "unknown"; WIND carries none)
    var_horiz_m2_s2: float | None = None


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


@dataclass(frozen=True)
class TimesyncSample:
    """TIMESYNC (#111) from the vehicle: ``tc1_ns`` its clock (PX4 and ArduPilot: time since
    boot, the clock of time_boot_ms, in ns), ``ts1_ns`` echoed from the request it answers
    (0 in a request of its own, which the bridge does not answer)."""

    tc1_ns: int
    ts1_ns: int


# ---------------------------------------------------------------------------------------------
# Decoders (return None on anything non-finite or absurd)
# ---------------------------------------------------------------------------------------------
def _ro3(a: float, b: float, c: float) -> np.ndarray:
    return _frombuffer(_PACK3(a, b, c))


def _ro33(*rows: float) -> np.ndarray:
    """The 3x3 matrix of nine values in row order, read-only."""
    return _ndarray(_SHAPE33, _F64, _PACK9(*rows))


_attitude = _frozen_maker(AttitudeSample)
_local_position = _frozen_maker(LocalPositionSample)
_global_position = _frozen_maker(GlobalPositionSample)
_vfr_hud = _frozen_maker(VfrHudSample)
_attitude_target = _frozen_maker(AttitudeTargetSample)


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
        a00, a02 * sr - sy * cr, a02 * cr + sy * sr,
        a10, a12 * sr + cy * cr, a12 * cr - cy * sr,
        -sp, cp * sr, cp * cr,
    )  # fmt: skip
    return _attitude(t, R, _ro3(wx, wy, wz), "ATTITUDE")


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
    return _ro33(*rows_of_unit_quat(w / n, x / n, y / n, z / n))


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
    return _local_position(t, _ro3(x, y, z), _ro3(vx, vy, vz))


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
    return _global_position(t, lat, lon, alt, rel, _ro3(*vel), heading, src)


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
    return _vfr_hud(a, g, thr / 100.0, math.radians(hdg) % (2 * math.pi), alt, climb, _t_rx(msg))


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
    try:
        var = float(msg.var_horiz)
    except (AttributeError, TypeError, ValueError):
        var = math.nan
    var_h = var if math.isfinite(var) and 0.0 < var <= MAX_SPEED_M_S**2 else None
    return WindSample(_ro((wx, wy, wz)), "WIND_COV", t, _t_rx(msg), var_h)


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
    return _attitude_target(t, rates, thrust, tm)


def decode_timesync(msg: Any) -> TimesyncSample | None:
    try:
        tc1, ts1 = int(msg.tc1), int(msg.ts1)
    except (AttributeError, TypeError, ValueError):
        return None
    if tc1 <= 0 or ts1 <= 0:  # a request (tc1 == 0), not an answer
        return None
    return TimesyncSample(tc1, ts1)


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
    "TIMESYNC": decode_timesync,
}
DECODED_TYPES = frozenset(_DECODERS)


def decode(msg: Any, mtype: str | None = None) -> Any:
    """Dispatch on ``msg.get_type()`` (``mtype``: what it returns, when the caller has read
    it); None for unhandled types or rejected content.

    Never raises.
    """
    try:
        fn = _DECODERS.get(msg.get_type() if mtype is None else mtype)
        return fn(msg) if fn is not None else None
    except Exception:  # noqa: BLE001 - a decoder bug must not take the loop down
        return None
