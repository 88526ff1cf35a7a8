"""The 3D moving-path-following law (Jain, de Sousa, Aguiar, Theorem 1), pure and exact.

Read it beside the paper (equation labels in brackets) and the restatement of the law in the
project's docs: one function per step.

1. :func:`steady_state_frame` [wdbasis]: {W_d} in {F} from v_t t1 + v_d (Assumption 1).
2. :func:`cross_track_errors`: y_w, z_w, the cross-track error on wd2, wd3.
3. :func:`transient_frame`: {D} in {W_d}, shaped by the look-ahead alpha.
4. :func:`desired_frame`: steps 1-3 at one point of the flow, composed into R_D^T.
5. :func:`progression_rate` [sdot].
6. :func:`feedforward_omega_DT`: omega_DT, the derivative of R_D along the closed-loop flow
   (omega_DI = omega_DT + omega_TI).
7. :func:`attitude_error`: Psi and e [ertilde] from d1 and the wind frame.
8. :func:`mpf_law` [omega]: -K_R e + Pi_R Rt^T omega_DI^D, then the extensions
   (:func:`psi_turn_direction`, :func:`limit_rates`).

Frames: {I} NED; {W} wind frame (w1 along the air-relative velocity); {T} target; {F}
parallel-transport frame at p_d(s); {W_d} steady-state desired velocity frame; {D} transient
desired frame. Vectors and matrices are tuples (see :mod:`mpf_mavlink.core.vec3`, matrices by
columns, so R_F^T = (f1, f2, f3)); the frames are built in {T}, where the path is fixed.

The feedforward omega_DI (angular velocity of {D} relative to {I}) is the exact derivative
of R_D^I along the closed-loop flow: R_D^T is a pure function of (s, p, target) and we
difference it along the known kinematics (pdot = v_w w1 + eta_hat, sdot from the law, the
target's velocity, acceleration, angular velocity and its rate), never along telemetry.
No I/O, no clock.
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
    add,
    add_scaled,
    cross,
    dot,
    mat_mul,
    mat_T_vec,
    mat_vec,
    norm,
    rotation_rate,
    sub,
)

Vec = Vec3  # kept for importers


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


# The path at one arc length, as TabulatedPath.eval gives it: (p_d, f1, f2, f3, k1, k2) in {T}.
_PathPoint = tuple[Vec3, Vec3, Vec3, Vec3, float, float]
# What the centre evaluation of the frames hands on to the command and the diagnostics.
_FrameDetails = tuple[Vec3, Vec3, Vec3, Mat3, Vec3, float, float]

_ZERO: Vec3 = (0.0, 0.0, 0.0)


def steady_state_frame(u_F: Vec3, v_w: float) -> Mat3:
    """[wdbasis] R_{W_d}^F = (wd1, wd2, wd3), components in {F}.

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


def cross_track_errors(pt_F: Vec3, R_Wd_F: Mat3) -> tuple[float, float]:
    """y_w = pt_x . wd2 and z_w = pt_x . wd3 (m), pt_x = (pt.f2) f2 + (pt.f3) f3 the cross-track
    error; pt_F is pt in {F}, and wd32 = 0."""
    _, pt_f2, pt_f3 = pt_F
    (_, wd22, _), (_, wd23, wd33) = R_Wd_F[1], R_Wd_F[2]
    return pt_f2 * wd22, pt_f2 * wd23 + pt_f3 * wd33


def transient_frame(y_w: float, z_w: float, alpha: float) -> Mat3:
    """R_D^{W_d} = (d1, d2, d3), components in {W_d}; alpha (m) the look-ahead distance."""
    n1 = math.sqrt(alpha * alpha + y_w * y_w + z_w * z_w)
    n2 = math.sqrt(alpha * alpha + y_w * y_w)
    d11, d21, d31 = alpha / n1, -y_w / n1, -z_w / n1
    d12, d22 = y_w / n2, alpha / n2  # d32 = 0
    # d3 = d1 x d2, written out with d32 = 0.
    d3 = (-d31 * d22, d31 * d12, d11 * d22 - d21 * d12)
    return (d11, d21, d31), (d12, d22, 0.0), d3


