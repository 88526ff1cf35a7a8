"""Simulated fixed-wing autopilot inner loops (pure Python, no JSBSim, no clock, no I/O).

Modelled on PX4's fixed-wing controllers:

* :class:`RateController` - one body axis:
  ``u = trim + s^2 (P e + I int(e)) + s FF omega_sp``, ``e = omega_sp - omega``,
  ``s = V_trim / max(V, V_min)``, ``u`` clipped to [-1, 1], the integral term (``I int(e)``) clamped
  to +-IMAX and frozen while the output is saturated in the direction of the error.
  Output sign: positive ``u`` produces a positive body rate. For the pitch axis this is
  nose-up, i.e. ``elevator = -u`` (JSBSim: positive elevator = trailing edge down = nose down);
  :class:`FixedWingAutopilot` does that conversion.
* :class:`AttitudeController` - roll/pitch setpoints -> body-rate setpoints (PX4 ``FW_R_TC`` /
  ``FW_P_TC`` time constants, rate limits, bank limit, coordinated-turn yaw rate).
* :class:`HoldController` - a compact TECS (total-energy throttle, energy-balance pitch) for
  airspeed + altitude hold, and a loiter-circle lateral guidance.
* :func:`fly_to_trim` - flies level with the loops and reports the trim found.

Units: SI, radians, NED / FRD. All state lives in the objects; ``update(dt, ...)`` is explicit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the plants' state; importing the plant at run time would load JSBSim
    from sim.plant.jsbsim_plant import PlantState

G = 9.80665


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def body_rates(pqr: Any) -> tuple[float, float, float]:
    """(p, q, r) of a state's ``pqr`` (an array or a sequence) as Python floats: a numpy scalar
    that reaches a rate loop's integrator stays in it, and every later step's arithmetic would
    be numpy's, many times slower than on floats (the same values)."""
    p, q, r = pqr
    return float(p), float(q), float(r)


# --------------------------------------------------------------------------- gains
@dataclass
class RateLoopGains:
    """Per-aircraft rate-loop gains, trims and airspeeds (PX4 parameter names in comments).

    Defaults are tuned for the shipped Skywalker X8 JSBSim model (sim/jsbsim_root/aircraft/x8)
    at V_trim = 16 m/s; PX4's stock values are in :meth:`px4_defaults`.

    X8 tuning rationale (16 m/s, full elevon travel +-30 deg):
    - Roll: steady roll rate per unit aileron = -Clda*da_max/Clp * 2V/b ~ 2.4 rad/s, so without
      sideslip FF ~0.42 would give p = p_sp; roll-mode time constant Ix/|Lp| ~ 0.19 s. But the
      rudderless X8 side-slips ~2-5 deg while rolling (weak Cnb, adverse yaw) and the dihedral
      effect (Clb) then eats ~1/4 of the roll power, so the measured sag with PX4's gains is
      ~30 % (p = 0.35 for 0.5 commanded, 90 % never reached). Tuned: FF 0.5 (PX4's value),
      P 0.3 (PX4 0.05), I 0.4 (PX4 0.1), IMAX 0.3: 90 % rise 0.20 s, overshoot 4 %, >= 0.43 held.
    - Pitch: a steady pull-up q needs delta_e ~ -0.29 rad per rad/s (alpha for the extra lift
      through Cma plus Cmq), i.e. FF ~ 0.55; short period ~ 1.7 Hz, damping ~0.6. P 0.12, I 0.2.
    - Yaw: the X8 has no rudder (the rudder channel moves nothing); PX4 defaults kept, harmless.
    """

    # roll (FW_RR_P, FW_RR_I, FW_RR_IMAX, FW_RR_FF)
    roll_p: float = 0.3
    roll_i: float = 0.4
    roll_imax: float = 0.3
    roll_ff: float = 0.5
    # pitch (FW_PR_*)
    pitch_p: float = 0.12
    pitch_i: float = 0.2
    pitch_imax: float = 0.4
    pitch_ff: float = 0.55
    # yaw (FW_YR_*)
    yaw_p: float = 0.05
    yaw_i: float = 0.1
    yaw_imax: float = 0.2
    yaw_ff: float = 0.3
    # aileron-rudder interconnect: rudder += rudder_mix * aileron (ArduPlane KFF_RDDRMIX), the
    # rudder that cancels the yaw an aileron deflection makes (adverse yaw); 0: none
    rudder_mix: float = 0.0
    # trims, in the normalized SURFACE command convention (TRIM_ROLL, TRIM_PITCH, TRIM_YAW):
    # elevator > 0 is nose down.
    trim_aileron: float = 0.0
    trim_elevator: float = 0.0
    trim_rudder: float = 0.0
    trim_throttle: float = 0.215  # X8 at 16 m/s, found with fly_to_trim
    # airspeeds (FW_AIRSPD_TRIM / MIN / MAX), m/s
    airspeed_trim: float = 16.0
    airspeed_min: float = 10.0
    airspeed_max: float = 22.0

    @classmethod
    def px4_defaults(cls) -> RateLoopGains:
        """PX4's stock gains (airspeeds min/trim/max 10/15/20 m/s), for comparison."""
        return cls(
            roll_p=0.05, roll_i=0.1, roll_imax=0.2, roll_ff=0.5,
            pitch_p=0.08, pitch_i=0.1, pitch_imax=0.4, pitch_ff=0.5,
            yaw_p=0.05, yaw_i=0.1, yaw_imax=0.2, yaw_ff=0.3,
            trim_throttle=0.3, airspeed_trim=15.0, airspeed_min=10.0, airspeed_max=20.0,
        )  # fmt: skip


