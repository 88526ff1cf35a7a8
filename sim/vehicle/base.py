"""The simulated vehicle's state (:class:`VehicleBase`): construction from the plant, autopilot,
link and rates; the boot and sim clocks; mode entry; the truth record. Tables of both autopilots'
modes and stock stream rates. See :mod:`sim.vehicle.vehicle` for the rules it honours."""

from __future__ import annotations

import math
import os
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("JSBSIM_DEBUG", "0")

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402

from sim.inner_loop import FixedWingAutopilot, fly_to_trim  # noqa: E402
from sim.plant.kinematic_plant import KinematicMavPlant, ned_to_geodetic_fast  # noqa: E402
from sim.vehicle.clock import Clock, make_clock  # noqa: E402

M = mavlink2
G = 9.80665

# --------------------------------------------------------------------------- mode tables
PX4_MAIN = {
    "MANUAL": 1,
    "ALTCTL": 2,
    "POSCTL": 3,
    "AUTO": 4,
    "ACRO": 5,
    "OFFBOARD": 6,
    "STABILIZED": 7,
}
PX4_AUTO_SUB = {"READY": 1, "TAKEOFF": 2, "LOITER": 3, "MISSION": 4, "RTL": 5, "LAND": 6}
PX4_MAIN_NAMES = {v: k for k, v in PX4_MAIN.items()}
PX4_SUB_NAMES = {v: k for k, v in PX4_AUTO_SUB.items()}

ARDUPLANE_MODES = {
    0: "MANUAL", 1: "CIRCLE", 2: "STABILIZE", 3: "TRAINING", 4: "ACRO", 5: "FBWA", 6: "FBWB",
    7: "CRUISE", 8: "AUTOTUNE", 10: "AUTO", 11: "RTL", 12: "LOITER", 13: "TAKEOFF", 15: "GUIDED",
}  # fmt: skip
ARDUPLANE_NUMBERS = {v: k for k, v in ARDUPLANE_MODES.items()}

# behaviours
LOITER, CRUISE, LEVEL, OFFBOARD, GUIDED = "loiter", "cruise", "level", "offboard", "guided"
_AP_BEHAVIOUR = {
    0: LEVEL, 1: LOITER, 2: LEVEL, 3: LEVEL, 4: LEVEL, 5: LEVEL, 6: CRUISE, 7: CRUISE,
    8: LEVEL, 10: LOITER, 11: LOITER, 12: LOITER, 13: LOITER, 15: GUIDED,
}  # fmt: skip
_PX4_BEHAVIOUR = {1: LEVEL, 2: CRUISE, 3: CRUISE, 4: LOITER, 5: LEVEL, 6: OFFBOARD, 7: LEVEL}

PX4_OFFBOARD_MIN_STREAM_S = 1.0  # setpoints must have been streaming this long
PX4_OFFBOARD_MAX_GAP_S = 0.5  # ... at more than 2 Hz
ARDUPILOT_FORCE_DISARM = 21196.0  # param2 magic of MAV_CMD_COMPONENT_ARM_DISARM


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """PX4 HEARTBEAT.custom_mode = (main << 16) | (sub << 24)."""
    return (int(main) << 16) | (int(sub) << 24)


