"""Configuration sections of the MAVLink bridge: ``mavlink`` and ``adapter``.

Validated strictly by :mod:`mpf_mavlink.config.schema` like every section (unknown keys, wrong
types and impossible values are one-line errors naming the key and the file). Units are in the
key names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, Protocol

from mpf_mavlink.config.fields import _doc, _ge, _nonneg, _pos, _rng
from mpf_mavlink.errors import ConfigError


class _Climb(Protocol):
    """What :meth:`AdapterSection.k_thrust` reads of the ``vehicle`` section."""

    @property
    def airspeed_m_s(self) -> float: ...

    @property
    def max_climb_rate_m_s(self) -> float | None: ...


MAV_COMP_ID_AUTOPILOT1 = 1  # PX4's and ArduPilot's autopilot component id


def hold_mode_error(mode: str, flavour: str) -> str | None:
    """Why ``mode`` cannot be the hold mode of a ``flavour`` ("px4", "ardupilot", "auto")
    autopilot, or None. The offboard mode itself is refused: handing back to it would leave the
    vehicle waiting for setpoints that no longer come."""
    from mpf_mavlink.mavlink.modes import (
        ARDUPLANE_GUIDED,
        PX4_OFFBOARD_MAIN,
        arduplane_mode_from_name,
        px4_mode_from_name,
    )

    ok: list[bool | None] = []  # per flavour: a mode other than offboard, offboard, unknown
    if flavour in ("px4", "auto"):
        try:
            ok.append(px4_mode_from_name(mode) != (PX4_OFFBOARD_MAIN, 0))
        except ValueError:
            ok.append(None)
    if flavour in ("ardupilot", "auto"):
        try:
            ok.append(arduplane_mode_from_name(mode) != ARDUPLANE_GUIDED)
        except ValueError:
            ok.append(None)
    if any(ok):
        return None
    if False in ok:
        return (
            f"{mode!r} is the offboard mode itself; hand back to a mode the autopilot flies alone"
        )
    who = {"px4": "a PX4 mode (e.g. AUTO.LOITER)", "ardupilot": "an ArduPlane mode (e.g. LOITER)"}
    return f"{mode!r} is not {who.get(flavour, 'a PX4 or ArduPlane mode')}"


@dataclass(frozen=True)
class MavlinkConfig:
    """Link, identities, timeouts and the offboard life cycle.

    Identities: we speak as ``source_system``/``source_component`` (a companion computer on the
    vehicle: same system id, component 191) to the autopilot ``vehicle_sysid``.
    ``target_sysid``: the system id that sends a live target (``target.type: mavlink``);
    FOLLOW_TARGET, or GLOBAL_POSITION_INT (+ ATTITUDE when present), from that id.
    Local frame: LOCAL_POSITION_NED when the autopilot streams it; otherwise GLOBAL_POSITION_INT
    about ``origin_*`` when given, else about HOME_POSITION. A live target needs a geodetic
    origin (``origin_*`` or HOME_POSITION).
    Re-engagement after a loss: at most ``reengage_max`` times, when telemetry (and the live
    target) come back within ``reengage_wait_s`` (s) of the hand-back and stay for
    ``reengage_settle_s`` (s), with the vehicle in the hold mode.
    """

    flavour: Literal["auto", "px4", "ardupilot"] = field(
        default="auto", metadata=_doc("the autopilot; auto: from its HEARTBEAT")
    )
    vehicle_sysid: int = field(default=1, metadata=_rng(1, 255))
    source_system: int = field(default=1, metadata=_rng(1, 255))
    source_component: int = field(default=191, metadata=_rng(0, 255))
    target_sysid: int | None = field(
        default=None, metadata=_rng(1, 255, "the system that sends a live target")
    )
    heartbeat_timeout_s: float = field(default=10.0, metadata=_pos())
    telemetry_timeout_s: float = field(
        default=0.5, metadata=_pos("no ATTITUDE for this long: stop and hand back")
    )
    attitude_stale_s: float = field(default=0.5, metadata=_pos())
    position_stale_s: float = field(default=0.5, metadata=_pos())
    airspeed_stale_s: float = field(default=0.5, metadata=_pos())
    wind_stale_s: float = field(
        default=2.0,
        metadata=_pos(
            "longer than the rest: wind streams are slow (ArduPilot WIND 1-4 Hz) and a stale "
            "one only switches to our own estimate"
        ),
    )
    wind_filter_tau_s: float = field(default=5.0, metadata=_pos())
    target_timeout_s: float = field(
        default=1.0,
        metadata=_pos(
            "a live target's staleness with target_estimator.mode last_sample (the filter has "
            "its own: target_estimator.max_position_sigma_m)"
        ),
    )
    min_setpoint_rate_hz: float = field(default=20.0, metadata=_ge(2.0))
    prestream_s: float = field(
        default=1.5,
        metadata=_ge(
            1.0,
            "setpoints streamed before OFFBOARD is asked for: PX4 wants 1 s counted from the "
            "first setpoint it received, so exactly 1 s is refused when the first ones are late",
        ),
    )
    mode_timeout_s: float = field(default=1.5, metadata=_pos())
    mode_retries: int = field(default=3, metadata=_ge(1))
    lockstep: bool = field(
        default=False,
        metadata=_doc(
            "the vehicle is a simulation in lockstep with us (`mpf-mavlink sim` sets it): the "
            "timeouts count the vehicle's time; false (a real autopilot): wall-clock time"
        ),
    )
    lockstep_wall_timeout_s: float = field(
        default=10.0, metadata=_pos("with lockstep: a vehicle silent this long is lost")
    )
    hold_mode: str | None = field(
        default=None,
        metadata=_doc("the mode handed back to; null: AUTO.LOITER (PX4), LOITER (ArduPlane)"),
    )
    arm: bool = field(default=False, metadata=_doc("arm the vehicle if it is disarmed"))
    reengage_max: int = field(
        default=0,
        metadata=_ge(
            0,
            "after telemetry or the live target was lost and control handed back: fly again "
            "up to this many times, once the stream is back for reengage_settle_s and the "
            "vehicle sits in the hold mode (a pilot's mode is never taken back); 0 ends the run",
        ),
    )
    reengage_wait_s: float = field(default=30.0, metadata=_pos())
    reengage_settle_s: float = field(default=1.0, metadata=_pos())
    mission_duration_s: float = field(default=120.0, metadata=_pos("how long `run` tracks"))
    signing_key_file: str | None = field(
        default=None, metadata=_doc("MAVLink 2 signing key (32 bytes); null: unsigned")
    )
    signing_link_id: int = field(default=0, metadata=_rng(0, 255))
    origin_lat_deg: float | None = field(
        default=None, metadata=_rng(-90.0, 90.0, "NED origin; null: HOME_POSITION")
    )
    origin_lon_deg: float | None = field(default=None, metadata=_rng(-180.0, 180.0))
    origin_alt_m: float | None = field(
        default=None, metadata=_doc("AMSL; lat, lon and alt are given together or not at all")
    )
    tlog_fsync_every_s: float | None = field(default=1.0, metadata=_nonneg())
    plots: bool = field(default=True, metadata=_doc("write the run directory's figures"))
    recording: Literal["full", "lean"] = field(
        default="full",
        metadata=_doc(
            "lean (campaigns): no tlog, no plots, one tracking row in five (a SIL's truth tables "
            "too; its figures still use every frame); every setpoint is "
            "still sent, so the flight is the same"
        ),
    )
    operator_display: bool = field(
        default=True,
        metadata=_doc(
            "what a ground station sees: NAMED_VALUE_FLOAT MPF_pt, MPF_psi, MPF_sdot, "
            "MPF_state and a STATUSTEXT on every state change and on the reason it stops"
        ),
    )
    operator_display_hz: float = field(default=2.0, metadata=_rng(0.1, 10.0))
    delay_compensation: bool = field(
        default=True,
        metadata=_doc(
            "the law acts on the state predicted to when its setpoint acts (core/guidance/"
            "predict.py); false: on the measured state"
        ),
    )
    known_delay_s: float = field(
        default=0.0,
        metadata=_rng(
            0.0, 0.2,
            "delay from an ATTITUDE sample to the autopilot's receipt of the answering "
            "setpoint, known beforehand; replaced once measured from ATTITUDE_TARGET",
        ),
    )  # fmt: skip
    position_instants: bool = field(
        default=True,
        metadata=_doc(
            "PX4 body rates: a LOCAL_POSITION_NED between two ATTITUDEs is a control instant "
            "too, so a slow ATTITUDE stream does not hold each rate setpoint a whole period"
        ),
    )
    request_streams: bool = field(
        default=True,
        metadata=_doc(
            "ask for the stream rates below (MAV_CMD_SET_MESSAGE_INTERVAL; REQUEST_DATA_STREAM "
            "for ArduPilot), measure them over 1 s and refuse to engage below a *_min_hz"
        ),
    )
    airspeed_is_eas: bool = field(
        default=True,
        metadata=_doc("VFR_HUD.airspeed is equivalent airspeed: convert to true (ISA)"),
    )
    airspeed_from_wind: bool = field(
        default=True,
        metadata=_doc(
            "while the autopilot's wind is fresh, the speed along w1 is |v_ground - wind|"
        ),
    )
    attitude_rate_hz: float = field(default=50.0, metadata=_pos())
    attitude_min_hz: float = field(default=20.0, metadata=_nonneg())
    position_rate_hz: float = field(default=50.0, metadata=_pos())
    position_min_hz: float = field(default=10.0, metadata=_nonneg())
    airspeed_rate_hz: float = field(default=10.0, metadata=_pos())
    airspeed_min_hz: float = field(default=4.0, metadata=_nonneg())
    wind_rate_hz: float = field(default=2.0, metadata=_nonneg())
    stream_timeout_s: float = field(default=5.0, metadata=_pos())
    home_timeout_s: float = field(
        default=5.0, metadata=_pos("wait for HOME_POSITION when the origin needs it")
    )
    set_fallback: bool = field(
        default=True,
        metadata=_doc(
            "choose and print what the autopilot does if our setpoints stop (ArduPlane: the "
            "guided target becomes a loiter about the path's centre; PX4: COM_OBL_RC_ACT made "
            "Hold with read-back, the Hold's loiter point the path's centre); false: nothing "
            "is read or set (bridge/px4_fallback.py)"
        ),
    )
    fallback_follow_s: float = field(
        default=5.0,
        metadata=_nonneg(
            "with set_fallback, while tracking: every this many seconds re-place that loiter "
            "point at the path's centre once it has moved 5 m (a moving target), so an "
            "aircraft whose bridge dies circles where the target is; 0: placed once"
        ),
    )

    def validate(self, src: str, target_type: str) -> None:
        """Contradictions between keys (and with ``target.type``), found before anything is
        opened or sent."""

        def fail(key: str, msg: str) -> ConfigError:
            return ConfigError(f"{src}: mavlink.{key}: {msg}")

        if self.hold_mode is not None and (why := hold_mode_error(self.hold_mode, self.flavour)):
            raise fail("hold_mode", why)
        if target_type == "mavlink" and self.target_sysid is None:
            raise fail(
                "target_sysid",
                "required by target.type mavlink (the system id that sends the target)",
            )
        origin = {
            "origin_lat_deg": self.origin_lat_deg,
            "origin_lon_deg": self.origin_lon_deg,
            "origin_alt_m": self.origin_alt_m,
        }
        given = [k for k, v in origin.items() if v is not None]
        if given and len(given) < 3:
            # GLOBAL_POSITION_INT.alt is AMSL: an origin altitude left at 0 would put the
            # vehicle its whole AMSL altitude below the path in NED, so all three or none
            missing = ", ".join(k for k in origin if k not in given)
            raise fail(
                missing.split(",")[0],
                f"required with {', '.join(given)} (the NED origin is lat, lon and AMSL "
                "altitude; leave all three out to use the vehicle's HOME_POSITION)",
            )
        if self.lockstep and self.lockstep_wall_timeout_s < self.telemetry_timeout_s:
            raise fail(
                "lockstep_wall_timeout_s",
                f"{self.lockstep_wall_timeout_s:g} is below mavlink.telemetry_timeout_s "
                f"{self.telemetry_timeout_s:g} (it bounds the vehicle-time timeouts from above)",
            )
        for k in ("attitude", "position", "airspeed"):
            if getattr(self, f"{k}_min_hz") > getattr(self, f"{k}_rate_hz"):
                raise fail(
                    f"{k}_min_hz",
                    f"{getattr(self, f'{k}_min_hz'):g} is above mavlink.{k}_rate_hz "
                    f"{getattr(self, f'{k}_rate_hz'):g} (the rate asked for)",
                )
        if self.target_sysid is not None and self.target_sysid == self.vehicle_sysid:
            raise fail(
                "target_sysid",
                f"{self.target_sysid} is the vehicle's own system id (mavlink.vehicle_sysid)",
            )
        if (self.source_system, self.source_component) == (
            self.vehicle_sysid,
            MAV_COMP_ID_AUTOPILOT1,
        ):
            raise fail(
                "source_component",
                f"{self.source_component} on system {self.source_system} is the autopilot's own "
                "id: we would impersonate it and drop its messages as our echo (a companion "
                "computer uses 191)",
            )


@dataclass(frozen=True)
class AdapterSection:
    """Setpoint adapter (see :class:`mpf_mavlink.core.adapter.AdapterParams`). The bank limit is
    ``vehicle.max_bank_rad`` and the airspeed set-point ``vehicle.airspeed_m_s``."""

    tau_roll_s: float = field(default=0.5, metadata=_pos())
    tau_pitch_s: float = field(default=1.0, metadata=_nonneg())
    max_roll_rate_rad_s: float = field(default=1.2217, metadata=_pos())
    max_pitch_rate_rad_s: float = field(default=1.0472, metadata=_pos())
    max_yaw_rate_rad_s: float = field(default=0.8727, metadata=_pos())
    min_pitch_rad: float = field(default=-0.35, metadata=_rng(-1.5, 0.0))
    max_pitch_rad: float = field(default=0.35, metadata=_rng(0.0, 1.5))
    trim_pitch_rad: float = field(default=0.03, metadata=_rng(-0.5, 0.5))
    trim_thrust: float = field(default=0.5, metadata=_rng(0.0, 1.0))
    thrust_min: float = field(
        default=0.0,
        metadata=_rng(
            0.0, 1.0,
            "as PX4 FW_THR_MIN and ArduPlane THR_MIN (0): a floor above it keeps adding "
            "energy the airframe cannot shed in an updraft",
        ),
    )  # fmt: skip
    thrust_max: float = field(default=1.0, metadata=_rng(0.0, 1.0))
    airspeed_kp: float = field(default=0.05, metadata=_nonneg())
    airspeed_ki: float = field(default=0.02, metadata=_nonneg())
    integrator_limit: float = field(default=1.0, metadata=_nonneg())
    load_factor_ff: float = field(default=0.2, metadata=_nonneg("thrust per g of extra load"))
    adaptive: bool = field(
        default=True,
        metadata=_doc(
            "learn the pitch offset (replaces trim_pitch_rad) and the turn gain (replaces the "
            "ideal coordinated turn); false: the fixed trim and the ideal turn"
        ),
    )
    trim_tau_s: float = field(default=4.0, metadata=_pos())
    trim_schedule: bool = field(
        default=True,
        metadata=_doc(
            "schedule the learnt pitch offset with the airspeed set-point (lift ~ 1 / V^2): its "
            "slope on (airspeed_m_s / set-point)^2 regressed online on the measured pitch less "
            "flight-path angle; needs adaptive"
        ),
    )
    trim_schedule_tau_s: float = field(
        default=60.0, metadata=_pos("the schedule's regression: forgetting time (s)")
    )
    trim_schedule_min_dv_m_s: float = field(
        default=0.3,
        metadata=_nonneg("the set-point's spread (m/s RMS) below which the slope is not learnt"),
    )
    turn_gain_tau_s: float = field(default=8.0, metadata=_pos())
    rate_bias_tau_s: float = field(
        default=1.0,
        metadata=_nonneg(
            "PX4 body rates: the autopilot's pitch-rate tracking error, low-passed with this "
            "time constant, is taken off the pitch rate sent; 0: off"
        ),
    )
    energy_control: bool = field(
        default=True,
        metadata=_doc(
            "total energy control of thrust and the flight-path demand; false: the airspeed "
            "PI (airspeed_kp, airspeed_ki)"
        ),
    )
    thrust_per_gamma: float | None = field(
        default=None,
        metadata=_pos(
            "throttle per rad of steady climb; null: (thrust_max - trim_thrust) / (climb / V) "
            "from vehicle.max_climb_rate_m_s, else 2.5"
        ),
    )
    speed_tau_s: float = field(default=4.0, metadata=_pos())
    energy_kp: float = field(default=1.0, metadata=_nonneg())
    energy_ki: float = field(default=0.6, metadata=_nonneg())
    vdot_tau_s: float = field(default=2.0, metadata=_nonneg())
    priority: Literal["airspeed", "height"] = field(
        default="airspeed",
        metadata=_doc(
            "what is held when thrust cannot meet both: the airspeed inside its envelope (the "
            "flight path gives way near the limits) or the height (the airspeed may leave it)"
        ),
    )
    balance_tau_s: float = field(default=1.0, metadata=_nonneg())
    reserve_gust_m_s: float = field(
        default=3.0,
        metadata=_nonneg(
            "energy reserve: a downdraft (m/s) that the path's sustained climb must leave room "
            "for in vehicle.max_climb_rate_m_s, or the airspeed set-point rises (up to "
            "vehicle.airspeed_max_m_s) to pay the rest from speed; 0: off. 3 m/s for 10 s is "
            "2.5 sigma of the 10 s mean of light turbulence at 400-600 m (MIL-F-8785C)"
        ),
    )
    reserve_gust_s: float = field(default=10.0, metadata=_pos("how long that downdraft lasts"))
    reserve_tau_s: float = field(default=20.0, metadata=_pos("low-pass of the path's climb"))
    reserve_rate_m_s2: float = field(
        default=0.1, metadata=_pos("how fast the reserve moves the airspeed set-point")
    )

    def k_thrust(self, v: _Climb) -> float:
        """thrust_per_gamma, or its value derived from the vehicle's climb (see the field)."""
        if self.thrust_per_gamma is not None:
            return self.thrust_per_gamma
        climb = v.max_climb_rate_m_s
        if climb is not None and self.thrust_max > self.trim_thrust:
            gam = math.asin(min(climb / v.airspeed_m_s, 0.99))
            return (self.thrust_max - self.trim_thrust) / gam
        return 2.5

    def validate(self, src: str) -> None:
        if self.thrust_min > self.thrust_max:
            raise ConfigError(
                f"{src}: adapter.thrust_min: {self.thrust_min:g} is above "
                f"adapter.thrust_max {self.thrust_max:g}"
            )
        if not self.thrust_min <= self.trim_thrust <= self.thrust_max:
            raise ConfigError(
                f"{src}: adapter.trim_thrust: {self.trim_thrust:g} is outside "
                "[thrust_min, thrust_max]"
            )