@dataclass
class AttitudeGains:
    """PX4 FW attitude loop: time constants and limits (FW_R_TC, FW_P_TC, FW_*_RMAX, FW_R_LIM)."""

    roll_tc: float = 0.4  # s
    pitch_tc: float = 0.4  # s
    roll_rate_max: float = math.radians(70.0)  # rad/s
    pitch_rate_max: float = math.radians(60.0)
    yaw_rate_max: float = math.radians(50.0)
    bank_max: float = math.radians(50.0)  # rad
    pitch_max: float = math.radians(30.0)
    pitch_min: float = math.radians(-30.0)
    airspeed_min: float = 10.0  # m/s, floor for the coordinated-turn yaw rate


@dataclass
class HoldGains:
    """TECS-lite and loiter gains (tuned on the X8 model)."""

    # outer loops -> rate setpoints
    alt_k: float = 0.25  # 1/s, climb-rate setpoint per metre of altitude error (TECS 1/tc)
    climb_max: float = 3.0  # m/s
    sink_max: float = 3.0  # m/s
    speed_k: float = 0.3  # 1/s, dV/dt setpoint per m/s of airspeed error
    accel_max: float = 2.0  # m/s^2
    # total energy rate (dimensionless: gamma + Vdot/g) -> throttle
    thr_p: float = 1.0
    thr_i: float = 0.5
    thr_ff: float = 2.0  # throttle per unit of commanded total energy rate (climb gamma)
    thr_min: float = 0.0
    thr_max: float = 1.0
    # energy balance rate (gamma - Vdot/g) -> pitch
    pitch_p: float = 1.0
    pitch_i: float = 0.3
    pitch_trim: float = 0.05  # rad, body pitch in level trimmed flight (X8 at 16 m/s)
    vdot_tau: float = 0.3  # s, low-pass on the airspeed derivative
    # loiter (Beard & McLain orbit following)
    loiter_radius: float = 80.0  # m
    loiter_k_orbit: float = 2.0  # approach gain (dimensionless)
    loiter_k_course: float = 1.2  # rad of bank per rad of course error
    bank_max: float = math.radians(50.0)


