"""The vehicle's telemetry streams at the autopilot's rates (what each message carries, per
flavour) and the requests that change them: MAV_CMD_SET_MESSAGE_INTERVAL, REQUEST_MESSAGE,
GET_HOME_POSITION, ArduPilot's REQUEST_DATA_STREAM, AUTOPILOT_VERSION."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from sim.plant.jsbsim_plant import vector_floats
from sim.vehicle.clock import StepClock
from sim.vehicle.config import TelemetryRates, stock_rates
from sim.vehicle.link import Link

# the pymavlink message classes of what the vehicle streams
SPEC = {
    name: getattr(M, f"MAVLink_{name}_message")
    for name in (
        "heartbeat",
        "attitude",
        "local_position_ned",
        "global_position_int",
        "vfr_hud",
        "wind",
        "wind_cov",
        "home_position",
        "sys_status",
        "system_time",
        "follow_target",
        "attitude_target",
        "gps_raw_int",
    )
}
_ATTITUDE, _LOCAL_POSITION = SPEC["attitude"], SPEC["local_position_ned"]
_GLOBAL_POSITION = SPEC["global_position_int"]
# streams after ATTITUDE within a frame (see Telemetry.frame)
STREAM_ORDER = (
    "heartbeat",
    "local_position",
    "global_position",
    "vfr_hud",
    "wind",
    "home_position",
    "sys_status",
    "system_time",
    "attitude_target",
    "gps_raw",
)
# message id -> stream name (for MAV_CMD_SET_MESSAGE_INTERVAL / REQUEST_MESSAGE)
STREAM_IDS = {
    M.MAVLINK_MSG_ID_ATTITUDE: "attitude",
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: "local_position",
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: "global_position",
    M.MAVLINK_MSG_ID_VFR_HUD: "vfr_hud",
    M.MAVLINK_MSG_ID_WIND: "wind",
    M.MAVLINK_MSG_ID_WIND_COV: "wind",
    M.MAVLINK_MSG_ID_HOME_POSITION: "home_position",
    M.MAVLINK_MSG_ID_SYS_STATUS: "sys_status",
    M.MAVLINK_MSG_ID_SYSTEM_TIME: "system_time",
    M.MAVLINK_MSG_ID_HEARTBEAT: "heartbeat",
    M.MAVLINK_MSG_ID_GPS_RAW_INT: "gps_raw",
}
# ArduPilot's REQUEST_DATA_STREAM groups -> our streams (MAV_DATA_STREAM_*: 0 all, 2 extended
# status, 6 position, 10 extra1, 11 extra2, 12 extra3)
AP_DATA_STREAMS = {
    2: ("sys_status", "gps_raw"),
    6: ("global_position", "local_position"),
    10: ("attitude",),
    11: ("vfr_hud",),
    12: ("wind", "system_time"),
}
# SYS_STATUS sensors (a simulated airframe lacks none of them)
_SENSORS = (
    M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | M.MAV_SYS_STATUS_SENSOR_3D_MAG
    | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | M.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE
    | M.MAV_SYS_STATUS_SENSOR_GPS
    | M.MAV_SYS_STATUS_AHRS
)
STREAM_COMMANDS = frozenset(
    (
        M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
        M.MAV_CMD_REQUEST_MESSAGE,
        M.MAV_CMD_GET_HOME_POSITION,
        M.MAV_CMD_SET_MESSAGE_INTERVAL,
    )
)


def eas_factor(alt_amsl_m: float) -> float:
    """EAS / TAS = sqrt(rho / rho0) in the ISA troposphere (what VFR_HUD.airspeed reports)."""
    h = min(max(alt_amsl_m, -500.0), 11000.0)
    return float((1.0 - 2.25577e-5 * h) ** 2.127940)


def _e7(deg: float) -> int:
    return int(round(deg * 1e7))


# x + _RINT - _RINT is x rounded to an integer half to even (IEEE's rounding of the sum, whose
# unit in the last place is 1) for |x| < 2**51: round(x) without its method look-up, for the
# integer fields of the message sent every frame
_RINT = 1.5 * 2.0**52


def _global_position(st: Any, ms: int, home_alt_m: float) -> tuple[int, ...]:
    """GLOBAL_POSITION_INT's fields from a plant state."""
    vx, vy, vz = vector_floats(st, "velocity_ned")
    r = _RINT
    alt = st.alt_m
    hdg = int(math.degrees(st.euler[2]) * 100.0 + r - r) % 36000
    return (ms, int(st.lat_deg * 1e7 + r - r), int(st.lon_deg * 1e7 + r - r),
            int(alt * 1000.0 + r - r), int((alt - home_alt_m) * 1000.0 + r - r),
            int(vx * 100 + r - r), int(vy * 100 + r - r), int(vz * 100 + r - r), hdg)  # fmt: skip


