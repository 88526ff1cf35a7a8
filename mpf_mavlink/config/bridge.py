"""Configuration sections of the MAVLink bridge: ``mavlink`` and ``adapter``.

Importing this module registers both in :data:`mpf_mavlink.config.schema.EXTRA_SECTIONS`, so every
config loaded afterwards validates them strictly (unknown keys, wrong types and impossible
values are one-line errors naming the key and the file). Units are in the key names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from mpf_mavlink.config.fields import EXTRA_SECTIONS, _nonneg, _pos
from mpf_mavlink.errors import ConfigError

MAV_COMP_ID_AUTOPILOT1 = 1  # PX4's and ArduPilot's autopilot component id


def hold_mode_error(mode: str, flavour: str) -> str | None:
    """Why ``mode`` cannot be the hold mode of a ``flavour`` ("px4", "ardupilot", "auto")
    autopilot, or None. The offboard mode itself is refused: handing back to it would leave the
    vehicle waiting for setpoints that no longer come."""
    from mpf_mavlink.mavlink.modes import arduplane_mode_from_name, px4_mode_from_name

    ok: list[bool | None] = []
    for fl, parse, offboard in (
        ("px4", px4_mode_from_name, (6, 0)),
        ("ardupilot", arduplane_mode_from_name, 15),
    ):
        if flavour in (fl, "auto"):
            try:
                ok.append(parse(mode) != offboard)
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

    flavour: Literal["auto", "px4", "ardupilot"] = "auto"
    vehicle_sysid: int = field(default=1, metadata={"check": ("range", 1, 255)})
    source_system: int = field(default=1, metadata={"check": ("range", 1, 255)})
    source_component: int = field(default=191, metadata={"check": ("range", 0, 255)})
    target_sysid: int | None = field(default=None, metadata={"check": ("range", 1, 255)})
    heartbeat_timeout_s: float = field(default=10.0, metadata=_pos())
    telemetry_timeout_s: float = field(
        default=0.5, metadata=_pos()
    )  # no ATTITUDE for this long: stop
    attitude_stale_s: float = field(default=0.5, metadata=_pos())
    position_stale_s: float = field(default=0.5, metadata=_pos())
    airspeed_stale_s: float = field(default=0.5, metadata=_pos())
    # Wind streams are slow (ArduPilot WIND ~1-4 Hz) and a stale one only switches to our own
    # estimate, so its default is longer.
    wind_stale_s: float = field(default=2.0, metadata=_pos())
    wind_filter_tau_s: float = field(default=5.0, metadata=_pos())
    # the live target's staleness with target_estimator.mode last_sample only (the estimator
    # has its own, from its uncertainty: target_estimator.max_position_sigma_m)
    target_timeout_s: float = field(default=1.0, metadata=_pos())
    min_setpoint_rate_hz: float = field(default=20.0, metadata={"check": ("ge", 2.0)})
    # PX4 wants >= 1 s of stream before OFFBOARD; it counts from the first setpoint it RECEIVED,
    # so exactly 1 s of sending is refused whenever the first ones arrived late (link jitter)
    prestream_s: float = field(default=1.5, metadata={"check": ("ge", 1.0)})
    mode_timeout_s: float = field(default=1.5, metadata=_pos())
    mode_retries: int = field(default=3, metadata={"check": ("ge", 1)})
    # The vehicle is a simulation in lockstep with us (it advances once our setpoint answers
    # its telemetry; `mpf-mavlink sim` sets this with its lockstep clock): telemetry_timeout_s,
    # the control step's staleness and mode_timeout_s count the VEHICLE's time (the newest
    # time_boot_ms it sent), since a slow simulation on a loaded host is not a lost link; a
    # vehicle that sends nothing at all is still lost after lockstep_wall_timeout_s of wall time.
    # False (a real autopilot): every timeout is wall-clock time.
    lockstep: bool = False
    lockstep_wall_timeout_s: float = field(default=10.0, metadata=_pos())
    hold_mode: str | None = None  # None: AUTO.LOITER (PX4), LOITER (ArduPlane)
    arm: bool = False
    # After telemetry (or the live target) was lost and control handed back: 0 ends the run;
    # N > 0 flies again, up to N times, once the stream is back for reengage_settle_s and the
    # vehicle sits in the hold mode (a pilot's mode is never taken back)
    reengage_max: int = field(default=0, metadata={"check": ("ge", 0)})
    reengage_wait_s: float = field(default=30.0, metadata=_pos())
    reengage_settle_s: float = field(default=1.0, metadata=_pos())
    mission_duration_s: float = field(default=120.0, metadata=_pos())
    signing_key_file: str | None = None
    signing_link_id: int = field(default=0, metadata={"check": ("range", 0, 255)})
    origin_lat_deg: float | None = field(default=None, metadata={"check": ("range", -90.0, 90.0)})
    origin_lon_deg: float | None = field(default=None, metadata={"check": ("range", -180.0, 180.0)})
    origin_alt_m: float | None = None
    tlog_fsync_every_s: float | None = field(default=1.0, metadata=_nonneg())
    plots: bool = True
    recording: Literal["full", "lean"] = "full"  # lean (campaigns): no plots, 1 row in 5, no tlog
    # What an operator's ground station sees of the guidance (bridge/operator.py): NAMED_VALUE_FLOAT
    # MPF_pt, MPF_psi, MPF_sdot, MPF_state at operator_display_hz (vehicle time), sent after the
    # setpoint, and a STATUSTEXT "MPF: ..." on every state change and on the reason it stops
    operator_display: bool = True
    operator_display_hz: float = field(default=2.0, metadata={"check": ("range", 0.1, 10.0)})
    # Delay compensation (mpf_mavlink/core/guidance/predict.py): the law acts on the state predicted
    # to when its setpoint acts. known_delay_s: the delay (s) from an ATTITUDE sample's time to
    # the autopilot's receipt of the setpoint that answers it, as known beforehand (serial link,
    # companion scheduling); the delay measured from the autopilot's ATTITUDE_TARGET echo
    # replaces it once measured. delay_compensation: false = the law acts on the measured state.
    delay_compensation: bool = True
    known_delay_s: float = field(default=0.0, metadata={"check": ("range", 0.0, 0.2)})
    # Multi-rate loop (PX4 body-rate setpoints): a LOCAL_POSITION_NED newer than the latest
    # ATTITUDE, and due before the next one, is a control instant too: the law steps on its
    # position and velocity with the attitude carried there by the ATTITUDE's body rates, so a
    # slow ATTITUDE stream does not hold each rate setpoint for a whole period. Streams at the
    # same rate (the defaults: 50 Hz each) give no such instant.
    position_instants: bool = True
    # Stream-rate negotiation before the checks: autopilots stream slowly on most links by
    # default (ArduPlane: 1 Hz per SRn group), so the bridge asks for what the loop needs
    # (MAV_CMD_SET_MESSAGE_INTERVAL per message; REQUEST_DATA_STREAM as ArduPilot's fallback),
    # measures the rates over 1 s and refuses to engage if a *_min_hz is not reached within
    # stream_timeout_s. Position: LOCAL_POSITION_NED (GLOBAL_POSITION_INT at up to 10 Hz as the
    # geodetic anchor); airspeed: VFR_HUD; wind: WIND (ArduPilot) / WIND_COV (PX4), optional.
    request_streams: bool = True
    # VFR_HUD.airspeed is an equivalent airspeed (ArduPilot EAS, PX4 calibrated): the speed
    # along w1 is true airspeed, EAS * sqrt(rho0 / rho) at VFR_HUD.alt (ISA)
    airspeed_is_eas: bool = True
    # while the autopilot's own wind (WIND / WIND_COV) is fresh, the speed along w1 is
    # |v_ground - wind|, the air-relative speed the law's kinematics assume (no EAS/TAS factor)
    airspeed_from_wind: bool = True
    attitude_rate_hz: float = field(default=50.0, metadata=_pos())
    attitude_min_hz: float = field(default=20.0, metadata=_nonneg())
    position_rate_hz: float = field(default=50.0, metadata=_pos())
    position_min_hz: float = field(default=10.0, metadata=_nonneg())
    airspeed_rate_hz: float = field(default=10.0, metadata=_pos())
    airspeed_min_hz: float = field(default=4.0, metadata=_nonneg())
    wind_rate_hz: float = field(default=2.0, metadata=_nonneg())
    stream_timeout_s: float = field(default=5.0, metadata=_pos())
    # HOME_POSITION is asked for (MAV_CMD_REQUEST_MESSAGE, then MAV_CMD_GET_HOME_POSITION) and
    # awaited up to this long when a live target or the ArduPlane fallback needs it
    home_timeout_s: float = field(default=5.0, metadata=_pos())
    # What the autopilot does if our setpoints stop (the bridge died), chosen and printed before
    # tracking. ArduPlane: once GUIDED is confirmed, its guided target (MAV_CMD_DO_REPOSITION)
    # becomes a loiter about the path's centre at the path's altitude, with the path's radius
    # and direction (flown after GUIDED_TIMEOUT). PX4: COM_OF_LOSS_T, COM_OBL_RC_ACT and the
    # RC-loss parameters are read, COM_OBL_RC_ACT is made Hold (5) by PARAM_SET with read-back
    # (the bridge refuses to engage when that is not confirmed: stock 0 is Position mode, which
    # on a fixed-wing flies straight on), and once OFFBOARD is confirmed the Hold's loiter point
    # becomes the path's centre (MAV_CMD_DO_REPOSITION, no mode change; radius NAV_LOITER_RAD).
    # false: nothing is read or set (bridge/px4_fallback.py)
    set_fallback: bool = True

    def validate(self, cfg: Any, src: str) -> None:
        """Contradictions between keys, found before anything is opened or sent."""

        def fail(key: str, msg: str) -> ConfigError:
            return ConfigError(f"{src}: mavlink.{key}: {msg}")

        if self.hold_mode is not None and (why := hold_mode_error(self.hold_mode, self.flavour)):
            raise fail("hold_mode", why)
        if cfg.target.type == "mavlink" and self.target_sysid is None:
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
                f"{self.source_component} on system {self.source_system} is the autopilot's own id: we would "
                "impersonate it and drop its messages as our echo (a companion computer uses 191)",
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
    min_pitch_rad: float = field(default=-0.35, metadata={"check": ("range", -1.5, 0.0)})
    max_pitch_rad: float = field(default=0.35, metadata={"check": ("range", 0.0, 1.5)})
    trim_pitch_rad: float = field(default=0.03, metadata={"check": ("range", -0.5, 0.5)})
    trim_thrust: float = field(default=0.5, metadata={"check": ("range", 0.0, 1.0)})
    # PX4 FW_THR_MIN and ArduPlane THR_MIN are 0 ("for electric aircraft this will normally be
    # set to zero"): a floor above it keeps adding energy the airframe cannot shed in an updraft
    thrust_min: float = field(default=0.0, metadata={"check": ("range", 0.0, 1.0)})
    thrust_max: float = field(default=1.0, metadata={"check": ("range", 0.0, 1.0)})
    airspeed_kp: float = field(default=0.05, metadata=_nonneg())
    airspeed_ki: float = field(default=0.02, metadata=_nonneg())
    integrator_limit: float = field(default=1.0, metadata=_nonneg())
    load_factor_ff: float = field(default=0.2, metadata=_nonneg())
    # learned pitch offset (replaces trim_pitch_rad) and turn gain (replaces the ideal
    # coordinated turn): see mpf_mavlink/core/adapter.py; false = the fixed trim and ideal turn
    adaptive: bool = True
    trim_tau_s: float = field(default=4.0, metadata=_pos())
    turn_gain_tau_s: float = field(default=8.0, metadata=_pos())
    # PX4 body rates: the autopilot's pitch-rate tracking error (flown - sent), low-passed with
    # this time constant, is taken off the pitch rate sent (mpf_mavlink/core/adapter.py); 0: off
    rate_bias_tau_s: float = field(default=1.0, metadata=_nonneg())
    # Total energy control of thrust and the flight-path demand (mpf_mavlink/core/adapter.py:
    # energy_thrust); false: the airspeed PI (airspeed_kp, airspeed_ki)
    energy_control: bool = True
    # throttle per rad of steady climb (k_T); null: (thrust_max - trim_thrust) / (climb / V)
    # from vehicle.max_climb_rate_m_s at vehicle.airspeed_m_s, else 2.5
    thrust_per_gamma: float | None = field(default=None, metadata=_pos())
    speed_tau_s: float = field(default=4.0, metadata=_pos())
    energy_kp: float = field(default=1.0, metadata=_nonneg())
    energy_ki: float = field(default=0.6, metadata=_nonneg())
    vdot_tau_s: float = field(default=2.0, metadata=_nonneg())
    # what is held when thrust cannot meet both: the airspeed inside its envelope
    # vehicle.airspeed_min/max_m_s (the flight path gives way near the limits) or the height
    # (the airspeed may leave the envelope)
    priority: Literal["airspeed", "height"] = "airspeed"
    balance_tau_s: float = field(default=1.0, metadata=_nonneg())

    def k_thrust(self, v: Any) -> float:
        """thrust_per_gamma, or its value derived from the vehicle's climb (see the field)."""
        if self.thrust_per_gamma is not None:
            return self.thrust_per_gamma
        climb = getattr(v, "max_climb_rate_m_s", None)
        if climb is not None and self.thrust_max > self.trim_thrust:
            gam = math.asin(min(climb / v.airspeed_m_s, 0.99))
            return (self.thrust_max - self.trim_thrust) / gam
        return 2.5

    def validate(self, cfg: Any, src: str) -> None:
        if self.thrust_min > self.thrust_max:
            raise ConfigError(
                f"{src}: adapter.thrust_min: {self.thrust_min:g} is above adapter.thrust_max {self.thrust_max:g}"
            )
        if not self.thrust_min <= self.trim_thrust <= self.thrust_max:
            raise ConfigError(
                f"{src}: adapter.trim_thrust: {self.trim_thrust:g} is outside [thrust_min, thrust_max]"
            )


EXTRA_SECTIONS["mavlink"] = MavlinkConfig
EXTRA_SECTIONS["adapter"] = AdapterSection