# --------------------------------------------------------------------------- rate loop
class RateController:
    """One PX4-style body-rate loop (see module docstring). Output positive = positive rate."""

    def __init__(
        self,
        p: float,
        i: float,
        imax: float,
        ff: float,
        trim: float = 0.0,
        airspeed_trim: float = 16.0,
        airspeed_min: float = 10.0,
    ):
        self.p, self.i, self.imax, self.ff, self.trim = p, i, imax, ff, trim
        self.airspeed_trim, self.airspeed_min = airspeed_trim, airspeed_min
        self.integrator = 0.0  # the I int(e) term, clamped to +-imax
        self.output = 0.0
        self._saturated = 0  # +1 / -1 when the last output was clipped high / low

    def reset(self) -> None:
        self.integrator = 0.0
        self.output = 0.0
        self._saturated = 0

    def update(self, dt: float, rate_sp: float, rate: float, airspeed: float) -> float:
        """One step: returns u in [-1, 1]. (Three of these run every physics step of the SIL:
        the floor and the clamp are written out, ``max`` and :func:`_clip` as they evaluate.)"""
        v_min = self.airspeed_min
        s = self.airspeed_trim / (v_min if v_min > airspeed else airspeed)
        e = rate_sp - rate
        # integrate unless that drives the saturated output further into saturation
        if self.i > 0.0 and dt > 0.0 and not (self._saturated * e > 0.0):
            x, hi = self.integrator + self.i * e * dt, self.imax
            lo = -hi
            self.integrator = lo if x < lo else hi if x > hi else x
        u = self.trim + s * s * (self.p * e + self.integrator) + s * self.ff * rate_sp
        if u > 1.0:
            u, self._saturated = 1.0, 1
        elif u < -1.0:
            u, self._saturated = -1.0, -1
        else:
            self._saturated = 0
        self.output = u
        return u


# --------------------------------------------------------------------------- attitude loop
class AttitudeController:
    """Roll/pitch angle setpoints -> body-rate setpoints (PX4 FW attitude controller)."""

    def __init__(self, gains: AttitudeGains | None = None):
        self.gains = gains or AttitudeGains()
        self.rates_sp = (0.0, 0.0, 0.0)

    def reset(self) -> None:
        self.rates_sp = (0.0, 0.0, 0.0)

    def update(
        self,
        dt: float,
        roll_sp: float,
        pitch_sp: float,
        roll: float,
        pitch: float,
        airspeed: float,
    ) -> tuple[float, float, float]:
        """Returns body-rate setpoints (p, q, r) in rad/s, including turn coordination."""
        g = self.gains
        roll_sp = _clip(roll_sp, -g.bank_max, g.bank_max)
        pitch_sp = _clip(pitch_sp, g.pitch_min, g.pitch_max)
        phid = (roll_sp - roll) / g.roll_tc
        thetad = (pitch_sp - pitch) / g.pitch_tc
        # coordinated turn: psid = g tan(phi) / V (actual roll, limited to +-80 deg as PX4 does)
        phi_c = _clip(roll, -1.396, 1.396)
        psid = G * math.tan(phi_c) / max(airspeed, g.airspeed_min)
        sf, cf = math.sin(roll), math.cos(roll)
        st, ct = math.sin(pitch), math.cos(pitch)
        p = phid - st * psid
        q = cf * thetad + ct * sf * psid
        r = -sf * thetad + cf * ct * psid
        p = _clip(p, -g.roll_rate_max, g.roll_rate_max)
        q = _clip(q, -g.pitch_rate_max, g.pitch_rate_max)
        r = _clip(r, -g.yaw_rate_max, g.yaw_rate_max)
        self.rates_sp = (p, q, r)
        return self.rates_sp