def _vfr_hud(st: Any) -> tuple[float, ...]:
    """VFR_HUD's fields: both autopilots report an equivalent airspeed (ArduPilot EAS, PX4
    calibrated)."""
    v = vector_floats(st, "velocity_ned")
    hdg = int(round(math.degrees(st.euler[2]))) % 360
    eas = st.airspeed * eas_factor(float(st.alt_m))
    return (eas, math.hypot(v[0], v[1]), hdg, int(round(100 * st.throttle)), st.alt_m,
            -float(v[2]))  # fmt: skip


def _gps_raw(st: Any, us: int) -> tuple[float, ...]:
    """GPS_RAW_INT's fields: a healthy 3D fix (HDOP 0.8, VDOP 1.2, 14 satellites, 0.5 m / 0.8 m
    accuracy)."""
    vn, ve, _ = vector_floats(st, "velocity_ned")
    cog = int(round(math.degrees(math.atan2(ve, vn)) * 100.0)) % 36000
    return (us, M.GPS_FIX_TYPE_3D_FIX, _e7(st.lat_deg), _e7(st.lon_deg),
            int(round(st.alt_m * 1000.0)), 80, 120, int(round(math.hypot(vn, ve) * 100.0)), cog,
            14, 0, 500, 800, 150, 0, 0)  # fmt: skip


# SYS_STATUS: every sensor present, enabled and healthy; health also sets GEOFENCE, as ArduPilot
# reports a fence it does not have (MAVProxy reads that bit clear as "fence breach")
_SYS_STATUS = (_SENSORS, _SENSORS, _SENSORS | M.MAV_SYS_STATUS_GEOFENCE, 100, 12600, 500, 90,
               0, 0, 0, 0, 0, 0, 0, 0, 0)  # fmt: skip


class WindEstimate:
    """The wind an autopilot reports: a first-order lag (``tau_s``; 0: the truth itself) of the
    true air-mass velocity, the way its estimator follows it (PX4 EKF2's wind states are a
    random walk observed through airspeed: gusts of a second or two barely move them). It starts
    at the truth: a vehicle that has flown a while has converged on the steady wind. Horizontal
    only: neither PX4's EKF2 nor ArduPilot's EKF2/EKF3 estimates a vertical wind (their getWind
    sets z = 0), so no autopilot reports one."""

    def __init__(self, tau_s: float = 0.0) -> None:
        self.tau_s = float(tau_s)
        self.value: tuple[float, float, float] | None = None  # None: not started (the truth)
        self._t = 0.0

    def update(self, wind_ned: Any, t: float) -> None:
        """Advance to time ``t`` (s) with the true wind ``wind_ned`` (m/s)."""
        wn, we = float(wind_ned[0]), float(wind_ned[1])
        if self.value is None:
            self.value = (wn, we, 0.0)
        else:
            k = 1.0 - math.exp(-max(0.0, t - self._t) / self.tau_s)
            e0, e1, _ = self.value
            self.value = (e0 + k * (wn - e0), e1 + k * (we - e1), 0.0)
        self._t = t


