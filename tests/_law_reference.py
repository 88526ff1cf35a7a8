"""The MPF law transcribed from /work/shared/spec/mpf-law.md in numpy, independently of the
package's law (tests/test_law_equivalence.py compares the two).

Every frame is a 3x3 rotation matrix built as the spec writes it (its columns the frame's axes):
R_T^I, R_F^T = [f1 f2 f3], R_{W_d}^F = [wd1 wd2 wd3] (wdbasis), R_D^{W_d} = [d1 d2 d3], and
R_D^I = R_T^I R_F^T R_{W_d}^F R_D^{W_d}. omega_DI (spec item 7) is NOT derived term by term as
the package does: R_D^I is evaluated as a function of time along the known first-order
kinematics (p + tau pdot, s + tau sdot, p_t + tau v_t, v_t + tau a_t, R_T^I (I + tau
hat(omega_TI)), omega_TI + tau omega_dot, {F} turning at sdot rate_F) at the complex time
tau = i h, and omega_DI^D = vee(R_D^T dR_D/dt) with dR_D/dt = Im R_D(i h) / h: the complex-step
derivative, exact to rounding (no difference is taken, h = 1e-30 makes the neglected h^2 terms
vanish). The path's evaluation (p_d, f1..f3, dp_d/ds, rate_F) is the package's: the tabulated
path is not what this checks. Not used by the package.
"""

from __future__ import annotations

import numpy as np

from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    VehicleState,
    apply_extensions,
)
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetState

H = 1e-30  # the complex step (s)
_NO_EXTENSIONS = Extensions()


def hat(v):
    """hat(a) b = a x b."""
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def vee(M):
    """The inverse of hat (of the skew part of M)."""
    return 0.5 * np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])


def desired_frame(tau, s, vehicle, target, path, gains, ext, sdot):
    """R_D^I and the quantities of the spec's steps 1-4 at time t + tau (tau real or complex,
    s), along the first-order kinematics (module docstring)."""
    eta = np.asarray(vehicle.wind, float) if ext.wind_compensation else np.zeros(3)
    w1 = vehicle.R_W_I[:, 0]
    p = vehicle.position + tau * (vehicle.airspeed * w1 + eta)
    p_t = target.position + tau * target.velocity
    v_t = target.velocity + tau * target.acceleration
    R_T_I = target.R_T_I @ (np.eye(3) + tau * hat(target.omega_T))
    omega_T = target.omega_T + tau * target.omega_dot_T
    p_d, f1, f2, f3, k1, k2, dp_ds, rate_F = (np.array(x) for x in path.eval_with_rate(s))
    R_F_T = np.column_stack([f1, f2, f3]) @ (np.eye(3) + tau * sdot * hat(rate_F))
    p_d = p_d + tau * sdot * dp_ds
    # p_f = p_t + R_T^I p_d; pt = p - p_f; v_d = omega_TI x p_d (all in {I} here)
    pt = p - (p_t + R_T_I @ p_d)
    v_d = R_T_I @ np.cross(omega_T, p_d)
    u = v_t + v_d - eta  # v_t t1 + v_d (- eta_hat)
    R_F_I = R_T_I @ R_F_T
    # step 2 [wdbasis], components in {F}
    u_F = R_F_I.T @ u
    wd21, wd31 = u_F[1] / vehicle.airspeed, u_F[2] / vehicle.airspeed
    radicand = 1 - wd21**2 - wd31**2
    wd11 = np.sqrt(radicand) if radicand.real > 1e-12 else 1e-6 + 0 * radicand
    wd1 = np.array([wd11, wd21, wd31])
    wd2 = np.array([-wd21, wd11, 0 * wd11]) / np.sqrt(wd11**2 + wd21**2)
    R_Wd_F = np.column_stack([wd1, wd2, np.cross(wd1, wd2)])
    # step 3: cross-track error and its components on wd2, wd3
    pt_F = R_F_I.T @ pt
    pt_x = pt_F - pt_F[0] * np.array([1.0, 0.0, 0.0])
    y_w, z_w = pt_x @ R_Wd_F[:, 1], pt_x @ R_Wd_F[:, 2]
    # step 4: the transient frame in {W_d}
    a = gains.alpha
    d1 = np.array([a, -y_w, -z_w]) / np.sqrt(a**2 + y_w**2 + z_w**2)
    d2 = np.array([y_w, a, 0 * y_w]) / np.sqrt(a**2 + y_w**2)
    R_D_Wd = np.column_stack([d1, d2, np.cross(d1, d2)])
    R_D_I = R_F_I @ R_Wd_F @ R_D_Wd
    return R_D_I, (pt, pt_F, p_t + R_T_I @ p_d, y_w, z_w, R_F_I, R_Wd_F, u, k1, k2)


def reference_mpf_law(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = _NO_EXTENSIONS,
) -> tuple[MpfCommand, MpfDiagnostics]:
    """The spec's law (steps 1-6) at (s, vehicle, target), as the package's law returns it."""
    eta = np.asarray(vehicle.wind, float) if ext.wind_compensation else np.zeros(3)
    v_w, R_W_I = vehicle.airspeed, np.asarray(vehicle.R_W_I, float)
    w1 = R_W_I[:, 0]
    _, (pt, pt_F, p_f, *_rest) = desired_frame(0.0, s, vehicle, target, path, gains, ext, 0.0)
    f1 = _rest[2][:, 0]  # f1 in {I}
    p_d = np.array(path.eval_with_rate(s)[0])
    v_d = target.R_T_I @ np.cross(target.omega_T, p_d)
    # step 1 [sdot]
    sdot = float((gains.K_p * pt + v_w * w1 + eta - target.velocity - v_d) @ f1)
    R_D_I, (_, _, _, y_w, z_w, R_F_I, R_Wd_F, u, k1, k2) = desired_frame(
        0.0, s, vehicle, target, path, gains, ext, sdot
    )
    R_c = desired_frame(1j * H, s, vehicle, target, path, gains, ext, sdot)[0]
    omega_DI = R_D_I @ vee(R_D_I.T @ (R_c.imag / H))  # omega_DI^D into {I}
    # step 5: attitude error
    Rt = R_D_I.T @ R_W_I
    psi = (1 - Rt[0, 0]) / 2
    e = 0.5 * np.array([Rt[0, 2], -Rt[0, 1]])
    # step 6: -K_R e + Pi_R Rt^T omega_DI^D
    ff = (Rt.T @ (R_D_I.T @ omega_DI))[1:]
    law = -gains.K_R * e + ff
    d1 = R_D_I[:, 0]
    Rw = tuple(tuple(R_W_I[:, k]) for k in range(3))
    cmd2, cmd3, mode = apply_extensions(tuple(law), tuple(ff), psi, tuple(d1), Rw, gains.K_R, ext)
    cmd = MpfCommand(vehicle.t, cmd2, cmd3, sdot, tuple(cmd2 * R_W_I[:, 1] + cmd3 * R_W_I[:, 2]))
    diag = MpfDiagnostics(
        vehicle.t, s, tuple(pt), float(np.linalg.norm(pt)), tuple(pt_F), tuple(p_f), psi,
        tuple(e), y_w, z_w, tuple(d1), tuple(R_F_I @ R_Wd_F[:, 0]), tuple(f1), tuple(omega_DI),
        tuple(ff), tuple(law), v_w - float(np.linalg.norm(u)), mode, k1, k2,
    )  # fmt: skip
    return cmd, diag