# --------------------------------------------------------------------------- hold / loiter
class HoldController:
    """Airspeed + altitude hold (TECS-lite) and loiter-circle guidance.

    ``update(...)`` returns ``(roll_sp, pitch_sp, throttle)``; pass ``roll_sp`` to fly a given
    bank, or call :meth:`loiter_roll` first for a circle, or :meth:`heading_roll` for a heading.
    """

    def __init__(self, gains: HoldGains | None = None, trim_throttle: float = 0.215):
        self.gains = gains or HoldGains()
        self.trim_throttle = trim_throttle
        self.thr_integ = 0.0
        self.pitch_integ = 0.0
        self._v_prev: float | None = None
        self.vdot = 0.0
        self.throttle = trim_throttle
        self.pitch_sp = self.gains.pitch_trim

    def reset(self) -> None:
        self.thr_integ = self.pitch_integ = 0.0
        self._v_prev = None
        self.vdot = 0.0

    # -- longitudinal
    def update(
        self,
        dt: float,
        airspeed_sp: float,
        altitude_sp: float,
        airspeed: float,
        altitude: float,
        climb_rate: float,
        roll_sp: float = 0.0,
    ) -> tuple[float, float, float]:
        """TECS-lite step. altitude: m up (any datum); climb_rate: m/s up (= -v_down)."""
        g = self.gains
        V = max(airspeed, 1.0)
        if self._v_prev is None or dt <= 0.0:
            self._v_prev = airspeed
        else:
            raw = (airspeed - self._v_prev) / dt
            self._v_prev = airspeed
            a = dt / (g.vdot_tau + dt)
            self.vdot += a * (raw - self.vdot)
        hdot_sp = _clip(g.alt_k * (altitude_sp - altitude), -g.sink_max, g.climb_max)
        vdot_sp = _clip(g.speed_k * (airspeed_sp - airspeed), -g.accel_max, g.accel_max)
        gam_sp, gam = hdot_sp / V, climb_rate / V
        ste_sp, ste = gam_sp + vdot_sp / G, gam + self.vdot / G  # total energy rate / (m g V)
        seb_sp, seb = gam_sp - vdot_sp / G, gam - self.vdot / G  # energy balance rate
        # throttle: feed-forward + PI on total-energy rate error; the trim covers level flight,
        # 1/cos(bank) covers the extra induced drag in a level turn (roughly).
        e_t = ste_sp - ste
        cos_b = max(math.cos(roll_sp), 0.5)
        thr_ff = self.trim_throttle * (1.0 + 0.6 * (1.0 / cos_b - 1.0)) + g.thr_ff * ste_sp
        thr = thr_ff + g.thr_p * e_t + self.thr_integ
        if dt > 0.0 and not ((thr >= g.thr_max and e_t > 0) or (thr <= g.thr_min and e_t < 0)):
            self.thr_integ = _clip(self.thr_integ + g.thr_i * e_t * dt, -0.5, 0.5)
        thr = _clip(thr_ff + g.thr_p * e_t + self.thr_integ, g.thr_min, g.thr_max)
        # pitch: flight path + PI on energy-balance rate error
        e_b = seb_sp - seb
        pitch = g.pitch_trim + seb_sp + g.pitch_p * e_b + self.pitch_integ
        lim_hi, lim_lo = math.radians(25.0), math.radians(-25.0)
        if dt > 0.0 and not ((pitch >= lim_hi and e_b > 0) or (pitch <= lim_lo and e_b < 0)):
            self.pitch_integ = _clip(self.pitch_integ + g.pitch_i * e_b * dt, -0.3, 0.3)
        pitch = _clip(g.pitch_trim + seb_sp + g.pitch_p * e_b + self.pitch_integ, lim_lo, lim_hi)
        self.throttle, self.pitch_sp = thr, pitch
        return roll_sp, pitch, thr

    # -- lateral
    def loiter_roll(
        self,
        center_ne: tuple[float, float],
        position_ne: tuple[float, float],
        velocity_ne: tuple[float, float],
        radius: float | None = None,
        direction: int = 1,
    ) -> float:
        """Bank setpoint (rad) to fly a circle about center_ne (m, N/E).

        direction +1: clockwise seen from above (right turns), -1: counter-clockwise.
        Course law of Beard & McLain (orbit following, eq. 10.13) plus the bank feed-forward
        atan(Vg^2 / (g R)).
        """
        g = self.gains
        R = g.loiter_radius if radius is None else radius
        lam = 1 if direction >= 0 else -1
        dn, de = position_ne[0] - center_ne[0], position_ne[1] - center_ne[1]
        d = math.hypot(dn, de)
        phi_c = math.atan2(de, dn)  # angular position on the circle
        chi_d = phi_c + lam * (math.pi / 2.0 + math.atan(g.loiter_k_orbit * (d - R) / R))
        vn, ve = velocity_ne
        vg = math.hypot(vn, ve)
        chi = math.atan2(ve, vn)
        ff = lam * math.atan(vg * vg / (G * R)) if d > 0.5 * R else 0.0
        roll = ff + g.loiter_k_course * _wrap_pi(chi_d - chi)
        return _clip(roll, -g.bank_max, g.bank_max)

    def heading_roll(self, course_sp: float, velocity_ne: tuple[float, float]) -> float:
        """Bank setpoint (rad) to fly a ground course (rad from north)."""
        g = self.gains
        chi = math.atan2(velocity_ne[1], velocity_ne[0])
        return _clip(g.loiter_k_course * _wrap_pi(course_sp - chi), -g.bank_max, g.bank_max)