class Telemetry:
    """The vehicle's streams: schedule, content, and the requests that change the rates.

    ``heartbeat`` returns (base_mode, custom_mode); ``echo`` the PX4 setpoint echo or None."""

    def __init__(
        self,
        px4: bool,
        rates: TelemetryRates,
        clock: StepClock,
        link: Link,
        home_lla: tuple[float, float, float],
        frame_period: float,
        heartbeat: Callable[[], tuple[int, int]],
        echo: Callable[[], Any],
    ) -> None:
        self.px4 = px4
        self.rates = rates
        self.stock = stock_rates("px4" if px4 else "ardupilot")
        self.clock, self.link = clock, link
        self.home_lla = home_lla
        self.frame_period = frame_period
        self._heartbeat, self._echo = heartbeat, echo
        self.next: dict[str, float] = {}  # boot s each stream is next due
        self.sent = dict.fromkeys(("attitude", *STREAM_ORDER), 0)  # messages produced per stream
        # the builders of the streams' messages (bytes, or None: nothing to send)
        self._build: dict[str, Callable[[], bytes | None]] = {
            "global_position": self._global_position,
            "heartbeat": self._heartbeat_msg,
            "wind": self._wind,
            "attitude_target": self._attitude_target,
            "system_time": self._system_time,
            "vfr_hud": self._vfr_hud,
            "home_position": self._home_position,
            "sys_status": self._sys_status,
            "gps_raw": self._gps_raw,
        }
        self.st: Any = None  # the state reported (set each frame by the vehicle)
        self.wind = WindEstimate()  # the wind reported
        self.unix0_us = int(time.time() * 1e6)
        self.on_version: Callable[[], None] = lambda: None  # AUTOPILOT_VERSION (gcs services)

    # ------------------------------------------------------------------ schedule
    def due(self, name: str, hz: float) -> bool:
        """Whether stream ``name`` at ``hz`` is due now (and schedule its next time if so)."""
        if hz <= 0:
            return False
        t = self.clock.boot_s
        nxt = self.next.get(name)
        if nxt is None or t + 1e-9 >= nxt:
            period = 1.0 / hz
            self.next[name] = t + period if nxt is None or t - nxt > period else nxt + period
            return True
        return False

    def set_rate(self, name: str, hz: float) -> None:
        setattr(self.rates, name, hz)
        self.next.pop(name, None)

    def slow_streams(self) -> None:
        """Queue the streams due after the 50 Hz pair (see :meth:`sim.vehicle.vehicle.SimVehicle
        .step_once` for why the pair leaves in a datagram of its own)."""
        r, nxt, t = self.rates, self.next, self.clock.boot_s + 1e-9
        if self.wind.tau_s > 0.0:
            self.wind.update(vector_floats(self.st, "wind_ned"), t)
        for name in STREAM_ORDER:
            n = nxt.get(name)
            if n is not None and t < n:
                continue  # not due (the common case: a cheap test before due()'s bookkeeping)
            if self.due(name, getattr(r, name)):
                self.send(name)

    # ------------------------------------------------------------------ content
    def attitude(self) -> None:
        """ATTITUDE (roll, pitch, yaw, p, q, r) of the state reported, stamped for lockstep."""
        st = self.st
        self.sent["attitude"] += 1
        ms = self.clock.ms()
        roll, pitch, yaw = st.euler
        p, q, r = vector_floats(st, "pqr")
        self.link.put(self.link.framer.pack(_ATTITUDE, ms, roll, pitch, yaw, p, q, r), ms)

    def local_position(self) -> None:
        st, ms = self.st, self.clock.ms()
        self.sent["local_position"] += 1
        x, y, z = vector_floats(st, "position_ned")
        vx, vy, vz = vector_floats(st, "velocity_ned")
        buf = self.link.framer.pack(_LOCAL_POSITION, ms, x, y, z, vx, vy, vz)
        self.link.put(buf, -1, ms)

    def send(self, name: str) -> None:
        """One message of stream ``name`` now."""
        if name == "attitude":
            self.attitude()
            return
        if name == "local_position":
            self.local_position()
            return
        self.sent[name] += 1
        buf = self._build[name]()
        if buf is not None:
            self.link.put(buf)

    def _global_position(self) -> bytes:
        fields = _global_position(self.st, self.clock.ms(), self.home_lla[2])
        return self.link.framer.pack(_GLOBAL_POSITION, *fields)

    def _heartbeat_msg(self) -> bytes:
        ap = M.MAV_AUTOPILOT_PX4 if self.px4 else M.MAV_AUTOPILOT_ARDUPILOTMEGA
        base, custom = self._heartbeat()
        return self.link.framer.pack(SPEC["heartbeat"], M.MAV_TYPE_FIXED_WING, ap, base, custom,
                                     M.MAV_STATE_ACTIVE, 3)  # fmt: skip

    def _wind(self) -> bytes:
        st, pack = self.st, self.link.framer.pack
        w = self.wind.value if self.wind.value is not None else vector_floats(st, "wind_ned")
        wn, we, wd = (float(x) for x in w)
        if self.px4:
            return pack(SPEC["wind_cov"], self.clock.us(), wn, we, 0.0, 0.0, 0.0, st.alt_m, 0.0,
                        0.0)  # fmt: skip
        direction = math.degrees(math.atan2(-we, -wn)) % 360.0
        return pack(SPEC["wind"], direction, math.sqrt(wn * wn + we * we + wd * wd), wd)

    def _attitude_target(self) -> bytes | None:
        # PX4's ATTITUDE_TARGET: the setpoint in use, stamped when it was received (a companion
        # measures its loop delay from it); nothing before the first setpoint
        echo = self._echo()
        if not self.px4 or echo is None:
            return None
        t_ms, tm, q, rates, thrust = echo
        return self.link.framer.pack(SPEC["attitude_target"], t_ms, tm, list(q), *rates, thrust)

    def _system_time(self) -> bytes:
        us = self.clock.us()
        return self.link.framer.pack(SPEC["system_time"], self.unix0_us + us, self.clock.ms())

    def _vfr_hud(self) -> bytes:
        return self.link.framer.pack(SPEC["vfr_hud"], *_vfr_hud(self.st))

    def _home_position(self) -> bytes:
        lat, lon, alt = self.home_lla
        return self.link.framer.pack(SPEC["home_position"], _e7(lat), _e7(lon),
                                     int(round(alt * 1000)), 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0],
                                     0.0, 0.0, 0.0, self.clock.us())  # fmt: skip

    def _sys_status(self) -> bytes:
        return self.link.framer.pack(SPEC["sys_status"], *_SYS_STATUS)

    def _gps_raw(self) -> bytes:
        return self.link.framer.pack(SPEC["gps_raw_int"], *_gps_raw(self.st, self.clock.us()))

    # ------------------------------------------------------------------ requests
    def command(self, msg: Any) -> None:
        """A command of :data:`STREAM_COMMANDS`, acknowledged."""
        cmd, p1, p2, ack = msg.command, msg.param1, msg.param2, self.link.ack
        if cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES or (
            cmd == M.MAV_CMD_REQUEST_MESSAGE and int(p1) == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
        ):
            ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            self.on_version()
            return
        if cmd == M.MAV_CMD_GET_HOME_POSITION:
            ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            self.send("home_position")
            return
        name = STREAM_IDS.get(int(p1))
        if name is None:
            ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            self.send(name)
        elif p2 < 0:
            self.set_rate(name, 0.0)
            ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
        elif p2 == 0:
            self.set_rate(name, getattr(self.stock, name))
            ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
        elif not self.px4 and p2 * 0.8 < self.frame_period * 1e6:
            # ArduPilot (GCS_Common.cpp, cap_message_interval): an interval shorter than 1.25
            # main-loop periods is refused, saying so (50 Hz at Plane's 50 Hz)
            self.link.statustext(
                M.MAV_SEVERITY_INFO,
                f"Requested rate for message ID {int(p1)} too fast. Increase SCHED_LOOP_RATE",
            )
            ack(cmd, M.MAV_RESULT_DENIED, msg)
        else:
            self.set_rate(name, 1e6 / p2)
            ack(cmd, M.MAV_RESULT_ACCEPTED, msg)

    def request_data_stream(self, msg: Any) -> None:
        """ArduPilot's REQUEST_DATA_STREAM (PX4 ignores it: MAV_CMD_SET_MESSAGE_INTERVAL only)."""
        if self.px4:
            return
        hz = float(msg.req_message_rate) if msg.start_stop else 0.0
        # ArduPilot caps a stream at 1.25 main-loop periods (40 Hz at Plane's 50 Hz loop)
        hz = min(hz, 1.0 / (1.25 * self.frame_period))
        sid = msg.req_stream_id
        groups = AP_DATA_STREAMS.values() if sid == 0 else [AP_DATA_STREAMS.get(sid, ())]
        for group in groups:
            for name in group:
                self.set_rate(name, hz)
