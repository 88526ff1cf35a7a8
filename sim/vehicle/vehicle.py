"""A simulated fixed-wing MAVLink vehicle (PX4 or ArduPlane flavour) for software-in-the-loop runs.

:class:`SimVehicle` composes a plant (:class:`sim.plant.jsbsim_plant.JSBSimPlant` by default, or
the cheap :class:`sim.plant.kinematic_plant.KinematicMavPlant`), the autopilot emulation
(:class:`sim.autopilot.emulation.AutopilotEmulation` around the inner loops of
:class:`sim.autopilot.inner_loop.FixedWingAutopilot`), a MAVLink endpoint on ONE pymavlink
connection (:class:`sim.vehicle.link.Link`, ``udpin:`` - it listens and answers whoever wrote last,
``udpout:`` or ``tcpin:``; :class:`sim.vehicle.telemetry.Telemetry`; the target's own system;
:class:`sim.vehicle.gcs_services.GcsServices`) and clocks (:class:`sim.vehicle.clock.StepClock`,
a pacing clock), all built from one :class:`sim.vehicle.config.VehicleConfig`. It is a separate
MAVLink peer and does not use :mod:`mpf_mavlink.mavlink`'s link.

Identity: system 1 / component 1, HEARTBEAT type MAV_TYPE_FIXED_WING, autopilot PX4 (12) or
ARDUPILOTMEGA (3), base_mode CUSTOM_MODE_ENABLED (+ SAFETY_ARMED when armed, + STABILIZE /
GUIDED / AUTO flags by mode), custom_mode PX4 ``(main << 16) | (sub << 24)`` or the ArduPlane
mode number. Power-on: armed, trimmed level flight (``fly_to_trim``), in Hold (PX4 AUTO.LOITER)
or LOITER (ArduPlane 12), circling about the position where the mode was entered.

Sim time: ``t`` (s) is 0 when :class:`SimVehicle` is ready (after the trim flight); the MAVLink
boot clock ``time_boot_ms`` counts the trim flight too (``time_boot_s = t + t_trim``), so it never
reads 0. ``time_usec`` fields use the same boot clock; SYSTEM_TIME's ``time_unix_usec`` is the
wall time at construction plus the boot clock. The moving target's motion is evaluated at ``t``.

Rules honoured (PX4 v1.16 commander and mavlink receiver, ArduPlane 4.7 GCS_MAVLink):

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
from collections.abc import Callable
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("JSBSIM_DEBUG", "0")


from sim.autopilot.emulation import AutopilotEmulation  # noqa: E402
from sim.autopilot.inner_loop import FixedWingAutopilot, fly_to_trim  # noqa: E402
from sim.autopilot.modes import Tunables  # noqa: E402
from sim.plant.kinematic_plant import KinematicMavPlant  # noqa: E402
from sim.plant.protocol import Plant  # noqa: E402
from sim.vehicle.clock import LockstepClock, StepClock, make_clock  # noqa: E402
from sim.vehicle.config import VehicleConfig  # noqa: E402
from sim.vehicle.dispatch import Dispatcher  # noqa: E402
from sim.vehicle.gcs_services import GcsServices  # noqa: E402
from sim.vehicle.link import Link  # noqa: E402
from sim.vehicle.lockstep import Lockstep  # noqa: E402
from sim.vehicle.target_stream import TargetStream  # noqa: E402
from sim.vehicle.telemetry import Telemetry  # noqa: E402
from sim.vehicle.truth import TruthRecorder  # noqa: E402

# what the vehicle acts on (through the incoming delay queue); the rest is dropped on arrival
_QUEUED = (
    frozenset(("COMMAND_LONG", "COMMAND_INT", "SET_MODE", "TIMESYNC", "REQUEST_DATA_STREAM"))
    | GcsServices.HANDLES
)


def plant_kwargs(
    cfg: VehicleConfig, position_ned: tuple[float, ...], heading: float, airspeed: float
) -> dict[str, Any]:
    """A plant's constructor arguments for ``cfg``, starting at ``position_ned`` (m),
    ``heading`` (rad), ``airspeed`` (m/s): a whole number of physics steps per frame, no
    longer than 1 / physics_rate_hz each."""
    n_sub = max(1, math.ceil(cfg.frame_period * cfg.physics_rate_hz - 1e-9))
    return dict(
        dt=cfg.frame_period / n_sub,
        lat0_deg=cfg.lat0_deg,
        lon0_deg=cfg.lon0_deg,
        alt0_m=cfg.alt0_m,
        position_ned=position_ned,
        heading=heading,
        airspeed=airspeed,
        **cfg.plant_options,
    )


def build_plant(cfg: VehicleConfig) -> tuple[Plant, Any, Any]:
    """The plant, trimmed where ``cfg`` asks: (plant, trim result or None, inner-loop autopilot).
    The plant starts behind the requested point along the ground track (heading + wind), so the
    trim flight ends about there whatever the wind."""
    heading, v = float(cfg.heading), float(cfg.airspeed)
    pos, wind = np.asarray(cfg.position_ned, float), np.asarray(cfg.wind_ned, float)
    ground = v * np.array([math.cos(heading), math.sin(heading), 0.0]) + (wind[0], wind[1], 0.0)
    shift = ground * cfg.trim_seconds
    plant = cfg.plant
    if isinstance(plant, str):
        kw = plant_kwargs(cfg, tuple(pos - shift), heading, v)
        if plant == "jsbsim":
            from sim.plant.jsbsim_plant import JSBSimPlant

            plant = JSBSimPlant(**kw)
        else:
            plant = KinematicMavPlant(**kw)
    if np.any(wind != 0.0):
        plant.set_wind(wind)
    if cfg.turbulence != "none":
        plant.set_turbulence(cfg.turbulence, cfg.seed)
    if cfg.wind_turbulence_m_s > 0.0:
        if not plant.has_random_wind:
            raise ValueError("wind_turbulence_m_s: the plant has no random wind (use jsbsim)")
        plant.set_random_wind(cfg.wind_turbulence_m_s, cfg.seed)
    ap = cfg.autopilot or FixedWingAutopilot()
    if isinstance(plant, KinematicMavPlant):
        ap.hold.gains.pitch_trim = 0.0  # no angle of attack in the kinematic model
    trim = None
    if cfg.trim_seconds > 0:
        track = math.atan2(shift[1], shift[0]) if np.hypot(shift[0], shift[1]) > 0 else heading
        trim = fly_to_trim(plant, ap, v, float(-pos[2]), seconds=cfg.trim_seconds, course=track)
    return plant, trim, ap


def tunables(cfg: VehicleConfig) -> Tunables:
    """The in-flight tunables at boot. The cruise airspeed is the trim clamped to min..max (the
    firmware's defaults widened to take the trim)."""
    v = float(cfg.airspeed)
    return Tunables(
        com_of_loss_t=float(cfg.com_of_loss_t),
        guided_timeout=float(cfg.guided_timeout),
        loiter_radius=float(cfg.loiter_radius),
        loiter_direction=1 if cfg.loiter_direction >= 0 else -1,
        cruise_airspeed=v,
        airspeed_trim=v,
        airspeed_min=min(10.0, v),
        airspeed_max=max(20.0 if cfg.flavour == "px4" else 30.0, v),
        px4_require_thrust=bool(cfg.px4_require_thrust),
    )


def _initial_mode(modes: Any, cfg: VehicleConfig) -> None:
    """The mode the vehicle boots in (cruise or hold), silently."""
    (modes.cruise if cfg.initial_mode == "cruise" else modes.hold)(announce=False)
    if cfg.initial_orbit is not None and cfg.initial_mode == "hold":
        # the operator parked the aircraft in an orbit before the mission (DO_REPOSITION with
        # a loiter radius, or a loiter mission item): the boot hold circles (north, east) at
        # that radius; any later hold entry loiters where it happens, as stock
        n, e, r = cfg.initial_orbit
        modes.center, modes.hold_radius = (float(n), float(e)), float(r)


def _link(cfg: VehicleConfig, clock: StepClock, lockstep: Lockstep, lockstep_clock: bool) -> Link:
    """The vehicle's MAVLink link (``lockstep_clock``: the clock is the lockstep one)."""
    link = Link(cfg.url, int(cfg.system_id), int(cfg.component_id),
                (int(cfg.target_system), int(cfg.target_component)), clock, lockstep,
                telemetry_latency_s=cfg.telemetry_latency_s,
                command_latency_s=cfg.command_latency_s, lockstep_clock=lockstep_clock,
                accept=_QUEUED)  # fmt: skip
    link.commands_on_answers = cfg.lockstep_from_connect and lockstep_clock
    return link


class SimVehicle:
    """A fixed-wing MAVLink vehicle around a plant and the emulated autopilot (module docstring).

    Drive it with :meth:`run` (clock-paced), :meth:`step_once` (one frame, no waiting; call
    :meth:`poll` in between if you like) or :meth:`start_in_thread` / :meth:`stop`.
    """

    def __init__(self, config: VehicleConfig) -> None:
        cfg = self.config = config
        self.flavour, self.px4 = cfg.flavour, cfg.flavour == "px4"
        self.sysid, self.compid = int(cfg.system_id), int(cfg.component_id)
        self.plant, self.trim, inner = build_plant(cfg)
        self.dt = float(self.plant.dt)
        self.n_sub = max(1, int(round(cfg.frame_period / self.dt)))
        self.frame_period = self.n_sub * self.dt
        self.origin = self.plant.origin
        self.home_lla = (self.origin.lat0_deg, self.origin.lon0_deg, self.origin.alt0_m)
        self.steady_wind = tuple(float(w) for w in cfg.wind_ned)
        # one-minus-cosine gusts: (t_start, trigger_gust kwargs), t in sim s after ready
        self._gusts = sorted((float(g["start_s"]), {k: x for k, x in g.items() if k != "start_s"})
                             for g in cfg.gusts)  # fmt: skip
        self.time = StepClock(self.dt, int(round(self.plant.t / self.dt)))
        # a peer in lockstep throughout is waited for through its slow steps (the checks, a
        # first import on a loaded host): a frame let go unanswered would change the flight
        answered_s = 5.0 if cfg.lockstep_from_connect else 1.0
        self.clock = make_clock(cfg.clock, answer_timeout_s=cfg.answer_timeout_s,
                                answered_timeout_s=answered_s, spin_s=cfg.lockstep_spin_s,
                                speed=cfg.realtime_speed)  # fmt: skip
        self.lockstep = Lockstep(self.frame_period, cfg.command_latency_s, cfg.lockstep_overlap,
                                 modes_end_waits=not cfg.lockstep_from_connect)  # fmt: skip
        self.link = _link(cfg, self.time, self.lockstep, self.clock.mode == "lockstep")
        if isinstance(self.clock, LockstepClock):
            self.clock.ready = self.link.readable
        self.tun = tunables(cfg)
        self.autopilot = AutopilotEmulation(self.px4, inner, self.dt, self.tun, self.time,
                                            self.link, self.plant.state, self.home_lla)  # fmt: skip
        self.modes = self.autopilot.modes
        _initial_mode(self.modes, cfg)
        self.telemetry = Telemetry(self.px4, cfg.telemetry_rates(), self.time, self.link,
                                   self.home_lla, self.frame_period,
                                   lambda: (self.modes.base_mode(), self.modes.custom_mode),
                                   lambda: self.autopilot.setpoints.echo)  # fmt: skip
        self.telemetry.wind.tau_s = float(cfg.wind_estimate_tau_s)
        self.gcs = GcsServices(self)
        self.telemetry.on_version = self.gcs.send_autopilot_version
        self.dispatch = Dispatcher(self.sysid, self.autopilot, self.telemetry, self.gcs,
                                   self.link, self.time)  # fmt: skip
        self.link.on_new_peer = self._new_peer
        self.link.on_epoch = self._take_epoch
        self.target = None if cfg.target is None else TargetStream(
            cfg.target, self.time, self.link, self.origin, self.home_lla[2], cfg.target_rate_hz,
            cfg.target_type == "boat", cfg.target_epoch == "bridge", cfg.target_feed,
            cfg.target_epoch_unix_s)  # fmt: skip
        self.truth_record = TruthRecorder(cfg.record_truth)
        self.profile: Any = None  # the firmware's identified behaviour (see use_profile)
        self.estimate: Any = None  # truth PlantState -> the state the autopilot has (a profile's)
        self._truth_st = self._st = self.plant.state()
        self.telemetry.st = self._st
        self._rates = self.plant.rates_airspeed()  # (p, q, r) rad/s, airspeed m/s: rate loops
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.wall_time_running = 0.0  # wall seconds spent in run()
        self.sim_time_running = 0.0  # sim seconds advanced in run()
        self._record()

    @classmethod
    def build(
        cls, flavour: str = "px4", url: str = "udpin:127.0.0.1:14540", **kw: Any
    ) -> SimVehicle:
        """``SimVehicle(VehicleConfig(flavour, url, **kw))``."""
        return cls(VehicleConfig(flavour=flavour, url=url, **kw))

    # ------------------------------------------------------------------ views
    @property
    def t(self) -> float:
        """Simulated time (s) since the vehicle was ready (0 after the trim flight)."""
        return self.time.t

    @property
    def time_boot_s(self) -> float:
        """The MAVLink boot clock (s): includes the trim flight."""
        return self.time.boot_s

    @property
    def mode_name(self) -> str:
        return self.modes.name

    @property
    def custom_mode(self) -> int:
        return self.modes.custom_mode

    @property
    def real_time_factor(self) -> float:
        """Sim seconds per wall second spent in :meth:`run` so far."""
        wall = self.wall_time_running
        return self.sim_time_running / wall if wall > 0 else float("nan")

    def truth(self) -> dict[str, np.ndarray]:
        """The plant's truth at frame rate (:meth:`sim.vehicle.truth.TruthRecorder.truth`)."""
        tgt = self.target
        epoch = tgt.epoch_boot_s if tgt is not None else self.time.ready_boot_s
        return self.truth_record.truth(self.config.target, epoch)

    # ------------------------------------------------------------------ the autopilot's view
    def observe(self) -> Any:
        """The plant's state as the autopilot has it (the truth without a profile)."""
        st = self._truth_st = self.plant.state()
        self._st = st if self.estimate is None else self.estimate(st)
        self.telemetry.st = self._st
        return self._st

    def _record(self) -> None:
        self.truth_record.record(
            self.time.t, self.time.boot_s, self._truth_st, self.modes.custom_mode
        )

    # ------------------------------------------------------------------ input
    def poll(self, timeout: float = 0.0) -> bool:
        """Read incoming MAVLink (waiting up to ``timeout`` wall s); True once the answer the
        lockstep awaits has arrived."""
        return self.link.poll(timeout)

    def has_peer(self) -> bool:
        return self.link.has_peer()

    def _new_peer(self) -> None:
        # a new peer hears who we are first: before our next 1 Hz HEARTBEAT a ground station
        # would take the target's (system 2) 10 Hz positions for the vehicle's
        self.telemetry.next.pop("heartbeat", None)

    def _take_epoch(self, msg: Any) -> None:
        if self.target is not None:
            self.target.take_epoch(msg)
            if self.target.epoch_changed:
                self.target.epoch_changed = False
                self.truth_record.forget_target()  # truth() recomputes them on the new clock

    def _apply_due(self) -> None:
        q, t, handle = self.link.incoming, self.time.boot_s + 1e-9, self.dispatch
        while q and q[0][0] <= t:
            handle(q.popleft()[1])

    # ------------------------------------------------------------------ stepping
    def step_once(self) -> float:
        """One frame: read pending input (no waiting), apply due commands, ``n_sub`` physics
        steps, due telemetry, truth. Returns the sim time ``t``.

        The frame's telemetry leaves in one datagram (PX4 sends one per cycle too), with
        LOCAL_POSITION_NED and ATTITUDE first: a peer that reads messages in order and acts on
        ATTITUDE (the bridge answers each one with a setpoint) starts on it with the position
        and velocity of the same instant, before it parses the slower streams behind it. A
        velocity one frame old would not do: the bridge's wind frame is the direction of ground
        velocity - wind, and 20 ms more lag in it costs the demo's tight guidance gains a
        factor 2-3 in tracking error. One datagram instead of two saves a send here and a
        wake-up and a read in the peer every frame."""
        link = self.link
        if not link.drained:
            link.poll(0.0)
        link.drained = False
        incoming = link.incoming
        if incoming:
            self._apply_due()
        ape, clock, dt = self.autopilot, self.time, self.dt
        step, offboard_rates = self.plant.step_rates, ape.offboard_rates
        rates, fresh = self._rates, True  # fresh: self._st is the state now
        last = self.n_sub - 1
        for i in range(self.n_sub):
            fast = offboard_rates(clock.boot_s)
            if fast is not None:
                # PX4 offboard body rates: the rate loops read only p, q, r and the airspeed,
                # so the full state (geodetic conversion, matrices) is not needed here
                a, e, r = ape.ap.rates_to_surfaces(dt, fast[0], rates, rates[3])
                rates = step(a, e, r, fast[1])
            else:
                rates = step(*ape.control(self._st if fresh else self.observe()))
            clock.advance()
            fresh = False
            # what falls due at the frame's end acts from the next frame's start (the same
            # physics), whether it was read before this frame or during the lockstep wait
            if incoming and i < last:
                self._apply_due()
        self._rates = rates
        plant = self.plant
        self.observe()
        tel = self.telemetry
        if tel.due("attitude", tel.rates.attitude):
            if tel.due("local_position", tel.rates.local_position):
                tel.local_position()
            tel.attitude()
        if self._gusts and self.time.t + 1e-9 >= self._gusts[0][0]:
            plant.trigger_gust(**self._gusts.pop(0)[1])
        tel.slow_streams()
        if self.target is not None:
            self.target.frame()
        self.link.flush()
        self._record()
        return self.time.t

    def run(self, duration_s: float) -> None:
        """Advance ``duration_s`` of sim time, paced by the clock (lockstep or realtime)."""
        clock = self.time
        end_k = clock.k + int(round(duration_s / self.dt)) if math.isfinite(duration_s) else None
        w0, k0 = time.perf_counter(), clock.k
        self.clock.start(clock.boot_s)
        try:
            peer, poll = _pacing(self)
            if self.config.lockstep_from_connect and self.clock.mode == "lockstep":
                # the peer's arrival is a wall-clock instant: the vehicle waits for it rather
                # than fly on, so the hand-over starts from the same state every time
                while not self._stop.is_set() and not self.has_peer():
                    self.link.poll(0.01)
            while not self._stop.is_set() and (end_k is None or clock.k < end_k):
                self.step_once()
                self.clock.wait(clock.boot_s, poll, peer)
        finally:
            self.wall_time_running += time.perf_counter() - w0
            self.sim_time_running += (clock.k - k0) * self.dt

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
        self.link.close()

    def __enter__(self) -> SimVehicle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _pacing(v: SimVehicle) -> tuple[Callable[[], bool], Callable[[float], bool]]:
    """How :meth:`SimVehicle.run` waits on its peer: (whether the clock counts the peer as
    present, the poll it waits with).

    With ``realtime_until_engaged`` the lockstep clock treats the peer as present only while it
    commands the vehicle (OFFBOARD / GUIDED). Until the bridge has taken control its hand-over
    rules run on wall-clock timers (>= 1 s of setpoints at >= 20 Hz before the mode request)
    while the autopilot's run on vehicle time; pacing that phase at real time keeps both in one
    time base, so the engagement happens after the same simulated time whatever the clock
    (lockstep and realtime runs start tracking from the same state). In lockstep from the
    connection on, the poll comes in slices of 50 ms that a :meth:`SimVehicle.stop` ends: a peer
    gone for good (the bridge done) is not waited for the full lockstep timeout."""
    if v.config.lockstep_from_connect and v.clock.mode == "lockstep":
        return v.has_peer, lambda timeout: v.link.poll(min(timeout, 0.05)) or v._stop.is_set()
    if v.config.realtime_until_engaged:
        engaged = ("offboard", "guided")
        return (lambda: v.modes.behaviour in engaged and v.link.has_peer()), v.link.poll
    return v.has_peer, v.link.poll


def use_profile(
    v: SimVehicle, profile: Any, seed: int = 0, full_thrust_throttle: float | None = None
) -> None:
    """Make ``v`` emulate ``profile`` (an :class:`sim.autopilot.profile.AutopilotProfile`):
    the reported (and controlled-on) state passes through its estimator model, the attitude
    set-points through its attitude response; the truth record stays the plant's.
    ``full_thrust_throttle``: the plant throttle that offboard thrust 1 maps to (the plant's
    level throttle at the profile's full-thrust airspeed; None: the cubic estimate)."""
    from sim.autopilot.profile import AttitudeShaper, RateWander, StateEstimate, thrust_scale

    ape = v.autopilot
    v.profile = profile
    v.estimate = StateEstimate(profile, seed)
    if profile.attitude.roll_rate_wander_rad_s:
        ape.wander = RateWander(profile.attitude, v.dt, seed)
    ape.shaper = AttitudeShaper(profile.attitude, v.dt, native_tau_s=ape.ap.attitude.gains.roll_tc)
    if full_thrust_throttle is not None:
        ape.thrust_scale = min(1.0, float(full_thrust_throttle))
    elif v.trim is not None:
        ape.thrust_scale = thrust_scale(profile.thrust, v.trim.throttle, v.tun.cruise_airspeed)
    ape.airspeed_scale = profile.estimator.airspeed_scale  # the report only (calib, issue 24)
    if profile.estimator.wind_tau_s is not None:
        v.telemetry.wind.tau_s = 0.0  # the profile's estimate carries its own lag
    v.observe()


__all__ = ["SimVehicle", "VehicleConfig", "build_plant", "tunables", "use_profile"]