# --------------------------------------------------------------------------- bundle
@dataclass
class FixedWingAutopilot:
    """The simulated autopilot: three rate loops + attitude loop + hold/loiter (one object).

    State inputs are plain floats or anything with PlantState's attributes (``euler``, ``pqr``,
    ``airspeed``, ``position_ned``, ``velocity_ned``).
    """

    gains: RateLoopGains = field(default_factory=RateLoopGains)
    attitude_gains: AttitudeGains = field(default_factory=AttitudeGains)
    hold_gains: HoldGains = field(default_factory=HoldGains)

    def __post_init__(self) -> None:
        self.configure(self.gains)
        self.attitude = AttitudeController(self.attitude_gains)
        self.hold = HoldController(self.hold_gains, trim_throttle=self.gains.trim_throttle)

    def configure(self, gains: RateLoopGains) -> None:
        """(Re)build the rate loops from ``gains`` (integrators reset)."""
        self.gains = gains
        k = gains
        vt, vm = k.airspeed_trim, k.airspeed_min
        self.roll = RateController(
            k.roll_p, k.roll_i, k.roll_imax, k.roll_ff, k.trim_aileron, vt, vm
        )
        # pitch loop works in nose-up-positive units: its trim is -trim_elevator
        self.pitch = RateController(
            k.pitch_p, k.pitch_i, k.pitch_imax, k.pitch_ff, -k.trim_elevator, vt, vm
        )
        self.yaw = RateController(k.yaw_p, k.yaw_i, k.yaw_imax, k.yaw_ff, k.trim_rudder, vt, vm)
        if hasattr(self, "hold"):
            self.hold.trim_throttle = gains.trim_throttle

    def reset(self) -> None:
        for c in (self.roll, self.pitch, self.yaw, self.attitude, self.hold):
            c.reset()

    def rates_to_surfaces(
        self,
        dt: float,
        rates_sp: tuple[float, float, float],
        pqr: tuple[float, float, float],
        airspeed: float,
    ) -> tuple[float, float, float]:
        """Body-rate setpoints (rad/s) -> (aileron, elevator, rudder) normalized commands."""
        a = self.roll.update(dt, rates_sp[0], pqr[0], airspeed)
        e = -self.pitch.update(dt, rates_sp[1], pqr[1], airspeed)
        r = self.yaw.update(dt, rates_sp[2], pqr[2], airspeed)
        if self.gains.rudder_mix:
            # about the trims: the mix answers the aileron the rate loop adds, not the trim's
            mix = self.gains.rudder_mix * (a - self.gains.trim_aileron)
            r = _clip(r + mix, -1.0, 1.0)
        return a, e, r

    def attitude_to_surfaces(
        self, dt: float, roll_sp: float, pitch_sp: float, st: PlantState
    ) -> tuple[float, float, float]:
        """Roll/pitch setpoints (rad) -> surfaces, using a PlantState-like ``st``."""
        roll, pitch, _ = st.euler
        rates = self.attitude.update(dt, roll_sp, pitch_sp, roll, pitch, st.airspeed)
        return self.rates_to_surfaces(dt, rates, body_rates(st.pqr), st.airspeed)

    def hold_step(
        self,
        dt: float,
        st: PlantState,
        airspeed_sp: float,
        altitude_sp: float,
        roll_sp: float = 0.0,
        altitude: float | None = None,
    ) -> tuple[float, float, float, float]:
        """Altitude/airspeed hold at a given bank: returns (aileron, elevator, rudder, throttle).

        ``altitude`` defaults to ``-st.position_ned[2]`` (height above the plant origin).
        """
        h = -float(st.position_ned[2]) if altitude is None else altitude
        climb = -float(st.velocity_ned[2])
        roll_sp, pitch_sp, thr = self.hold.update(
            dt, airspeed_sp, altitude_sp, st.airspeed, h, climb, roll_sp
        )
        a, e, r = self.attitude_to_surfaces(dt, roll_sp, pitch_sp, st)
        return a, e, r, thr

    def loiter_step(
        self,
        dt: float,
        st: PlantState,
        center_ne: tuple[float, float],
        airspeed_sp: float,
        altitude_sp: float,
        radius: float | None = None,
        direction: int = 1,
    ) -> tuple[float, float, float, float]:
        """Loiter circle (Hold mode / failsafe): returns (aileron, elevator, rudder, throttle)."""
        pos, vel = st.position_ned, st.velocity_ned
        roll_sp = self.hold.loiter_roll(
            center_ne, (float(pos[0]), float(pos[1])), (float(vel[0]), float(vel[1])),
            radius, direction,
        )  # fmt: skip
        return self.hold_step(dt, st, airspeed_sp, altitude_sp, roll_sp)


