"""A simulated fixed-wing MAVLink vehicle (PX4 or ArduPlane flavour) for software-in-the-loop runs.

:class:`SimVehicle` owns a plant (:class:`sim.plant.jsbsim_plant.JSBSimPlant` by default, or the cheap
:class:`sim.plant.kinematic_plant.KinematicMavPlant`), the simulated autopilot
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
import threading
import time
from typing import Any

from sim.autopilot.emulation import AutopilotEmulation
from sim.vehicle.base import (
    ARDUPLANE_MODES,
    OFFBOARD,
    PX4_AUTO_SUB,
    PX4_MAIN,
    TelemetryRates,
    px4_custom_mode,
    px4_decode_custom_mode,
)


class SimVehicle(AutopilotEmulation):
    """A fixed-wing MAVLink vehicle around a plant and the simulated autopilot (module docstring).

    Drive it with :meth:`run` (clock-paced), :meth:`step_once` (one frame, no waiting; call
    :meth:`poll` in between if you like) or :meth:`start_in_thread` / :meth:`stop`.
    """

    # the firmware's identified behaviour (sim/autopilot_profile.py): None = the plain emulation
    profile: Any = None
    _estimate: Any = None  # truth PlantState -> the state the autopilot reports and controls on
    _shaper: Any = None  # the attitude set-point as the firmware's loop would fly it
    _truth_st: Any = None
    _wander: Any = None  # the profile's slow roll-rate error of body-rate offboard
    thrust_scale = 1.0  # plant throttle per unit of offboard thrust (profile.thrust)

    def use_profile(
        self, profile: Any, seed: int = 0, full_thrust_throttle: float | None = None
    ) -> None:
        """Emulate ``profile`` (an :class:`sim.autopilot_profile.AutopilotProfile`) from now on:
        the reported (and controlled-on) state passes through its estimator model, the attitude
        set-points through its attitude response; the truth record stays the plant's.
        ``full_thrust_throttle``: the plant throttle that offboard thrust 1 maps to (the plant's
        level throttle at the profile's full-thrust airspeed; None: the cubic estimate)."""
        from sim.autopilot_profile import AttitudeShaper, RateWander, StateEstimate, thrust_scale

        self.profile = profile
        self._estimate = StateEstimate(profile, seed)
        if profile.attitude.roll_rate_wander_rad_s:
            self._wander = RateWander(profile.attitude, self.dt, seed)
        self._shaper = AttitudeShaper(
            profile.attitude, self.dt, native_tau_s=self.ap.attitude.gains.roll_tc
        )
        if full_thrust_throttle is not None:
            self.thrust_scale = min(1.0, float(full_thrust_throttle))
        elif self.trim is not None:
            self.thrust_scale = thrust_scale(
                profile.thrust, self.trim.throttle, self.cruise_airspeed
            )
        if profile.estimator.wind_tau_s is not None:
            self.wind_estimate_tau_s = 0.0  # the profile's estimate carries its own lag
        self._truth_st = self.plant.state()
        self._st = self._estimate(self._truth_st)

    def _observe(self) -> Any:
        """The plant's state as the autopilot has it (the truth without a profile)."""
        st = self.plant.state()
        if self._estimate is None:
            return st
        self._truth_st = st
        return self._estimate(st)

    def _record(self) -> None:
        truth = self._truth_st
        if truth is None or self._estimate is None:
            super()._record()
            return
        est, self._st = self._st, truth  # the record is the plant's truth, not the estimate
        try:
            super()._record()
        finally:
            self._st = est

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
                rsp = sp[1]
                if self._wander is not None:
                    rsp = (rsp[0] + self._wander(), rsp[1], rsp[2])
                a, e, r = ap.rates_to_surfaces(dt, rsp, rates, rates[3])
                cmd = (a, e, r, sp[2] * self.thrust_scale if self.armed else 0.0)
            else:
                if not fresh:
                    self._st = self._observe()
                cmd = self._control(self._st)
            plant.step(*cmd)
            self._k += 1
            rates, fresh = self._rates_fn(), False
            # what falls due at the frame's end acts from the next frame's start (the same
            # physics), whether it was read before this frame or during the lockstep wait
            if self._in and i < last:
                self._apply_due()
        self._rates = rates
        self._st = self._observe()
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


def main(argv: list[str] | None = None) -> int:
    """``python -m sim.vehicle.vehicle --flavour px4 --url udpin:127.0.0.1:14540 --duration 600``."""
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
