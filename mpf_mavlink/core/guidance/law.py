"""The 3D moving-path-following law (Jain, de Sousa, Aguiar, Theorem 1), pure and exact.

Read it beside the paper. Equation numbers are the paper's as its LaTeX source numbers them
(IEEEtran, in order), with its labels in brackets:

- (1)  [UAVKinematics] pdot = v_w w1 (plus the wind estimate eta_hat, the paper's Remark).
- (5)  [MPFpositionerrorkinematics] the position error's rate, used for the feedforward.
- (6)  [attitudeErrorFunction] Psi = (1 - Rt11) / 2, Rt = R_W^D.
- (9)  [ertilde] e = [Rt13, -Rt12] / 2.
- (10) [ffomega] omega_DI = omega_TI + omega_FT + omega_{W_d F} + omega_{D W_d} (where (11)
  and (23) print omega_{W_d D}^{W_d}, the rate of {W_d} relative to {F} is meant).
- (15) [wdbasis] the steady-state frame {W_d} in {F}: :func:`steady_state_frame`.
- (17)-(19) the cross-track error pt_x and y_w, z_w: :func:`cross_track_errors`.
- (20) R_D^{W_d}, the transient frame {D} in {W_d}: :func:`transient_direction` (its d1)
  and :func:`transient_frame_rate`.
- (22) [sdot] the virtual point's progression.
- (23) [omega] -K_R e + Pi_R Rt^T omega_DI^D, the reference for the autopilot: :func:`mpf_law`.

Frames: {I} NED; {W} wind frame (w1 along the air-relative velocity); {T} target; {F}
parallel-transport frame at p_d(s); {W_d} steady-state desired velocity frame; {D} transient
desired frame. The frames are built in {T}, where the path is fixed. Vectors and matrices are
tuples (:mod:`mpf_mavlink.core.vec3`; matrices by columns, so R_F^T = (f1, f2, f3)).

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
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetState
from mpf_mavlink.core.vec3 import (
    Mat3,
    Vec3,
    cross,
    dot,
    norm,
)

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


_ZERO: Vec3 = (0.0, 0.0, 0.0)


def steady_state_frame(u_F: Vec3, v_w: float) -> Mat3:
    """(15) [wdbasis] R_{W_d}^F = (wd1, wd2, wd3), components in {F}.

    u_F: u = v_t t1 + v_d (- eta_hat with wind compensation) in {F}, the velocity the path
    point asks of the vehicle (m/s); v_w airspeed (m/s).
    """
    wd21 = u_F[1] / v_w
    wd31 = u_F[2] / v_w
    radicand = 1.0 - wd21 * wd21 - wd31 * wd31
    # Assumption 1 keeps the radicand > 0; outside it the frame stays defined (the
    # diagnostics' path_speed_margin says so).
    wd11 = math.sqrt(radicand) if radicand > 1e-12 else 1e-6
    n = math.sqrt(wd11 * wd11 + wd21 * wd21)
    wd12, wd22 = -wd21 / n, wd11 / n  # wd32 = 0
    # wd3 = wd1 x wd2, written out with wd32 = 0.
    wd13, wd23, wd33 = -wd31 * wd22, wd31 * wd12, wd11 * wd22 - wd21 * wd12
    return (wd11, wd21, wd31), (wd12, wd22, 0.0), (wd13, wd23, wd33)


def steady_state_frame_rate(R_Wd_F: Mat3, wd21_dot: float, wd31_dot: float) -> Vec3:
    """omega_{W_d F}^F (rad/s): (15) differentiated, given the rates of wd21 and wd31 (1/s).

    wd1 = (cos g cos x, cos g sin x, sin g) and wd2 = (-sin x, cos x, 0): heading x then climb g
    in {F}, so omega_{W_d F} = x_dot f3 - g_dot wd2.
    """
    (wd11, wd21, wd31), (wd12, wd22, _), _ = R_Wd_F
    # wd11 = sqrt(1 - wd21^2 - wd31^2); held at its floor outside Assumption 1.
    wd11_dot = -(wd21 * wd21_dot + wd31 * wd31_dot) / wd11 if wd11 > 1e-6 else 0.0
    nn = wd11 * wd11 + wd21 * wd21  # cos^2 g
    n = math.sqrt(nn)
    heading_dot = (wd11 * wd21_dot - wd21 * wd11_dot) / nn
    n_dot = (wd11 * wd11_dot + wd21 * wd21_dot) / n
    climb_dot = (n * wd31_dot - wd31 * n_dot) / (nn + wd31 * wd31)
    return (-climb_dot * wd12, -climb_dot * wd22, heading_dot)


def cross_track_errors(pt_F: Vec3, R_Wd_F: Mat3) -> tuple[float, float]:
    """(17)-(19): y_w = pt_x . wd2 and z_w = pt_x . wd3 (m), where pt_x = (0, pt.f2, pt.f3) in
    {F} is the cross-track error; pt_F is pt in {F}, and wd32 = 0."""
    _, pt_f2, pt_f3 = pt_F
    (_, wd22, _), (_, wd23, wd33) = R_Wd_F[1], R_Wd_F[2]
    return pt_f2 * wd22, pt_f2 * wd23 + pt_f3 * wd33


def cross_track_rates(
    pt_F: Vec3, pt_f2_dot: float, pt_f3_dot: float, R_Wd_F: Mat3, omega_WdF_F: Vec3
) -> tuple[float, float]:
    """d/dt of (18)-(19) (m/s): y_w = pt.f2 wd22 and z_w = pt.f2 wd23 + pt.f3 wd33, given the
    rates of pt.f2, pt.f3, while {W_d} turns at omega = omega_{W_d F}^F = (o1, o2, o3):
    d(wd_k)/dt = omega x wd_k, of which the components used here are written out."""
    _, x2, x3 = pt_F
    _, (wd12, wd22, _), (wd13, wd23, wd33) = R_Wd_F
    o1, o2, o3 = omega_WdF_F
    y_w_dot = pt_f2_dot * wd22 + x2 * o3 * wd12  # d(wd22)/dt = o3 wd12 (wd32 = 0)
    z_w_dot = pt_f2_dot * wd23 + pt_f3_dot * wd33
    z_w_dot += x2 * (o3 * wd13 - o1 * wd33) + x3 * (o1 * wd23 - o2 * wd13)
    return y_w_dot, z_w_dot


def transient_direction(y_w: float, z_w: float, alpha: float) -> Vec3:
    """(20) d1, the first column of R_D^{W_d} (components in {W_d}; alpha (m) the look-ahead):
    all that (6) and (9) use. The frame's other columns, d2 = (y_w, alpha, 0) / |(alpha, y_w)|
    and d3 = d1 x d2, enter only through its rate (:func:`transient_frame_rate`)."""
    n1 = math.sqrt(alpha * alpha + y_w * y_w + z_w * z_w)
    return alpha / n1, -y_w / n1, -z_w / n1


def transient_frame_rate(
    y_w: float, z_w: float, y_w_dot: float, z_w_dot: float, alpha: float
) -> Vec3:
    """omega_{D W_d}^{W_d} (rad/s): (20) differentiated.

    d1 = (alpha, -y_w, -z_w) / n1 and d2 = (y_w, alpha, 0) / n2 are heading
    x = atan2(-y_w, alpha) then climb g = atan2(-z_w, n2) in {W_d}, n2 = |(alpha, y_w)|, so
    omega_{D W_d} = x_dot wd3 - g_dot d2.
    """
    nn2 = alpha * alpha + y_w * y_w
    nn1 = nn2 + z_w * z_w
    n2 = math.sqrt(nn2)
    heading_dot = -alpha * y_w_dot / nn2
    climb_dot = (z_w * y_w * y_w_dot / n2 - n2 * z_w_dot) / nn1
    return (-climb_dot * y_w / n2, -climb_dot * alpha / n2, heading_dot)


def progression_rate(pt_f1: float, r: Vec3, f1: Vec3, K_p: float) -> float:
    """(22) [sdot] = (K_p pt + v_w w1 + eta_hat - v_t t1 - v_d) . f1 (m/s), in {T}, where
    pt_f1 = pt . f1 and r = R_I^T (v_w w1 + eta_hat - v_t) - v_d is the vehicle's velocity
    relative to the path point (m/s)."""
    r0, r1, r2 = r
    e0, e1, e2 = f1
    return K_p * pt_f1 + (r0 * e0 + r1 * e1 + r2 * e2)


def feedforward_omega_DT(
    sdot: float,
    dp_ds: Vec3,
    rate_F: Vec3,
    R_F_T: Mat3,
    R_Wd_F: Mat3,
    y_w: float,
    z_w: float,
    alpha: float,
    v_w: float,
    flow: tuple[Vec3, Vec3, Vec3, Vec3, Vec3, Vec3, Vec3, Vec3, Vec3],
) -> Vec3:
    """omega_DT^T (rad/s): (10) less omega_TI, i.e. omega_FT + omega_{W_d F} + omega_{D W_d},
    each the exact derivative of its frame along the closed-loop flow.

    sdot (22); dp_ds, rate_F from :meth:`TabulatedPath.eval_with_rate`; R_F^T, R_{W_d}^F,
    y_w, z_w, alpha as in (15)-(20). flow, all in {T}: q = R_I^T (p - p_t), c = R_I^T (pdot -
    v_t) (m/s), uu = R_I^T (v_t - eta_hat), a_t = R_I^T pddot_t (m/s^2), omega_TI^T (rad/s),
    its rate (rad/s^2), p_d, and pt and u (15) in {F}.
    """
    q, c, uu, a_t, omega, omega_dot, p_d, pt_F, u_F = flow
    tau, m_kappa_2, kappa_1 = rate_F
    o1, o2, o3 = sdot * tau, sdot * m_kappa_2, sdot * kappa_1  # omega_FT^F
    # (5) in {T}: pt_dot = qdot - p_d_dot with qdot = c - omega_TI x q and p_d_dot = sdot
    # dp_d/ds; u = uu + v_d with d(uu)/dt = a_t - omega_TI x uu (eta_hat held) and
    # v_d = omega_TI x p_d, so u_dot = a_t + omega_dot x p_d + omega_TI x (p_d_dot - uu).
    # The vector algebra is written out on scalars: this is the hot path.
    w0, w1, w2 = omega
    g0, g1, g2 = dp_ds
    pd0, pd1, pd2 = sdot * g0, sdot * g1, sdot * g2
    x0, x1, x2 = q
    c0, c1, c2 = c
    pt_dot0 = c0 - (w1 * x2 - w2 * x1) - pd0
    pt_dot1 = c1 - (w2 * x0 - w0 * x2) - pd1
    pt_dot2 = c2 - (w0 * x1 - w1 * x0) - pd2
    x0, x1, x2 = p_d
    c0, c1, c2 = omega_dot
    g0, g1, g2 = uu
    g0, g1, g2 = pd0 - g0, pd1 - g1, pd2 - g2
    a0, a1, a2 = a_t
    u_dot0 = a0 + (c1 * x2 - c2 * x1) + (w1 * g2 - w2 * g1)
    u_dot1 = a1 + (c2 * x0 - c0 * x2) + (w2 * g0 - w0 * g2)
    u_dot2 = a2 + (c0 * x1 - c1 * x0) + (w0 * g1 - w1 * g0)
    # Their f2, f3 components (all that (15), (18), (19) use) in {F}, which turns at
    # omega_FT: d(f_k . x)/dt = f_k . x_dot - (omega_FT^F x x^F)_k.
    _, (a0, a1, a2), (c0, c1, c2) = R_F_T  # f2, f3
    x0, x1, x2 = pt_F
    pt_f2_dot = a0 * pt_dot0 + a1 * pt_dot1 + a2 * pt_dot2 - (o3 * x0 - o1 * x2)
    pt_f3_dot = c0 * pt_dot0 + c1 * pt_dot1 + c2 * pt_dot2 - (o1 * x1 - o2 * x0)
    x0, x1, x2 = u_F
    wd21_dot = (a0 * u_dot0 + a1 * u_dot1 + a2 * u_dot2 - (o3 * x0 - o1 * x2)) / v_w
    wd31_dot = (c0 * u_dot0 + c1 * u_dot1 + c2 * u_dot2 - (o1 * x1 - o2 * x0)) / v_w
    omega_WdF_F = steady_state_frame_rate(R_Wd_F, wd21_dot, wd31_dot)
    y_w_dot, z_w_dot = cross_track_rates(pt_F, pt_f2_dot, pt_f3_dot, R_Wd_F, omega_WdF_F)
    b0, b1, b2 = transient_frame_rate(y_w, z_w, y_w_dot, z_w_dot, alpha)
    # Summed in {F}: omega_FT^F + omega_{W_d F}^F + R_{W_d}^F omega_{D W_d}^{W_d} (wd32 = 0),
    # then into {T} by R_F^T.
    a0, a1, a2 = omega_WdF_F
    (x0, x1, x2), (g0, g1, _), (c0, c1, c2) = R_Wd_F
    o1 += a0 + (b0 * x0 + b1 * g0 + b2 * c0)
    o2 += a1 + (b0 * x1 + b1 * g1 + b2 * c1)
    o3 += a2 + (b0 * x2 + b2 * c2)
    (x0, x1, x2), (a0, a1, a2), (c0, c1, c2) = R_F_T
    return (
        o1 * x0 + o2 * a0 + o3 * c0,
        o1 * x1 + o2 * a1 + o3 * c1,
        o1 * x2 + o2 * a2 + o3 * c2,
    )


def attitude_error(d1: Vec3, w1: Vec3, w2: Vec3, w3: Vec3) -> tuple[float, float, float]:
    """(6) Psi and (9) e = (e2, e3) from d1 and the columns w1, w2, w3 of R_W^I (all in NED).

    Rt = R_W^D = (R_D^I)^T R_W^I; its first row is (d1.w1, d1.w2, d1.w3).
    """
    d0, d1_, d2 = d1
    a0, a1, a2 = w1
    b0, b1, b2 = w2
    c0, c1, c2 = w3
    Rt11 = a0 * d0 + a1 * d1_ + a2 * d2
    Rt12 = b0 * d0 + b1 * d1_ + b2 * d2
    Rt13 = c0 * d0 + c1 * d1_ + c2 * d2
    return 0.5 * (1.0 - Rt11), 0.5 * Rt13, -0.5 * Rt12


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
    law2: float,
    law3: float,
    ff2: float,
    ff3: float,
    psi: float,
    d1: Vec3,
    R_W_I: Mat3,
    K_R: float,
    ext: Extensions,
) -> tuple[float, float, str]:
    """The command [w2, w3] (rad/s) after the :class:`Extensions` (the psi turn, then the rate
    limit) from the law's command and its feedforward, and the mode it was made in."""
    if not (ext.psi_turn or ext.rate_limit is not None):
        return law2, law3, "law"
    cmd2, cmd3 = law2, law3
    mode = "law"
    if ext.psi_turn and psi >= ext.psi_turn_threshold:
        rate = ext.psi_turn_rate if ext.psi_turn_rate is not None else 0.5 * K_R
        v2, v3 = psi_turn_direction(R_W_I, d1)
        cmd2, cmd3 = rate * v2 + ff2, rate * v3 + ff3
        mode = "psi_turn"
    if ext.rate_limit is not None:
        cmd2, cmd3, saturated = limit_rates(cmd2, cmd3, ext)
        if saturated:
            mode += "+sat"
    return cmd2, cmd3, mode


