"""Total energy control of a fixed-wing: thrust for the energy rate, the flight path for the
balance, the airspeed reserve (Lambregts' TECS, shaped for the setpoint adapter).

:class:`Tecs` holds the parameters and is the controller; its memory is an :class:`EnergyState`
passed in and returned (pure: no I/O, no clock). core/adapter.py composes it: the adapter turns
the law's turn into bank and body rates, this decides thrust and how far the flight path gives
way when thrust cannot meet the demand. SI units, radians; gamma is the air-relative
flight-path angle (> 0 climbing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from mpf_mavlink.constants import GRAVITY_M_S2


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


class EnergyState(NamedTuple):
    """The energy controller's memory.

    integ: the thrust integrator (thrust units); v_prev, v_sp_prev: the previous airspeed and
    set-point (m/s, None: none yet); vdot_f: the filtered dV/dt (m/s^2); gam_f: the fed-forward
    flight-path angle, low-passed (rad, None: none yet); balance: the flight-path offset (rad,
    <= 0 when thrust is short) that the priority takes off the pitch demand; gam_m_f: the
    measured flight-path angle, low-passed (rad); thrust_engaged: the thrust (0..1) the
    autopilot flies at engagement, the first step sets the integrator so that the first thrust
    sent is this one (no step), then None. The reserve: the path point's down coordinate last
    step (m), the path's climb low-passed over reserve_tau_s (m/s) and the set-point flown
    (m/s), each None until known.
    """

    integ: float = 0.0
    v_prev: float | None = None
    v_sp_prev: float | None = None
    vdot_f: float = 0.0
    gam_f: float | None = None
    balance: float = 0.0
    gam_m_f: float | None = None
    thrust_engaged: float | None = None
    path_down_prev: float | None = None
    climb_f: float | None = None
    v_res: float | None = None

    def for_reengage(self, thrust_engaged: float | None) -> EnergyState:
        """After a hand-back: integrator and filters afresh, starting from ``thrust_engaged``
        (0..1, already checked finite or None); the reserve's learnt climb and set-point stay."""
        return EnergyState(thrust_engaged=thrust_engaged, climb_f=self.climb_f, v_res=self.v_res)


