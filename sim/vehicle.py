"""A simulated fixed-wing MAVLink vehicle (PX4 or ArduPlane flavour) for software-in-the-loop runs.

:class:`SimVehicle` owns a plant (:class:`sim.plant_jsbsim.JSBSimPlant` by default, or the cheap
:class:`sim.plant_kinematic_mav.KinematicMavPlant`), the simulated autopilot
(:class:`sim.inner_loop.FixedWingAutopilot`) and ONE pymavlink connection (``udpin:`` - it listens
and answers whoever wrote last, ``udpout:`` or ``tcpin:``). It is a separate MAVLink peer and does
not use :mod:`mpf_mavlink.mavlink`.

Identity: system 1 / component 1, HEARTBEAT type MAV_TYPE_FIXED_WING, autopilot PX4 (12) or
ARDUPILOTMEGA (3), base_mode CUSTOM_MODE_ENABLED (+ SAFETY_ARMED when armed, + STABILIZE /
GUIDED / AUTO flags by mode), custom_mode PX4 ``(main << 16) | (sub << 24)`` or the ArduPlane
mode number. Power-on: armed, trimmed level flight (``fly_to_trim``), in Hold (PX4 AUTO.LOITER)
or LOITER (ArduPlane 12), circling about the position where the mode was entered.

Sim time: ``t`` (s) is 0 when :class:`SimVehicle` is ready (after the trim flight); the MAVLink
boot clock ``time_boot_ms`` counts the trim flight too (``time_boot_s = t + t_trim``), so it never
reads 0. ``time_usec`` fields use the same boot clock; SYSTEM_TIME's ``time_unix_usec`` is the
wall time at construction plus the boot clock. The moving target's motion is evaluated at ``t``.

Rules honoured (see /work/shared/spec/mavlink-interfaces.md):

* PX4: OFFBOARD is accepted (COMMAND_ACK ACCEPTED) only if SET_ATTITUDE_TARGET has been
  streaming with gaps <= 0.5 s (> 2 Hz) for >= 1 s, else TEMPORARILY_REJECTED (what PX4's
  commander answers to a refused mode change). type_mask 128 = body rates + thrust; with
  "throttle ignore" (64) the thrust is ZERO; per-axis rate-ignore bits give a zero rate setpoint
  on that axis; a used non-finite field drops the message (not counted as signal). With bit 128
  clear the quaternion's roll/pitch go to the attitude controller (PX4 FW attitude offboard).
  No setpoint for ``com_of_loss_t`` (1.0 s) of sim time in OFFBOARD -> Hold (AUTO.LOITER about
  the current position) and a STATUSTEXT "Failsafe: no offboard signal, switching to Hold".
* ArduPlane: SET_ATTITUDE_TARGET only in GUIDED (15); dropped silently otherwise. Only the
  quaternion is used; per ArduPlane's handler (inverted mask ``m = ~type_mask & 0x87``): roll is
  taken if ``m & 0x81``, pitch if ``m & 0x82``, yaw if ``m & 0x84`` (so whenever the attitude is
  used all three angles are taken; type_mask 134 takes roll alone). The yaw Euler angle goes
  straight to the rudder as ArduPlane does: rudder = clip(yaw_deg / 45, -1, 1) (ArduPlane
  constrains the forced yaw in centidegrees to +-4500 = full rudder). Thrust (0..1) is used when
  "throttle ignore" is clear. Each forced axis times out after ``guided_timeout`` (3 s); then that
  axis goes back to ArduPlane's own guidance: loiter about the position where GUIDED was entered,
  TECS pitch/throttle, rudder from the yaw damper - the mode stays GUIDED.
* Modes without external setpoints: AUTO.* / LOITER / CIRCLE / RTL / AUTO / TAKEOFF -> loiter
  circle (radius ``loiter_radius``) at the entry altitude and cruise airspeed; POSCTL / ALTCTL /
  FBWB / CRUISE -> course + altitude hold; MANUAL / STABILIZED / ACRO / FBWA / ... -> wings level
  at trim pitch and trim throttle (no pilot sticks in the simulation).

Telemetry (rates configurable, :class:`TelemetryRates`): ATTITUDE, LOCAL_POSITION_NED (50 Hz),
GLOBAL_POSITION_INT, VFR_HUD (10 Hz), WIND (ArduPilot: direction the wind comes FROM, 3-D speed,
speed_z = down component, as ArduPilot) or WIND_COV (PX4: wind_x/y north/east, wind_z = 0 as PX4)
at 2 Hz, HOME_POSITION and SYS_STATUS and SYSTEM_TIME at 1 Hz, HEARTBEAT 1 Hz. Latency: outgoing
and incoming messages can be delayed by a fixed amount of SIM time (delay queues).

The target is its own MAVLink system (default 2/1): HEARTBEAT (MAV_TYPE_GROUND_ROVER or
SURFACE_BOAT, autopilot MAV_AUTOPILOT_INVALID) at 1 Hz, FOLLOW_TARGET (est_capabilities 15) and
GLOBAL_POSITION_INT at ``target_rate_hz``; position from ``target.state(t)`` in NED about the
vehicle's geodetic origin. The target's clock starts when the vehicle is ready
(``target_epoch="ready"``), or, with ``target_epoch="bridge"``, at the mission origin the bridge
announces (STATUSTEXT ``MPF t0=<autopilot boot time, s>``): a bridge that flies its own copy of
a scripted target counts that target's time from its origin, and only that epoch puts the
simulated target where the bridge believes it is (from the vehicle's readiness it ran ~1 s
ahead: the bridge takes its origin when its checks pass).
"""

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