def _diagnostics(
    t: float, s: float, R_I_T: Mat3, R_F_T: Mat3, wd1_F: Vec3, d1: Vec3, x_I: Vec3, p_t: Vec3,
    p_d: Vec3, pt: Vec3, pt_F: Vec3, y_w: float, z_w: float, psi: float, e2: float, e3: float,
    margin: float, omega_DI: Vec3, ff2: float, ff3: float, law2: float, law3: float, mode: str,
    k1: float, k2: float,
) -> MpfDiagnostics:  # fmt: skip
    """The record of what :func:`mpf_law` saw, its vectors in NED (see :class:`MpfDiagnostics`).

    Given (positional, this runs at every bridge frame): the frames R_I^T, R_F^T, wd1 in {F}
    and d1 (NED); the errors p - p_t (NED), p_t, p_d, pt and pt in {F} ({T} unless noted),
    y_w, z_w, Psi, e2, e3 and the Assumption 1 margin; the rates omega_DI (NED), the
    feedforward and the law's command on w2, w3; the mode and the curvatures k1, k2.
    """
    # Into NED by R_T^I (written out, as in mpf_law): p_d (p_f = p_t + p_d and pt = (p - p_t)
    # - p_d), wd1 = R_T^I R_F^T wd1^F and f1.
    (xn, yn, zn), (xe, ye, ze), (xd, yd, zd) = R_I_T
    (f1x, f1y, f1z), (f2x, f2y, f2z), (f3x, f3y, f3z) = R_F_T
    a0, a1, a2 = p_d
    pdn = xn * a0 + yn * a1 + zn * a2
    pde = xe * a0 + ye * a1 + ze * a2
    pdd = xd * a0 + yd * a1 + zd * a2
    x0, x1, x2 = wd1_F
    a0 = x0 * f1x + x1 * f2x + x2 * f3x
    a1 = x0 * f1y + x1 * f2y + x2 * f3y
    a2 = x0 * f1z + x1 * f2z + x2 * f3z
    wd1 = (xn * a0 + yn * a1 + zn * a2, xe * a0 + ye * a1 + ze * a2, xd * a0 + yd * a1 + zd * a2)
    f1 = (
        xn * f1x + yn * f1y + zn * f1z,
        xe * f1x + ye * f1y + ze * f1z,
        xd * f1x + yd * f1y + zd * f1z,
    )
    a0, a1, a2 = x_I
    b0, b1, b2 = p_t
    x0, x1, x2 = pt
    # tuple.__new__: the NamedTuple without its keyword-parsing constructor (hot path).
    return tuple.__new__(
        MpfDiagnostics,
        (t, s, (a0 - pdn, a1 - pde, a2 - pdd), math.sqrt(x0 * x0 + x1 * x1 + x2 * x2),
         pt_F, (b0 + pdn, b1 + pde, b2 + pdd), psi, (e2, e3), y_w, z_w, d1, wd1, f1,
         omega_DI, (ff2, ff3), (law2, law3), margin, mode, k1, k2),
    )  # fmt: skip