@dataclass(frozen=True)
class Tecs:
    """Total energy control: parameters (SI units, radians) and the controller's steps.

    Thrust: T = trim_thrust + k_T E_c~ + k_E (E_c - E) + k_I integral(E_c - E) dt + k_n (n - 1)
    (:meth:`energy_rate_thrust`), or without ``energy_control`` the airspeed PI trim_thrust +
    airspeed_kp e + airspeed_ki integral(e) + k_n (n - 1), e = V_sp - V (:meth:`airspeed_pi`).
    Balance and priority: :meth:`priority_balance`, entering the pitch demand by
    :meth:`flight_path_rate`. Limits: thrust_min..thrust_max, the integrator's
    integrator_limit, the airspeed envelope airspeed_min..max_m_s the "airspeed" priority
    protects, the pitch range the flight path is held in (min/max_pitch_rad, tau_pitch_s ahead).
    Reserve: :meth:`airspeed_setpoint` (:func:`reserve_airspeed`).
    """

    airspeed_sp_m_s: float = 15.0
    airspeed_min_m_s: float = 0.0
    airspeed_max_m_s: float = math.inf
    trim_thrust: float = 0.5
    thrust_min: float = 0.0
    thrust_max: float = 1.0
    airspeed_kp: float = 0.05  # thrust per m/s
    airspeed_ki: float = 0.02  # thrust per (m/s s)
    integrator_limit: float = 1.0  # |integrator| (thrust units)
    load_factor_ff: float = 0.2  # k_n: thrust per g of extra load (n - 1)
    energy_control: bool = True  # False: the airspeed PI
    thrust_per_gamma: float = 2.5  # k_T: throttle per rad of flight-path angle (steady climb)
    speed_tau_s: float = 4.0  # tau_V: airspeed error -> acceleration demand
    energy_kp: float = 1.0  # k_E: throttle per rad of total energy rate error
    energy_ki: float = 0.6  # k_I: throttle per rad s of it
    vdot_tau_s: float = 2.0  # low-pass of dV/dt and of the flight-path angles (s)
    priority: str = "airspeed"  # "airspeed" or "height": what is held when thrust cannot
    balance_tau_s: float = 1.0  # low-pass of the priority's flight-path offset (s)
    min_pitch_rad: float = -0.35
    max_pitch_rad: float = 0.35
    tau_pitch_s: float = 1.0  # the pitch demand's look-ahead (s)
    max_climb_m_s: float = math.inf  # the reserve (reserve_airspeed)
    reserve_gust_m_s: float = 0.0
    reserve_gust_s: float = 10.0
    reserve_tau_s: float = 20.0
    reserve_rate_m_s2: float = 0.1

    def flight_path_rate(self, st: EnergyState, gamd_law: float) -> tuple[float, float]:
        """Energy balance -> pitch: (gamma_dot demand, offset) rad/s and rad. The priority's
        offset (previous step's, low-passed) lowers (raises) the flight-path demand while
        thrust is at its ceiling (floor): the law's gamma_dot plus the rate that takes the
        offset out over one tau_pitch."""
        lead = self.tau_pitch_s if self.tau_pitch_s > 0.0 else 1.0
        bal = st.balance if self.energy_control else 0.0
        return gamd_law + bal / lead, bal

    def thrust(
        self, st: EnergyState, v: float, v_sp: float, gamma: float, gamd_law: float,
        trim: float, n: float, bal: float, dt: float, g: float = GRAVITY_M_S2,
    ) -> tuple[float, EnergyState]:  # fmt: skip
        """Thrust (0..1) and the memory after this step: :meth:`energy_rate_thrust` when
        ``energy_control`` is on, else :meth:`airspeed_pi`; v, v_sp (m/s), gamma (rad) and the
        law's gamd_law (rad/s), the pitch trim (rad), the load factor n (g), the offset bal of
        :meth:`flight_path_rate` (rad), dt (s)."""
        ff = self.load_factor_ff * (n - 1.0)
        en = st._replace(balance=bal)
        if self.energy_control:
            # the flight-path angle the law aims at one tau_pitch ahead (pitch limits included)
            gamma_law = gamma + gamd_law * self.tau_pitch_s
            gamma_c = _clip(gamma_law, self.min_pitch_rad - trim, self.max_pitch_rad - trim)
            return self.energy_rate_thrust(en, v, v_sp, gamma, gamma_c, ff, dt, g, gamma_law)
        thrust, integ = self.airspeed_pi(st.integ, v_sp - v, ff, dt)
        return thrust, en._replace(integ=integ)

    def airspeed_pi(self, integ: float, e: float, ff: float, dt: float) -> tuple[float, float]:
        """The airspeed PI (``energy_control`` off): (thrust, integrator). Conditional
        integration: the integrator moves only when the output is not saturated in the
        direction e (m/s) pushes."""
        base = self.trim_thrust + self.airspeed_kp * e + ff
        raw = base + integ
        if dt > 0.0 and not (
            (raw >= self.thrust_max and e > 0) or (raw <= self.thrust_min and e < 0)
        ):
            lo = max(-self.integrator_limit, self.thrust_min - base)
            hi = min(self.integrator_limit, self.thrust_max - base)
            integ = _clip(integ + self.airspeed_ki * e * dt, min(lo, 0.0), max(hi, 0.0))
        return _clip(base + integ, self.thrust_min, self.thrust_max), integ

    def energy_rate_thrust(
        self, st: EnergyState, v: float, v_sp: float, gamma: float, gamma_c: float, ff: float,
        dt: float, g: float = GRAVITY_M_S2, gamma_law: float | None = None,
    ) -> tuple[float, EnergyState]:  # fmt: skip
        """Thrust from the total specific energy rate, and the priority's flight-path offset.

        Lambregts' total energy control (TECS; A. A. Lambregts, "Vertical flight path and speed
        control autopilot design using total energy principles", AIAA 83-2239, 1983; and
        "Functional integration of vertical flight path and speed control using energy
        principles", NASA CP-2296, 1984): the specific total energy rate normalised by V,
        E_dot / (m g V) = gamma + V_dot / g, is what thrust changes (T - D = W (gamma + V_dot / g)
        for small angles), while the balance gamma - V_dot / g is what the elevator moves at
        constant thrust. Here:

          E_c = gamma_c + V_dot_c / g,  V_dot_c = V_dot_sp + (V_sp - V) / tau_V  (the demand)
          E   = gamma + V_dot / g                                           (what is flown)
          T   = T_trim + k_T E_c~ + k_E (E_c - E) + k_I integral(E_c - E) dt + k_n (n - 1)

        gamma_c: the flight-path angle the law aims at one tau_pitch ahead, which carries the
        path's slope, the target's climb and the law's correction (gamma + gamma_dot tau).
        gamma_c, gamma and V_dot (from the airspeed's difference) are low-passed over vdot_tau_s
        before they enter:
        gusts tilt the air-relative gamma and the law's correction rings with them: over 0.5 s the
        throttle chattered between idle and 0.8 in light turbulence and swung 0-0.7 through a
        circle's capture (airspeed to 20 m/s, captured in 36 s); over 2 s the capture took 10 s. k_T
        (thrust_per_gamma) is the airframe's throttle per rad of steady climb, so the feed-forward
        alone flies a demanded climb at constant speed; k_E, k_I close the loop on what it misses.
        Anti-windup: the integrator moves only when the output is not saturated in the direction
        the error pushes, and never beyond what takes the output to a limit.

        Priority (when thrust cannot meet E_c): the unmet rate u = (T_raw - T_limit) / (k_T + k_E)
        (rad; > 0 short of thrust, < 0 a surplus at the floor, e.g. an updraft at idle), so the
        flight path thrust sustains at its limit is gamma_c - u. ``priority`` "airspeed" (the
        default: the safe one) holds the airspeed inside its envelope [airspeed_min_m_s,
        airspeed_max_m_s]: the path's flight-path angle stands while the airspeed has room, and from
        1 m/s inside the limit to the limit the law's flight-path demand ``gamma_law`` (gamma +
        gamma_dot tau, unclipped; None: gamma_c) is moved to the sustainable one (weight ramping 0
        -> 1, low-passed over balance_tau_s): at the ceiling the aircraft climbs only as steeply as
        full thrust sustains, at the floor it puts an updraft's surplus into height rather than
        speed. "height": the flight path never gives way (the airspeed may leave its envelope).
        Moving the flight path at the set-point already (weight 1 at any airspeed) put every
        updraft of moderate turbulence into height: 1.48 m RMS, 10.9 m max in SIL against 0.83 /
        6.0 m with the envelope rule.
        Returns (thrust, state); the state's ``balance`` is that offset (rad).
        """
        p = self
        integ, v_prev, v_sp_prev, vdot_f, gam_f, bal, gam_m_f, t_eng = st[:8]
        a = min(1.0, dt / p.vdot_tau_s) if p.vdot_tau_s > 0.0 and dt > 0.0 else 1.0
        if v_prev is not None and dt > 0.0:
            vdot_f += a * ((v - v_prev) / dt - vdot_f)
        vsp_dot = (v_sp - v_sp_prev) / dt if v_sp_prev is not None and dt > 0.0 else 0.0
        gam_f = gamma_c if gam_f is None else gam_f + a * (gamma_c - gam_f)
        gam_m_f = gamma if gam_m_f is None else gam_m_f + a * (gamma - gam_m_f)
        tau_v = p.speed_tau_s if p.speed_tau_s > 0.0 else 1.0
        vdot_c = vsp_dot + (v_sp - v) / tau_v
        e_E = (gam_f - gam_m_f) + (vdot_c - vdot_f) / g
        base = p.trim_thrust + p.thrust_per_gamma * (gam_f + vdot_c / g) + p.energy_kp * e_E + ff
        if t_eng is not None:  # engagement: start from the autopilot's thrust (no step)
            lim = p.integrator_limit
            integ = _clip(_clip(t_eng, p.thrust_min, p.thrust_max) - base, -lim, lim)
            t_eng = None
        raw = base + integ
        if dt > 0.0 and not (
            (raw >= p.thrust_max and e_E > 0) or (raw <= p.thrust_min and e_E < 0)
        ):
            lo = max(-p.integrator_limit, p.thrust_min - base)
            hi = min(p.integrator_limit, p.thrust_max - base)
            integ = _clip(integ + p.energy_ki * e_E * dt, min(lo, 0.0), max(hi, 0.0))
        raw = base + integ
        thrust = _clip(raw, p.thrust_min, p.thrust_max)
        law = gamma_c if gamma_law is None else gamma_law
        bal = self.priority_balance(bal, raw - thrust, v, gamma_c, law, dt)
        return thrust, tuple.__new__(
            EnergyState, (integ, v, v_sp, vdot_f, gam_f, bal, gam_m_f, t_eng, *st[8:])
        )

    def priority_balance(
        self, bal: float, unmet: float, v: float, gamma_c: float, law: float, dt: float
    ) -> float:
        """Priorities and limits: the flight-path offset (rad, low-passed) of
        :meth:`energy_rate_thrust`; ``unmet`` the thrust its limit cut off (raw - applied),
        ``law`` the law's flight-path demand (rad), v (m/s), dt (s)."""
        p = self
        k = p.thrust_per_gamma + p.energy_kp
        u = unmet / k if k > 0.0 else 0.0
        # the flight path thrust sustains at its limit, against what the law asks (unclipped)
        sus = gamma_c - u
        off = min(0.0, sus - law) if u > 0.0 else max(0.0, sus - law) if u < 0.0 else 0.0
        w = 0.0  # height: the flight path never gives way
        if p.priority == "airspeed":  # ... but near the envelope's edges (1 m/s ramp) it does
            w = _clip(p.airspeed_min_m_s + 1.0 - v, 0.0, 1.0) if u > 0.0 else 0.0
            w = _clip(v - p.airspeed_max_m_s + 1.0, 0.0, 1.0) if u < 0.0 else w
        span = p.max_pitch_rad - p.min_pitch_rad  # at most the whole pitch range
        target = _clip(w * off, -span, span)
        if dt > 0.0:
            b = min(1.0, dt / p.balance_tau_s) if p.balance_tau_s > 0.0 else 1.0
            bal += b * (target - bal)
            if abs(bal) < 1e-6 and target == 0.0:
                bal = 0.0
        return bal

    def airspeed_setpoint(
        self, st: EnergyState, path_down: float | None, dt: float, g: float,
        airspeed_sp: float | None,
    ) -> tuple[float, EnergyState]:  # fmt: skip
        """The airspeed set-point (m/s) and the memory with the reserve's step: ``airspeed_sp``
        when given and finite, else the reserve's set-point when it is on, else
        airspeed_sp_m_s. The reserve: the path's climb from the path point's down coordinate
        ``path_down`` (m), low-passed over reserve_tau_s, and the set-point
        :func:`reserve_airspeed` gives for it, moved at most reserve_rate_m_s2. Off (None) without
        a design gust, a known climb capability or the path point."""
        p = self
        if not (
            p.reserve_gust_m_s > 0.0 and math.isfinite(p.max_climb_m_s) and path_down is not None
            and math.isfinite(path_down)
        ):  # fmt: skip
            res: tuple[float | None, float | None, float | None] = (None, None, None)
        else:
            res = self._reserve_step(st, path_down, dt, g)
        st = tuple.__new__(EnergyState, (*st[:8], *res))
        if airspeed_sp is not None and math.isfinite(airspeed_sp):
            return airspeed_sp, st
        return (p.airspeed_sp_m_s if res[2] is None else res[2]), st

    def _reserve_step(
        self, st: EnergyState, path_down: float, dt: float, g: float
    ) -> tuple[float, float | None, float]:
        """(path_down_prev, climb_f, v_res) of the reserve after this step."""
        p = self
        climb_f = st.climb_f
        prev = st.path_down_prev
        if prev is not None and dt > 0.0:
            # a jump of the path point (a re-planned s) is not a climb: at most the airspeed
            c = _clip((prev - path_down) / dt, -p.airspeed_sp_m_s, p.airspeed_sp_m_s)
            a = min(1.0, dt / p.reserve_tau_s) if p.reserve_tau_s > 0.0 else 1.0
            climb_f = c if climb_f is None else climb_f + a * (c - climb_f)
        v0 = p.airspeed_sp_m_s
        v_res = v0 if st.v_res is None else st.v_res
        if climb_f is not None:
            want = reserve_airspeed(
                v0, p.airspeed_max_m_s, climb_f, p.max_climb_m_s, p.reserve_gust_m_s,
                p.reserve_gust_s, g,
            )  # fmt: skip
            step = p.reserve_rate_m_s2 * max(dt, 0.0)
            v_res = _clip(want, v_res - step, v_res + step)
        return path_down, climb_f, v_res