def desired_frame(
    path_point: _PathPoint, q: Vec3, uu: Vec3, omega: Vec3, v_w: float, alpha: float
) -> tuple[Mat3, _FrameDetails]:
    """R_D^T = R_F^T R_{W_d}^F R_D^{W_d} at one point of the flow, everything in {T}.

    path_point: the path at s; q = R_T^T (p - p_t), the vehicle relative to the target (m);
    uu = R_T^T (v_t - eta_hat) (m/s); omega = omega_TI^T (rad/s); v_w (m/s); alpha (m).
    Returns R_D^T and (pt, v_d, u, R_{W_d}^F, pt in {F}, y_w, z_w) for the diagnostics.
    """
    p_d, f1, f2, f3, _, _ = path_point
    R_F_T = (f1, f2, f3)
    pt = sub(q, p_d)  # position error p - p_f
    v_d = cross(omega, p_d)  # velocity of the path point from the target's rotation
    u = add(uu, v_d)  # v_t t1 + v_d - eta_hat
    R_Wd_F = steady_state_frame(mat_T_vec(R_F_T, u), v_w)
    pt_F = mat_T_vec(R_F_T, pt)
    y_w, z_w = cross_track_errors(pt_F, R_Wd_F)
    R_D_Wd = transient_frame(y_w, z_w, alpha)
    R_D_T = mat_mul(R_F_T, mat_mul(R_Wd_F, R_D_Wd))
    return R_D_T, (pt, v_d, u, R_Wd_F, pt_F, y_w, z_w)


def progression_rate(pt_f1: float, c: Vec3, v_d: Vec3, f1: Vec3, K_p: float) -> float:
    """[sdot] = (K_p pt + v_w w1 + eta_hat - v_t t1 - v_d) . f1 (m/s), in {T}, where
    pt_f1 = pt . f1 and c = R_T^T (v_w w1 + eta_hat - v_t) is the vehicle's velocity relative
    to the target."""
    return K_p * pt_f1 + dot(sub(c, v_d), f1)


# Step for differencing R_D^T along the flow (s). Central differences cancel the symmetric
# second-order terms of a first-order state advance, so the error is O(h^2) ~ 1e-8 relative,
# and round-off (~1e-16 / h) is smaller still.
FD_STEP_S = 1e-4


def feedforward_omega_DT(
    path: TabulatedPath,
    s: float,
    sdot: float,
    q: Vec3,
    c: Vec3,
    uu: Vec3,
    a_t: Vec3,
    omega: Vec3,
    omega_dot: Vec3,
    R_D_T: Mat3,
    v_w: float,
    alpha: float,
) -> Vec3:
    """omega_DT^T (rad/s): the angular velocity of {D} relative to {T}, by central differences
    of R_D^T = desired_frame(...) along the closed-loop flow, with R_D^T at the centre given.

    The flow in {T}: sdot from the law; qdot = c - omega x q; d(uu)/dt = a_t - omega x uu with
    a_t = R_T^T a_t^I (eta_hat held); omega_dot from the target. Then
    omega_DT^T = vee(dR/dt R^T) for R = R_D^T (:func:`rotation_rate`).
    """
    h = FD_STEP_S
    q_dot = sub(c, cross(omega, q))
    uu_dot = sub(a_t, cross(omega, uu))
    R_plus, _ = desired_frame(
        path.eval(s + h * sdot),
        add_scaled(q, h, q_dot),
        add_scaled(uu, h, uu_dot),
        add_scaled(omega, h, omega_dot),
        v_w,
        alpha,
    )
    R_minus, _ = desired_frame(
        path.eval(s - h * sdot),
        add_scaled(q, -h, q_dot),
        add_scaled(uu, -h, uu_dot),
        add_scaled(omega, -h, omega_dot),
        v_w,
        alpha,
    )
    return rotation_rate(R_plus, R_minus, R_D_T, 2.0 * h)