_NO_EXTENSIONS = Extensions()


def mpf_law(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = _NO_EXTENSIONS,
    diagnostics: bool = True,
) -> tuple[MpfCommand, MpfDiagnostics | None]:
    """Evaluate the MPF law (22) [sdot], (23) [omega] at the vehicle's time.

    s is the virtual point's arc length (m, unwrapped); the target state must be for the same
    time as the vehicle (extrapolate it first: :meth:`TargetState.extrapolate`).
    Returns the command and the diagnostics record (None when ``diagnostics`` is False, which
    saves the cost of building it inside integrators).

    This is the hot path (once per bridge step, four times per step of the kinematic RK4), so
    it is written out on scalars: rotations as sums of products (vec3 says what they are),
    vectors unpacked into named components ({T}'s x, y, z; NED's n, e, d) rather than indexed.
    """
    t = float(vehicle.t)
    s = float(s)
    v_w = float(vehicle.airspeed)
    K_p, K_R, alpha = gains.K_p, gains.K_R, gains.alpha
    # ndarray.tolist() gives lists, which are only unpacked. R_W^I's rows hold the north, east
    # and down components of w1, w2, w3; R_T^I's rows are NED's axes in {T} (the columns of
    # R_I^T = (R_T^I)^T, so mat_T_vec(R_I_T, .) is R_T^I).
    (w1n, w2n, w3n), (w1e, w2e, w3e), (w1d, w2d, w3d) = vehicle.R_W_I.tolist()
    R_I_T: Mat3 = target.R_T_I.tolist()
    (xn, yn, zn), (xe, ye, ze), (xd, yd, zd) = R_I_T  # north, east, down axes in {T}
    p_t: Vec3 = target.position.tolist()
    omega_TI: Vec3 = target.omega_T.tolist()  # omega_TI^T
    ox, oy, oz = omega_TI

    # Into {T}, where the path is fixed: the vehicle relative to the target, the target's
    # velocity less the wind, and the vehicle's velocity (1) relative to the target's,
    # c = R_I^T (v_w w1 + eta_hat - v_t) = v_w w1^T - uu.
    a0, a1, a2 = vehicle.position.tolist()
    b0, b1, b2 = p_t
    x_I = a0, a1, a2 = a0 - b0, a1 - b1, a2 - b2  # p - p_t in NED
    q = (xn * a0 + xe * a1 + xd * a2, yn * a0 + ye * a1 + yd * a2, zn * a0 + ze * a1 + zd * a2)
    a0, a1, a2 = target.velocity.tolist()
    if ext.wind_compensation:
        b0, b1, b2 = vehicle.wind.tolist()
        a0, a1, a2 = a0 - b0, a1 - b1, a2 - b2
    uu = u0, u1, u2 = (
        xn * a0 + xe * a1 + xd * a2,
        yn * a0 + ye * a1 + yd * a2,
        zn * a0 + ze * a1 + zd * a2,
    )
    c = c0, c1, c2 = (
        v_w * (xn * w1n + xe * w1e + xd * w1d) - u0,
        v_w * (yn * w1n + ye * w1e + yd * w1d) - u1,
        v_w * (zn * w1n + ze * w1e + zd * w1d) - u2,
    )

    # The virtual point: p_d(s), R_F^T, dp_d/ds and the rate of {F} per unit s.
    p_d, f1, f2, f3, k1, k2, dp_ds, rate_F = path.eval_with_rate(s)
    (f1x, f1y, f1z), (f2x, f2y, f2z), (f3x, f3y, f3z) = f1, f2, f3
    a0, a1, a2 = p_d
    x0, x1, x2 = q
    x0, x1, x2 = pt = (x0 - a0, x1 - a1, x2 - a2)  # position error pt = p - p_f, in {T}
    pt_F = pt_f1, _, _ = (  # (f1 . pt, f2 . pt, f3 . pt)
        f1x * x0 + f1y * x1 + f1z * x2,
        f2x * x0 + f2y * x1 + f2z * x2,
        f3x * x0 + f3y * x1 + f3z * x2,
    )
    b0, b1, b2 = oy * a2 - oz * a1, oz * a0 - ox * a2, ox * a1 - oy * a0  # v_d = omega_TI x p_d
    sdot = progression_rate(pt_f1, (c0 - b0, c1 - b1, c2 - b2), f1, K_p)  # (22)

    # The desired frames (15), (17)-(19), (20).
    x0, x1, x2 = u0 + b0, u1 + b1, u2 + b2  # u = v_t t1 + v_d - eta_hat
    u_F = (
        f1x * x0 + f1y * x1 + f1z * x2,
        f2x * x0 + f2y * x1 + f2z * x2,
        f3x * x0 + f3y * x1 + f3z * x2,
    )
    R_Wd_F = steady_state_frame(u_F, v_w)
    y_w, z_w = cross_track_errors(pt_F, R_Wd_F)
    x0, x1, x2 = transient_direction(y_w, z_w, alpha)
    # d1 = R_T^I R_F^T R_{W_d}^F d1^{W_d}, in NED (wd32 = 0).
    (a0, a1, a2), (b0, b1, _), (b2, g1, g2) = R_Wd_F
    a0, a1, a2 = x0 * a0 + x1 * b0 + x2 * b2, x0 * a1 + x1 * b1 + x2 * g1, x0 * a2 + x2 * g2
    b0 = a0 * f1x + a1 * f2x + a2 * f3x
    b1 = a0 * f1y + a1 * f2y + a2 * f3y
    b2 = a0 * f1z + a1 * f2z + a2 * f3z
    d1_I = (xn * b0 + yn * b1 + zn * b2, xe * b0 + ye * b1 + ze * b2, xd * b0 + yd * b1 + zd * b2)
    w1, w2, w3 = (w1n, w1e, w1d), (w2n, w2e, w2d), (w3n, w3e, w3d)
    psi, e2, e3 = attitude_error(d1_I, w1, w2, w3)  # (6), (9)

    # (10) omega_DI = omega_TI + omega_FT + omega_{W_d F} + omega_{D W_d}, each term exact.
    a0, a1, a2 = target.acceleration.tolist()
    a_t = (xn * a0 + xe * a1 + xd * a2, yn * a0 + ye * a1 + yd * a2, zn * a0 + ze * a1 + zd * a2)
    flow = (q, c, uu, a_t, omega_TI, target.omega_dot_T.tolist(), p_d, pt_F, u_F)
    R_F_T: Mat3 = (f1, f2, f3)
    b0, b1, b2 = feedforward_omega_DT(
        sdot, dp_ds, rate_F, R_F_T, R_Wd_F, y_w, z_w, alpha, v_w, flow
    )
    a0, a1, a2 = ox + b0, oy + b1, oz + b2
    omega_DI = a0, a1, a2 = (  # in NED
        xn * a0 + yn * a1 + zn * a2,
        xe * a0 + ye * a1 + ze * a2,
        xd * a0 + yd * a1 + zd * a2,
    )

    # (23) [omega]: -K_R e + Pi_R Rt^T omega_DI^D, the last term being omega_DI on w2, w3.
    ff2 = a0 * w2n + a1 * w2e + a2 * w2d
    ff3 = a0 * w3n + a1 * w3e + a2 * w3d
    m_K_R = -K_R
    law2, law3 = m_K_R * e2 + ff2, m_K_R * e3 + ff3
    if ext.psi_turn or ext.rate_limit is not None:
        cmd2, cmd3, mode = apply_extensions(law2, law3, ff2, ff3, psi, d1_I, (w1, w2, w3), K_R, ext)
    else:  # the paper's law as it is (apply_extensions would return it unchanged)
        cmd2, cmd3, mode = law2, law3, "law"
    # tuple.__new__ builds the NamedTuples without their keyword-parsing constructor (~0.3 us
    # each, on the hot path). The command's omega_w1_I is R_W^I [0, w2, w3], in NED.
    cmd: MpfCommand = tuple.__new__(
        MpfCommand,
        (t, cmd2, cmd3, sdot,
         (cmd2 * w2n + cmd3 * w3n, cmd2 * w2e + cmd3 * w3e, cmd2 * w2d + cmd3 * w3d)),
    )  # fmt: skip
    if not diagnostics:
        return cmd, None
    x0, x1, x2 = u_F  # |u| = |u_F|
    margin = v_w - math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    return cmd, _diagnostics(
        t, s, R_I_T, R_F_T, R_Wd_F[0], d1_I, x_I, p_t, p_d, pt, pt_F, y_w, z_w, psi, e2, e3,
        margin, omega_DI, ff2, ff3, law2, law3, mode, k1, k2,
    )  # fmt: skip