from mpf_mavlink.core.frames import matrix_to_quat_wxyz  # noqa: E402
from sim.clock import Clock, make_clock  # noqa: E402
from sim.inner_loop import FixedWingAutopilot, fly_to_trim  # noqa: E402
from sim.plant_kinematic_mav import KinematicMavPlant, ned_to_geodetic_fast  # noqa: E402

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
    SYSTEM_TIME 1, ATTITUDE_TARGET 10 Hz."""
    if flavour == "ardupilot":
        return TelemetryRates(1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.0)
    return TelemetryRates(100.0, 30.0, 50.0, 10.0, 10.0, 0.5, 5.0, 1.0, 1.0, 10.0)


# ArduPilot's REQUEST_DATA_STREAM groups -> our streams (MAV_DATA_STREAM_*: 0 all, 2 extended
# status, 6 position, 10 extra1, 11 extra2, 12 extra3)
_AP_DATA_STREAMS = {
    2: ("sys_status",),
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
                 "wind_cov", "home_position", "sys_status", "system_time", "follow_target", "attitude_target")
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
                 "sys_status", "system_time", "attitude_target")  # fmt: skip

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
}


class _QueueWriter:
    """File-like sink for a pymavlink encoder: packets go to the vehicle's outgoing delay queue."""

    def __init__(self, vehicle: SimVehicle):
        self.v = vehicle

    def write(self, buf: bytes) -> None:
        self.v._put(bytes(buf))


def _finite(*vals: float) -> bool:
    return all(math.isfinite(v) for v in vals)


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


