"""The MPF law of core/guidance/law.py unrolled on floats, for the kinematic simulator.

Read law.py for the law: this is the same IEEE operations in the same order, written out on
named components instead of 3-tuples and one call per equation, so it returns the same numbers
bit for bit (tests/test_law_equivalence.py asserts it). It stays where it pays in a user's
flow: ``mpf-mavlink sim`` of the paper's kinematic closed loop (4 law evaluations per RK4
step) takes 1.36x the CPU time with law.py's form (whole-process A/B, 5 runs each: 3.52 s
against 2.58 s median), so sim/plant/kinematic.py uses this one. The bridge uses law.py: its
control path measured 1.16x the CPU time with it (a recorded 600 s demo's 30,134 steps, 5
passes) and the SIL demo 1.12x, under the 1.2x that would pay for a second form there.
``mpf_law_unrolled`` is one 190-line function (the exception to the house's 80 lines):
splitting it costs the calls and tuples it exists to avoid.

Vectors are named components (x, y, z in {T}; n, e, d in NED; 1, 2, 3 on a frame's axes, as
wd21 is the second component of wd1) and matrices their columns (R_F^T = (f1, f2, f3)). No I/O,
no clock.
"""

from __future__ import annotations

import math
from typing import cast

from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    MpfErrors,
    VehicleState,
    limit_rates,
    psi_turn_direction,
)
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetState
from mpf_mavlink.core.vec3 import Vec3

