"""The emulated stock autopilot (PX4 commander / ArduPlane): its mode (:mod:`.modes`), the
external setpoints it takes (:mod:`.setpoints`), the commands it answers (:mod:`.commands`),
and what it flies each physics step through the inner loops (:class:`AutopilotEmulation`).
The rules are listed in :mod:`sim.vehicle.vehicle`."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from sim.autopilot.commands import Commands, Outbox
from sim.autopilot.inner_loop import body_rates
from sim.autopilot.modes import CRUISE, GUIDED, LOITER, OFFBOARD, Modes, Time, Tunables
from sim.autopilot.setpoints import Setpoints, clip

Surfaces = tuple[float, float, float, float]  # aileron, elevator, rudder (-1..1), throttle 0..1


def flown_state(st: Any, airspeed_scale: float) -> Any:
    """The reported state ``st`` with the airspeed the firmware flies on: the report's
    ``airspeed_scale`` (profile) undone; ``st`` itself when there is none."""
    if airspeed_scale == 1.0:
        return st
    return dataclasses.replace(st, airspeed=st.airspeed / airspeed_scale)


class AutopilotEmulation:
    """Modes, setpoints and commands of one flavour, and the control of one physics step.

    ``ap`` is the inner-loop autopilot (:class:`sim.autopilot.inner_loop.FixedWingAutopilot`);
    ``state``
    returns the state the autopilot has now (the plant's, or a profile's estimate of it)."""

    def __init__(
        self,
        px4: bool,
        ap: Any,
        dt: float,
        tunables: Tunables,
        clock: Time,
        out: Outbox,
        state: Callable[[], Any],
        home_lla: tuple[float, float, float],
    ) -> None:
        self.px4 = px4
        self.ap = ap
        self.ap_dt = float(dt)  # the physics step (s)
        self.tun = tunables
        self.clock = clock
        self.out = out
        self.state = state
        self.home_lla = home_lla
        self.setpoints = Setpoints()
        self.modes = Modes(px4, tunables, clock, state, self._announce)
        self.modes.on_guided = self.setpoints.reset_forced
        self.commands = Commands(px4, self.modes, self.setpoints, tunables, home_lla, state, out)
        # the firmware's identified behaviour (sim/autopilot/profile.py), None: the plain rules
        self.shaper: Any = None  # the attitude set-point as the firmware's loop would fly it
        self.wander: Any = None  # a slow roll-rate error of body-rate offboard
        self.thrust_scale = 1.0  # plant throttle per unit of offboard thrust
        # reported airspeed / the airspeed the firmware flies on (profile estimator
        # airspeed_scale): the loops below undo it, so only the report changes
        self.airspeed_scale = 1.0

    def _announce(self, text: str) -> None:
        self.out.statustext(M.MAV_SEVERITY_INFO, text)

    # ------------------------------------------------------------------ input
    def set_attitude_target(self, msg: Any, ms: int) -> None:
        """A SET_ATTITUDE_TARGET addressed to the vehicle (``ms``: boot time now)."""
        sp = self.setpoints
        if self.px4:
            sp.take_px4(msg, self.clock.boot_s, ms, self.tun.px4_require_thrust)
        elif self.modes.behaviour != GUIDED:
            sp.dropped["not_guided"] += 1
        else:
            sp.take_ardupilot(msg, self.clock.boot_s)

    # ------------------------------------------------------------------ control
    def offboard_rates(self, boot_s: float) -> tuple[tuple[float, ...], float] | None:
        """The body-rate set-point (rad/s) and throttle to fly now, when PX4 offboard flies body
        rates within its loss timeout: the rate loops then need only p, q, r and the airspeed
        (no full state). None otherwise."""
        sp = self.setpoints
        s = sp.sp
        if (
            self.modes.behaviour != OFFBOARD
            or s is None
            or s[0] != "rates"
            or sp.sp_last is None
            or boot_s - sp.sp_last > self.tun.com_of_loss_t
        ):
            return None
        rsp = s[1]
        if self.wander is not None:
            rsp = (rsp[0] + self.wander(), rsp[1], rsp[2])
        return rsp, (s[2] * self.thrust_scale if self.modes.armed else 0.0)

    def control(self, st: Any) -> Surfaces:
        """The surfaces and throttle of one physics step from the state ``st``."""
        dt, ap, modes = self.ap_dt, self.ap, self.modes
        st = flown_state(st, self.airspeed_scale)
        if modes.behaviour == OFFBOARD:
            out = self._offboard(st)
            if out is not None:
                return out
        beh = modes.behaviour
        if beh == GUIDED:
            return self._guided(st)
        tun = self.tun
        if beh == LOITER:
            out = ap.loiter_step(
                dt,
                st,
                modes.center,
                tun.cruise_airspeed,
                modes.alt_sp,
                modes.hold_radius,
                tun.loiter_direction,
            )
        elif beh == CRUISE:
            roll = ap.hold.heading_roll(modes.course, (st.velocity_ned[0], st.velocity_ned[1]))
            out = ap.hold_step(dt, st, tun.cruise_airspeed, modes.alt_sp, roll)
        else:  # LEVEL: wings level, trim pitch, trim throttle
            a, e, r = ap.attitude_to_surfaces(dt, 0.0, ap.hold.gains.pitch_trim, st)
            out = (a, e, r, ap.hold.trim_throttle)
        a, e, r, thr = out
        return a, e, r, (thr if modes.armed else 0.0)

    def _offboard(self, st: Any) -> Surfaces | None:
        """PX4 offboard, or None after the failsafe to Hold (no setpoint for COM_OF_LOSS_T)."""
        sp, t = self.setpoints, self.clock.boot_s
        if sp.sp_last is None or t - sp.sp_last > self.tun.com_of_loss_t:
            self.out.statustext(
                M.MAV_SEVERITY_CRITICAL, "Failsafe: no offboard signal, switching to Hold"
            )
            self.modes.hold()
            return None
        assert sp.sp is not None  # offboard is only available with a setpoint
        kind, vals, thrust = sp.sp
        dt, ap = self.ap_dt, self.ap
        if kind == "rates":
            a, e, r = ap.rates_to_surfaces(dt, vals, body_rates(st.pqr), st.airspeed)
        else:
            roll_sp, pitch_sp = vals
            if self.shaper is not None:
                roll_sp, pitch_sp = self.shaper(roll_sp, pitch_sp)
            a, e, r = ap.attitude_to_surfaces(dt, roll_sp, pitch_sp, st)
        return a, e, r, (thrust * self.thrust_scale if self.modes.armed else 0.0)

    def _guided(self, st: Any) -> Surfaces:
        """ArduPlane GUIDED: each forced axis until it times out, else its own loiter + TECS."""
        dt, ap, t, modes, tun = self.ap_dt, self.ap, self.clock.boot_s, self.modes, self.tun
        fv, to = self.setpoints.forced, tun.guided_timeout
        fresh = [x is not None and t - x < to for x in self.setpoints.forced_t]
        gl = self.setpoints.guided_loiter
        center, alt_sp, radius, direction = (
            gl
            if gl is not None
            else (modes.center, modes.alt_sp, tun.loiter_radius, tun.loiter_direction)
        )
        pos, vel = st.position_ned, st.velocity_ned
        if fresh[0]:
            roll_sp = fv[0]
        else:
            roll_sp = ap.hold.loiter_roll(
                center,
                (float(pos[0]), float(pos[1])),
                (float(vel[0]), float(vel[1])),
                radius,
                direction,
            )
        _, pitch_tecs, thr_tecs = ap.hold.update(
            dt, tun.cruise_airspeed, alt_sp, st.airspeed, -float(pos[2]), -float(vel[2]), roll_sp
        )
        pitch_sp = fv[1] if fresh[1] else pitch_tecs
        if self.shaper is not None:  # the firmware's own attitude loop: lag, gain, bias (profile)
            roll_sp, pitch_sp = self.shaper(roll_sp, pitch_sp)
        a, e, r = ap.attitude_to_surfaces(dt, roll_sp, pitch_sp, st)
        if fresh[2]:
            r = clip(math.degrees(fv[2]) / 45.0, -1.0, 1.0)  # ArduPlane: +-4500 cdeg = full rudder
        thr = fv[3] if fresh[3] else thr_tecs
        return a, e, r, (thr if modes.armed else 0.0)
