"""The 3D moving-path-following law (Jain, de Sousa, Aguiar, Theorem 1), pure and exact.

Read it beside the paper: one function per equation, named as the paper names the quantities,
its number in the docstring. Numbers are the paper's as its LaTeX source numbers them
(IEEEtran, in order), with its labels in brackets:

- (1)  [UAVKinematics] pdot = v_w w1 (+ eta_hat, the Remark): :func:`relative_kinematics`.
- (5)  [MPFpositionerrorkinematics] the position error's rate: :func:`error_rates`.
- (6)  [attitudeErrorFunction] Psi = (1 - Rt11) / 2 and (9) [ertilde] e = [Rt13, -Rt12] / 2,
  Rt = R_W^D: :func:`attitude_error`.
- (10) [ffomega] omega_DI = omega_TI + omega_FT + omega_{W_d F} + omega_{D W_d}
  (:func:`desired_frame_rate`; where (11) and (23) print omega_{W_d D}^{W_d}, the rate of
  {W_d} relative to {F} is meant).
- (15) [wdbasis] the steady-state frame {W_d} in {F}: :func:`steady_state_frame`, its rate
  :func:`steady_state_frame_rate`.
- (17)-(19) the cross-track error pt_x and y_w, z_w: :func:`cross_track_errors`, their rates
  :func:`cross_track_rates`.
- (20) R_D^{W_d}, the transient frame {D} in {W_d}: :func:`transient_direction` (its d1) and
  :func:`transient_frame_rate`.
- (22) [sdot] the virtual point's progression: :func:`progression`.
- (23) [omega] -K_R e + Pi_R Rt^T omega_DI^D, the reference for the autopilot:
  :func:`autopilot_reference`.

:func:`mpf_law` composes them: :func:`law_instant` evaluates (1), (22), (15), (17)-(20), (6),
(9) in that order, :func:`desired_rate` the rates (5) and (10), then (23) and the extensions.

Frames: {I} NED; {W} wind frame (w1 along the air-relative velocity); {T} target; {F}
parallel-transport frame at p_d(s); {W_d} steady-state desired velocity frame; {D} transient
desired frame. The frames are built in {T}, where the path is fixed. Vectors are 3-tuples of
floats and rotation matrices R_A^B the tuples of A's axes in B (core/vec3.py: R_F^T = (f1, f2,
f3)): this runs once per bridge step and four times per step of the kinematic simulator, where
a numpy call on a 3-vector costs ~10x the arithmetic.

The feedforward omega_DI (10) must be the exact rate of {D} along the closed-loop flow: each
term is differentiated analytically along the known kinematics (pdot = v_w w1 + eta_hat,
sdot from (22), the target's velocity, acceleration, angular velocity and its rate), never
along telemetry. {W_d} in {F} and {D} in {W_d} are each a heading chi then a climb gamma
from their parent frame (wd32 = 0 in (15), d32 = 0 in (20)), so each turns at chi_dot about
its parent's third axis and -gamma_dot about its own second axis. No I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.float_arrays import FloatArrays
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.paths.base import PathPointRate
from mpf_mavlink.core.target import TargetState
from mpf_mavlink.core.vec3 import Mat3, Vec3, add, cross, dot, mat_T_vec, mat_vec, norm, scale, sub

Vec = Vec3  # the records' vector fields


@dataclass(frozen=True)
class Gains:
    """K_p (1/s) on the along-track error in sdot; K_R (1/s) on the attitude error;
    alpha (m) the look-ahead distance that shapes the transient frame {D}."""

    K_p: float = 4.0
    K_R: float = 2.0
    alpha: float = 1.0


@dataclass(frozen=True)
class Extensions:
    """Practical extensions; all off (the defaults) gives the paper's law bit for bit.

    rate_limit: a cap (rad/s) on the command [w2, w3]; None = off. ``rate_limit_mode``
      ``per_axis`` (the default) caps the flight-path rate w2 and the turn rate w3 each on its
      own, as an autopilot's pitch channel and bank limit are independent: a turn held at its
      limit keeps the whole vertical correction (scaled together, the Cessna convoy's capture
      turn left 0.05 of 0.2 rad/s to the pitch plane and dived 68 m below the path, its
      airspeed falling to 29 m/s in the pull-up). ``magnitude`` scales [w2, w3] down along its
      own direction to |[w2, w3]| <= rate_limit.
    psi_turn: when Psi >= psi_turn_threshold (heading more than 90 deg from d1 by default),
      replace the feedback by a turn of constant rate psi_turn_rate (rad/s; None = K_R/2, which
      equals the law's own feedback magnitude at Psi = 1/2, so the command is continuous there)
      about w1 x d1; at the antipode (w1 = -d1) the turn is a right turn about the local
      vertical. The feedforward is kept.
    wind_compensation: use the vehicle's wind estimate eta_hat in sdot and W_d (the paper's
      Remark); off = eta_hat is ignored (the paper's simulations).
    """

    rate_limit: float | None = None
    rate_limit_mode: Literal["per_axis", "magnitude"] = "per_axis"
    psi_turn: bool = False
    psi_turn_threshold: float = 0.5
    psi_turn_rate: float | None = None
    wind_compensation: bool = False


@dataclass(frozen=True)
class VehicleState:
    """Vehicle at time t (s): position p (NED, m), wind frame R_W_I (columns w1, w2, w3 in
    NED), airspeed v_w (m/s) and the wind estimate eta_hat (NED, m/s, air-mass velocity)."""

    t: float
    position: NDArray[np.float64]
    R_W_I: NDArray[np.float64]
    airspeed: float
    wind: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    # The same numbers as floats in a state made by :func:`vehicle_state_of_floats`: R_W^I by
    # rows (9), then p and eta_hat (3 each). The law reads these; the arrays are built when
    # first read. Not an init argument, so dataclasses.replace drops it (cannot go stale).
    floats: tuple[float, ...] | None = field(default=None, init=False, repr=False, compare=False)


_ARRAYS = FloatArrays((("R_W_I", 0, 9), ("position", 9, 12), ("wind", 12, 15)))
_ARRAYS.install(VehicleState)


def vehicle_state_of_floats(t: float, floats: tuple[float, ...], airspeed: float) -> VehicleState:
    """The :class:`VehicleState` at time t (s) with airspeed v_w (m/s) of 15 floats in the
    order of :attr:`VehicleState.floats` (R_W^I by rows, p, eta_hat), whose arrays are built
    when first read (read-only): the law and the prediction read the floats. Made without the
    frozen dataclass's ``__init__`` (an ``object.__setattr__`` a field) and without numpy
    calls: it is made at every control step."""
    vs = _new(VehicleState)
    d = vs.__dict__
    d["t"], d["airspeed"], d["floats"] = t, airspeed, floats
    return vs


_new = object.__new__


class MpfCommand(NamedTuple):
    """The law's output at time t (s).

    w2, w3: commanded angular velocity of the wind frame about w2 and w3 (rad/s);
    sdot: progression of the virtual point (m/s); omega_w1_I: the same command as the
    angular velocity of w1 in NED (rad/s), which is what the fixed-wing adapter needs.
    (A NamedTuple: immutable like a frozen dataclass, ~5x cheaper to build on the hot path.)
    """

    t: float
    w2: float
    w3: float
    sdot: float
    omega_w1_I: Vec


class MpfDiagnostics(NamedTuple):
    """What the law saw at time t: errors, frames and the feedforward.

    Vectors are tuples (x, y, z) in NED unless noted. A NamedTuple (immutable, typed): a
    frozen dataclass of 20 fields costs ~10 us to build, this ~1 us.
    """

    t: float
    s: float  # virtual point arc length (m)
    pt: Vec  # position error p - p_f (m)
    pt_norm: float  # |pt| (m)
    pt_F: Vec  # pt in {F}: along-track, along f2, along f3 (m)
    p_f: Vec  # desired position p_t + R_T^I p_d(s) (m)
    psi: float  # attitude error function Psi in [0, 1]
    e: tuple[float, float]  # attitude error vector e
    y_w: float  # cross-track error along wd2 (m)
    z_w: float  # cross-track error along wd3 (m)
    d1: Vec  # desired transient direction
    wd1: Vec  # steady-state desired direction
    f1: Vec  # path tangent
    omega_DI: Vec  # angular velocity of {D} relative to {I} (rad/s)
    feedforward: tuple[float, float]  # Pi_R Rt^T omega_DI^D (rad/s)
    w_cmd_law: tuple[float, float]  # the paper's command before extensions (rad/s)
    path_speed_margin: float  # v_w - |v_t t1 + v_d - eta_hat| (m/s); Assumption 1 when > 0
    mode: str  # "law" or "psi_turn", with "+sat" when the rate limit acted
    k1: float  # path curvature along f2 (1/m)
    k2: float  # path curvature along f3 (1/m)


class MpfErrors(NamedTuple):
    """The fields of :class:`MpfDiagnostics` a run's rows record (the same names, units and
    floats), from :func:`mpf_errors`: the errors and frames of an instant without the law's
    rates."""

    t: float
    s: float
    pt: Vec
    pt_norm: float
    p_f: Vec
    psi: float
    e: tuple[float, float]
    y_w: float
    z_w: float
    path_speed_margin: float
    mode: str  # as the caller gave it (mpf_errors)


# --------------------------------------------------------------------------- the inputs
# Vectors are 3-tuples and rotation matrices tuples of their columns (core/vec3.py): R_W^I =
# (w1, w2, w3) in NED, R_T^I = {T}'s axes in NED, R_F^T = (f1, f2, f3), R_{W_d}^F = (wd1, wd2,
# wd3). A numpy call on a 3-vector costs ~1 us; these helpers ~0.1 us.

_ZERO3: Vec3 = (0.0, 0.0, 0.0)


def vehicle_vectors(vehicle: VehicleState, ext: Extensions) -> tuple[Mat3, Vec3, Vec3]:
    """(R_W^I, p, eta_hat) of the vehicle (NED; m, m/s), from its floats when it has them;
    eta_hat is zero without wind compensation (the paper's simulations ignore it)."""
    f = vehicle.floats
    if f is not None:
        R = (f[0], f[3], f[6]), (f[1], f[4], f[7]), (f[2], f[5], f[8])
        return R, (f[9], f[10], f[11]), (f[12], f[13], f[14])
    (a0, b0, c0), (a1, b1, c1), (a2, b2, c2) = vehicle.R_W_I.tolist()
    eta = tuple(vehicle.wind.tolist()) if ext.wind_compensation else _ZERO3
    p = tuple(vehicle.position.tolist())
    return ((a0, a1, a2), (b0, b1, b2), (c0, c1, c2)), p, eta


TargetVectors = tuple[Mat3, Vec3, Vec3, Vec3, Vec3, Vec3]


def target_vectors(target: TargetState) -> TargetVectors:
    """(R_T^I, p_t, v_t, pddot_t, omega_TI^T, its rate) of the target (NED but the last two,
    in {T}; m, m/s, m/s^2, rad/s, rad/s^2), from its floats when it has them."""
    f = target.floats
    if f is not None:
        R = (f[0], f[3], f[6]), (f[1], f[4], f[7]), (f[2], f[5], f[8])
        return R, f[9:12], f[12:15], f[15:18], f[18:21], f[21:24]  # type: ignore[return-value]
    (a0, b0, c0), (a1, b1, c1), (a2, b2, c2) = target.R_T_I.tolist()
    return (
        ((a0, a1, a2), (b0, b1, b2), (c0, c1, c2)), tuple(target.position.tolist()),
        tuple(target.velocity.tolist()), tuple(target.acceleration.tolist()),
        tuple(target.omega_T.tolist()), tuple(target.omega_dot_T.tolist()),
    )  # fmt: skip


# --------------------------------------------------------------------------- the equations


def relative_kinematics(
    R_T_I: Mat3, r: Vec3, v_t: Vec3, eta: Vec3, w1: Vec3, v_w: float, wind: bool
) -> tuple[Vec3, Vec3, Vec3]:
    """(1) [UAVKinematics] pdot = v_w w1 + eta_hat, seen from the target, in {T}: with
    r = p - p_t (NED), q = R_I^T r (m), uu = R_I^T (v_t - eta_hat) (m/s, eta_hat only when
    ``wind``) and c = R_I^T pdot - uu = v_w w1^T - uu, the vehicle's velocity relative to the
    target (m/s)."""
    q = mat_T_vec(R_T_I, r)
    uu = mat_T_vec(R_T_I, sub(v_t, eta) if wind else v_t)
    c = sub(scale(v_w, mat_T_vec(R_T_I, w1)), uu)
    return q, uu, c


def progression(K_p: float, pt_F: Vec3, c: Vec3, v_d: Vec3, f1: Vec3) -> float:
    """(22) [sdot] sdot = (K_p pt + v_w w1 + eta_hat - v_t t1 - v_d) . f1 (m/s): pt_F the
    position error in {F} (m), c = v_w w1 + eta_hat - v_t t1 and v_d = omega_TI x p_d in {T}."""
    return K_p * pt_F[0] + dot(sub(c, v_d), f1)


def steady_state_frame(u_F: Vec3, v_w: float) -> tuple[Mat3, float, float]:
    """(15) [wdbasis] R_{W_d}^F = (wd1, wd2, wd3), components in {F}, from u = v_t t1 + v_d
    (- eta_hat) in {F} (m/s, the velocity the path point asks of the vehicle) and v_w (m/s);
    then nn = wd11^2 + wd21^2 and n = sqrt(nn), which :func:`steady_state_frame_rate` reuses.
    """
    wd21 = u_F[1] / v_w
    wd31 = u_F[2] / v_w
    radicand = 1.0 - wd21 * wd21 - wd31 * wd31
    # Assumption 1 keeps the radicand > 0; outside it the frame stays defined (the
    # diagnostics' path_speed_margin says so).
    wd11 = math.sqrt(radicand) if radicand > 1e-12 else 1e-6
    nn = wd11 * wd11 + wd21 * wd21
    n = math.sqrt(nn)
    wd1 = (wd11, wd21, wd31)
    wd2 = (-wd21 / n, wd11 / n, 0.0)
    return (wd1, wd2, cross(wd1, wd2)), nn, n


def cross_track_errors(pt_F: Vec3, R_Wd_F: Mat3) -> tuple[Vec3, float, float]:
    """(17)-(19) pt_x = pt - (pt . f1) f1 in {F} (m) and y_w = pt_x . wd2, z_w = pt_x . wd3."""
    pt_x = (0.0, pt_F[1], pt_F[2])
    return pt_x, dot(pt_x, R_Wd_F[1]), dot(pt_x, R_Wd_F[2])


def transient_direction(y_w: float, z_w: float, alpha: float) -> Vec3:
    """(20) d1 = (alpha, -y_w, -z_w) / |.|, the first column of R_D^{W_d} (in {W_d}; y_w, z_w
    and the look-ahead alpha in m): all that (6) and (9) use. d2 = (y_w, alpha, 0) / |.| and
    d3 = d1 x d2 enter only through the frame's rate (:func:`transient_frame_rate`)."""
    n1 = norm((alpha, -y_w, -z_w))
    return alpha / n1, -y_w / n1, -z_w / n1


def attitude_error(R_W_I: Mat3, d1: Vec3) -> tuple[float, tuple[float, float]]:
    """(6) [attitudeErrorFunction] Psi = (1 - Rt11) / 2 and (9) [ertilde] e = (Rt13, -Rt12) / 2,
    where Rt = R_W^D = (R_D^I)^T R_W^I has the first row (d1 . w1, d1 . w2, d1 . w3); d1 NED."""
    w1, w2, w3 = R_W_I
    return 0.5 * (1.0 - dot(w1, d1)), (0.5 * dot(w3, d1), -0.5 * dot(w2, d1))


def error_rates(
    c: Vec3, q: Vec3, uu: Vec3, p_d: Vec3, dp_ds: Vec3, sdot: float, omega_FT_F: Vec3,
    R_F_T: Mat3, pt_F: Vec3, u_F: Vec3, a_t: Vec3, omega_T: Vec3, omega_dot_T: Vec3,
) -> tuple[Vec3, Vec3]:  # fmt: skip
    """(5) [MPFpositionerrorkinematics] pt_dot and u_dot (u = v_t t1 + v_d - eta_hat) in {F}
    (m/s, m/s^2), each the rate of its {F} components: d(x^F)/dt = R_T^F x_dot - omega_FT^F x x^F.

    In {T}: pt_dot = qdot - p_d_dot with qdot = c - omega_TI x q and p_d_dot = sdot dp_d/ds;
    u = uu + v_d with d(uu)/dt = a_t - omega_TI x uu (eta_hat held) and v_d = omega_TI x p_d,
    so u_dot = a_t + omega_dot x p_d + omega_TI x (p_d_dot - uu), a_t = R_I^T pddot_t.
    """
    p_d_dot = scale(sdot, dp_ds)
    pt_dot = sub(sub(c, cross(omega_T, q)), p_d_dot)
    u_dot = add(add(a_t, cross(omega_dot_T, p_d)), cross(omega_T, sub(p_d_dot, uu)))
    pt_F_dot = sub(mat_T_vec(R_F_T, pt_dot), cross(omega_FT_F, pt_F))
    u_F_dot = sub(mat_T_vec(R_F_T, u_dot), cross(omega_FT_F, u_F))
    return pt_F_dot, u_F_dot


def steady_state_frame_rate(
    R_Wd_F: Mat3, nn: float, n: float, wd21_dot: float, wd31_dot: float
) -> Vec3:
    """omega_{W_d F}^F (rad/s): (15) differentiated, given the rates of wd21 and wd31 (1/s)
    and nn, n from :func:`steady_state_frame`.

    wd1 = (cos g cos x, cos g sin x, sin g) and wd2 = (-sin x, cos x, 0): heading x then climb g
    in {F}, so omega_{W_d F} = x_dot f3 - g_dot wd2.
    """
    (wd11, wd21, wd31), (wd12, wd22, _), _ = R_Wd_F
    # wd11 = sqrt(1 - wd21^2 - wd31^2); held at its floor outside Assumption 1.
    wd11_dot = -(wd21 * wd21_dot + wd31 * wd31_dot) / wd11 if wd11 > 1e-6 else 0.0
    heading_dot = (wd11 * wd21_dot - wd21 * wd11_dot) / nn
    n_dot = (wd11 * wd11_dot + wd21 * wd21_dot) / n
    m_climb_dot = -((n * wd31_dot - wd31 * n_dot) / (nn + wd31 * wd31))
    return m_climb_dot * wd12, m_climb_dot * wd22, heading_dot


def cross_track_rates(
    pt_x: Vec3, pt_F_dot: Vec3, R_Wd_F: Mat3, omega_WdF_F: Vec3
) -> tuple[float, float]:
    """(17)-(19) differentiated: (y_w_dot, z_w_dot) (m/s) while {W_d} turns at omega_{W_d F}^F:
    d(pt_x . wd_k)/dt = pt_x_dot . wd_k + pt_x . (omega_{W_d F} x wd_k), pt_x_dot = (0, pt_F_dot
    along f2, f3) in {F}."""
    _, wd2, wd3 = R_Wd_F
    pt_x_dot = (0.0, pt_F_dot[1], pt_F_dot[2])
    # pt_x . (omega_{W_d F} x wd2) = pt_x2 x_dot wd12, as omega_{W_d F} = x_dot f3 - g_dot wd2.
    y_w_dot = dot(pt_x_dot, wd2) + pt_x[1] * omega_WdF_F[2] * wd2[0]
    return y_w_dot, dot(pt_x_dot, wd3) + dot(pt_x, cross(omega_WdF_F, wd3))


def transient_frame_rate(
    y_w: float, z_w: float, y_w_dot: float, z_w_dot: float, alpha: float
) -> Vec3:
    """omega_{D W_d}^{W_d} (rad/s): (20) differentiated, given the cross-track errors (m) and
    their rates (m/s).

    d1 = (alpha, -y_w, -z_w) / n1 and d2 = (y_w, alpha, 0) / n2 are heading
    x = atan2(-y_w, alpha) then climb g = atan2(-z_w, n2) in {W_d}, n2 = |(alpha, y_w)|, so
    omega_{D W_d} = x_dot wd3 - g_dot d2.
    """
    nn2 = alpha * alpha + y_w * y_w
    nn1 = nn2 + z_w * z_w
    n2 = math.sqrt(nn2)
    heading_dot = -alpha * y_w_dot / nn2
    m_climb_dot = -((z_w * y_w * y_w_dot / n2 - n2 * z_w_dot) / nn1)
    return m_climb_dot * y_w / n2, m_climb_dot * alpha / n2, heading_dot


def desired_frame_rate(
    R_T_I: Mat3, omega_T: Vec3, R_F_T: Mat3, omega_FT_F: Vec3, R_Wd_F: Mat3,
    omega_WdF_F: Vec3, omega_DWd_Wd: Vec3,
) -> Vec3:  # fmt: skip
    """(10) [ffomega] omega_DI = omega_TI + omega_FT + omega_{W_d F} + omega_{D W_d} (NED,
    rad/s): summed in {F}, into {T} by R_F^T plus omega_TI^T, into NED by R_T^I."""
    omega_DT_F = add(omega_FT_F, add(omega_WdF_F, mat_vec(R_Wd_F, omega_DWd_Wd)))
    return mat_vec(R_T_I, add(omega_T, mat_vec(R_F_T, omega_DT_F)))


def autopilot_reference(
    K_R: float, e: tuple[float, float], omega_DI: Vec3, R_W_I: Mat3
) -> tuple[tuple[float, float], tuple[float, float]]:
    """(23) [omega] [w2, w3] = -K_R e + Pi_R Rt^T omega_DI^D (rad/s), the last term being
    omega_DI on w2, w3 (the feedforward); returns (command, feedforward)."""
    ff = (dot(omega_DI, R_W_I[1]), dot(omega_DI, R_W_I[2]))
    m_K_R = -K_R
    return (m_K_R * e[0] + ff[0], m_K_R * e[1] + ff[1]), ff


# --------------------------------------------------------------------------- extensions


def psi_turn_direction(R_W_I: Mat3, d1: Vec3) -> tuple[float, float]:
    """Unit direction on (w2, w3) of the turn that brings w1 onto d1: about w1 x d1; at the
    antipode (w1 = -d1) a right turn about the local vertical (down)."""
    w1, w2, w3 = R_W_I
    axis = cross(w1, d1)
    n = norm(axis)
    if n > 1e-3:
        return dot(axis, w2) / n, dot(axis, w3) / n
    v2, v3 = w2[2], w3[2]  # the vertical (0, 0, 1) on w2, w3
    nu = math.hypot(v2, v3)
    return (v2 / nu, v3 / nu) if nu > 1e-6 else (0.0, 1.0)


def limit_rates(w2: float, w3: float, ext: Extensions) -> tuple[float, float, bool]:
    """The rate limit of :class:`Extensions` on the command (rad/s); True when it acted."""
    lim = ext.rate_limit
    if lim is None:
        return w2, w3, False
    if ext.rate_limit_mode == "per_axis":
        if abs(w2) > lim or abs(w3) > lim:
            return max(-lim, min(lim, w2)), max(-lim, min(lim, w3)), True
        return w2, w3, False
    mag = math.hypot(w2, w3)
    if mag > lim:
        k = lim / mag
        return w2 * k, w3 * k, True
    return w2, w3, False


def apply_extensions(
    law: tuple[float, float],
    ff: tuple[float, float],
    psi: float,
    d1: Vec3,
    R_W_I: Mat3,
    K_R: float,
    ext: Extensions,
) -> tuple[float, float, str]:
    """The command [w2, w3] (rad/s) after the :class:`Extensions` (the psi turn, then the rate
    limit) from the law's command and its feedforward, and the mode it was made in."""
    cmd2, cmd3 = law
    if not (ext.psi_turn or ext.rate_limit is not None):
        return cmd2, cmd3, "law"
    mode = "law"
    if ext.psi_turn and psi >= ext.psi_turn_threshold:
        rate = ext.psi_turn_rate if ext.psi_turn_rate is not None else 0.5 * K_R
        v2, v3 = psi_turn_direction(R_W_I, d1)
        cmd2, cmd3 = rate * v2 + ff[0], rate * v3 + ff[1]
        mode = "psi_turn"
    if ext.rate_limit is not None:
        cmd2, cmd3, saturated = limit_rates(cmd2, cmd3, ext)
        if saturated:
            mode += "+sat"
    return cmd2, cmd3, mode


# --------------------------------------------------------------------------- the law

_NO_EXTENSIONS = Extensions()
_LawResult = tuple[MpfCommand, MpfDiagnostics | None]
_new_tuple = tuple.__new__  # the NamedTuples without their keyword-parsing constructor (~0.3 us)


class Instant(NamedTuple):
    """What (1), (6), (9), (15)-(22) give at one instant: the law's errors and frames, which
    its rates (5), (10), (23) and the records read. Frames as in the module docstring."""

    t: float  # s
    s: float  # virtual point arc length (m)
    v_w: float  # airspeed (m/s)
    R_W_I: Mat3
    R_T_I: Mat3
    target: TargetVectors
    r: Vec3  # p - p_t (NED, m)
    q: Vec3  # p - p_t in {T} (m)
    uu: Vec3  # v_t - eta_hat in {T} (m/s)
    c: Vec3  # pdot - v_t in {T} (m/s)
    point: PathPointRate  # p_d, f1, f2, f3, k1, k2, dp_d/ds, rate of {F} per unit s (in {T})
    R_F_T: Mat3
    pt_F: Vec3  # position error in {F} (m)
    pt_T: Vec3  # position error in {T} (m)
    u_F: Vec3  # v_t t1 + v_d - eta_hat in {F} (m/s)
    sdot: float  # m/s
    R_Wd_F: Mat3
    nn: float  # wd11^2 + wd21^2
    n: float  # its root
    pt_x: Vec3  # cross-track error in {F} (m)
    y_w: float  # m
    z_w: float  # m
    d1: Vec3  # NED
    psi: float
    e: tuple[float, float]


def law_instant(
    s: float, vehicle: VehicleState, target: TargetState, path: TabulatedPath, gains: Gains,
    ext: Extensions,
) -> Instant:  # fmt: skip
    """(1), (22), (15), (17)-(19), (20), (6), (9) in that order at arc length s (m)."""
    v_w = float(vehicle.airspeed)
    R_W_I, p, eta = vehicle_vectors(vehicle, ext)
    tv = target_vectors(target)
    R_T_I, p_t, v_t, _, omega_T, _ = tv
    r = sub(p, p_t)
    q, uu, c = relative_kinematics(R_T_I, r, v_t, eta, R_W_I[0], v_w, ext.wind_compensation)
    point = path.eval_with_rate(s)
    p_d, f1, f2, f3 = point[:4]
    R_F_T = (f1, f2, f3)
    pt_T = sub(q, p_d)  # the position error pt = p - p_f, in {T}
    pt_F = mat_T_vec(R_F_T, pt_T)
    v_d = cross(omega_T, p_d)  # the path point's velocity from the target's rotation
    sdot = progression(gains.K_p, pt_F, c, v_d, f1)  # (22)
    u_F = mat_T_vec(R_F_T, add(uu, v_d))
    R_Wd_F, nn, n = steady_state_frame(u_F, v_w)  # (15)
    pt_x, y_w, z_w = cross_track_errors(pt_F, R_Wd_F)  # (17)-(19)
    d1_Wd = transient_direction(y_w, z_w, gains.alpha)  # (20)
    d1 = mat_vec(R_T_I, mat_vec(R_F_T, mat_vec(R_Wd_F, d1_Wd)))  # R_T^I R_F^T R_{W_d}^F d1
    psi, e = attitude_error(R_W_I, d1)  # (6), (9)
    return _new_tuple(Instant, (
        float(vehicle.t), s, v_w, R_W_I, R_T_I, tv, r, q, uu, c, point, R_F_T, pt_F, pt_T, u_F,
        sdot, R_Wd_F, nn, n, pt_x, y_w, z_w, d1, psi, e,
    ))  # fmt: skip


def desired_rate(x: Instant, alpha: float) -> Vec3:
    """(5), (15)', (17)-(20)' and (10): omega_DI (NED, rad/s), the exact rate of {D} along the
    closed-loop flow at the instant x, each frame's rate in turn."""
    _, _, _, a_I, omega_T, omega_dot_T = x.target
    p_d, dp_ds, rate_F = x.point[0], x.point[6], x.point[7]
    omega_FT_F = scale(x.sdot, rate_F)  # parallel transport: sdot (tau, -kappa_2, kappa_1)
    pt_F_dot, u_F_dot = error_rates(
        x.c, x.q, x.uu, p_d, dp_ds, x.sdot, omega_FT_F, x.R_F_T, x.pt_F, x.u_F,
        mat_T_vec(x.R_T_I, a_I), omega_T, omega_dot_T,
    )  # (5)  # fmt: skip
    omega_WdF_F = steady_state_frame_rate(
        x.R_Wd_F, x.nn, x.n, u_F_dot[1] / x.v_w, u_F_dot[2] / x.v_w
    )  # (15) differentiated
    y_w_dot, z_w_dot = cross_track_rates(x.pt_x, pt_F_dot, x.R_Wd_F, omega_WdF_F)
    omega_DWd_Wd = transient_frame_rate(x.y_w, x.z_w, y_w_dot, z_w_dot, alpha)
    return desired_frame_rate(
        x.R_T_I, omega_T, x.R_F_T, omega_FT_F, x.R_Wd_F, omega_WdF_F, omega_DWd_Wd
    )  # (10)


def mpf_law(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = _NO_EXTENSIONS,
    diagnostics: bool = True,
    errors_mode: str | None = None,
) -> tuple[MpfCommand, MpfDiagnostics | None]:
    """Evaluate the MPF law (22) [sdot], (23) [omega] at the vehicle's time.

    s is the virtual point's arc length (m, unwrapped); the target state must be for the same
    time as the vehicle (extrapolate it first: :meth:`TargetState.extrapolate`).
    Returns the command and the diagnostics record (None when ``diagnostics`` is False, which
    saves the cost of building it inside integrators). ``errors_mode``: :func:`mpf_errors`'s
    (it then returns None and an :class:`MpfErrors` recorded with that mode).
    """
    x = law_instant(float(s), vehicle, target, path, gains, ext)
    if errors_mode is not None:  # mpf_errors: the record without the rates
        return cast(_LawResult, (None, errors_record(x, errors_mode)))  # mpf_errors unwraps it
    omega_DI = desired_rate(x, gains.alpha)  # (10)
    law, ff = autopilot_reference(gains.K_R, x.e, omega_DI, x.R_W_I)  # (23)
    cmd2, cmd3, mode = apply_extensions(law, ff, x.psi, x.d1, x.R_W_I, gains.K_R, ext)
    # The command's omega_w1_I is R_W^I [0, w2, w3], in NED.
    omega_w1_I = add(scale(cmd2, x.R_W_I[1]), scale(cmd3, x.R_W_I[2]))
    cmd: MpfCommand = _new_tuple(MpfCommand, (x.t, cmd2, cmd3, x.sdot, omega_w1_I))
    if not diagnostics:
        return cmd, None
    return cmd, diagnostics_record(x, omega_DI, ff, law, mode)


def _record_vectors(x: Instant) -> tuple[Vec3, float, Vec3, float]:
    """(pt NED, |pt|, p_f NED, v_w - |u|): the position error pt = (p - p_t) - R_T^I p_d (m),
    the desired point p_f = p_t + R_T^I p_d (m) and the Assumption 1 margin (m/s, |u| = |u_F|)."""
    p_d_I = mat_vec(x.R_T_I, x.point[0])
    return sub(x.r, p_d_I), norm(x.pt_T), add(x.target[1], p_d_I), x.v_w - norm(x.u_F)


def errors_record(x: Instant, mode: str) -> MpfErrors:
    """The :class:`MpfErrors` of the instant x, recorded with ``mode``."""
    pt, pt_norm, p_f, margin = _record_vectors(x)
    return _new_tuple(
        MpfErrors, (x.t, x.s, pt, pt_norm, p_f, x.psi, x.e, x.y_w, x.z_w, margin, mode)
    )


def diagnostics_record(
    x: Instant, omega_DI: Vec3, ff: tuple[float, float], law: tuple[float, float], mode: str
) -> MpfDiagnostics:
    """The :class:`MpfDiagnostics` of the instant x and its rates; wd1 = R_T^I R_F^T wd1^F and
    f1 into NED."""
    pt, pt_norm, p_f, margin = _record_vectors(x)
    wd1 = mat_vec(x.R_T_I, mat_vec(x.R_F_T, x.R_Wd_F[0]))
    f1 = mat_vec(x.R_T_I, x.R_F_T[0])
    return _new_tuple(MpfDiagnostics, (
        x.t, x.s, pt, pt_norm, x.pt_F, p_f, x.psi, x.e, x.y_w, x.z_w, x.d1, wd1, f1, omega_DI,
        ff, law, margin, mode, x.point[4], x.point[5],
    ))  # fmt: skip


def mpf_errors(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = _NO_EXTENSIONS,
    mode: str = "law",
) -> MpfErrors:
    """The errors and frames of :func:`mpf_law` at (s, vehicle, target), without its rates
    (10)-(23): the record of an instant that is logged but not flown (the bridge's sample
    instant when the command comes from a predicted state), at half the law's cost. The same
    code as the law's up to (9), so the same floats as its :class:`MpfDiagnostics`; ``mode``
    is recorded as given (the mode of the evaluation that was flown)."""
    return errors_record(law_instant(float(s), vehicle, target, path, gains, ext), mode)