# --------------------------------------------------------------------------- trim
@dataclass(frozen=True)
class TrimResult:
    throttle: float  # 0..1
    elevator: float  # normalized, >0 nose down
    aileron: float  # normalized
    pitch: float  # rad
    alpha: float  # rad
    airspeed: float  # m/s (mean over the last seconds)
    altitude: float  # m above the plant origin (mean over the last seconds)


def fly_to_trim(
    plant: Any,  # JSBSimPlant or KinematicPlant (no common interface yet)
    controllers: FixedWingAutopilot,
    airspeed: float,
    altitude: float,
    seconds: float = 15.0,
    average_last: float = 3.0,
    apply: bool = True,
    course: float | None = None,
) -> TrimResult:
    """Fly wings-level at ``airspeed`` / ``altitude`` (m above the plant origin) with the loops.

    JSBSim's built-in trim fails for electric-motor models, so trim is found by flying:
    after ``seconds`` of simulated flight the commands averaged over the last ``average_last``
    seconds are the trim. With ``apply`` the autopilot's trims (throttle, elevator, aileron) are
    set to them (the rate-loop integrators are then reset). ``course`` (rad from north): the
    ground course to hold (None: the course of the first state, which is the heading when a
    wind was set after the initial conditions, not the track over the ground).
    ``plant`` needs ``dt``, ``step(a, e, r, t)`` and ``state()`` (see sim.plant.jsbsim_plant).
    """
    dt = plant.dt
    n = int(round(seconds / dt))
    n_avg = max(1, int(round(min(average_last, seconds) / dt)))
    sums = [0.0] * 7
    for k in range(n):
        st = plant.state()
        if course is None:
            course = math.atan2(float(st.velocity_ned[1]), float(st.velocity_ned[0]))
        roll_sp = controllers.hold.heading_roll(course, (st.velocity_ned[0], st.velocity_ned[1]))
        a, e, r, thr = controllers.hold_step(dt, st, airspeed, altitude, roll_sp)
        plant.step(a, e, r, thr)
        if k >= n - n_avg:
            for i, v in enumerate(
                (thr, e, a, st.euler[1], st.alpha, st.airspeed, -st.position_ned[2])
            ):
                sums[i] += float(v)
    m = [s / n_avg for s in sums]
    res = TrimResult(*m)
    if apply:
        controllers.configure(
            replace(
                controllers.gains,
                trim_throttle=res.throttle,
                trim_elevator=res.elevator,
                trim_aileron=res.aileron,
            )
        )
        controllers.hold.trim_throttle = res.throttle
        controllers.hold.thr_integ = 0.0
    return res
