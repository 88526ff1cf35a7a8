"""Plain values -> pymavlink messages. Encoders refuse (``ValueError``) to put a non-finite or
out-of-range number on the wire.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from mpf_mavlink.mavlink.modes import (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    Flavour,
    arduplane_mode_from_name,
    px4_mode_from_name,
)
from mpf_mavlink.mavlink.pymav import dialect as _d
from mpf_mavlink.mavlink.wire_limits import (
    ARM_FORCE_MAGIC,
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_REPOSITION,
    MAV_CMD_DO_SET_MODE,
    MAV_CMD_GET_HOME_POSITION,
    MAV_CMD_REQUEST_MESSAGE,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    MAX_RATE_RAD_S,
    TYPE_MASK_ARDUPLANE_ATTITUDE,
    TYPE_MASK_PX4_RATES,
    _finite,
    _geodetic_ok,
)


# ---------------------------------------------------------------------------------------------
# Encoders (raise ValueError rather than send a non-finite or out-of-range value)
# ---------------------------------------------------------------------------------------------
def _check_ids(time_boot_ms: int, target_sys: int, target_comp: int) -> int:
    if (  # plain ints in range (every setpoint): the same answer without the conversions
        type(time_boot_ms) is int
        and type(target_sys) is int
        and type(target_comp) is int
        and time_boot_ms >= 0
        and 0 <= target_sys <= 255
        and 0 <= target_comp <= 255
    ):
        return time_boot_ms & 0xFFFFFFFF
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
    mav: Any,
    target_sys: int,
    target_comp: int,
    flavour: Flavour | str,
    mode: str | int | tuple[int, ...],
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
    px4: bool = False,
) -> Any:
    """COMMAND_INT MAV_CMD_DO_REPOSITION (frame MAV_FRAME_GLOBAL, AMSL): ArduPlane in GUIDED
    makes it its guided waypoint, a loiter of ``radius_m`` (param3) about it, counter-clockwise
    when param4 is non-zero (ArduPlane/GCS_MAVLink_Plane.cpp, handle_command_int_do_reposition;
    in GUIDED it leaves the forced attitude alone). ``px4``: param2 = 0 (no mode change) and
    param3/param4 NaN (PX4 reads param4 as a yaw and has no radius there: its Hold loiters
    NAV_LOITER_RAD); the navigator keeps the point for the next Hold (navigator_main.cpp)."""
    _check_ids(0, target_sys, target_comp)
    if not _geodetic_ok(lat_deg, lon_deg, alt_amsl_m) or not (0.0 < radius_m < 1e5):
        raise ValueError(
            f"bad reposition target {lat_deg!r}, {lon_deg!r}, {alt_amsl_m!r} m, radius "
            f"{radius_m!r} m"
        )
    p3, p4 = (math.nan, math.nan) if px4 else (float(radius_m), 1.0 if counter_clockwise else 0.0)
    return mav.command_int_encode(
        target_sys, target_comp, _d.MAV_FRAME_GLOBAL, MAV_CMD_DO_REPOSITION, 0, 0,
        -1.0, 0.0, p3, p4,
        int(round(lat_deg * 1e7)), int(round(lon_deg * 1e7)), float(alt_amsl_m),
    )  # fmt: skip
