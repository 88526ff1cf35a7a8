"""From the law's command (the angular velocity of w1) to what a fixed-wing autopilot accepts.

Pure functions: no I/O. Frames: NED inertial, FRD body. The bank needed to turn the velocity
vector is set by the specific force the wing must produce: ``f = a - g`` (gravity g = [0, 0, g]
in NED), of which the part normal to w1 is lift; the bank is the angle of the lift about w1.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple

from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.core.energy import EnergyState, Tecs, reserve_airspeed
from mpf_mavlink.quaternion import quat_of_euler

__all__ = [
    "AdapterParams", "AdapterState", "Setpoint", "TrimSchedule", "adapt", "reserve_airspeed",
]  # fmt: skip

Vec = tuple[float, float, float]


def bank_and_load_factor(w1: Vec, accel: Vec, g: float = GRAVITY_M_S2) -> tuple[float, float]:
    """Bank angle (rad, > 0 right wing down) and load factor n (g) that produce ``accel``.

    w1: unit air-relative velocity direction (NED); accel: the acceleration of the vehicle
    normal to w1 that the turn needs (NED, m/s^2), e.g. ``v_w * (omega x w1)``.
    Level flight (accel = 0) gives (0, 1); a level right turn of centripetal acceleration a
    gives (atan(a/g), sqrt(1 + (a/g)^2)).
    """
    fx, fy, fz = accel[0], accel[1], accel[2] - g
    d = fx * w1[0] + fy * w1[1] + fz * w1[2]
    fx, fy, fz = fx - d * w1[0], fy - d * w1[1], fz - d * w1[2]
    # Local "down" normal to w1, and "right" = down x w1.
    k = w1[2]
    nx, ny, nz = -k * w1[0], -k * w1[1], 1.0 - k * w1[2]
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn < 1e-9:  # vertical flight: bank is undefined; report it about north
        nx, ny, nz = 1.0, 0.0, 0.0
        nn = 1.0
    nx, ny, nz = nx / nn, ny / nn, nz / nn
    rx = ny * w1[2] - nz * w1[1]
    ry = nz * w1[0] - nx * w1[2]
    rz = nx * w1[1] - ny * w1[0]
    bank = math.atan2(fx * rx + fy * ry + fz * rz, -(fx * nx + fy * ny + fz * nz))
    load = math.sqrt(fx * fx + fy * fy + fz * fz) / g
    return bank, load


# ----------------------------------------------------------------------------- setpoints
# The law's command -> what an autopilot accepts. Pure: the memory (airspeed integrator,
# learned pitch trim and its airspeed schedule, learned turn gain, pitch-rate bias) is passed in
# and returned as an explicit AdapterState. Why each loop the law leaves open is closed here,
# with its derivation and stability bound: docs/architecture.md, "The setpoint adapter".


@dataclass(frozen=True)
class AdapterParams:
    """Limits and gains of the setpoint adapter (SI units, radians).

    tau_roll_s: first-order time constant to reach the bank set-point (PX4 roll rate);
    tau_pitch_s: look-ahead on the flight-path-angle rate (ArduPlane pitch);
    trim_pitch_rad: angle of attack at trim (pitch = flight-path angle + trim_pitch);
    the energy control's parameters (thrust, airspeed envelope, priority, reserve) are those
    of :class:`~mpf_mavlink.core.energy.Tecs` (same names), which :attr:`tecs` composes.
    """

    max_bank_rad: float = 0.785398
    tau_roll_s: float = 0.5
    tau_pitch_s: float = 1.0
    max_roll_rate_rad_s: float = 1.2217  # 70 deg/s (PX4 FW_R_RMAX)
    max_pitch_rate_rad_s: float = 1.0472  # 60 deg/s
    max_yaw_rate_rad_s: float = 0.8727  # 50 deg/s
    min_pitch_rad: float = -0.35
    max_pitch_rad: float = 0.35
    trim_pitch_rad: float = 0.03
    airspeed_sp_m_s: float = 15.0
    airspeed_min_m_s: float = 0.0  # the envelope the "height" priority protects (m/s)
    airspeed_max_m_s: float = math.inf
    trim_thrust: float = 0.5
    thrust_min: float = 0.0  # PX4 FW_THR_MIN, ArduPlane THR_MIN (electric: 0)
    thrust_max: float = 1.0
    airspeed_kp: float = 0.05  # thrust per m/s
    airspeed_ki: float = 0.02  # thrust per (m/s s)
    # |ki integral(e)| <= this (thrust units); also never beyond what takes the output from
    # trim to thrust_min / thrust_max, so a saturated output stops the integrator there
    integrator_limit: float = 1.0
    load_factor_ff: float = 0.2  # thrust per g of extra load (n - 1)
    adaptive: bool = True  # learn trim_hat and turn_gain (else the fixed trim, ideal turn)
    trim_tau_s: float = 4.0
    trim_limit_rad: float = 0.2  # |trim_hat| <= this; also the bound of K_hat (0..this)
    # pitch trim scheduled with the airspeed set-point (module comment): on/off, the
    # regression's forgetting time (s) and the set-point spread (m/s RMS) it needs to learn
    trim_schedule: bool = True
    trim_schedule_tau_s: float = 60.0
    trim_schedule_min_dv_m_s: float = 0.3
    turn_gain_tau_s: float = 8.0
    turn_gain_min: float = 0.5
    turn_gain_max: float = 1.5
    turn_learn_min_bank_rad: float = 0.0873  # 5 deg: below it the ratio is noise
    # pitch-rate bias (module comment): low-pass time constant of the autopilot's pitch-rate
    # tracking error subtracted from the pitch rate sent; 0 turns it off
    rate_bias_tau_s: float = 1.0
    # total energy control (module comment "speed and height"); False: the airspeed PI above
    energy_control: bool = True
    thrust_per_gamma: float = 2.5  # k_T: throttle per rad of flight-path angle (steady climb)
    speed_tau_s: float = 4.0  # tau_V: airspeed error -> acceleration demand (V_sp - V) / tau_V
    energy_kp: float = 1.0  # k_E: throttle per rad of total energy rate error
    energy_ki: float = 0.6  # k_I: throttle per rad s of it (integral: the energy error)
    vdot_tau_s: float = 2.0  # low-pass of the measured dV/dt and of the fed-forward gamma
    priority: str = "airspeed"  # "airspeed" or "height": what is held when thrust cannot
    balance_tau_s: float = 1.0  # low-pass of the flight-path offset that the priority takes
    # energy reserve (:func:`reserve_airspeed`): the steady climb at full thrust at the set-point
    # (m/s; inf: unknown, no reserve), the design downdraft (m/s, 0: off) and how long it lasts
    # (s), the low-pass of the path's climb (s) and how fast the set-point moves (m/s^2)
    max_climb_m_s: float = math.inf
    reserve_gust_m_s: float = 0.0
    reserve_gust_s: float = 10.0
    reserve_tau_s: float = 20.0
    reserve_rate_m_s2: float = 0.1

    @cached_property
    def tecs(self) -> Tecs:
        """The energy controller (core/energy.py) of these parameters: the fields of its names.
        Built once per parameter set (a frozen dataclass keeps it)."""
        return Tecs(**{f.name: getattr(self, f.name) for f in dataclasses.fields(Tecs)})


class TrimSchedule(NamedTuple):
    """The pitch trim's airspeed schedule (module comment): exponentially weighted moments of
    x = (V_0 / v_sp)^2 (dimensionless) and of the measured theta - gamma y (rad), and the slope
    K_hat (rad per unit x, 0..trim_limit_rad; 0 until the set-point has spread enough)."""

    mx: float | None = None  # mean of x (None: no sample yet)
    my: float = 0.0  # mean of y (rad)
    sxx: float = 0.0  # variance of x
    sxy: float = 0.0  # covariance of x and y (rad)
    k: float = 0.0  # K_hat (rad)
    v_prev: float | None = None  # the set-point last step (m/s)
    vdot_f: float = 0.0  # its rate, low-passed over vdot_tau_s (m/s^2)

    def offset(self, x: float) -> float:
        """The scheduled trim (rad) at x: K_hat (x - mean x), 0 before any sample."""
        return 0.0 if self.mx is None else self.k * (x - self.mx)


class AdapterState(NamedTuple):
    """Memory of the adapter: the learned pitch offset trim_hat (rad, None until the first
    measurement) and turn gain (achieved heading rate per coordinated-turn rate, 1 = ideal),
    what was sent last, and the energy controller's :class:`EnergyState`. A NamedTuple
    (immutable like a frozen dataclass): a new one is built at every control step, ~0.3 us
    against ~2.3 us for the dataclass."""

    trim_hat: float | None = None
    turn_gain: float = 1.0
    bank_prev: float | None = None  # rad, the bank set-point sent last
    # rad/s, the heading rate that bank was sent for (None: the bank was clipped, learn nothing)
    chid_prev: float | None = None
    # rad/s, the autopilot's pitch-rate tracking error (flown - sent, low-passed), and the pitch
    # rate sent last (None: not sent, or sent clipped: learn nothing from it)
    q_bias: float = 0.0
    q_sent: float | None = None
    energy: EnergyState = EnergyState()
    sched: TrimSchedule = TrimSchedule()

    def for_reengage(self, thrust_engaged: float | None = None) -> AdapterState:
        """After a hand-back: the thrust and pitch-rate integrators and the energy filters start
        afresh (the autopilot flew the aircraft meanwhile, its own integrators moved), what was
        learned of the airframe stays. ``thrust_engaged`` (0..1): the thrust the autopilot flies
        now (VFR_HUD.throttle); the energy control's first step starts from it (no step at
        engagement: its integrator takes up the difference from the configured trim)."""
        te = (
            thrust_engaged if thrust_engaged is not None and math.isfinite(thrust_engaged) else None
        )
        return AdapterState(
            self.trim_hat, self.turn_gain, energy=self.energy.for_reengage(te), sched=self.sched
        )


class Setpoint(NamedTuple):
    """What is sent, for either flavour (a NamedTuple: built at every control step).

    body_rates_frd: (p, q, r) rad/s (PX4 type_mask 128; carried for logs with ArduPlane);
    q_wxyz: attitude quaternion (w, x, y, z), roll = bank, yaw = 0 (ArduPlane GUIDED);
    thrust: 0..1; bank_rad, pitch_rad: the attitude set-point; load_factor: n (g);
    safe: True when a non-finite input forced the wings-level, trim-thrust set-point.
    """

    body_rates_frd: tuple[float, float, float]
    q_wxyz: tuple[float, float, float, float]
    thrust: float
    bank_rad: float
    pitch_rad: float
    load_factor: float
    safe: bool = False


#: The state of a first step (no memory yet)
_FRESH = AdapterState()


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


def heading_and_path_angle_rates(w1: Vec, omega: Vec) -> tuple[float, float]:
    """(chi_dot, gamma_dot) rad/s of the direction w1 = [cos g cos c, cos g sin c, -sin g]
    turning at omega (NED, rad/s): w1_dot = omega x w1. Vertical w1 gives (0, gamma_dot)."""
    dx = omega[1] * w1[2] - omega[2] * w1[1]
    dy = omega[2] * w1[0] - omega[0] * w1[2]
    dz = omega[0] * w1[1] - omega[1] * w1[0]
    h2 = w1[0] * w1[0] + w1[1] * w1[1]
    h = math.sqrt(h2)
    if h < 1e-6:
        return 0.0, 0.0
    return (w1[0] * dy - w1[1] * dx) / h2, -dz / h


def roll_rate_gain(tau_roll_s: float, hold_s: float) -> float:
    """Roll rate per radian of bank error (1/s) for a roll-rate set-point held ``hold_s`` s.

    The bank should follow its set-point as a first-order lag of time constant tau_roll. A
    rate set-point held over T from the roll phi_a at which it starts acting does that exactly
    when it closes the fraction 1 - exp(-T / tau_roll) of the error over the hold:
    p = (bank - phi_a) (1 - exp(-T / tau_roll)) / T, the zero-order-hold equivalent of
    (bank - phi) / tau_roll (which it tends to as T -> 0). The loop's poles are then 0 and
    exp(-T / tau_roll). Against the roll predicted to the middle of the hold instead, with the
    continuous gain, the poles are the roots of z^2 + (1.5 T / tau - 1) z - T / (2 tau): +-0.58
    at 10 Hz with tau_roll 0.15 s, and with the rate loop's own lag the alternating one left the
    unit circle (SIL: the roll-rate set-point banged +-70 deg/s at 5 Hz, the X8 0.63 m RMS)."""
    if not (hold_s > 0.0 and math.isfinite(hold_s)):
        return 1.0 / tau_roll_s
    return -math.expm1(-hold_s / tau_roll_s) / hold_s


def safe_setpoint(p: AdapterParams, roll: float = 0.0) -> Setpoint:
    """Wings level, trim pitch, trim thrust; the roll rate levels the wings when roll is known."""
    rr = -roll / p.tau_roll_s if math.isfinite(roll) else 0.0
    rr = _clip(rr, -p.max_roll_rate_rad_s, p.max_roll_rate_rad_s)
    pitch = _clip(p.trim_pitch_rad, p.min_pitch_rad, p.max_pitch_rad)
    thr = _clip(p.trim_thrust, p.thrust_min, p.thrust_max)
    return Setpoint((rr, 0.0, 0.0), quat_of_euler(0.0, pitch, 0.0), thr, 0.0, pitch, 1.0, True)


def adapt(
    omega_w1_I: Vec,
    airspeed: float,
    R_B_N: list[list[float]] | Any,
    w1: Vec,
    dt: float,
    params: AdapterParams,
    state: AdapterState = _FRESH,
    g: float = GRAVITY_M_S2,
    meas: tuple[Any, Any] | None = None,
    hold_s: float = 0.0,
    airspeed_sp: float | None = None,
    path_down_m: float | None = None,
) -> tuple[Setpoint, AdapterState]:
    """The law's command -> body rates (PX4), quaternion (ArduPlane) and thrust.

    omega_w1_I: angular velocity of w1 (NED, rad/s); airspeed (m/s); R_B_N: current attitude
    (body FRD -> NED, 3x3); w1: current unit air-relative velocity (NED); dt (s): time since
    the previous call (for the integrator; 0 freezes it).
    Bank: from the specific force of a = v (omega x w1) (gravity included), clipped to
    +-max_bank. Body rates: p = phid - sin(theta) psid, q = cos(phi) thetad + cos(theta)
    sin(phi) psid, r = -sin(phi) thetad + cos(phi) cos(theta) psid with phid =
    (bank_sp - phi) / tau_roll and psid, thetad the heading and flight-path-angle rates of w1.
    Any non-finite value gives :func:`safe_setpoint` (flag ``safe``) and keeps the integrator.
    ``meas``: (R_B_N, body rates FRD rad/s) as MEASURED (R_B_N may be a prediction), for
    learning trim_hat and turn_gain (module comment); None learns nothing.
    ``hold_s`` (s): how long the set-point is held (the telemetry period; 0: a continuous
    loop), with R_B_N the attitude when it starts acting (:func:`roll_rate_gain`).
    ``airspeed_sp`` (m/s): the airspeed set-point now (None: ``params.airspeed_sp_m_s``, raised
    by the energy reserve, :func:`reserve_airspeed`), its rate fed forward (Tecs.thrust);
    ``path_down_m`` (m, NED down): the law's path point now, whose rate low-passed over
    reserve_tau_s is the sustained climb the reserve is sized for."""
    roll, pitch, ok = _roll_pitch_if_finite(omega_w1_I, airspeed, R_B_N, w1, dt)
    if not ok:
        return safe_setpoint(params, roll), state
    ox, oy, oz = omega_w1_I
    v = airspeed
    accel = (
        v * (oy * w1[2] - oz * w1[1]),
        v * (oz * w1[0] - ox * w1[2]),
        v * (ox * w1[1] - oy * w1[0]),
    )
    bank, n = bank_and_load_factor(w1, accel, g)
    trim_hat, k_turn = state.trim_hat, state.turn_gain
    gamma = math.asin(_clip(-w1[2], -1.0, 1.0))
    chid, gamd_law = heading_and_path_angle_rates(w1, omega_w1_I)
    tecs = params.tecs
    v_sp, energy = tecs.airspeed_setpoint(state.energy, path_down_m, dt, g, airspeed_sp)
    gamd, bal = tecs.flight_path_rate(energy, gamd_law)
    sched, x_sp = _schedule_input(params, state.sched, v_sp, dt)
    if params.adaptive and meas is not None:
        # the law's demand is what trim_hat integrates; not while the priority overrides it
        # (the standing vertical error is then the energy's, not a pitch offset's)
        trim_hat, k_turn, sched = _learn(
            params, state, meas, w1, v, dt, g, gamd_law, gamma, bal != 0.0, x_sp, sched
        )
    if params.adaptive and k_turn != 1.0:
        bank = math.atan(math.tan(_clip(bank, -1.4, 1.4)) / k_turn)
    clipped = abs(bank) > params.max_bank_rad
    bank = _clip(bank, -params.max_bank_rad, params.max_bank_rad)
    p, q, r, q_bias, q_free = _body_rates(
        params, state, meas, dt, hold_s, roll, pitch, bank, chid, gamd
    )
    trim, pitch_sp = _pitch_setpoint(params, trim_hat, gamma, gamd, sched.offset(x_sp))
    thrust, energy = tecs.thrust(energy, v, v_sp, gamma, gamd_law, trim, n, bal, dt, g)
    qw, qx, qy, qz = quat = quat_of_euler(bank, pitch_sp, 0.0)
    if not (
        math.isfinite(p) and math.isfinite(q) and math.isfinite(r) and math.isfinite(thrust)
        and math.isfinite(bank) and math.isfinite(pitch_sp) and math.isfinite(qw)
        and math.isfinite(qx) and math.isfinite(qy) and math.isfinite(qz)
    ):  # fmt: skip
        return safe_setpoint(params, roll), state
    # tuple.__new__: the NamedTuples without their keyword-parsing constructors (every step)
    return tuple.__new__(Setpoint, ((p, q, r), quat, thrust, bank, pitch_sp, n, False)), (
        tuple.__new__(AdapterState, (
            trim_hat, k_turn, bank, None if clipped else chid, q_bias, q if q_free else None,
            energy, sched,
        ))
    )  # fmt: skip


def _roll_pitch_if_finite(
    omega_w1_I: Vec, airspeed: float, R_B_N: list[list[float]] | Any, w1: Vec, dt: float
) -> tuple[float, float, bool]:
    """(roll, pitch, ok) of the attitude R_B_N (rad); ok: every input of :func:`adapt` is
    there, finite, and the airspeed positive (roll 0 when it could not be read)."""
    try:
        # only row 2 is used (a numpy matrix or nested lists)
        R2 = R_B_N[2].tolist() if hasattr(R_B_N, "tolist") else R_B_N[2]  # type: ignore[union-attr]
        roll = math.atan2(R2[1], R2[2])
        pitch = math.asin(_clip(-R2[0], -1.0, 1.0))
        ox, oy, oz = omega_w1_I
        ok = (
            math.isfinite(ox) and math.isfinite(oy) and math.isfinite(oz)
            and math.isfinite(airspeed) and math.isfinite(w1[0]) and math.isfinite(w1[1])
            and math.isfinite(w1[2]) and math.isfinite(dt) and math.isfinite(roll)
            and math.isfinite(pitch) and airspeed > 0.0
        )  # fmt: skip
    except (TypeError, ValueError, IndexError):
        return 0.0, 0.0, False
    return roll, pitch, ok


def _schedule_input(
    params: AdapterParams, st: TrimSchedule, v_sp: float, dt: float
) -> tuple[TrimSchedule, float]:
    """The schedule's memory after this step's set-point v_sp (m/s) and its x = (V_0 / v_ahead)^2
    with v_ahead the set-point one tau_pitch ahead (module comment); x is 1 when the schedule
    is off or v_sp not a positive finite airspeed."""
    if not (params.trim_schedule and params.adaptive and v_sp > 1.0 and math.isfinite(v_sp)):
        return st, 1.0
    vdot_f = st.vdot_f
    if st.v_prev is not None and dt > 0.0:
        a = min(1.0, dt / params.vdot_tau_s) if params.vdot_tau_s > 0.0 else 1.0
        vdot_f += a * ((v_sp - st.v_prev) / dt - vdot_f)
    # never outside the airspeed window the set-point itself keeps to
    v_ahead = _clip(
        v_sp + params.tau_pitch_s * vdot_f,
        max(params.airspeed_min_m_s, 1.0),
        max(params.airspeed_max_m_s, v_sp),
    )
    r = params.airspeed_sp_m_s / v_ahead
    st = st._replace(v_prev=v_sp, vdot_f=vdot_f)
    return st, (r * r if math.isfinite(r) else 1.0)


def _pitch_setpoint(
    params: AdapterParams, trim_hat: float | None, gamma: float, gamd: float, sched: float = 0.0
) -> tuple[float, float]:
    """(trim, pitch set-point) rad: the flight-path angle of w1 (= theta - alpha) advanced by
    tau_pitch, plus the trim angle of attack (learnt when ``adaptive``, with the airspeed
    schedule's ``sched`` rad). Adding the trim to the *measured* pitch would integrate it each
    cycle."""
    if params.adaptive and trim_hat is not None:
        trim = trim_hat + sched
    else:
        trim = params.trim_pitch_rad
    pitch_sp = _clip(
        gamma + gamd * params.tau_pitch_s + trim,
        params.min_pitch_rad,
        params.max_pitch_rad,
    )
    return trim, pitch_sp


def _body_rates(
    params: AdapterParams,
    state: AdapterState,
    meas: tuple[Any, Any] | None,
    dt: float,
    hold_s: float,
    roll: float,
    pitch: float,
    bank: float,
    chid: float,
    gamd: float,
) -> tuple[float, float, float, float, bool]:
    """(p, q, r) FRD rad/s for the bank set-point and the heading/flight-path rates chid, gamd;
    with the pitch-rate bias learnt and whether no limit cut q (see :func:`adapt`)."""
    sphi, cphi = math.sin(roll), math.cos(roll)
    sth, cth = math.sin(pitch), math.cos(pitch)
    phid = (bank - roll) * roll_rate_gain(params.tau_roll_s, hold_s)
    p = _clip(phid - sth * chid, -params.max_roll_rate_rad_s, params.max_roll_rate_rad_s)
    # The body rates carry the pitch limits the attitude set-point has (min/max_pitch_rad): the
    # flight-path rate is cut so the body pitch it aims at one tau_pitch ahead stays within
    # them. Without it a capture from 33 m below the path pitched a PX4 vehicle to 37 deg.
    lead = params.tau_pitch_s if params.tau_pitch_s > 0.0 else 1.0
    gamd_b = _clip(
        gamd, (params.min_pitch_rad - pitch) / lead, (params.max_pitch_rad - pitch) / lead
    )
    q_turn = cth * sphi * chid  # the turn's share of the pitch rate
    q_bias = _pitch_rate_bias(params, state, meas, dt, q_turn)
    q_law = cphi * gamd_b + q_turn - q_bias
    q = _clip(q_law, -params.max_pitch_rate_rad_s, params.max_pitch_rate_rad_s)
    q_free = q == q_law and gamd_b == gamd  # neither the rate nor the pitch limits cut it
    r = _clip(
        -sphi * gamd_b + cphi * cth * chid, -params.max_yaw_rate_rad_s, params.max_yaw_rate_rad_s
    )
    return p, q, r, q_bias, q_free


def _pitch_rate_bias(
    params: AdapterParams,
    state: AdapterState,
    meas: tuple[Any, Any] | None,
    dt: float,
    q_turn: float,
) -> float:
    """The autopilot's pitch-rate tracking error (rad/s, flown - sent), low-passed with
    rate_bias_tau_s from the measured pitch rate against the pitch rate sent last (module
    comment); never beyond the turn's pitch rate q_turn itself (0 with the wings level)."""
    if params.rate_bias_tau_s <= 0.0:
        return 0.0
    b = state.q_bias
    if meas is not None and state.q_sent is not None and dt > 0.0:
        try:
            q_m = float(meas[1][1])
        except (TypeError, ValueError, IndexError):
            q_m = math.nan
        if math.isfinite(q_m):
            b += min(1.0, dt / params.rate_bias_tau_s) * ((q_m - state.q_sent) - b)
    lim = abs(q_turn) if math.isfinite(q_turn) else 0.0
    return _clip(b, -lim, lim)


def _learn(
    params: AdapterParams,
    state: AdapterState,
    meas: tuple[Any, Any],
    w1: Vec,
    v: float,
    dt: float,
    g: float,
    gamd: float,
    gamma: float,
    freeze_trim: bool = False,
    x_sp: float = 1.0,
    sched: TrimSchedule | None = None,
) -> tuple[float | None, float, TrimSchedule]:
    """One step of the three estimates (module comment) from the measured attitude and rates,
    the law's flight-path-angle rate demand gamd (rad/s) and the trim schedule's x_sp of the
    airspeed set-point (``sched``: the schedule's memory this step, default the state's); a
    non-finite or missing measurement changes nothing."""
    trim_hat, k_turn = state.trim_hat, state.turn_gain
    sched = state.sched if sched is None else sched
    sched_in = sched
    try:
        R, rates = meas
        R2 = R[2].tolist() if hasattr(R, "tolist") else R[2]
        phi = math.atan2(R2[1], R2[2])
        theta = math.asin(_clip(-R2[0], -1.0, 1.0))
        q_m, r_m = float(rates[1]), float(rates[2])
    except (TypeError, ValueError, IndexError):
        return trim_hat, k_turn, sched
    off = theta - gamma
    if not (
        math.isfinite(off) and math.isfinite(q_m) and math.isfinite(r_m) and math.isfinite(gamd)
    ):
        return trim_hat, k_turn, sched
    lim = params.trim_limit_rad
    if params.trim_schedule and dt > 0.0:
        sched = _schedule_step(params, sched, x_sp, off, dt)
    if trim_hat is None:
        trim_hat = _clip(off, -lim, lim)
    elif dt > 0.0:
        pitch_sp = gamma + gamd * params.tau_pitch_s + trim_hat + sched_in.offset(x_sp)
        pushing_out = (pitch_sp >= params.max_pitch_rad and gamd > 0) or (
            pitch_sp <= params.min_pitch_rad and gamd < 0
        )
        if not (pushing_out or freeze_trim):
            trim_hat = _clip(
                trim_hat + params.tau_pitch_s / params.trim_tau_s * gamd * dt, -lim, lim
            )
    if dt > 0.0 and params.turn_learn_min_bank_rad <= abs(phi) < 1.2 and v > 1.0:
        psid = (q_m * math.sin(phi) + r_m * math.cos(phi)) / max(math.cos(theta), 0.2)
        # psi_dot = k g tan(phi) / V for the bank flown, not the bank asked (it leads by the
        # roll loop's lag); the integral of the relative error is unbiased where a ratio is not
        pred = k_turn * g * math.tan(phi) / v
        err = (psid - pred) / max(abs(pred), 1e-3) * (1.0 if pred > 0 else -1.0)
        if math.isfinite(err):
            a = min(1.0, dt / params.turn_gain_tau_s)
            k_turn = _clip(
                k_turn + a * k_turn * _clip(err, -0.5, 0.5),
                params.turn_gain_min, params.turn_gain_max,
            )  # fmt: skip
    return trim_hat, k_turn, sched


def _schedule_step(
    params: AdapterParams, st: TrimSchedule, x: float, y: float, dt: float
) -> TrimSchedule:
    """One step of the trim schedule's regression of y = theta - gamma (rad) on x (module
    comment): exponentially weighted moments over trim_schedule_tau_s, and K_hat = cov / var
    once the set-point's spread exceeds trim_schedule_min_dv_m_s (else K_hat stays)."""
    if st.mx is None:
        return st._replace(mx=x, my=y)
    a = min(1.0, dt / params.trim_schedule_tau_s)
    dx, dy = x - st.mx, y - st.my
    mx, my = st.mx + a * dx, st.my + a * dy
    sxx = (1.0 - a) * (st.sxx + a * dx * dx)
    sxy = (1.0 - a) * (st.sxy + a * dx * dy)
    # x's spread for the set-point's: dx = -2 dv / V_0 near V_0
    v0 = params.airspeed_sp_m_s
    dx_min = 2.0 * params.trim_schedule_min_dv_m_s / v0 if v0 > 0.0 else math.inf
    k = st.k
    if sxx > dx_min * dx_min:
        # lift falls with 1 / V^2: the slope on x is the lift's share of the angle, >= 0
        k = _clip(sxy / sxx, 0.0, params.trim_limit_rad)
    return tuple.__new__(TrimSchedule, (mx, my, sxx, sxy, k, st.v_prev, st.vdot_f))