def px4_decode_custom_mode(custom_mode: int) -> tuple[int, int]:
    """(main, sub) from a PX4 custom_mode."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


@dataclass
class TelemetryRates:
    """Stream rates in Hz (0 disables a stream). The defaults are a fast link; a vehicle starts
    with :func:`stock_rates` of its flavour unless told otherwise."""

    attitude: float = 50.0
    local_position: float = 50.0
    global_position: float = 10.0
    vfr_hud: float = 10.0
    wind: float = 2.0
    home_position: float = 1.0
    sys_status: float = 1.0
    system_time: float = 1.0
    heartbeat: float = 1.0
    attitude_target: float = 10.0  # PX4 only (its onboard link); ArduPlane does not stream it
    gps_raw: float = 1.0  # GPS_RAW_INT (what log tools and ground stations take the GPS from)


def stock_rates(flavour: str) -> TelemetryRates:
    """What the stock autopilot streams on the link a companion computer uses, before anyone
    asks for more (frames limit everything to 1 / frame_period).

    ArduPlane: every SRn/MAVn stream group at 1 Hz (AP_MAV_DEFAULT_STREAM_RATE_* for Plane in
    libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp): ATTITUDE (EXTRA1), GLOBAL_POSITION_INT +
    LOCAL_POSITION_NED (POSITION), VFR_HUD (EXTRA2), WIND + SYSTEM_TIME (EXTRA3), SYS_STATUS
    (EXTENDED_STATUS); HOME_POSITION is not streamed (only sent when asked).
    PX4: the onboard-mode instance (SITL's offboard link on 14540, ``mavlink start -m onboard``;
    src/modules/mavlink/mavlink_main.cpp, MAVLINK_MODE_ONBOARD): ATTITUDE 100, LOCAL_POSITION_NED
    30, GLOBAL_POSITION_INT 50, VFR_HUD 10, WIND_COV 10, HOME_POSITION 0.5, SYS_STATUS 5,
    SYSTEM_TIME 1, ATTITUDE_TARGET 10 Hz. GPS_RAW_INT: ArduPlane's EXTENDED_STATUS group (1 Hz);
    PX4 1 Hz (its normal-mode rate: a ground station on the link sees the GPS)."""
    if flavour == "ardupilot":
        return TelemetryRates(1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0)
    return TelemetryRates(100.0, 30.0, 50.0, 10.0, 10.0, 0.5, 5.0, 1.0, 1.0, 10.0, 1.0)


# ArduPilot's REQUEST_DATA_STREAM groups -> our streams (MAV_DATA_STREAM_*: 0 all, 2 extended
# status, 6 position, 10 extra1, 11 extra2, 12 extra3)
_AP_DATA_STREAMS = {
    2: ("sys_status", "gps_raw"),
    6: ("global_position", "local_position"),
    10: ("attitude",),
    11: ("vfr_hud",),
    12: ("wind", "system_time"),
}


def eas_factor(alt_amsl_m: float) -> float:
    """EAS / TAS = sqrt(rho / rho0) in the ISA troposphere (what VFR_HUD.airspeed reports)."""
    h = min(max(alt_amsl_m, -500.0), 11000.0)
    return (1.0 - 2.25577e-5 * h) ** 2.127940


# The pymavlink message classes of what the vehicle streams. Framing is pymavlink's own: it costs
# ~5 us per message here, ~1.7 ms of CPU per simulated second at the stock rates (scripts/bench
# --only mavlink_framing_us), which is why the hand-written framer this replaced was not worth it.
_SPEC = {
    name: getattr(M, f"MAVLink_{name}_message")
    for name in ("heartbeat", "attitude", "local_position_ned", "global_position_int", "vfr_hud", "wind",
                 "wind_cov", "home_position", "sys_status", "system_time", "follow_target", "attitude_target",
                 "gps_raw_int")
}  # fmt: skip


class _Packer:
    """Frames messages with pymavlink for one ``MAVLink`` object (its ids, sequence counter and
    signing), returning the bytes for the vehicle's datagram batching instead of sending them."""

    def __init__(self, mav: Any) -> None:
        self.mav = mav

    def pack(self, cls: Any, *args: Any) -> bytes:
        """One framed message from the field values in pymavlink's ``*_encode`` order."""
        mav = self.mav
        buf = cls(*args).pack(mav)
        mav.seq = (mav.seq + 1) & 0xFF  # what MAVLink.send does after packing
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(buf)
        return bytes(buf)


# A UDP datagram carries several packets (as PX4 does), up to this many bytes.
_DATAGRAM_MAX = 1400
# Streams after ATTITUDE within a frame (see SimVehicle._telemetry).
_STREAM_ORDER = ("heartbeat", "local_position", "global_position", "vfr_hud", "wind", "home_position",
                 "sys_status", "system_time", "attitude_target", "gps_raw")  # fmt: skip