# The flat results of _steady_state_frame and _transient_direction (see each).
WdFrame = tuple[float, float, float, float, float, float, float, float, float, float]
Vec5 = tuple[float, float, float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

_NO_EXTENSIONS = Extensions()
_LawResult = tuple[MpfCommand, MpfDiagnostics | None]


def _steady_state_frame(u_f2: float, u_f3: float, v_w: float) -> WdFrame:
    """(15) [wdbasis] R_{W_d}^F = (wd1, wd2, wd3), components in {F}, as (wd11, wd21, wd31,
    wd12, wd22, wd13, wd23, wd33) (wd32 = 0), then nn = wd11^2 + wd21^2 and n = sqrt(nn)
    (cos^2 and cos of wd1's climb in {F}), which :func:`_steady_state_frame_rate` reuses.

    u_f2, u_f3: u = v_t t1 + v_d (- eta_hat with wind compensation) on f2 and f3, the velocity
    the path point asks of the vehicle (m/s); v_w airspeed (m/s).
    """
    wd21 = u_f2 / v_w
    wd31 = u_f3 / v_w
    radicand = 1.0 - wd21 * wd21 - wd31 * wd31
    # Assumption 1 keeps the radicand > 0; outside it the frame stays defined (the
    # diagnostics' path_speed_margin says so).
    wd11 = math.sqrt(radicand) if radicand > 1e-12 else 1e-6
    nn = wd11 * wd11 + wd21 * wd21
    n = math.sqrt(nn)
    wd12, wd22 = -wd21 / n, wd11 / n  # wd32 = 0
    # wd3 = wd1 x wd2, written out with wd32 = 0.
    return (
        wd11, wd21, wd31, wd12, wd22, -wd31 * wd22, wd31 * wd12, wd11 * wd22 - wd21 * wd12,
        nn, n,
    )  # fmt: skip


def _steady_state_frame_rate(
    wd11: float, wd21: float, wd31: float, wd12: float, wd22: float, nn: float, n: float,
    wd21_dot: float, wd31_dot: float,
) -> Vec3:  # fmt: skip
    """omega_{W_d F}^F (rad/s): (15) differentiated, given the rates of wd21 and wd31 (1/s),
    the frame's wd11 ... wd22 and nn, n from :func:`_steady_state_frame`.

    wd1 = (cos g cos x, cos g sin x, sin g) and wd2 = (-sin x, cos x, 0): heading x then climb g
    in {F}, so omega_{W_d F} = x_dot f3 - g_dot wd2.
    """
    # wd11 = sqrt(1 - wd21^2 - wd31^2); held at its floor outside Assumption 1.
    wd11_dot = -(wd21 * wd21_dot + wd31 * wd31_dot) / wd11 if wd11 > 1e-6 else 0.0
    heading_dot = (wd11 * wd21_dot - wd21 * wd11_dot) / nn
    n_dot = (wd11 * wd11_dot + wd21 * wd21_dot) / n
    m_climb_dot = -((n * wd31_dot - wd31 * n_dot) / (nn + wd31 * wd31))
    return m_climb_dot * wd12, m_climb_dot * wd22, heading_dot


def _transient_direction(y_w: float, z_w: float, alpha: float) -> Vec5:
    """(20) d1, the first column of R_D^{W_d} (components in {W_d}; y_w, z_w the cross-track
    errors (17)-(19), alpha the look-ahead, m): all that (6) and (9) use; then nn1 = alpha^2
    + y_w^2 + z_w^2 and nn2 = alpha^2 + y_w^2, which :func:`_transient_frame_rate` reuses.
    The frame's other columns, d2 = (y_w, alpha, 0) / |(alpha, y_w)| and d3 = d1 x d2, enter
    only through its rate."""
    nn2 = alpha * alpha + y_w * y_w
    nn1 = nn2 + z_w * z_w
    n1 = math.sqrt(nn1)
    return alpha / n1, -y_w / n1, -z_w / n1, nn1, nn2


def _transient_frame_rate(
    y_w: float, z_w: float, y_w_dot: float, z_w_dot: float, alpha: float, nn1: float, nn2: float
) -> Vec3:
    """omega_{D W_d}^{W_d} (rad/s): (20) differentiated, given the cross-track errors (m), their
    rates (m/s) and nn1, nn2 from :func:`_transient_direction`.

    d1 = (alpha, -y_w, -z_w) / n1 and d2 = (y_w, alpha, 0) / n2 are heading
    x = atan2(-y_w, alpha) then climb g = atan2(-z_w, n2) in {W_d}, n2 = |(alpha, y_w)|, so
    omega_{D W_d} = x_dot wd3 - g_dot d2.
    """
    n2 = math.sqrt(nn2)
    heading_dot = -alpha * y_w_dot / nn2
    m_climb_dot = -((z_w * y_w * y_w_dot / n2 - n2 * z_w_dot) / nn1)
    return m_climb_dot * y_w / n2, m_climb_dot * alpha / n2, heading_dot


def _apply_extensions(
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


def mpf_law_unrolled(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = _NO_EXTENSIONS,
    diagnostics: bool = True,
    errors_mode: str | None = None,
) -> tuple[MpfCommand, MpfDiagnostics | None]:
    """:func:`~mpf_mavlink.core.guidance.law.mpf_law` (same arguments, same results bit for
    bit), one paragraph per equation written out on floats (the module docstring says why)."""
    t = float(vehicle.t)
    s = float(s)
    v_w = float(vehicle.airspeed)
    K_p, K_R, alpha = gains.K_p, gains.K_R, gains.alpha
    # ndarray.tolist() gives lists, which are only unpacked. R_W^I's rows hold the north, east
    # and down components of w1, w2, w3; R_T^I's rows are NED's axes in {T} (R_I^T's columns).
    # The target's numbers come as floats when its producer kept them (TargetState.floats).
    # The vehicle's too (VehicleState.floats).
    vf = vehicle.floats
    if vf is not None:
        w1n, w2n, w3n, w1e, w2e, w3e, w1d, w2d, w3d, pn, pe, pd, hn, he, hd = vf
    else:
        (w1n, w2n, w3n), (w1e, w2e, w3e), (w1d, w2d, w3d) = vehicle.R_W_I.tolist()
        pn, pe, pd = vehicle.position.tolist()
        hn, he, hd = vehicle.wind.tolist() if ext.wind_compensation else (0.0, 0.0, 0.0)
    tf = target.floats
    if tf is not None:
        (xn, yn, zn, xe, ye, ze, xd, yd, zd, tn, te, td, vn, ve, vd, an, ae, ad,
         ox, oy, oz, dx, dy, dz) = tf  # fmt: skip
    else:
        (xn, yn, zn), (xe, ye, ze), (xd, yd, zd) = target.R_T_I.tolist()
        tn, te, td = target.position.tolist()  # p_t (NED)
        vn, ve, vd = target.velocity.tolist()  # v_t (NED)
        an, ae, ad = target.acceleration.tolist()  # pddot_t (NED)
        ox, oy, oz = target.omega_T.tolist()  # omega_TI^T
        dx, dy, dz = target.omega_dot_T.tolist()  # its rate

    # Into {T}, where the path is fixed: q = R_I^T (p - p_t), the vehicle relative to the
    # target; uu = R_I^T (v_t - eta_hat), the target's velocity less the wind; and c = R_I^T
    # (v_w w1 + eta_hat - v_t) = v_w w1^T - uu, the vehicle's velocity (1) relative to it.
    rn, re, rd = pn - tn, pe - te, pd - td  # p - p_t (NED)
    qx = xn * rn + xe * re + xd * rd
    qy = yn * rn + ye * re + yd * rd
    qz = zn * rn + ze * re + zd * rd
    a0, a1, a2 = vn, ve, vd
    if ext.wind_compensation:
        a0, a1, a2 = a0 - hn, a1 - he, a2 - hd
    ux = xn * a0 + xe * a1 + xd * a2
    uy = yn * a0 + ye * a1 + yd * a2
    uz = zn * a0 + ze * a1 + zd * a2
    cx = v_w * (xn * w1n + xe * w1e + xd * w1d) - ux
    cy = v_w * (yn * w1n + ye * w1e + yd * w1d) - uy
    cz = v_w * (zn * w1n + ze * w1e + zd * w1d) - uz

    # The virtual point: p_d(s), R_F^T = (f1, f2, f3), the curvatures k1, k2, dp_d/ds and the
    # rate of {F} per unit s, (tau, -kappa_2, kappa_1) (TabulatedPath.eval_with_rate).
    (pdx, pdy, pdz, f1x, f1y, f1z, f2x, f2y, f2z, f3x, f3y, f3z, k1, k2,
     gx, gy, gz, tau, m_kappa_2, kappa_1) = path.eval_flat(s)  # fmt: skip
    ex, ey, ez = qx - pdx, qy - pdy, qz - pdz  # the position error pt = p - p_f, in {T}
    pt1 = f1x * ex + f1y * ey + f1z * ez  # pt in {F}: along-track, along f2, along f3
    pt2 = f2x * ex + f2y * ey + f2z * ez
    pt3 = f3x * ex + f3y * ey + f3z * ez
    vdx, vdy, vdz = oy * pdz - oz * pdy, oz * pdx - ox * pdz, ox * pdy - oy * pdx  # omega_TI x p_d

    # (22) [sdot] = (K_p pt + v_w w1 + eta_hat - v_t t1 - v_d) . f1 (m/s), in {T}.
    sdot = K_p * pt1 + ((cx - vdx) * f1x + (cy - vdy) * f1y + (cz - vdz) * f1z)

    # (15) {W_d} from u = v_t t1 + v_d - eta_hat, in {F} (u_F1 only enters its rate).
    a0, a1, a2 = ux + vdx, uy + vdy, uz + vdz
    uF1 = f1x * a0 + f1y * a1 + f1z * a2
    uF2 = f2x * a0 + f2y * a1 + f2z * a2
    uF3 = f3x * a0 + f3y * a1 + f3z * a2
    wd11, wd21, wd31, wd12, wd22, wd13, wd23, wd33, nn, n = _steady_state_frame(uF2, uF3, v_w)
    # (17)-(19): y_w = pt_x . wd2, z_w = pt_x . wd3 (m), pt_x = (0, pt.f2, pt.f3) in {F}.
    y_w = pt2 * wd22
    z_w = pt2 * wd23 + pt3 * wd33
    # (20) d1 in {W_d}, then in NED: d1 = R_T^I R_F^T R_{W_d}^F d1^{W_d} (wd32 = 0).
    x0, x1, x2, nn1, nn2 = _transient_direction(y_w, z_w, alpha)
    a0 = x0 * wd11 + x1 * wd12 + x2 * wd13
    a1 = x0 * wd21 + x1 * wd22 + x2 * wd23
    a2 = x0 * wd31 + x2 * wd33
    b0 = a0 * f1x + a1 * f2x + a2 * f3x
    b1 = a0 * f1y + a1 * f2y + a2 * f3y
    b2 = a0 * f1z + a1 * f2z + a2 * f3z
    d1n = xn * b0 + yn * b1 + zn * b2
    d1e = xe * b0 + ye * b1 + ze * b2
    d1d = xd * b0 + yd * b1 + zd * b2

    # (6) Psi = (1 - Rt11) / 2 and (9) e = (Rt13, -Rt12) / 2, where Rt = R_W^D = (R_D^I)^T R_W^I
    # has the first row (d1.w1, d1.w2, d1.w3).
    psi = 0.5 * (1.0 - (w1n * d1n + w1e * d1e + w1d * d1d))
    e2 = 0.5 * (w3n * d1n + w3e * d1e + w3d * d1d)
    e3 = -0.5 * (w2n * d1n + w2e * d1e + w2d * d1d)
    if errors_mode is not None:  # mpf_errors: the record below without the rates
        pdn = xn * pdx + yn * pdy + zn * pdz
        pde = xe * pdx + ye * pdy + ze * pdz
        pdd = xd * pdx + yd * pdy + zd * pdz
        errors = tuple.__new__(
            MpfErrors,
            (t, s, (rn - pdn, re - pde, rd - pdd), math.sqrt(ex * ex + ey * ey + ez * ez),
             (tn + pdn, te + pde, td + pdd), psi, (e2, e3), y_w, z_w,
             v_w - math.sqrt(uF1 * uF1 + uF2 * uF2 + uF3 * uF3), errors_mode),
        )  # fmt: skip
        return cast(_LawResult, (None, errors))  # mpf_errors unwraps it

    # (10) omega_DI = omega_TI + omega_FT + omega_{W_d F} + omega_{D W_d}, each the exact rate
    # of its frame along the closed-loop flow. omega_FT^F = sdot (tau, -kappa_2, kappa_1).
    o1, o2, o3 = sdot * tau, sdot * m_kappa_2, sdot * kappa_1
    # (5) in {T}: pt_dot = qdot - p_d_dot with qdot = c - omega_TI x q and p_d_dot = sdot
    # dp_d/ds; u = uu + v_d with d(uu)/dt = a_t - omega_TI x uu (eta_hat held) and v_d =
    # omega_TI x p_d, so u_dot = a_t + omega_dot x p_d + omega_TI x (p_d_dot - uu), where
    # a_t = R_I^T pddot_t and omega_dot is omega_TI^T's rate.
    g0, g1, g2 = sdot * gx, sdot * gy, sdot * gz  # p_d_dot
    pt_dot0 = cx - (oy * qz - oz * qy) - g0
    pt_dot1 = cy - (oz * qx - ox * qz) - g1
    pt_dot2 = cz - (ox * qy - oy * qx) - g2
    g0, g1, g2 = g0 - ux, g1 - uy, g2 - uz
    u_dot0 = (xn * an + xe * ae + xd * ad) + (dy * pdz - dz * pdy) + (oy * g2 - oz * g1)
    u_dot1 = (yn * an + ye * ae + yd * ad) + (dz * pdx - dx * pdz) + (oz * g0 - ox * g2)
    u_dot2 = (zn * an + ze * ae + zd * ad) + (dx * pdy - dy * pdx) + (ox * g1 - oy * g0)
    # Their f2, f3 components (all that (15), (18), (19) use) in {F}, which turns at
    # omega_FT: d(f_k . x)/dt = f_k . x_dot - (omega_FT^F x x^F)_k.
    pt_f2_dot = f2x * pt_dot0 + f2y * pt_dot1 + f2z * pt_dot2 - (o3 * pt1 - o1 * pt3)
    pt_f3_dot = f3x * pt_dot0 + f3y * pt_dot1 + f3z * pt_dot2 - (o1 * pt2 - o2 * pt1)
    wd21_dot = (f2x * u_dot0 + f2y * u_dot1 + f2z * u_dot2 - (o3 * uF1 - o1 * uF3)) / v_w
    wd31_dot = (f3x * u_dot0 + f3y * u_dot1 + f3z * u_dot2 - (o1 * uF2 - o2 * uF1)) / v_w
    a0, a1, a2 = _steady_state_frame_rate(
        wd11, wd21, wd31, wd12, wd22, nn, n, wd21_dot, wd31_dot
    )  # omega_{W_d F}^F
    # d/dt of (18)-(19) while {W_d} turns at omega_{W_d F}^F = a: d(wd_k)/dt = a x wd_k, of
    # which the components used here are written out (d(wd22)/dt = a2 wd12 as wd32 = 0).
    y_w_dot = pt_f2_dot * wd22 + pt2 * a2 * wd12
    z_w_dot = pt_f2_dot * wd23 + pt_f3_dot * wd33
    z_w_dot += pt2 * (a2 * wd13 - a0 * wd33) + pt3 * (a0 * wd23 - a1 * wd13)
    b0, b1, b2 = _transient_frame_rate(y_w, z_w, y_w_dot, z_w_dot, alpha, nn1, nn2)
    # Summed in {F}: omega_FT^F + omega_{W_d F}^F + R_{W_d}^F omega_{D W_d}^{W_d} (wd32 = 0),
    # into {T} by R_F^T plus omega_TI^T, then into NED by R_T^I.
    o1 += a0 + (b0 * wd11 + b1 * wd12 + b2 * wd13)
    o2 += a1 + (b0 * wd21 + b1 * wd22 + b2 * wd23)
    o3 += a2 + (b0 * wd31 + b2 * wd33)
    a0 = ox + (o1 * f1x + o2 * f2x + o3 * f3x)
    a1 = oy + (o1 * f1y + o2 * f2y + o3 * f3y)
    a2 = oz + (o1 * f1z + o2 * f2z + o3 * f3z)
    on = xn * a0 + yn * a1 + zn * a2  # omega_DI (NED)
    oe = xe * a0 + ye * a1 + ze * a2
    od = xd * a0 + yd * a1 + zd * a2

    # (23) [omega]: -K_R e + Pi_R Rt^T omega_DI^D, the last term being omega_DI on w2, w3.
    ff2 = on * w2n + oe * w2e + od * w2d
    ff3 = on * w3n + oe * w3e + od * w3d
    m_K_R = -K_R
    law2, law3 = m_K_R * e2 + ff2, m_K_R * e3 + ff3
    if ext.psi_turn or ext.rate_limit is not None:
        R_W_I = (w1n, w1e, w1d), (w2n, w2e, w2d), (w3n, w3e, w3d)
        cmd2, cmd3, mode = _apply_extensions(
            law2, law3, ff2, ff3, psi, (d1n, d1e, d1d), R_W_I, K_R, ext
        )
    else:  # the paper's law as it is (apply_extensions would return it unchanged)
        cmd2, cmd3, mode = law2, law3, "law"
    # tuple.__new__ builds the NamedTuples without their keyword-parsing constructor (~0.3 us
    # each). The command's omega_w1_I is R_W^I [0, w2, w3], in NED.
    cmd: MpfCommand = tuple.__new__(
        MpfCommand,
        (t, cmd2, cmd3, sdot,
         (cmd2 * w2n + cmd3 * w3n, cmd2 * w2e + cmd3 * w3e, cmd2 * w2d + cmd3 * w3d)),
    )  # fmt: skip
    if not diagnostics:
        return cmd, None

    # The record, its vectors into NED by R_T^I: p_d (p_f = p_t + p_d and pt = (p - p_t) -
    # p_d), wd1 = R_T^I R_F^T wd1^F and f1; the Assumption 1 margin v_w - |u| (|u| = |u_F|).
    pdn = xn * pdx + yn * pdy + zn * pdz
    pde = xe * pdx + ye * pdy + ze * pdz
    pdd = xd * pdx + yd * pdy + zd * pdz
    a0 = wd11 * f1x + wd21 * f2x + wd31 * f3x
    a1 = wd11 * f1y + wd21 * f2y + wd31 * f3y
    a2 = wd11 * f1z + wd21 * f2z + wd31 * f3z
    return cmd, tuple.__new__(
        MpfDiagnostics,
        (t, s, (rn - pdn, re - pde, rd - pdd), math.sqrt(ex * ex + ey * ey + ez * ez),
         (pt1, pt2, pt3), (tn + pdn, te + pde, td + pdd), psi, (e2, e3), y_w, z_w,
         (d1n, d1e, d1d),
         (xn * a0 + yn * a1 + zn * a2, xe * a0 + ye * a1 + ze * a2, xd * a0 + yd * a1 + zd * a2),
         (xn * f1x + yn * f1y + zn * f1z, xe * f1x + ye * f1y + ze * f1z,
          xd * f1x + yd * f1y + zd * f1z),
         (on, oe, od), (ff2, ff3), (law2, law3),
         v_w - math.sqrt(uF1 * uF1 + uF2 * uF2 + uF3 * uF3), mode, k1, k2),
    )  # fmt: skip