# --------------------------------------------------------------------------- the vehicle
class SimVehicle:
    """A fixed-wing MAVLink vehicle around a plant and the simulated autopilot (module docstring).

    Drive it with :meth:`run` (clock-paced), :meth:`step_once` (one frame, no waiting; call
    :meth:`poll` in between if you like) or :meth:`start_in_thread` / :meth:`stop`.
    """

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
        # parameters a companion may read (PX4's offboard-loss failsafe; ArduPlane's timeout)
        self.params: dict[str, float] = (
            {"COM_OF_LOSS_T": float(com_of_loss_t), "COM_OBL_RC_ACT": 0.0}
            if flavour == "px4"
            else {"GUIDED_TIMEOUT": float(guided_timeout)}
        )

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
                from sim.plant_jsbsim import JSBSimPlant

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
        self._out: deque[tuple[float, bytes, int]] = deque()  # (due, packet, ATTITUDE ms or -1)
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
        # a realistic feed (sim/target_feed.py) instead of the exact state at target_rate_hz
        self.target_feed = None
        if target_feed is not None and target is not None:
            from sim.target_feed import feed_from_options

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

    def _offboard_available(self) -> bool:
        t, last, start = self._boot_t, self._sp_last, self._sp_stream_start
        return (
            last is not None
            and start is not None
            and t - last <= PX4_OFFBOARD_MAX_GAP_S
            and t - start >= PX4_OFFBOARD_MIN_STREAM_S - 1e-9
        )

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

    # ------------------------------------------------------------------ control (one physics step)
    def _control(self, st) -> tuple[float, float, float, float]:
        dt, ap, t = self.dt, self.ap, self._boot_t
        beh = self._behaviour
        if beh == OFFBOARD:
            if self._sp_last is None or t - self._sp_last > self.com_of_loss_t:
                self._statustext(
                    M.MAV_SEVERITY_CRITICAL, "Failsafe: no offboard signal, switching to Hold"
                )
                self._set_px4_mode(PX4_MAIN["AUTO"], PX4_AUTO_SUB["LOITER"])
                beh = self._behaviour
            else:
                assert self._sp is not None  # offboard is only available with a setpoint
                kind, vals, thrust = self._sp
                if kind == "rates":
                    a, e, r = ap.rates_to_surfaces(dt, vals, tuple(st.pqr), st.airspeed)
                else:
                    a, e, r = ap.attitude_to_surfaces(dt, vals[0], vals[1], st)
                return a, e, r, (thrust if self.armed else 0.0)
        if beh == GUIDED:
            return self._guided_control(st)
        if beh == LOITER:
            out = ap.loiter_step(dt, st, self._center, self.cruise_airspeed, self._alt_sp,
                                 self._hold_radius, self.loiter_direction)  # fmt: skip
        elif beh == CRUISE:
            roll = ap.hold.heading_roll(self._course, (st.velocity_ned[0], st.velocity_ned[1]))
            out = ap.hold_step(dt, st, self.cruise_airspeed, self._alt_sp, roll)
        else:  # LEVEL: wings level, trim pitch, trim throttle
            a, e, r = ap.attitude_to_surfaces(dt, 0.0, ap.hold.gains.pitch_trim, st)
            out = (a, e, r, ap.hold.trim_throttle)
        a, e, r, thr = out
        return a, e, r, (thr if self.armed else 0.0)

    def _guided_control(self, st) -> tuple[float, float, float, float]:
        dt, ap, t = self.dt, self.ap, self._boot_t
        ft, fv, to = self._forced_t, self._forced, self.guided_timeout
        fresh = [x is not None and t - x < to for x in ft]
        gl = self._guided_loiter
        center, alt_sp, radius, direction = (
            gl if gl is not None
            else (self._center, self._alt_sp, self.loiter_radius, self.loiter_direction)
        )  # fmt: skip
        if fresh[0]:
            roll_sp = fv[0]
        else:
            pos, vel = st.position_ned, st.velocity_ned
            roll_sp = ap.hold.loiter_roll(center, (float(pos[0]), float(pos[1])),
                                          (float(vel[0]), float(vel[1])), radius,
                                          direction)  # fmt: skip
        climb = -float(st.velocity_ned[2])
        _, pitch_tecs, thr_tecs = ap.hold.update(
            dt,
            self.cruise_airspeed,
            alt_sp,
            st.airspeed,
            -float(st.position_ned[2]),
            climb,
            roll_sp,
        )
        pitch_sp = fv[1] if fresh[1] else pitch_tecs
        a, e, r = ap.attitude_to_surfaces(dt, roll_sp, pitch_sp, st)
        if fresh[2]:
            r = _clip(math.degrees(fv[2]) / 45.0, -1.0, 1.0)  # ArduPlane: +-4500 cdeg = full rudder
        thr = fv[3] if fresh[3] else thr_tecs
        return a, e, r, (thr if self.armed else 0.0)

    # ------------------------------------------------------------------ stepping
    def step_once(self) -> float:
        """One frame: read pending input (no waiting), apply due commands, ``n_sub`` physics
        steps, due telemetry, truth. Returns the sim time ``t``."""
        self.poll(0.0)
        self._apply_due()
        plant, ap, dt = self.plant, self.ap, self.dt
        rates, fresh = self._rates, True  # fresh: self._st is the state now
        last = self.n_sub - 1
        for i in range(self.n_sub):
            sp = self._sp
            if (
                self._behaviour == OFFBOARD
                and sp is not None
                and sp[0] == "rates"
                and self._sp_last is not None
                and self._k * dt - self._sp_last <= self.com_of_loss_t
            ):
                # Hot path (PX4 offboard body rates): the rate loops read only p, q, r and the
                # airspeed, so the full state (geodetic conversion, matrices) is not needed here.
                a, e, r = ap.rates_to_surfaces(dt, sp[1], rates, rates[3])
                cmd = (a, e, r, sp[2] if self.armed else 0.0)
            else:
                if not fresh:
                    self._st = plant.state()
                cmd = self._control(self._st)
            plant.step(*cmd)
            self._k += 1
            rates, fresh = self._rates_fn(), False
            # what falls due at the frame's end acts from the next frame's start (the same
            # physics), whether it was read before this frame or during the lockstep wait
            if self._in and i < last:
                self._apply_due()
        self._rates = rates
        self._st = plant.state()
        if self._due("attitude", self.rates.attitude):
            # the 50 Hz pair first, in its own datagram (see _telemetry)
            if self._due("local_position", self.rates.local_position):
                self._send_stream("local_position")
            self._send_attitude((*self._st.euler, *self._st.pqr))
            self._flush()
        if self._gusts and self.t + 1e-9 >= self._gusts[0][0]:
            plant.trigger_gust(**self._gusts.pop(0)[1])
        self._telemetry()
        self._flush()
        self._record()
        return self.t

    def run(self, duration_s: float) -> None:
        """Advance ``duration_s`` of sim time, paced by the clock (lockstep or realtime)."""
        end_k = self._k + int(round(duration_s / self.dt)) if math.isfinite(duration_s) else None
        w0, k0 = time.perf_counter(), self._k
        self.clock.start(self._boot_t)
        try:
            peer = self._lockstep_peer if self.realtime_until_engaged else self.has_peer
            while not self._stop.is_set() and (end_k is None or self._k < end_k):
                self.step_once()
                self.clock.wait(self._boot_t, self.poll, peer)
        finally:
            self.wall_time_running += time.perf_counter() - w0
            self.sim_time_running += (self._k - k0) * self.dt

    def start_in_thread(self, duration_s: float = math.inf) -> threading.Thread:
        """Run in a daemon thread until :meth:`stop` (or ``duration_s`` of sim time)."""
        if self._thread is not None and self._thread.is_alive():
            raise RuntimeError("already running")
        self._stop.clear()
        self._thread = threading.Thread(
            target=self.run, args=(duration_s,), daemon=True, name="SimVehicle"
        )
        self._thread.start()
        return self._thread

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def close(self) -> None:
        self.stop()
        try:
            self.conn.close()
        except Exception:  # pragma: no cover - closing is best effort
            pass

    def __enter__(self) -> SimVehicle:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def real_time_factor(self) -> float:
        """Sim seconds per wall second spent in :meth:`run` so far."""
        return (
            self.sim_time_running / self.wall_time_running
            if self.wall_time_running > 0
            else float("nan")
        )

    def _lockstep_peer(self) -> bool:
        """With ``realtime_until_engaged``: the lockstep clock treats the peer as present only
        while it commands the vehicle (OFFBOARD / GUIDED). Until the bridge has taken control its
        hand-over rules run on wall-clock timers (>= 1 s of setpoints at >= 20 Hz before the mode
        request) while the autopilot's run on vehicle time; pacing that phase at real time keeps
        both in one time base, so the engagement happens after the same simulated time whatever
        the clock (lockstep and realtime runs start tracking from the same state)."""
        return self._behaviour in (OFFBOARD, GUIDED) and self.has_peer()

    # ------------------------------------------------------------------ input
    def has_peer(self) -> bool:
        c = self.conn
        if getattr(c, "udp_server", False):  # pymavlink >= 2.4.4x keeps a set of clients
            return bool(getattr(c, "clients", None)) or getattr(c, "last_address", None) is not None
        if hasattr(c, "listen"):  # tcpin
            return getattr(c, "port", None) is not None
        return True

    def poll(self, timeout: float = 0.0) -> bool:
        """Read incoming MAVLink (waiting up to ``timeout`` wall s for the first byte).

        Returns True when a SET_ATTITUDE_TARGET arrived after the last telemetry was written.
        """
        if self._answered:
            self._drain()
            return True
        if timeout > 0.0:
            try:
                self.conn.select(timeout)
            except Exception:  # pragma: no cover
                time.sleep(min(timeout, 0.001))
        self._drain()
        return self._answered

    def _drain(self) -> None:
        if self._udp:
            self._drain_udp()
            return
        recv = self.conn.recv_msg
        for _ in range(10000):
            try:
                msg = recv()
            except (ConnectionError, OSError):
                return
            if msg is None:
                return
            self._on_msg(msg)

    def _drain_udp(self) -> None:
        """Read whole datagrams; a datagram that is one SET_ATTITUDE_TARGET (the bridge's answer,
        50 per simulated second) is decoded without pymavlink, anything else goes to pymavlink."""
        conn = self.conn
        port, server, parse = conn.port, conn.udp_server, conn.mav.parse_buffer
        for _ in range(10000):
            try:
                data, addr = port.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:  # ICMP for an earlier send (peer not up yet): cleared
                continue
            except OSError:
                return
            if server:  # what pymavlink's mavudp.recv does: remember the peer to answer it
                conn.clients.add(addr)
                conn.clients_last_alive[addr] = time.time()
            for msg in parse(data) or ():
                self._on_msg(msg)

    def _on_msg(self, msg: Any) -> None:
        mt = msg.get_type()
        if mt == "BAD_DATA":
            return
        self.rx_count += 1
        due = self._boot_t + self.command_latency_s
        if mt == "SET_ATTITUDE_TARGET":
            tb = msg.time_boot_ms
            if tb == 0:  # a peer that does not stamp its setpoints: any answer counts
                self._unstamped = True
            elif tb > self._answer_ms:
                self._answer_ms = tb
            self.answers += 1
            tw = self._att_t.get(tb) if self._lockstep_clock else None
            if tw is not None:
                # lockstep: the bridge answered at once in vehicle time, the latency runs
                # from the ATTITUDE it answers (not from when this process got to read it)
                due = max(self._boot_t, tw + self.command_latency_s)
        elif mt == "STATUSTEXT":
            if self._epoch_from_bridge:
                self._take_epoch(msg)
            return
        elif mt not in ("COMMAND_LONG", "COMMAND_INT", "SET_MODE", "TIMESYNC",
                        "REQUEST_DATA_STREAM", "PARAM_REQUEST_READ"):  # fmt: skip
            return
        q = self._in
        i = len(q)
        while i > 0 and q[i - 1][0] > due:  # kept in order of due time
            i -= 1
        q.insert(i, (due, msg))

    def _take_epoch(self, msg: Any) -> None:
        """The bridge's mission origin (``MPF t0=``, autopilot boot s) as the target's t = 0."""
        from mpf_mavlink.bridge.controller import parse_marker

        text = msg.text if isinstance(msg.text, str) else bytes(msg.text).decode("ascii", "replace")
        mk = parse_marker(text)
        if mk is not None and mk[0] == "t0" and mk[1] is not None:
            with self._lock:
                self.target_epoch_boot_s = float(mk[1])
                self._tgt_rows.clear()  # truth() recomputes them on the new clock

    @property
    def target_t(self) -> float:
        """The target's time (s): boot time minus its epoch."""
        return self._k * self.dt - (self.target_epoch_boot_s or 0.0)

    def _apply_due(self) -> None:
        q, t = self._in, self._boot_t + 1e-9
        while q and q[0][0] <= t:
            _, msg = q.popleft()
            self._handle(msg)

    def _handle(self, msg) -> None:
        mt = msg.get_type()
        if mt == "SET_ATTITUDE_TARGET":
            if msg.target_system not in (0, self.sysid):
                self.dropped["wrong_target"] += 1
                return
            (self._sat_px4 if self.px4 else self._sat_ardupilot)(msg)
        elif mt in ("COMMAND_LONG", "COMMAND_INT"):
            if msg.target_system not in (0, self.sysid):
                return
            self._command(msg)
        elif mt == "SET_MODE":
            if msg.target_system not in (0, self.sysid):
                return
            if self.px4:
                main, sub = px4_decode_custom_mode(msg.custom_mode)
                res = self._do_set_mode(float(msg.base_mode), float(main), float(sub))
                self._ack(M.MAV_CMD_DO_SET_MODE, res, msg)  # PX4 turns SET_MODE into DO_SET_MODE
            else:
                res = self._do_set_mode(float(msg.base_mode), float(msg.custom_mode), 0.0)
                self._ack(M.MAVLINK_MSG_ID_SET_MODE, res, msg)  # ArduPilot acks with command 11
        elif mt == "REQUEST_DATA_STREAM":
            if msg.target_system not in (0, self.sysid) or self.px4:
                return  # PX4 ignores it (MAV_CMD_SET_MESSAGE_INTERVAL only)
            hz = float(msg.req_message_rate) if msg.start_stop else 0.0
            # ArduPilot caps a stream at 1.25 main-loop periods (40 Hz at Plane's 50 Hz loop)
            hz = min(hz, 1.0 / (1.25 * self.frame_period))
            groups = _AP_DATA_STREAMS.values() if msg.req_stream_id == 0 else (
                [_AP_DATA_STREAMS[msg.req_stream_id]] if msg.req_stream_id in _AP_DATA_STREAMS else [])  # fmt: skip
            for group in groups:
                for name in group:
                    setattr(self.rates, name, hz)
                    self._next.pop(name, None)
        elif mt == "PARAM_REQUEST_READ":
            if msg.target_system not in (0, self.sysid):
                return
            pid = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else ""
            names = list(self.params)
            if pid in self.params:
                i = names.index(pid)
            elif 0 <= msg.param_index < len(names) and not pid:
                i, pid = msg.param_index, names[msg.param_index]
            else:
                return  # both autopilots stay silent about a parameter they do not have
            self._mav.send(self._mav.param_value_encode(
                pid.encode("ascii"), self.params[pid], M.MAV_PARAM_TYPE_REAL32, len(names), i))  # fmt: skip
        elif mt == "TIMESYNC" and msg.tc1 == 0:
            self._mav.send(self._mav.timesync_encode(int(self._boot_t * 1e9), msg.ts1))

    # PX4 offboard setpoint
    def _sat_px4(self, msg) -> None:
        tm = msg.type_mask
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
        if not _finite(*used):
            self.dropped["nonfinite"] += 1
            return
        thrust = 0.0 if thr_ignore else _clip(float(msg.thrust), 0.0, 1.0)
        if att_ignore:
            sp = (
                "rates",
                tuple(0.0 if tm & (1 << i) else float(rates[i]) for i in range(3)),
                thrust,
            )
        else:
            from mpf_mavlink.core.frames import matrix_to_euler, quat_wxyz_to_matrix

            try:
                roll, pitch, _ = matrix_to_euler(quat_wxyz_to_matrix(msg.q))
            except ValueError:
                self.dropped["nonfinite"] += 1
                return
            sp = ("att", (roll, pitch), thrust)
        self._sp = sp
        # what ATTITUDE_TARGET echoes: PX4 stamps the setpoint when its receiver publishes it
        self._sp_echo = (self._ms(), msg.type_mask, tuple(msg.q), rates, float(msg.thrust))
        if thr_ignore and self.px4_require_thrust:
            return  # applied if already offboard, but not counted as an offboard signal
        t = self._boot_t
        if self._sp_last is None or t - self._sp_last > PX4_OFFBOARD_MAX_GAP_S:
            self._sp_stream_start = t
        self._sp_last = t

    # ArduPlane guided attitude
    def _sat_ardupilot(self, msg) -> None:
        if self._behaviour != GUIDED:
            self.dropped["not_guided"] += 1
            return
        q = list(msg.q)
        if not _finite(*q) or (not (msg.type_mask & 64) and not _finite(msg.thrust)):
            self.dropped["nonfinite"] += 1
            return
        from mpf_mavlink.core.frames import matrix_to_euler, quat_wxyz_to_matrix

        inv = (~msg.type_mask) & 0xFF
        am = inv & 0x87
        t = self._boot_t
        try:
            euler = matrix_to_euler(quat_wxyz_to_matrix(q)) if am else (0.0, 0.0, 0.0)
        except ValueError:
            self.dropped["nonfinite"] += 1
            return
        for i, bit in enumerate((0x81, 0x82, 0x84)):
            if am & bit:
                self._forced[i] = float(euler[i])
                self._forced_t[i] = t
        if inv & 0x40:
            self._forced[3] = _clip(float(msg.thrust), 0.0, 1.0)
            self._forced_t[3] = t

    # commands
    def _ack(self, command: int, result: int, msg, reason: str | None = None) -> None:
        self._mav.send(
            self._mav.command_ack_encode(
                command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            )
        )
        if reason:
            self._statustext(
                M.MAV_SEVERITY_WARNING if result != M.MAV_RESULT_ACCEPTED else M.MAV_SEVERITY_INFO,
                reason,
            )

    def _command(self, msg) -> None:
        cmd = msg.command
        p1, p2, p3 = msg.param1, msg.param2, msg.param3
        if cmd == M.MAV_CMD_DO_SET_MODE:
            res = self._do_set_mode(p1, p2, p3)
            reason = self._reject_reason
            self._reject_reason = None
            self._ack(cmd, res, msg, reason)
        elif cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p1 >= 0.5:
                self.armed = True
                self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            elif abs(p2 - ARDUPILOT_FORCE_DISARM) < 0.5:
                self.armed = False
                self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            else:  # in the air: both autopilots refuse a disarm unless forced
                res = M.MAV_RESULT_TEMPORARILY_REJECTED if self.px4 else M.MAV_RESULT_FAILED
                self._ack(cmd, res, msg, "Disarm refused: vehicle is flying (use force 21196)")
        elif cmd == M.MAV_CMD_DO_REPOSITION and not self.px4 and msg.get_type() == "COMMAND_INT":
            self._ack(cmd, self._reposition(msg), msg)
        elif cmd == M.MAV_CMD_GET_HOME_POSITION:
            self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            self._send_stream("home_position")
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            name = _STREAM_IDS.get(int(p1))
            if name is None:
                self._ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)
            else:
                self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
                self._send_stream(name)
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            name = _STREAM_IDS.get(int(p1))
            if name is None:
                self._ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)
                return
            if p2 < 0:
                hz = 0.0
            elif p2 == 0:
                hz = getattr(self.stock, name)
            else:
                hz = 1e6 / p2
                if not self.px4 and p2 * 0.8 < self.frame_period * 1e6:
                    # ArduPilot (GCS_Common.cpp, cap_message_interval): an interval shorter
                    # than 1.25 main-loop periods is refused, saying so (50 Hz at Plane's 50 Hz)
                    self._statustext(M.MAV_SEVERITY_INFO, f"Requested rate for message ID {int(p1)} too fast. Increase SCHED_LOOP_RATE")  # fmt: skip
                    self._ack(cmd, M.MAV_RESULT_DENIED, msg)
                    return
            setattr(self.rates, name, hz)
            self._next.pop(name, None)
            self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
        else:
            self._ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)

    def _reposition(self, msg) -> int:
        """ArduPlane's MAV_CMD_DO_REPOSITION (COMMAND_INT): in GUIDED (or with the change-mode
        flag) the guided target becomes a loiter of radius param3 (> 0; else the loiter radius)
        about (x, y, z), counter-clockwise when param4 is non-zero; the forced attitude stays."""
        from mpf_mavlink.core.frames import geodetic_to_ned

        lat, lon = msg.x * 1e-7, msg.y * 1e-7
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0) or (msg.x == 0 and msg.y == 0):
            return M.MAV_RESULT_DENIED
        alt = float(msg.z)
        if msg.frame in (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            alt += self.home_lla[2]
        elif msg.frame not in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            return M.MAV_RESULT_DENIED
        if not (int(msg.param2) & 1) and self._behaviour != GUIDED:
            return M.MAV_RESULT_FAILED
        if self._behaviour != GUIDED:
            self._set_ap_mode(ARDUPLANE_NUMBERS["GUIDED"])
        n, e, d = (float(v) for v in geodetic_to_ned(lat, lon, alt, *self.home_lla))
        r = (
            float(msg.param3)
            if math.isfinite(msg.param3) and msg.param3 > 0
            else self.loiter_radius
        )
        ccw = math.isfinite(msg.param4) and msg.param4 != 0.0
        self._guided_loiter = ((n, e), -d, r, -1 if ccw else 1)
        return M.MAV_RESULT_ACCEPTED

    def _do_set_mode(self, p1: float, p2: float, p3: float) -> int:
        self._reject_reason = None
        if not (int(p1) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
            self._reject_reason = "Mode change refused: custom mode flag (param1 = 1) not set"
            return M.MAV_RESULT_UNSUPPORTED if not self.px4 else M.MAV_RESULT_DENIED
        if self.px4:
            main, sub = int(round(p2)), int(round(p3))
            if main not in PX4_MAIN_NAMES or (
                main == PX4_MAIN["AUTO"] and sub not in PX4_SUB_NAMES and sub != 0
            ):
                self._reject_reason = f"Mode change refused: unknown PX4 mode {main}/{sub}"
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            if (
                main == PX4_MAIN["OFFBOARD"]
                and self._behaviour != OFFBOARD
                and not self._offboard_available()
            ):
                self._reject_reason = (
                    "Mode change refused: offboard setpoints not streaming (> 2 Hz for 1 s)"
                )
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            if main == PX4_MAIN["AUTO"] and sub == 0:
                sub = PX4_AUTO_SUB["MISSION"]  # PX4: AUTO without a sub mode is MISSION
            if px4_custom_mode(main, sub if main == PX4_MAIN["AUTO"] else 0) != self._custom_mode:
                self._set_px4_mode(main, sub)  # re-selecting the current mode changes nothing
            return M.MAV_RESULT_ACCEPTED
        number = int(round(p2))
        if number not in ARDUPLANE_MODES:
            self._reject_reason = f"Mode change refused: unknown ArduPlane mode {number}"
            return M.MAV_RESULT_FAILED
        if number != self._custom_mode:
            self._set_ap_mode(number)
        return M.MAV_RESULT_ACCEPTED

    # ------------------------------------------------------------------ output
    def _statustext(self, severity: int, text: str) -> None:
        self.statustexts.append((self.t if hasattr(self, "_k0") else 0.0, text))
        if hasattr(self, "_mav"):
            self._mav.send(self._mav.statustext_encode(severity, text.encode()[:50]))

    def _due(self, name: str, hz: float) -> bool:
        if hz <= 0:
            return False
        t = self._boot_t
        nxt = self._next.get(name)
        if nxt is None or t + 1e-9 >= nxt:
            period = 1.0 / hz
            nxt = t + period if nxt is None or t - nxt > period else nxt + period
            self._next[name] = nxt
            return True
        return False

    def _telemetry(self) -> None:
        """Queue the streams that are due (step_once has sent LOCAL_POSITION_NED and ATTITUDE
        already, in a datagram of their own: a peer that acts on ATTITUDE - the bridge answers
        each one with a setpoint - starts on it with the position and velocity of the same
        instant, and the slower streams, encoded after that datagram left and parsed by the peer
        after its answer, stay off the lockstep path telemetry -> answer -> next frame; they
        reach the peer at most one 20 ms frame later, as the phases of independent autopilot
        streams do anyway). A velocity one frame old would not do: the bridge's wind frame is
        the direction of ground velocity - wind, and 20 ms more lag in it costs the tight
        guidance gains of the demo a factor 2-3 in tracking error (measured)."""
        r, nxt, t = self.rates, self._next, self._k * self.dt + 1e-9
        for name in _STREAM_ORDER:
            n = nxt.get(name)
            if n is not None and t < n:
                continue  # not due (the common case: a cheap test before _due's bookkeeping)
            if self._due(name, getattr(r, name)):
                self._send_stream(name)
        if self.target is not None:
            if self._due("target_heartbeat", 1.0):
                self._put(self._ftp.pack(_SPEC["heartbeat"], self._target_type, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                         M.MAV_STATE_ACTIVE, 3))  # fmt: skip
            if self.target_feed is not None:
                for buf in self.target_feed.poll(self._k * self.dt, self.target_t):
                    self._put(buf)
            elif self._due("target", self.target_rate_hz):
                self._send_target()

    def _send_attitude(self, att: tuple[float, float, float, float, float, float]) -> None:
        """ATTITUDE from (roll, pitch, yaw, p, q, r) (rad, rad/s)."""
        self._sent["attitude"] = self._sent.get("attitude", 0) + 1
        ms = self._ms()
        self._put(self._fp.pack(_SPEC["attitude"], ms, *att), ms)

    def _put(self, buf: bytes, attitude_ms: int = -1) -> None:
        """Queue one framed packet; it leaves ``telemetry_latency_s`` of sim time from now.
        ``attitude_ms``: the time_boot_ms of an ATTITUDE packet (the bridge answers those)."""
        self._out.append((self._k * self.dt + self.telemetry_latency_s, buf, attitude_ms))

    def _send_stream(self, name: str) -> None:
        st, ms, S = self._st, self._ms(), _SPEC
        pack, put = self._fp.pack, self._put
        self._sent[name] = self._sent.get(name, 0) + 1
        if name == "heartbeat":
            ap = M.MAV_AUTOPILOT_PX4 if self.px4 else M.MAV_AUTOPILOT_ARDUPILOTMEGA
            put(pack(S["heartbeat"], M.MAV_TYPE_FIXED_WING, ap, self._base_mode(), self._custom_mode,
                     M.MAV_STATE_ACTIVE, 3))  # fmt: skip
        elif name == "attitude":
            self._sent[name] -= 1  # counted by _send_attitude
            self._send_attitude((*st.euler, *st.pqr))
        elif name == "local_position":
            x, y, z = st.position_ned
            vx, vy, vz = st.velocity_ned
            put(pack(S["local_position_ned"], ms, x, y, z, vx, vy, vz))
        elif name == "global_position":
            vx, vy, vz = st.velocity_ned
            hdg = int(round(math.degrees(st.euler[2]) * 100.0)) % 36000
            put(pack(S["global_position_int"],
                ms, int(round(st.lat_deg * 1e7)), int(round(st.lon_deg * 1e7)), int(round(st.alt_m * 1000.0)),
                int(round((st.alt_m - self.home_lla[2]) * 1000.0)),
                int(round(vx * 100)), int(round(vy * 100)), int(round(vz * 100)), hdg))  # fmt: skip
        elif name == "vfr_hud":
            v = st.velocity_ned
            hdg = int(round(math.degrees(st.euler[2]))) % 360
            # both autopilots report an equivalent airspeed (ArduPilot EAS, PX4 calibrated)
            eas = st.airspeed * eas_factor(float(st.alt_m))
            put(pack(S["vfr_hud"], eas, math.hypot(v[0], v[1]), hdg, int(round(100 * st.throttle)),
                     st.alt_m, -float(v[2])))  # fmt: skip
        elif name == "wind":
            wn, we, wd = (float(v) for v in st.wind_ned)
            if self.px4:
                put(pack(S["wind_cov"], self._us(), wn, we, 0.0, 0.0, 0.0, st.alt_m, 0.0, 0.0))
            else:
                direction = math.degrees(math.atan2(-we, -wn)) % 360.0
                put(pack(S["wind"], direction, math.sqrt(wn * wn + we * we + wd * wd), wd))
        elif name == "home_position":
            lat, lon, alt = self.home_lla
            put(pack(S["home_position"], int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
                     0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, self._us()))  # fmt: skip
        elif name == "sys_status":
            s = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                 | M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE)  # fmt: skip
            put(pack(S["sys_status"], s, s, s, 100, 12600, 500, 90, 0, 0, 0, 0, 0, 0, 0, 0, 0))
        elif name == "system_time":
            put(pack(S["system_time"], self.unix0_us + self._us(), ms))
        elif name == "attitude_target":
            # PX4's ATTITUDE_TARGET: the setpoint in use, stamped when it was received (a
            # companion measures its loop delay from it); nothing before the first setpoint
            echo = getattr(self, "_sp_echo", None)
            if self.px4 and echo is not None:
                t_ms, tm, q, rates, thrust = echo
                put(pack(S["attitude_target"], t_ms, tm, list(q), *rates, thrust))

    def _send_target(self) -> None:
        ts = self.target.state(self.target_t)
        n, e, d = (float(v) for v in ts.position)
        lat, lon, alt = ned_to_geodetic_fast(self.origin, n, e, d)
        q = matrix_to_quat_wxyz(ts.R_T_I)
        vel = [float(v) for v in ts.velocity]
        acc = [float(v) for v in ts.acceleration]
        rates = [float(v) for v in ts.omega_T]
        pack, ms = self._ftp.pack, self._ms()
        lat7, lon7 = int(round(lat * 1e7)), int(round(lon * 1e7))
        self._put(
            pack(
                _SPEC["follow_target"],
                ms,
                15,
                lat7,
                lon7,
                alt,
                vel,
                acc,
                list(q),
                rates,
                [0.0, 0.0, 0.0],
                0,
            )
        )
        yaw = math.atan2(ts.R_T_I[1, 0], ts.R_T_I[0, 0])
        self._put(pack(_SPEC["global_position_int"],
            ms, lat7, lon7, int(round(alt * 1000)), int(round((alt - self.home_lla[2]) * 1000)),
            int(round(vel[0] * 100)), int(round(vel[1] * 100)), int(round(vel[2] * 100)),
            int(round(math.degrees(yaw) * 100)) % 36000))  # fmt: skip

    def _flush(self) -> None:
        """Send the packets that are due, bundled into as few datagrams as fit (PX4 does the same:
        one datagram per send cycle), so the peer wakes up once per frame, not once per packet."""
        q, t = self._out, self._boot_t + 1e-9
        if not q or q[0][0] > t:
            return
        wrote = False
        chunk: list[bytes] = []
        size = 0
        att_ms = -1
        while q and q[0][0] <= t:
            _, buf, ms = q.popleft()
            att_ms = max(att_ms, ms)
            if chunk and size + len(buf) > _DATAGRAM_MAX:
                wrote |= self._write(b"".join(chunk))
                chunk, size = [], 0
            chunk.append(buf)
            size += len(buf)
        if chunk:
            wrote |= self._write(b"".join(chunk))
        if wrote and att_ms >= 0:
            self._attitude_written(att_ms, t - 1e-9)

    def _attitude_written(self, ms: int, t: float) -> None:
        """An ATTITUDE stamped ``ms`` left at vehicle time ``t`` (s): choose the one to await."""
        w = self._att_written
        if len(w) == w.maxlen:
            self._att_t.pop(w[0][0], None)
        w.append((ms, t))
        self._att_t[ms] = t
        self._unstamped = False
        # the answer to an ATTITUDE written at tw acts at tw + latency: await the latest one
        # that acts before the end of the next frame
        horizon = t + self.frame_period - self.command_latency_s - 1e-6
        for m, tw in reversed(w):
            if tw < horizon:
                self._await_ms = m
                return
        self._await_ms = -1

    @property
    def _answered(self) -> bool:
        return self._answer_ms >= self._await_ms or self._unstamped

    def _write(self, data: bytes) -> bool:
        try:
            self.conn.write(data)
            return True
        except OSError:
            return False

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


def main(argv: list[str] | None = None) -> int:
    """``python -m sim.vehicle --flavour px4 --url udpin:127.0.0.1:14540 --duration 600``."""
    import argparse

    ap = argparse.ArgumentParser(description="Simulated fixed-wing MAVLink vehicle (SIL)")
    ap.add_argument("--flavour", choices=("px4", "ardupilot"), default="px4")
    ap.add_argument("--url", default="udpin:127.0.0.1:14540")
    ap.add_argument("--plant", choices=("jsbsim", "kinematic"), default="jsbsim")
    ap.add_argument("--clock", choices=("lockstep", "realtime"), default="lockstep")
    ap.add_argument(
        "--duration", type=float, default=math.inf, help="sim seconds (default: forever)"
    )
    ap.add_argument("--target", choices=("none", "paper", "stationary"), default="none")
    a = ap.parse_args(argv)
    target = None
    if a.target != "none":
        from mpf_mavlink.core.target import PaperProfile, Stationary

        target = PaperProfile() if a.target == "paper" else Stationary()
    v = SimVehicle(a.flavour, a.url, plant=a.plant, clock=a.clock, target=target)
    print(f"SimVehicle {a.flavour} on {a.url} ({a.plant}, {a.clock}) in {v.mode_name}", flush=True)
    try:
        v.run(a.duration)
    except KeyboardInterrupt:
        pass
    finally:
        v.close()
    print(f"sim {v.t:.1f} s, real-time factor {v.real_time_factor:.1f}", flush=True)
    return 0


__all__ = [
    "SimVehicle",
    "TelemetryRates",
    "PX4_MAIN",
    "PX4_AUTO_SUB",
    "ARDUPLANE_MODES",
    "px4_custom_mode",
    "px4_decode_custom_mode",
]


if __name__ == "__main__":
    raise SystemExit(main())