# message id -> stream name (for MAV_CMD_SET_MESSAGE_INTERVAL / REQUEST_MESSAGE)
_STREAM_IDS = {
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


class _QueueWriter:
    """File-like sink for a pymavlink encoder: packets go to the vehicle's outgoing delay queue."""

    def __init__(self, vehicle: VehicleBase):
        self.v = vehicle

    def write(self, buf: bytes) -> None:
        self.v._put(bytes(buf))


def _finite(*vals: float) -> bool:
    return all(math.isfinite(v) for v in vals)


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


# --------------------------------------------------------------------------- the vehicle


class VehicleBase:
    """Plant, autopilot, link and clocks of one simulated vehicle; mode entry and the truth record."""

    #: boot time (s) of the target's t = 0: the vehicle's readiness, or the bridge's origin
    target_epoch_boot_s: float | None = None

    def __init__(
        self,
        flavour: str = "px4",
        url: str = "udpin:127.0.0.1:14540",
        *,
        plant: str | Any = "jsbsim",
        clock: str | Clock = "lockstep",
        position_ned=(0.0, 0.0, -100.0),
        heading: float = 0.0,
        airspeed: float = 16.0,
        lat0_deg: float = 47.397742,
        lon0_deg: float = 8.545594,
        alt0_m: float = 488.0,
        target=None,
        target_system: int = 2,
        target_component: int = 1,
        target_type: str = "rover",
        target_rate_hz: float = 10.0,
        rates: TelemetryRates | dict | None = None,
        frame_period: float = 0.02,
        telemetry_latency_s: float = 0.0,
        command_latency_s: float = 0.0,
        wind_estimate_tau_s: float = 0.0,
        answer_timeout_s: float = 0.05,
        realtime_speed: float = 1.0,
        com_of_loss_t: float = 1.0,
        guided_timeout: float = 3.0,
        loiter_radius: float = 80.0,
        loiter_direction: int = 1,
        trim_seconds: float = 12.0,
        wind_ned=(0.0, 0.0, 0.0),
        turbulence: str = "none",
        seed: int = 0,
        system_id: int = 1,
        component_id: int = 1,
        autopilot: FixedWingAutopilot | None = None,
        px4_require_thrust: bool = False,
        record_truth: bool = True,
        plant_options: dict | None = None,
        physics_rate_hz: float = 120.0,
        gusts: list[dict] | None = None,
        realtime_until_engaged: bool = False,
        initial_mode: str = "hold",
        initial_orbit: tuple[float, float, float] | None = None,
        target_epoch: str = "ready",
        target_feed: dict | None = None,
    ):
        if flavour not in ("px4", "ardupilot"):
            raise ValueError("flavour must be 'px4' or 'ardupilot'")
        self.flavour = flavour
        self.px4 = flavour == "px4"
        self.sysid, self.compid = int(system_id), int(component_id)
        self.cruise_airspeed = float(airspeed)
        self.telemetry_latency_s = float(telemetry_latency_s)
        self.command_latency_s = float(command_latency_s)
        # the wind the autopilot reports: its estimator's first-order lag of the true air-mass
        # velocity (0: the truth itself); see SilConfig.wind_estimate_tau_s
        self.wind_estimate_tau_s = float(wind_estimate_tau_s)
        self._wind_est: tuple[float, float, float] | None = None
        self._wind_est_t = 0.0
        self.com_of_loss_t = float(com_of_loss_t)
        self.guided_timeout = float(guided_timeout)
        self.loiter_radius = float(loiter_radius)
        self.loiter_direction = 1 if loiter_direction >= 0 else -1
        self.px4_require_thrust = bool(px4_require_thrust)
        self.record = bool(record_truth)
        self.stock = stock_rates(flavour)
        if isinstance(rates, dict):  # None entries: the flavour's stock rate
            rates = TelemetryRates(
                **{k: (getattr(self.stock, k) if v is None else v) for k, v in rates.items()}
            )
        self.rates = rates or stock_rates(flavour)
        # ArduPlane's guided fallback (MAV_CMD_DO_REPOSITION in GUIDED): centre, altitude,
        # radius and direction of the loiter it flies when the attitude setpoints stop
        self._guided_loiter: tuple[tuple[float, float], float, float, int] | None = None
        # tunables a ground station sets through parameters (sim.vehicle.gcs_services): the cruise
        # airspeed is the trim clamped to min..max (the firmware defaults widened to the trim)
        self.obl_rc_act = 0  # PX4 COM_OBL_RC_ACT: 0 = position (Hold), what the SIL flies
        self.airspeed_trim = self.cruise_airspeed
        self.airspeed_min = min(10.0, self.cruise_airspeed)
        self.airspeed_max = max(20.0 if self.px4 else 30.0, self.cruise_airspeed)
        self._steady_wind = tuple(float(w) for w in wind_ned)

        # ---- plant: start behind the requested point so the trim flight ends about there
        heading = float(heading)
        pos = np.asarray(position_ned, float)
        wind = np.asarray(wind_ned, float)
        ground_dir = np.array([math.cos(heading), math.sin(heading), 0.0])
        shift = (
            self.cruise_airspeed * ground_dir + np.array([wind[0], wind[1], 0.0])
        ) * trim_seconds
        start = pos - shift
        if isinstance(plant, str):
            n_sub = max(
                1, math.ceil(frame_period * physics_rate_hz - 1e-9)
            )  # physics at >= the rate
            dt = frame_period / n_sub
            kw = dict(
                dt=dt, lat0_deg=lat0_deg, lon0_deg=lon0_deg, alt0_m=alt0_m,
                position_ned=tuple(start), heading=heading, airspeed=self.cruise_airspeed,
                **(plant_options or {}),
            )  # fmt: skip
            if plant == "jsbsim":
                from sim.plant.jsbsim_plant import JSBSimPlant

                plant = JSBSimPlant(**kw)
            elif plant == "kinematic":
                plant = KinematicMavPlant(**kw)
            else:
                raise ValueError("plant must be 'jsbsim', 'kinematic' or a plant object")
        self.plant = plant
        self.dt = float(plant.dt)
        self.n_sub = max(1, int(round(frame_period / self.dt)))
        self.frame_period = self.n_sub * self.dt
        self.origin = plant.origin
        self.home_lla = (self.origin.lat0_deg, self.origin.lon0_deg, self.origin.alt0_m)
        if np.any(wind != 0.0):
            plant.set_wind(wind)
        if turbulence != "none":
            plant.set_turbulence(turbulence, seed)
        # one-minus-cosine gusts: (t_start, trigger_gust kwargs), t in sim s after ready
        self._gusts = sorted(((float(g["start_s"]), {k: v for k, v in g.items() if k != "start_s"}) for g in gusts or ()),
                             key=lambda g: g[0])  # fmt: skip
        self.realtime_until_engaged = bool(realtime_until_engaged)

        # ---- autopilot, trim flight
        self.ap = autopilot or FixedWingAutopilot()
        if isinstance(plant, KinematicMavPlant):
            self.ap.hold.gains.pitch_trim = 0.0  # no angle of attack in the kinematic model
        self.trim = None
        if trim_seconds > 0:
            # hold the ground track the start point was shifted along (heading + wind), so the
            # trim flight ends at the requested point whatever the wind
            track = (
                math.atan2(float(shift[1]), float(shift[0]))
                if np.hypot(shift[0], shift[1]) > 0
                else heading
            )
            self.trim = fly_to_trim(
                plant,
                self.ap,
                self.cruise_airspeed,
                float(-pos[2]),
                seconds=trim_seconds,
                course=track,
            )
        self._k = int(round(plant.t / self.dt))  # physics steps since boot (incl. trim)
        self._k0 = self._k
        self.target_epoch_boot_s = self._k0 * self.dt
        self._st = plant.state()
        rates_fn = getattr(plant, "rates_airspeed", None)
        self._rates_fn = (
            rates_fn
            if rates_fn is not None
            else lambda: (*plant.state().pqr, plant.state().airspeed)
        )
        self._rates = self._rates_fn()  # (p, q, r) rad/s, airspeed m/s: what the rate loops read

        # ---- mode state
        self.armed = True
        self._mode_t = 0.0
        self.mode_changes: list[tuple[float, str]] = []
        self.mode_log: list[tuple[float, float, str]] = []  # (t, wall perf_counter s, mode name)
        self.statustexts: list[tuple[float, str]] = []
        # PX4 offboard stream bookkeeping (sim boot time, s)
        self._reject_reason: str | None = None
        self._sp_last: float | None = None
        self._sp_stream_start: float | None = None
        self._sp: tuple | None = (
            None  # ("rates", (p, q, r), thrust) | ("att", (roll, pitch), thrust)
        )
        # ArduPlane guided forced axes: values and times (boot s)
        self._forced = [0.0, 0.0, 0.0, 0.0]  # roll, pitch, yaw (rad), throttle (0..1)
        self._forced_t: list[float | None] = [None, None, None, None]
        self.dropped: dict[str, int] = {
            "nonfinite": 0,
            "not_guided": 0,
            "wrong_target": 0,
            "no_axes": 0,
        }
        if initial_mode not in ("hold", "cruise"):
            raise ValueError("initial_mode must be 'hold' or 'cruise'")
        if initial_mode == "cruise":  # course + altitude hold along the start heading
            if self.px4:
                self._set_px4_mode(PX4_MAIN["POSCTL"], announce=False)
            else:
                self._set_ap_mode(ARDUPLANE_NUMBERS["CRUISE"], announce=False)
        elif self.px4:
            self._set_px4_mode(PX4_MAIN["AUTO"], PX4_AUTO_SUB["LOITER"], announce=False)
        else:
            self._set_ap_mode(ARDUPLANE_NUMBERS["LOITER"], announce=False)
        if initial_orbit is not None and initial_mode == "hold":
            # the operator parked the aircraft in an orbit before the mission (DO_REPOSITION with
            # a loiter radius, or a loiter mission item): the boot hold circles (north, east) at
            # that radius; any later hold entry loiters where it happens, as stock
            self._center = (float(initial_orbit[0]), float(initial_orbit[1]))
            self._hold_radius = float(initial_orbit[2])

        # ---- MAVLink
        self.url = url
        self.conn = mavutil.mavlink_connection(
            url, source_system=self.sysid, source_component=self.compid, dialect="ardupilotmega",
            autoreconnect=True,
        )  # fmt: skip
        # (due, packet, ATTITUDE ms or -1, LOCAL_POSITION_NED ms or -1)
        self._out: deque[tuple[float, bytes, int, int]] = deque()
        self._in: deque[tuple[float, Any]] = deque()
        self._mav = M.MAVLink(_QueueWriter(self), srcSystem=self.sysid, srcComponent=self.compid)
        self.target = target
        if target_epoch not in ("ready", "bridge"):
            raise ValueError("target_epoch must be 'ready' or 'bridge'")
        self._epoch_from_bridge = target_epoch == "bridge"
        self.target_system = int(target_system)
        self.target_rate_hz = float(target_rate_hz)
        self._tmav = M.MAVLink(
            _QueueWriter(self), srcSystem=self.target_system, srcComponent=int(target_component)
        )
        self._fp, self._ftp = _Packer(self._mav), _Packer(self._tmav)
        # parameters, missions, AUTOPILOT_VERSION, FTP: a component of its own
        from sim.vehicle.gcs_services import GcsServices

        self.gcs = GcsServices(self)
        # a realistic feed (sim/target/feed.py) instead of the exact state at target_rate_hz
        self.target_feed = None
        if target_feed is not None and target is not None:
            from sim.target.feed import feed_from_options

            self.target_feed = feed_from_options(
                target, self._tmav, ned_to_geodetic_fast, plant.origin, target_feed
            )
        # plain UDP links are read datagram by datagram (setpoints decoded without pymavlink)
        self._udp = type(self.conn).__name__ == "mavudp"
        self._target_type = (
            M.MAV_TYPE_SURFACE_BOAT if target_type == "boat" else M.MAV_TYPE_GROUND_ROVER
        )
        # Lockstep: a frame waits for the SET_ATTITUDE_TARGET stamped with (at least) the
        # time_boot_ms of the ATTITUDE it answers (the bridge stamps its setpoints so); a late
        # answer to an earlier frame must not count, or one slow answer would leave every later
        # command one frame late for the rest of the run. The ATTITUDE awaited is the latest
        # one whose answer would act within the next frame: with a command latency of a frame
        # or more, that is an earlier frame's, and the bridge computes while the vehicle steps
        # (the latency is the lookahead that lets the two peers run in parallel).
        self._await_ms = -1  # time_boot_ms of the ATTITUDE awaited
        self._answer_ms = -1  # the highest stamp of the setpoints received
        self._unstamped = False  # a setpoint stamped 0 since the last ATTITUDE was written
        self._att_written: deque[tuple[int, float]] = deque(maxlen=512)  # (ms, vehicle time)
        self._att_t: dict[int, float] = {}  # the same, by ms
        # A bridge that also answers LOCAL_POSITION_NED between ATTITUDE samples (a multi-rate
        # loop: mavlink.position_instants) is awaited on those frames too, from its first answer
        # stamped with a position-only frame's time on; before that (and for a bridge that never
        # does) they are not awaited, so a peer answering ATTITUDE only is not held up by them.
        self._pos_t: dict[int, float] = {}  # position-only frames: ms -> vehicle time written
        self.answers_positions = False
        self.answers = 0  # SET_ATTITUDE_TARGET messages received
        self.rx_count = 0
        self.unix0_us = int(time.time() * 1e6)
        self._next: dict[str, float] = {}
        self._sent: dict[str, int] = {}

        # ---- clock, truth, threading
        self.clock = make_clock(clock, answer_timeout_s=answer_timeout_s, speed=realtime_speed)
        self._lockstep_clock = self.clock.mode == "lockstep"
        self._rows: list[tuple] = []  # truth, one row per frame (see _record / truth())
        self._tgt_rows: list[tuple] = []  # target position, velocity for the rows so far
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.wall_time_running = 0.0  # wall seconds spent in run()
        self.sim_time_running = 0.0  # sim seconds advanced in run()
        self._record()

    # ------------------------------------------------------------------ time
    @property
    def _boot_t(self) -> float:
        return self._k * self.dt

    @property
    def time_boot_s(self) -> float:
        """The MAVLink boot clock (s): includes the trim flight."""
        return self._k * self.dt

    @property
    def t(self) -> float:
        """Simulated time (s) since the vehicle was ready (0 after the trim flight)."""
        return (self._k - self._k0) * self.dt

    def _ms(self) -> int:
        return int(round(self._k * self.dt * 1000.0))

    def _us(self) -> int:
        return int(round(self._k * self.dt * 1e6))

    # ------------------------------------------------------------------ modes
    @property
    def mode_name(self) -> str:
        return self._mode_name

    @property
    def custom_mode(self) -> int:
        return self._custom_mode

    # ------------------------------------------------------------------ output
    def _statustext(self, severity: int, text: str) -> None:
        self.statustexts.append((self.t if hasattr(self, "_k0") else 0.0, text))
        if hasattr(self, "_mav"):
            self._mav.send(self._mav.statustext_encode(severity, text.encode()[:50]))

    def _enter(self, behaviour: str, name: str, custom_mode: int, announce: bool) -> None:
        st = self.plant.state()  # now, not the frame's start (a mode change can come mid-frame)
        self._behaviour = behaviour
        self._mode_name = name
        self._custom_mode = custom_mode
        self._center = (float(st.position_ned[0]), float(st.position_ned[1]))
        self._hold_radius = self.loiter_radius
        self._alt_sp = -float(st.position_ned[2])
        self._course = math.atan2(float(st.velocity_ned[1]), float(st.velocity_ned[0]))
        self._mode_t = self._boot_t
        self.mode_changes.append((self.t if hasattr(self, "_k0") else 0.0, name))
        self.mode_log.append((self.t if hasattr(self, "_k0") else 0.0, time.perf_counter(), name))
        if behaviour == GUIDED:
            self._forced_t = [None, None, None, None]
            self._guided_loiter = None  # a new GUIDED entry loiters where it was entered
        if announce:
            self._statustext(M.MAV_SEVERITY_INFO, f"Mode {name}")

    def _set_px4_mode(self, main: int, sub: int = 0, announce: bool = True) -> None:
        if main == PX4_MAIN["AUTO"] and sub == 0:
            sub = PX4_AUTO_SUB["MISSION"]  # PX4: AUTO without a sub mode is MISSION
        name = PX4_MAIN_NAMES[main] + (
            f".{PX4_SUB_NAMES.get(sub, sub)}" if main == PX4_MAIN["AUTO"] else ""
        )
        if main != PX4_MAIN["AUTO"]:
            sub = 0
        self._enter(_PX4_BEHAVIOUR[main], name, px4_custom_mode(main, sub), announce)

    def _set_ap_mode(self, number: int, announce: bool = True) -> None:
        self._enter(_AP_BEHAVIOUR[number], ARDUPLANE_MODES[number], int(number), announce)

    def _base_mode(self) -> int:
        b = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            b |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if self._behaviour != LEVEL or self._mode_name not in ("MANUAL", "ACRO"):
            b |= M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self._behaviour in (OFFBOARD, GUIDED, LOITER):
            b |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if self._behaviour == LOITER:
            b |= M.MAV_MODE_FLAG_AUTO_ENABLED
        return b

    @property
    def target_t(self) -> float:
        """The target's time (s): boot time minus its epoch."""
        return self._k * self.dt - (self.target_epoch_boot_s or 0.0)

    # ------------------------------------------------------------------ truth
    def _record(self) -> None:
        if not self.record:
            return
        # One flat row per frame (the target's state is a pure function of t: computed in
        # truth(), off the lockstep frame's critical path).
        st = self._st
        row = (self.t, self._k * self.dt, *st.position_ned, *st.velocity_ned, *st.euler, st.airspeed,
               *st.wind_ned, st.throttle, self._custom_mode)  # fmt: skip
        with self._lock:
            self._rows.append(row)

    def truth(self) -> dict[str, np.ndarray]:
        """Plant truth at frame (telemetry) rate: t (s since ready), time_boot_s, position_ned (N,3),
        velocity_ned (N,3), euler (N,3: roll, pitch, yaw rad), airspeed (N), wind_ned (N,3),
        throttle (N), mode (N, custom_mode), target_t (N: the target's clock, s) and
        target_position / target_velocity (N,3) with a target."""
        with self._lock:
            A = np.array(self._rows, dtype=float).reshape(-1, 17)
            tgt = self._tgt_rows
            epoch = self.target_epoch_boot_s or 0.0
            if self.target is not None:
                for tb in A[len(tgt) :, 1]:
                    ts = self.target.state(float(tb) - epoch)
                    tgt.append((*ts.position, *ts.velocity))
            T = np.array(tgt, dtype=float).reshape(-1, 6)
        return {
            "t": A[:, 0], "time_boot_s": A[:, 1], "position_ned": A[:, 2:5], "velocity_ned": A[:, 5:8],
            "euler": A[:, 8:11], "airspeed": A[:, 11], "wind_ned": A[:, 12:15], "throttle": A[:, 15],
            "mode": A[:, 16].astype(np.int64), "target_position": T[:, 0:3], "target_velocity": T[:, 3:6],
            "target_t": A[:, 1] - epoch,
        }  # fmt: skip

    def sent_counts(self) -> dict[str, int]:
        """Messages produced per stream so far (for tests and diagnostics)."""
        return dict(self._sent)

    @property
    def real_time_factor(self) -> float:
        """Sim seconds per wall second spent in :meth:`run` so far."""
        return (
            self.sim_time_running / self.wall_time_running
            if self.wall_time_running > 0
            else float("nan")
        )

    def _put(self, buf: bytes, attitude_ms: int = -1, position_ms: int = -1) -> None:
        """Queue one framed packet; it leaves ``telemetry_latency_s`` of sim time from now.
        ``attitude_ms``: the time_boot_ms of an ATTITUDE packet (the bridge answers those);
        ``position_ms``: that of a LOCAL_POSITION_NED (a multi-rate bridge answers those too)."""
        due = self._k * self.dt + self.telemetry_latency_s
        self._out.append((due, buf, attitude_ms, position_ms))
