"""External setpoints as the stock autopilot takes them from SET_ATTITUDE_TARGET: PX4's
offboard setpoint (body rates or attitude, thrust) and its stream bookkeeping, ArduPlane's
GUIDED forced axes (roll, pitch, yaw, throttle), each stamped with when it arrived. Malformed
or non-finite input is dropped and counted, never applied."""

from __future__ import annotations

import math
from math import isfinite
from typing import Any

from mpf_mavlink.core.frames import matrix_to_euler, quat_wxyz_to_matrix

PX4_OFFBOARD_MIN_STREAM_S = 1.0  # setpoints must have been streaming this long
PX4_OFFBOARD_MAX_GAP_S = 0.5  # ... at more than 2 Hz


def finite(*vals: float) -> bool:
    return all(map(math.isfinite, vals))


def clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


class Setpoints:
    """The latest external setpoints and when they came (vehicle boot time, s)."""

    def __init__(self) -> None:
        # PX4 offboard: ("rates", (p, q, r), thrust) | ("att", (roll, pitch), thrust)
        self.sp: tuple[str, tuple[float, ...], float] | None = None
        self.sp_last: float | None = None  # boot s of the last setpoint counted as signal
        self.stream_start: float | None = None  # ... of the first of the current stream
        # what ATTITUDE_TARGET echoes: (ms, type_mask, q, body rates, thrust)
        self.echo: tuple[int, int, tuple[float, ...], tuple[float, ...], float] | None = None
        # ArduPlane GUIDED: roll, pitch, yaw (rad), throttle (0..1) and when each was forced
        self.forced = [0.0, 0.0, 0.0, 0.0]
        self.forced_t: list[float | None] = [None, None, None, None]
        # ArduPlane's guided fallback (MAV_CMD_DO_REPOSITION in GUIDED): centre, altitude,
        # radius and direction of the loiter it flies when the attitude setpoints stop
        self.guided_loiter: tuple[tuple[float, float], float, float, int] | None = None
        self.dropped: dict[str, int] = {
            "nonfinite": 0,
            "not_guided": 0,
            "wrong_target": 0,
            "no_axes": 0,
        }

    def offboard_available(self, t: float) -> bool:
        """PX4's rule for entering OFFBOARD at boot time ``t``: setpoints for >= 1 s at > 2 Hz."""
        last, start = self.sp_last, self.stream_start
        return (
            last is not None
            and start is not None
            and t - last <= PX4_OFFBOARD_MAX_GAP_S
            and t - start >= PX4_OFFBOARD_MIN_STREAM_S - 1e-9
        )

    def reset_forced(self) -> None:
        """A new GUIDED entry: no axis is forced until a setpoint says so, and it loiters where
        it was entered."""
        self.forced_t = [None, None, None, None]
        self.guided_loiter = None

    def take_px4(self, msg: Any, t: float, ms: int, require_thrust: bool) -> None:
        """PX4 offboard: type_mask 128 = body rates + thrust (a rate-ignore bit gives a zero
        rate on that axis), else the quaternion's roll and pitch; "throttle ignore" (64) gives
        zero thrust. ``t``, ``ms``: boot time now (s, ms)."""
        tm = msg.type_mask
        if tm == 128:
            # every body rate and the thrust (what a companion streams, once per lockstep frame
            # in the SIL): the rules below without the lists they build for the general mask
            p, q, r, thr = msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate, msg.thrust
            if not (isfinite(thr) and isfinite(p) and isfinite(q) and isfinite(r)):
                self.dropped["nonfinite"] += 1
                return
            self.sp = ("rates", (float(p), float(q), float(r)), clip(float(thr), 0.0, 1.0))
            self.echo = (ms, tm, tuple(msg.q), (p, q, r), float(thr))
            if self.sp_last is None or t - self.sp_last > PX4_OFFBOARD_MAX_GAP_S:
                self.stream_start = t
            self.sp_last = t
            return
        att_ignore, thr_ignore = bool(tm & 128), bool(tm & 64)
        rates = (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
        used = [] if thr_ignore else [msg.thrust]
        if att_ignore:
            if tm & 7 == 7:
                self.dropped["no_axes"] += 1
                return
            used += [rates[i] for i in range(3) if not tm & (1 << i)]
        else:
            used += list(msg.q)
        if not finite(*used):
            self.dropped["nonfinite"] += 1
            return
        thrust = 0.0 if thr_ignore else clip(float(msg.thrust), 0.0, 1.0)
        if att_ignore:
            body = tuple(0.0 if tm & (1 << i) else float(rates[i]) for i in range(3))
            self.sp = ("rates", body, thrust)
        else:
            try:
                roll, pitch, _ = matrix_to_euler(quat_wxyz_to_matrix(msg.q))
            except ValueError:
                self.dropped["nonfinite"] += 1
                return
            self.sp = ("att", (roll, pitch), thrust)
        # PX4 stamps the ATTITUDE_TARGET echo when its receiver publishes the setpoint
        self.echo = (ms, tm, tuple(msg.q), rates, float(msg.thrust))
        if thr_ignore and require_thrust:
            return  # applied if already offboard, but not counted as an offboard signal
        if self.sp_last is None or t - self.sp_last > PX4_OFFBOARD_MAX_GAP_S:
            self.stream_start = t
        self.sp_last = t

    def take_ardupilot(self, msg: Any, t: float) -> None:
        """ArduPlane GUIDED (inverted mask ``m = ~type_mask & 0x87``): roll if ``m & 0x81``,
        pitch if ``m & 0x82``, yaw if ``m & 0x84``; thrust unless "throttle ignore"."""
        q = list(msg.q)
        if not finite(*q) or (not (msg.type_mask & 64) and not finite(msg.thrust)):
            self.dropped["nonfinite"] += 1
            return
        inv = (~msg.type_mask) & 0xFF
        am = inv & 0x87
        try:
            euler = matrix_to_euler(quat_wxyz_to_matrix(q)) if am else (0.0, 0.0, 0.0)
        except ValueError:
            self.dropped["nonfinite"] += 1
            return
        for i, bit in enumerate((0x81, 0x82, 0x84)):
            if am & bit:
                self.forced[i] = float(euler[i])
                self.forced_t[i] = t
        if inv & 0x40:
            self.forced[3] = clip(float(msg.thrust), 0.0, 1.0)
            self.forced_t[3] = t
