"""Configuration sections of the software-in-the-loop (SIL) vehicle: ``sil`` and ``aircraft``.

Validated strictly by :mod:`mpf_mavlink.config.schema` like every section: unknown keys, wrong
types and impossible values are one-line errors naming the key and the file. Units are in the
key names; NED, radians. Only configuration lives here: the simulation is in ``sim/``.

``sil.link: udp`` makes ``mpf-mavlink sim`` fly the scenario with the SIL vehicle (JSBSim or the
kinematic plant behind a MAVLink endpoint) and the bridge as separate MAVLink peers over UDP
loopback; ``none`` (the default) keeps the guidance core's in-process closed loop of the paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from mpf_mavlink.config.bridge import MavlinkConfig, hold_mode_error
from mpf_mavlink.config.fields import Vec3, _doc, _fail, _ge, _nonneg, _open, _pos, _rng
from mpf_mavlink.errors import ConfigError

if TYPE_CHECKING:
    from mpf_mavlink.config.autopilot_profile import ResolvedProfile

_REPO = Path(__file__).resolve().parents[2]


def _rate(doc: str = "") -> dict[str, Any]:
    return _nonneg(doc)


@dataclass(frozen=True)
class TelemetryConfig:
    """Stream rates of the simulated autopilot at power-on (Hz; 0 disables a stream; left out:
    the stock rate of ``sil.flavour`` on a companion's link, ``sim.vehicle.config.stock_rates``:
    ArduPlane 1 Hz per stream group and no HOME_POSITION, PX4's onboard link fast). The bridge
    asks for the rates it needs (MAV_CMD_SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM), which the
    vehicle honours, as the real autopilots do."""

    attitude_hz: float | None = field(default=None, metadata=_rate())
    local_position_hz: float | None = field(default=None, metadata=_rate())
    global_position_hz: float | None = field(default=None, metadata=_rate())
    vfr_hud_hz: float | None = field(default=None, metadata=_rate())
    wind_hz: float | None = field(default=None, metadata=_rate())
    home_position_hz: float | None = field(default=None, metadata=_rate())
    sys_status_hz: float | None = field(default=None, metadata=_rate())
    system_time_hz: float | None = field(default=None, metadata=_rate())
    heartbeat_hz: float | None = field(default=None, metadata=_rate())
    attitude_target_hz: float | None = field(default=None, metadata=_rate("PX4 flavour only"))


@dataclass(frozen=True)
class GustEventConfig:
    """One-minus-cosine gust (JSBSim cosine-gust) starting ``start_s`` seconds of simulated
    time after the vehicle is ready: the air moves along ``direction_ned`` (normalized) with a
    (1 - cos) ramp over ``rise_s``, ``magnitude_m_s`` held ``hold_s``, a cosine decay over
    ``decay_s``."""

    start_s: float = field(default=0.0, metadata=_nonneg())
    direction_ned: Vec3 = (0.0, 1.0, 0.0)
    magnitude_m_s: float = field(default=5.0, metadata=_nonneg())
    rise_s: float = field(default=1.0, metadata=_pos())
    hold_s: float = field(default=2.0, metadata=_nonneg())
    decay_s: float = field(default=1.0, metadata=_pos())


@dataclass(frozen=True)
class OutageConfig:
    """A window of the target feed with no report: ``start_s`` (target time, s), ``duration_s``."""

    start_s: float = field(default=0.0, metadata=_nonneg())
    duration_s: float = field(default=5.0, metadata=_pos())


@dataclass(frozen=True)
class TargetFeedConfig:
    """The simulated target reports itself as a real one does (``sim/target/feed.py``): every
    ``1 / rate_hz`` s, white noise on the position (``position_noise_m`` per horizontal axis,
    ``vertical_noise_m``, None: the same), the velocity and the turn rate, stamped with its own
    clock (the vehicle's boot clock + ``clock_offset_s``), lost with probability ``dropout`` in
    bursts of ``dropout_burst`` reports on average (and during ``outages``), delivered
    ``latency_s + U(0, latency_jitter_s)`` later (a jitter above the period reorders reports).
    ``attitude``: FOLLOW_TARGET carries attitude and rates (and ATTITUDE follows each
    GLOBAL_POSITION_INT); ``messages``: which messages carry the fix. ``seed``: the feed's own."""

    rate_hz: float = field(default=1.0, metadata=_rng(0.05, 50.0))
    position_noise_m: float = field(default=0.0, metadata=_nonneg())
    vertical_noise_m: float | None = field(default=None, metadata=_nonneg())
    velocity_noise_m_s: float = field(default=0.0, metadata=_nonneg())
    turn_rate_noise_rad_s: float = field(default=0.0, metadata=_nonneg())
    latency_s: float = field(default=0.0, metadata=_nonneg())
    latency_jitter_s: float = field(default=0.0, metadata=_nonneg())
    dropout: float = field(default=0.0, metadata=_rng(0.0, 0.95))
    dropout_burst: float = field(default=1.0, metadata=_ge(1.0))
    outages: list[OutageConfig] = field(default_factory=list)
    attitude: bool = False
    messages: Literal["both", "follow_target", "global_position_int"] = "both"
    clock_offset_s: float = field(default=0.0, metadata=_nonneg())
    seed: int = 0


@dataclass(frozen=True)
class SilConfig:
    """The simulated vehicle behind its MAVLink endpoint, and how ``mpf-mavlink sim`` links it.

    link: ``none`` = the paper's in-process kinematic loop; ``udp`` = vehicle and bridge as two
      processes talking MAVLink over UDP loopback (``port``: fixed port, None: a free one).
    plant: ``jsbsim`` (the ``aircraft`` section) or ``kinematic`` (bank-to-turn, steady wind only).
    flavour: which autopilot the vehicle presents (the bridge flies it in OFFBOARD / GUIDED).
    clock: ``lockstep`` (the vehicle advances once the bridge has answered the last telemetry,
      waiting at most ``answer_timeout_s`` of wall time, 5 s after a frame the bridge answered;
      from the bridge's first message on, in every phase: the bridge answers each ATTITUDE with
      a setpoint or a SYSTEM_TIME clock answer and counts its hand-over on the vehicle's clock,
      so the same seed flies the same flight bit for bit; ``lockstep_spin_s``: how long the
      vehicle polls for the answer before it sleeps, which spares the bridge's send a wake-up of
      the vehicle: only the wait changes, never the flight; sim/vehicle/clock.py) or
      ``realtime`` (paced to ``realtime_speed`` x the wall clock).
    target_live: the bridge takes the moving target from the vehicle's MAVLink stream (the
      target is its own system ``target_system``: FOLLOW_TARGET + GLOBAL_POSITION_INT at
      ``target_rate_hz``) instead of its own copy of the scripted motion; ``target_feed``: a
      realistic feed instead (rate, noise, latency, drop-outs; :class:`TargetFeedConfig`).
    Starting state: trimmed level flight at ``initial_position_ned_m`` with heading
    ``initial_heading_rad`` (None: ``kinematic.initial_position_ned_m`` and the yaw of
    ``kinematic.initial_attitude_rpy_rad``, the state ``check`` uses), after ``trim_s`` of flight,
    in ``initial_mode``: ``hold`` (loiter about that point) or ``cruise`` (straight on).
    Atmosphere: steady ``wind_ned_m_s`` (air-mass velocity, blowing toward), Milspec Dryden
    ``turbulence`` (long gusts), ArduPilot SITL's high-frequency random wind
    ``wind_turbulence_m_s`` (its SIM_WIND_TURB), both seeded with ``seed`` (jsbsim only),
    one-minus-cosine ``gusts``.
    wind_estimate_tau_s: the wind the vehicle reports (WIND_COV / WIND) is a first-order lag of
      the true air-mass velocity with this time constant, as an autopilot's estimator follows
      it; 0 reports the truth, gusts included.
    """

    link: Literal["none", "udp"] = "none"
    plant: Literal["jsbsim", "kinematic"] = "jsbsim"
    flavour: Literal["px4", "ardupilot"] = "px4"
    clock: Literal["lockstep", "realtime"] = "lockstep"
    answer_timeout_s: float = field(default=0.05, metadata=_pos())
    lockstep_spin_s: float = field(
        default=0.0005,
        metadata=_rng(
            0.0, 0.01, "wall s the lockstep vehicle polls for the answer before it sleeps"
        ),
    )
    realtime_speed: float = field(default=1.0, metadata=_pos())
    port: int | None = field(default=None, metadata=_rng(1024, 65535, "null: a free one"))
    frame_period_s: float = field(default=0.02, metadata=_open(0.0, 0.5))
    physics_rate_hz: float = field(default=120.0, metadata=_rng(50.0, 1000.0))
    telemetry: TelemetryConfig = field(default_factory=TelemetryConfig)
    telemetry_latency_s: float = field(default=0.0, metadata=_nonneg())
    command_latency_s: float = field(default=0.0, metadata=_nonneg())
    # PX4 EKF2's wind states: a random walk of EKF2_WIND_NSD 0.05 m/s^2/sqrt(Hz) seen through
    # airspeed of EKF2_EAS_NOISE 1.4 m/s; fused at f Hz, a scalar Kalman filter's time constant is
    # 1.4 / (0.05 sqrt(f)): 8.9 s at 10 Hz, 4.0 s at 50 Hz; 6 s is f = 20 Hz
    wind_estimate_tau_s: float = field(
        default=6.0, metadata=_nonneg("lag of the reported wind; 0: the truth")
    )
    offboard_loss_timeout_s: float = field(default=1.0, metadata=_pos("PX4 COM_OF_LOSS_T"))
    guided_timeout_s: float = field(default=3.0, metadata=_pos("ArduPlane GUIDED_TIMEOUT"))
    loiter_radius_m: float = field(default=80.0, metadata=_pos())
    target_live: bool = True
    target_system: int = field(default=2, metadata=_rng(2, 255))
    target_rate_hz: float = field(default=10.0, metadata=_pos())
    target_feed: TargetFeedConfig | None = None
    target_type: Literal["rover", "boat"] = field(
        default="rover", metadata=_doc("the target's HEARTBEAT type")
    )
    initial_position_ned_m: Vec3 | None = None
    initial_heading_rad: float | None = None
    trim_s: float = field(default=12.0, metadata=_pos())
    initial_mode: Literal["hold", "cruise"] = field(
        default="hold",
        metadata=_doc(
            "hold: loiter (PX4 AUTO.LOITER, ArduPlane LOITER); cruise: course and altitude "
            "hold (POSCTL, CRUISE)"
        ),
    )
    wind_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    turbulence: Literal["none", "light", "moderate", "severe"] = "none"
    wind_turbulence_m_s: float = field(
        default=0.0,
        metadata=_nonneg(
            "ArduPilot SITL's SIM_WIND_TURB (m/s; 0: off): its random wind every physics step "
            "(sim/plant/sitl_turbulence.py), seeded with seed (jsbsim only)"
        ),
    )
    seed: int = field(
        default=0, metadata=_rng(0, 2**31 - 3, "JSBSim's noise engine takes seeds below 2^31 - 2")
    )
    gusts: list[GustEventConfig] = field(default_factory=list)
    home_lat_deg: float = field(default=47.397742, metadata=_rng(-90.0, 90.0))
    home_lon_deg: float = field(default=8.545594, metadata=_rng(-180.0, 180.0))
    home_alt_m: float = 488.0
    autopilot_profile: str | None = field(
        default=None,
        metadata=_doc(
            "the firmware's identified behaviour the vehicle emulates (sim/autopilot/profile.py): "
            "auto (the identified profile of sil.flavour, its autopilot part: SIH's thrust "
            "ceiling dropped), none (the plain emulation; as left out) or a file absolute, "
            "relative to the config file, or to the repository (configs/autopilots/*.yaml), "
            "applied as written"
        ),
    )

    def profile(self, src: str) -> ResolvedProfile | None:
        """The profile the vehicle flies (None: the plain emulation); ConfigError naming
        ``sil.autopilot_profile`` when it cannot be read."""
        if self.autopilot_profile is None or self.autopilot_profile == "none":
            return None  # the plain emulation: the profiles' module need not load
        from mpf_mavlink.config.autopilot_profile import resolve_profile

        base = Path(src).resolve().parent if src and not src.startswith("<") else None
        try:
            return resolve_profile(self.autopilot_profile, self.flavour, base)
        except ConfigError as e:
            raise _fail(src, "sil.autopilot_profile", str(e)) from None

    def profile_path(self, src: str) -> Path | None:
        """The profile's file (None: no profile)."""
        r = self.profile(src)
        return None if r is None else r.path

    def validate(self, src: str, target_type: str, m: MavlinkConfig) -> None:
        """Contradictions with ``target.type`` and the ``mavlink`` section."""
        if self.link == "none":
            return
        res = self.profile(src)
        if res is not None:
            want = "px4" if self.flavour == "px4" else "arduplane"
            if res.profile.autopilot != want:
                raise _fail(
                    src, "sil.autopilot_profile",
                    f"{res.path} is a {res.profile.autopilot} profile but sil.flavour is "
                    f"{self.flavour!r}",
                )  # fmt: skip
        if self.plant == "kinematic" and (
            self.turbulence != "none" or self.gusts or self.wind_turbulence_m_s > 0.0
        ):
            key = (
                "sil.turbulence"
                if self.turbulence != "none"
                else "sil.wind_turbulence_m_s"
                if self.wind_turbulence_m_s > 0.0
                else "sil.gusts"
            )
            raise _fail(
                src, key, "the kinematic plant has steady wind only (use sil.plant: jsbsim)"
            )
        for i, g in enumerate(self.gusts):
            if math.hypot(*g.direction_ned) < 1e-9:
                raise _fail(src, f"sil.gusts[{i}].direction_ned", "must not be zero")
        if target_type == "mavlink":
            raise _fail(
                src,
                "target.type",
                "the SIL vehicle publishes the scripted target: use stationary, constant_turn "
                "or paper",
            )
        if self.target_feed is not None and not self.target_live:
            raise _fail(src, "sil.target_feed", "needs sil.target_live: true")
        # `--set sil.flavour=X` alone switches the SIL's autopilot (schema._follow_sil_flavour
        # makes the bridge's flavour and hold mode follow it); set apart, they must agree
        if m.flavour not in ("auto", self.flavour):
            raise _fail(
                src, "mavlink.flavour", f"is {m.flavour!r} but sil.flavour is {self.flavour!r} "
                "(--set sil.flavour alone switches both)",
            )  # fmt: skip
        if m.hold_mode is not None:
            why = hold_mode_error(m.hold_mode, self.flavour)
            if why:
                raise _fail(src, "mavlink.hold_mode", f"{why} (sil.flavour is {self.flavour!r}; "
                            "--set sil.flavour alone switches both)")  # fmt: skip


@dataclass(frozen=True)
class ControlChannelConfig:
    """A JSBSim command property and its sign relative to the autopilot's convention (aileron > 0
    rolls right, elevator > 0 nose down, rudder > 0 yaws right, throttle 0..1).
    property None: the FlightGear/JSBSim standard ``fcs/<channel>-cmd-norm``."""

    property: str | None = None
    sign: float = field(default=1.0, metadata={"check": ("sign",), "doc": "1 or -1"})


@dataclass(frozen=True)
class ControlsConfig:
    """The JSBSim command of each control channel (:class:`ControlChannelConfig`)."""

    aileron: ControlChannelConfig = ControlChannelConfig()
    elevator: ControlChannelConfig = ControlChannelConfig()
    rudder: ControlChannelConfig = ControlChannelConfig()
    throttle: ControlChannelConfig = ControlChannelConfig()

    def mapping(self) -> dict[str, tuple[str, float]]:
        """Channel -> (JSBSim property, sign)."""
        return {
            ch: (c.property or f"fcs/{ch}-cmd-norm", c.sign)
            for ch, c in (
                ("aileron", self.aileron),
                ("elevator", self.elevator),
                ("rudder", self.rudder),
                ("throttle", self.throttle),
            )
        }


@dataclass(frozen=True)
class RateLoopConfig:
    """PX4-style rate loops (FW_RR_*, FW_PR_*, FW_YR_*): P, I, IMAX, FF per axis (None: the
    simulated autopilot's default, tuned for the shipped X8)."""

    roll_p: float | None = field(default=None, metadata=_nonneg())
    roll_i: float | None = field(default=None, metadata=_nonneg())
    roll_imax: float | None = field(default=None, metadata=_nonneg())
    roll_ff: float | None = field(default=None, metadata=_nonneg())
    pitch_p: float | None = field(default=None, metadata=_nonneg())
    pitch_i: float | None = field(default=None, metadata=_nonneg())
    pitch_imax: float | None = field(default=None, metadata=_nonneg())
    pitch_ff: float | None = field(default=None, metadata=_nonneg())
    yaw_p: float | None = field(default=None, metadata=_nonneg())
    yaw_i: float | None = field(default=None, metadata=_nonneg())
    yaw_imax: float | None = field(default=None, metadata=_nonneg())
    yaw_ff: float | None = field(default=None, metadata=_nonneg())


@dataclass(frozen=True)
class AttitudeLoopConfig:
    """PX4 attitude loop (FW_R_TC, FW_P_TC, FW_*_RMAX, FW_R_LIM) and the hold modes' pitch trim
    and bank limit (None: the simulated autopilot's default)."""

    roll_tc_s: float | None = field(default=None, metadata=_pos())
    pitch_tc_s: float | None = field(default=None, metadata=_pos())
    roll_rate_max_rad_s: float | None = field(default=None, metadata=_pos())
    pitch_rate_max_rad_s: float | None = field(default=None, metadata=_pos())
    yaw_rate_max_rad_s: float | None = field(default=None, metadata=_pos())
    bank_max_rad: float | None = field(default=None, metadata=_open(0.0, 1.5))
    pitch_trim_rad: float | None = field(default=None, metadata=_rng(-0.5, 0.5))


@dataclass(frozen=True)
class AircraftConfig:
    """The JSBSim aircraft of the SIL vehicle (``sil.plant: jsbsim``).

    model: aircraft name (``<root>/aircraft/<model>/<model>.xml``); root_dir: None = the shipped
    ``sim/jsbsim_root`` (Skywalker X8), ``jsbsim`` = the aircraft shipped in the jsbsim package
    (c172x, J3Cub, ...), or a directory (relative paths: to the config file) with ``aircraft/``,
    ``engine/`` (and ``systems/``). trim_airspeed_m_s: cruise / hold airspeed, and where the
    rate loops' airspeed scaling is 1. trim_throttle: first guess for the trim flight (the trim
    found by flying replaces it). trim_from_fdm: take trim_throttle and the hold modes' pitch
    trim from JSBSim's own trim (``simulation/do_simple_trim``) at trim_airspeed_m_s and the
    start altitude instead (sim/plant/airframe_trim.py). gains_from_fdm: derive the rate
    loops' gains and surface trims (and the throttle and pitch trim) from a short
    identification of the FDM at trim_airspeed_m_s (sim/plant/airframe_ident.py); rate_loop
    entries given still win.
    airspeed_min_m_s / airspeed_max_m_s: the rate loops' scaling
    limits (FW_AIRSPD_MIN / MAX). controls: command properties and signs.
    """

    model: str = "x8"
    root_dir: str | None = None
    trim_airspeed_m_s: float = field(default=16.0, metadata=_pos())
    trim_throttle: float = field(default=0.3, metadata=_rng(0.0, 1.0))
    trim_from_fdm: bool = False
    gains_from_fdm: bool = False
    airspeed_min_m_s: float | None = field(default=None, metadata=_pos())
    airspeed_max_m_s: float | None = field(default=None, metadata=_pos())
    controls: ControlsConfig = field(default_factory=ControlsConfig)
    rate_loop: RateLoopConfig = field(default_factory=RateLoopConfig)
    attitude_loop: AttitudeLoopConfig = field(default_factory=AttitudeLoopConfig)

    def resolved_root(self, src: str) -> Path | None:
        """The JSBSim root directory (None: the shipped one)."""
        if self.root_dir is None:
            return None
        if self.root_dir == "jsbsim":
            import jsbsim

            return Path(jsbsim.get_default_root_dir())
        p = Path(self.root_dir).expanduser()
        if not p.is_absolute() and src and not src.startswith("<"):
            p = Path(src).resolve().parent / p
        return p

    def validate(self, src: str, sil: SilConfig) -> None:
        if sil.link == "none" or sil.plant != "jsbsim":
            return
        root = self.resolved_root(src)
        if root is not None and not root.is_dir():
            raise _fail(src, "aircraft.root_dir", f"{root} is not a directory")
        if root is None:
            root = _REPO / "sim" / "jsbsim_root"
        xml = root / "aircraft" / self.model / f"{self.model}.xml"
        if not xml.is_file():
            raise _fail(src, "aircraft.model", f"no JSBSim aircraft {xml}")
        for ch in ("aileron", "elevator", "rudder", "throttle"):
            if getattr(self.controls, ch).property == "":
                raise _fail(src, f"aircraft.controls.{ch}.property", "must name a JSBSim property")
        lo, hi = self.airspeed_min_m_s, self.airspeed_max_m_s
        if lo is not None and lo >= self.trim_airspeed_m_s:
            raise _fail(src, "aircraft.airspeed_min_m_s", "must be below trim_airspeed_m_s")
        if hi is not None and hi <= self.trim_airspeed_m_s:
            raise _fail(src, "aircraft.airspeed_max_m_s", "must be above trim_airspeed_m_s")
