"""What one SIL vehicle is built from: :class:`VehicleConfig` (one typed record, read by every
piece) and the telemetry rates of each flavour (:class:`TelemetryRates`, :func:`stock_rates`).

A config file becomes a :class:`VehicleConfig` through :func:`sim.sil.vehicle_config`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

FLAVOURS = ("px4", "ardupilot")


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


@dataclass
class VehicleConfig:
    """Everything a :class:`sim.vehicle.vehicle.SimVehicle` is built from. SI units, NED, rad;
    times in simulated seconds unless they say wall."""

    flavour: str = "px4"  # "px4" or "ardupilot": the rules and messages emulated
    url: str = "udpin:127.0.0.1:14540"  # the pymavlink connection (udpin, udpout, tcpin)
    # plant: "jsbsim", "kinematic" or a plant object (dt, step, state, origin, t)
    plant: Any = "jsbsim"
    plant_options: dict[str, Any] = field(default_factory=dict)  # more plant constructor args
    physics_rate_hz: float = 120.0  # physics steps at least this often
    frame_period: float = 0.02  # one telemetry frame (s): the lockstep unit
    clock: Any = "lockstep"  # "lockstep", "realtime" or a clock object (sim.vehicle.clock)
    # lockstep: wall s to wait for the bridge's answer (1 s after a frame it answered: clock.py)
    answer_timeout_s: float = 0.05
    # lockstep: wall s to poll for the answer before sleeping (0: sleep at once; clock.py)
    lockstep_spin_s: float = 0.0
    # lockstep: await only the answer that acts in the next frame (with a command latency of a
    # frame or more an earlier frame's, so the peer computes while the vehicle steps); False:
    # the answer to the telemetry just written (strict alternation: the same flight, slower)
    lockstep_overlap: bool = True
    realtime_speed: float = 1.0  # realtime clock: times real time
    # pace at real time until the bridge commands the vehicle (see sim.vehicle.vehicle._pacing)
    realtime_until_engaged: bool = False
    # lockstep from the peer's first message on, in every phase (a peer that answers every
    # ATTITUDE, with a setpoint or a clock answer: the bridge with mavlink.lockstep): no frame
    # advances before a peer is there, nor unanswered, so the hand-over runs on vehicle time
    lockstep_from_connect: bool = False
    # the point (m NED about home) and heading (rad) where the trim flight ends, its airspeed
    position_ned: tuple[float, float, float] = (0.0, 0.0, -100.0)
    heading: float = 0.0
    airspeed: float = 16.0
    trim_seconds: float = 12.0  # the trim flight before the vehicle is ready (0: none)
    lat0_deg: float = 47.397742  # home (PX4 SITL's)
    lon0_deg: float = 8.545594
    alt0_m: float = 488.0
    wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)  # steady air-mass velocity (m/s)
    turbulence: str = "none"  # none, light, moderate, severe (JSBSim Dryden)
    # ArduPilot SITL's SIM_WIND_TURB (m/s): its random wind every physics step (jsbsim only)
    wind_turbulence_m_s: float = 0.0
    seed: int = 0
    # one-minus-cosine gusts: {"start_s": s after ready, **JSBSimPlant.trigger_gust kwargs}
    gusts: list[dict[str, Any]] = field(default_factory=list)
    # the autopilot
    autopilot: Any = None  # a sim.autopilot.inner_loop.FixedWingAutopilot (None: its defaults)
    initial_mode: str = "hold"  # "hold" (loiter) or "cruise" (course + altitude hold)
    initial_orbit: tuple[float, float, float] | None = None  # boot hold (north, east, radius m)
    com_of_loss_t: float = 1.0  # PX4 COM_OF_LOSS_T: offboard setpoint loss -> Hold
    guided_timeout: float = 3.0  # ArduPlane GUIDED forced-axis timeout
    loiter_radius: float = 80.0
    loiter_direction: int = 1  # 1 clockwise, -1 counter-clockwise
    px4_require_thrust: bool = False  # PX4: setpoints ignoring thrust are not offboard signal
    # the reported wind lags the truth by this first-order time constant (0: the truth)
    wind_estimate_tau_s: float = 0.0
    # the link
    system_id: int = 1
    component_id: int = 1
    rates: TelemetryRates | dict[str, float | None] | None = None  # None: the stock rates
    telemetry_latency_s: float = 0.0  # outgoing delay queue
    command_latency_s: float = 0.0  # incoming delay queue
    # the moving target, its own MAVLink system: motion.state(t) (mpf_mavlink.core.target)
    target: Any = None
    target_system: int = 2
    target_component: int = 1
    target_type: str = "rover"  # "rover" or "boat" (its HEARTBEAT type)
    target_rate_hz: float = 10.0
    # the target's t = 0: "ready" (the vehicle's), "bridge" (the STATUSTEXT MPF t0= it sends)
    # or "unix" (target_epoch_unix_s, a fleet's common epoch; a realtime clock only)
    target_epoch: str = "ready"
    target_epoch_unix_s: float | None = None
    target_feed: dict[str, Any] | None = None  # a realistic feed (sim.target.feed) instead
    record_truth: bool = True  # one truth row per frame (SimVehicle.truth)

    def __post_init__(self) -> None:
        if self.flavour not in FLAVOURS:
            raise ValueError("flavour must be 'px4' or 'ardupilot'")
        if self.initial_mode not in ("hold", "cruise"):
            raise ValueError("initial_mode must be 'hold' or 'cruise'")
        if self.target_epoch not in ("ready", "bridge", "unix"):
            raise ValueError("target_epoch must be 'ready', 'bridge' or 'unix'")
        if (self.target_epoch == "unix") != (self.target_epoch_unix_s is not None):
            raise ValueError("target_epoch 'unix' goes with target_epoch_unix_s (and only it)")
        if self.target_epoch == "unix" and self.clock != "realtime":
            raise ValueError("target_epoch 'unix' needs the realtime clock (Unix time is wall)")
        if isinstance(self.plant, str) and self.plant not in ("jsbsim", "kinematic"):
            raise ValueError("plant must be 'jsbsim', 'kinematic' or a plant object")
        if not self.wind_turbulence_m_s >= 0.0:  # NaN too
            raise ValueError("wind_turbulence_m_s must be >= 0 m/s")

    def telemetry_rates(self) -> TelemetryRates:
        """The rates to start with: the flavour's stock rates, overridden where given."""
        stock = stock_rates(self.flavour)
        if isinstance(self.rates, TelemetryRates):
            return dataclasses.replace(self.rates)
        if not self.rates:
            return stock
        unknown = set(self.rates) - {f.name for f in dataclasses.fields(TelemetryRates)}
        if unknown:
            raise ValueError(f"unknown telemetry stream(s) {sorted(unknown)}")
        given = {k: v for k, v in self.rates.items() if v is not None}
        return dataclasses.replace(stock, **given)