def attitude_error(d1: Vec3, R_W_I: Mat3) -> tuple[float, float, float]:
    """Psi [attitudeErrorFunction] and e = (e2, e3) [ertilde] from d1 and R_W^I (both in NED).

    Rt = R_W^D = (R_D^I)^T R_W^I; its first row is (d1.w1, d1.w2, d1.w3).
    """
    Rt11, Rt12, Rt13 = mat_T_vec(R_W_I, d1)
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
    """Evaluate the MPF law [sdot], [omega] at the vehicle's time.

    s is the virtual point's arc length (m, unwrapped); the target state must be for the same
    time as the vehicle (extrapolate it first: :meth:`TargetState.extrapolate`).
    Returns the command and the diagnostics record (None when ``diagnostics`` is False, which
    saves the cost of building it inside integrators).
    """
    t = float(vehicle.t)
    s = float(s)
    v_w = float(vehicle.airspeed)
    # ndarray.tolist() gives lists; the vec3 helpers only index and unpack them. The
    # transposes' rows are the matrices' columns.
    R_W_I: Mat3 = vehicle.R_W_I.T.tolist()  # (w1, w2, w3) in NED
    R_T_I: Mat3 = target.R_T_I.T.tolist()  # (t1, t2, t3) in NED
    eta: Vec3 = vehicle.wind.tolist() if ext.wind_compensation else _ZERO
    p_t: Vec3 = target.position.tolist()
    v_t: Vec3 = target.velocity.tolist()
    omega: Vec3 = target.omega_T.tolist()  # omega_TI^T
    w1, w2, w3 = R_W_I
    # Into {T}: the vehicle relative to the target, its velocity as the law models it
    # (v_w w1 + eta_hat) relative to the target's, and the target's velocity less the wind.
    q = mat_T_vec(R_T_I, sub(vehicle.position.tolist(), p_t))
    c = mat_T_vec(R_T_I, sub(add_scaled(eta, v_w, w1), v_t))
    uu = mat_T_vec(R_T_I, sub(v_t, eta))

    path_point = path.eval(s)
    p_d, f1, f2, f3, k1, k2 = path_point
    R_D_T, (pt, v_d, u, R_Wd_F, pt_F, y_w, z_w) = desired_frame(
        path_point, q, uu, omega, v_w, gains.alpha
    )
    sdot = progression_rate(pt_F[0], c, v_d, f1, gains.K_p)
    omega_DT = feedforward_omega_DT(
        path, s, sdot, q, c, uu,
        mat_T_vec(R_T_I, target.acceleration.tolist()), omega, target.omega_dot_T.tolist(),
        R_D_T, v_w, gains.alpha,
    )  # fmt: skip
    omega_DI = mat_vec(R_T_I, add(omega_DT, omega))  # omega_DT + omega_TI, in NED
    d1 = mat_vec(R_T_I, R_D_T[0])
    psi, e2, e3 = attitude_error(d1, R_W_I)
    # [omega]: -K_R e + Pi_R Rt^T omega_DI^D, the last term being omega_DI on w2, w3.
    ff2, ff3 = dot(omega_DI, w2), dot(omega_DI, w3)
    law2, law3 = -gains.K_R * e2 + ff2, -gains.K_R * e3 + ff3
    cmd2, cmd3 = law2, law3
    mode = "law"
    if ext.psi_turn and psi >= ext.psi_turn_threshold:
        rate = ext.psi_turn_rate if ext.psi_turn_rate is not None else 0.5 * gains.K_R
        v2, v3 = psi_turn_direction(R_W_I, d1)
        cmd2, cmd3 = rate * v2 + ff2, rate * v3 + ff3
        mode = "psi_turn"
    cmd2, cmd3, saturated = limit_rates(cmd2, cmd3, ext)
    if saturated:
        mode += "+sat"
    # The command as the angular velocity of w1 in NED: R_W^I [0, w2, w3].
    cmd = MpfCommand(t, cmd2, cmd3, sdot, mat_vec(R_W_I, (0.0, cmd2, cmd3)))
    if not diagnostics:
        return cmd, None
    R_F_T = (f1, f2, f3)
    diag = MpfDiagnostics(
        t,
        s,
        mat_vec(R_T_I, pt),
        norm(pt),
        pt_F,
        add(p_t, mat_vec(R_T_I, p_d)),
        psi,
        (e2, e3),
        y_w,
        z_w,
        d1,
        mat_vec(R_T_I, mat_vec(R_F_T, R_Wd_F[0])),
        mat_vec(R_T_I, f1),
        omega_DI,
        (ff2, ff3),
        (law2, law3),
        v_w - norm(u),  # Assumption 1 holds while > 0
        mode,
        k1,
        k2,
    )
    return cmd, diag