def reserve_airspeed(
    v_sp: float,
    v_max: float,
    climb: float,
    max_climb: float,
    gust: float,
    gust_s: float,
    g: float = GRAVITY_M_S2,
) -> float:
    """The airspeed set-point (m/s) that carries the kinetic energy a design downdraft needs.

    A steady climb ``climb`` (m/s, the path's) leaves ``max_climb - climb`` of the climb at full
    thrust for gusts. A downdraft of ``gust`` m/s lasting ``gust_s`` s beyond that spare is
    R = (gust - (max_climb - climb)) gust_s metres of height that thrust cannot supply; the
    total energy equation (Lambregts: E = m g h + m V^2 / 2, so dh = -V dV / g at constant E)
    pays it from speed if the aircraft flies V_r = sqrt(v_sp^2 + 2 g R) before the gust and
    may slow to the set-point's floor. Flying faster costs some climb (drag); the SIL X8 at
    430 m loses 0.05 m/s of its 4.2 m/s going from 16 to 18 m/s (the cost is not in R: the
    reserve is sized for the set-point's capability). Within [v_sp, v_max]; v_sp itself when a
    figure is not finite or the spare covers the gust."""
    r = (gust - (max_climb - max(climb, 0.0))) * gust_s
    if not (math.isfinite(r) and r > 0.0 and v_max > v_sp):
        return v_sp
    return min(v_max, math.sqrt(v_sp * v_sp + 2.0 * g * r))
