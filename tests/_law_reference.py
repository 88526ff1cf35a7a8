"""The MPF law exactly as it was before its rewrite (main b3b000e: finite-difference omega_DI), frozen.

tests/test_law_equivalence.py compares the rewritten law against this copy on many states.
Not used by the package. The path evaluation is frozen too (``reference_path_eval``), since the
rewrite also changed how TabulatedPath.eval evaluates the Hermite cubic.
"""
# ruff: noqa
# mypy: ignore-errors

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    VehicleState,
)

Tuple3 = tuple[float, float, float]
from mpf_mavlink.core.target import TargetState

Vec = tuple[float, float, float]


def _cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


# Everything the centre evaluation hands on besides R_D^T (see _frame).
_Extra = tuple[Vec, Vec, Vec, Vec, float, float, Vec, Vec, Vec, float, float, float, float]
_Frame = tuple[float, float, float, float, float, float, float, float, float, _Extra]
_PathEval = Callable[[float], tuple[Vec, Vec, Vec, Vec, float, float]]


def _frame(
    s: float,
    q0: float, q1: float, q2: float,
    uu0: float, uu1: float, uu2: float,
    o0: float, o1: float, o2: float,
    peval: _PathEval,
    v_w: float,
    a: float,
) -> _Frame:  # fmt: skip
    """[wdbasis] W_d and the transient frame D at one point of the flow, in {T} coordinates.

    q = R_T^T (p - p_t): vehicle position relative to the target (m);
    uu = R_T^T (v_t - eta_hat): target velocity less the wind estimate (m/s);
    o = omega_TI^T (rad/s); path point p_d(s), v_d = o x p_d; a = alpha (m).
    Returns d1, d2, d3 (the columns of R_D^T, 9 floats) and, for the centre evaluation,
    (p_d, f1, f2, f3, k1, k2, pt, u, wd1 in {F}, pt.f2, pt.f3, y_w, z_w) where
    u = v_t t1 + v_d - eta_hat.
    Vectors arrive as scalars and tuples are unpacked once: this runs three times per law
    evaluation and tuple indexing would cost as much as the arithmetic.
    """
    pd, f1, f2, f3, k1, k2 = peval(s)
    pd0, pd1, pd2 = pd
    a0, a1_, a2_ = f1
    b0, b1_, b2_ = f2
    c0, c1_, c2_ = f3
    pt0, pt1, pt2 = q0 - pd0, q1 - pd1, q2 - pd2
    # u = v_t t1 + v_d - eta_hat: v_w times the air-relative direction needed in steady state.
    u0 = uu0 + o1 * pd2 - o2 * pd1
    u1 = uu1 + o2 * pd0 - o0 * pd2
    u2 = uu2 + o0 * pd1 - o1 * pd0
    iv = 1.0 / v_w
    wd21 = (u0 * b0 + u1 * b1_ + u2 * b2_) * iv
    wd31 = (u0 * c0 + u1 * c1_ + u2 * c2_) * iv
    rad = 1.0 - wd21 * wd21 - wd31 * wd31
    # Assumption 1 keeps rad > 0; outside it we keep the frame defined (the margin says so).
    wd11 = math.sqrt(rad) if rad > 1e-12 else 1e-6
    n = 1.0 / math.sqrt(wd11 * wd11 + wd21 * wd21)
    wd12, wd22 = -wd21 * n, wd11 * n
    # wd3 = wd1 x wd2 in {F} components (wd32 = 0).
    wd13 = -wd31 * wd22
    wd23 = wd31 * wd12
    wd33 = wd11 * wd22 - wd21 * wd12
    pF2 = pt0 * b0 + pt1 * b1_ + pt2 * b2_
    pF3 = pt0 * c0 + pt1 * c1_ + pt2 * c2_
    # Cross-track error pt_x = pt - (pt.f1) f1, projected on wd2 and wd3.
    y_w = pF2 * wd22
    z_w = pF2 * wd23 + pF3 * wd33
    n1 = 1.0 / math.sqrt(a * a + y_w * y_w + z_w * z_w)
    n2 = 1.0 / math.sqrt(a * a + y_w * y_w)
    x1, y1, z1 = a * n1, -y_w * n1, -z_w * n1  # d1 in {W_d}
    x2, y2 = y_w * n2, a * n2  # d2 in {W_d} (third component 0)
    x3, y3, z3 = -z1 * y2, z1 * x2, x1 * y2 - y1 * x2  # d3 = d1 x d2
    # {W_d} axes in {F}: wd1 = (wd11, wd21, wd31), wd2 = (wd12, wd22, 0), wd3 = (wd13, wd23,
    # wd33); each d_k goes {W_d} -> {F} (g) -> {T}.
    g1 = x1 * wd11 + y1 * wd12 + z1 * wd13
    g2 = x1 * wd21 + y1 * wd22 + z1 * wd23
    g3 = x1 * wd31 + z1 * wd33
    h1 = x2 * wd11 + y2 * wd12
    h2 = x2 * wd21 + y2 * wd22
    h3 = x2 * wd31
    k1_ = x3 * wd11 + y3 * wd12 + z3 * wd13
    k2_ = x3 * wd21 + y3 * wd22 + z3 * wd23
    k3_ = x3 * wd31 + z3 * wd33
    return (
        g1 * a0 + g2 * b0 + g3 * c0,
        g1 * a1_ + g2 * b1_ + g3 * c1_,
        g1 * a2_ + g2 * b2_ + g3 * c2_,
        h1 * a0 + h2 * b0 + h3 * c0,
        h1 * a1_ + h2 * b1_ + h3 * c1_,
        h1 * a2_ + h2 * b2_ + h3 * c2_,
        k1_ * a0 + k2_ * b0 + k3_ * c0,
        k1_ * a1_ + k2_ * b1_ + k3_ * c1_,
        k1_ * a2_ + k2_ * b2_ + k3_ * c2_,
        (
            pd,
            f1,
            f2,
            f3,
            k1,
            k2,
            (pt0, pt1, pt2),
            (u0, u1, u2),
            (wd11, wd21, wd31),
            pF2,
            pF3,
            y_w,
            z_w,
        ),
    )


# Step for differencing R_D^T along the flow (s). Central differences cancel the symmetric
# second-order terms of a first-order state advance, so the error is O(h^2) ~ 1e-8 relative,
# and round-off (~1e-16 / h) is smaller still.
FD_STEP_S = 1e-4

_NO_EXTENSIONS = Extensions()


def reference_mpf_law(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = _NO_EXTENSIONS,
    diagnostics: bool = True,
    fd_step: float = FD_STEP_S,
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
    # R_W^I: columns w1, w2, w3 (NED). R_T^I: rows r_i, R_T^T v = sum_i v_i r_i.
    (w10, w20, w30), (w11, w21, w31), (w12, w22, w32) = vehicle.R_W_I.tolist()
    (T00, T01, T02), (T10, T11, T12), (T20, T21, T22) = target.R_T_I.tolist()
    if ext.wind_compensation:
        e0, e1, e2 = vehicle.wind.tolist()
    else:
        e0 = e1 = e2 = 0.0
    p0, p1, p2 = vehicle.position.tolist()
    tp0, tp1, tp2 = target.position.tolist()
    tv0, tv1, tv2 = target.velocity.tolist()
    ta0, ta1, ta2 = target.acceleration.tolist()
    o0, o1, o2 = target.omega_T.tolist()
    od0, od1, od2 = target.omega_dot_T.tolist()
    # The vehicle's ground velocity as the law models it: v_w w1 + eta_hat (NED).
    gv0, gv1, gv2 = v_w * w10 + e0, v_w * w11 + e1, v_w * w12 + e2
    # Into {T}: q = R_T^T (p - p_t), c = R_T^T (pdot - v_t), uu = R_T^T (v_t - eta_hat),
    # at = R_T^T a_t.
    x0, x1, x2 = p0 - tp0, p1 - tp1, p2 - tp2
    q0 = T00 * x0 + T10 * x1 + T20 * x2
    q1 = T01 * x0 + T11 * x1 + T21 * x2
    q2 = T02 * x0 + T12 * x1 + T22 * x2
    x0, x1, x2 = gv0 - tv0, gv1 - tv1, gv2 - tv2
    c0 = T00 * x0 + T10 * x1 + T20 * x2
    c1 = T01 * x0 + T11 * x1 + T21 * x2
    c2 = T02 * x0 + T12 * x1 + T22 * x2
    x0, x1, x2 = tv0 - e0, tv1 - e1, tv2 - e2
    uu0 = T00 * x0 + T10 * x1 + T20 * x2
    uu1 = T01 * x0 + T11 * x1 + T21 * x2
    uu2 = T02 * x0 + T12 * x1 + T22 * x2
    at0 = T00 * ta0 + T10 * ta1 + T20 * ta2
    at1 = T01 * ta0 + T11 * ta1 + T21 * ta2
    at2 = T02 * ta0 + T12 * ta1 + T22 * ta2
    alpha = gains.alpha
    peval = lambda s_: reference_path_eval(path, s_)
    D10, D11, D12, D20, D21, D22, D30, D31, D32, extra = _frame(
        s, q0, q1, q2, uu0, uu1, uu2, o0, o1, o2, peval, v_w, alpha
    )
    pd, f1, f2, f3, k1, k2, pt, u, wdF, pF2, pF3, y_w, z_w = extra
    pd0, pd1, pd2 = pd
    f10, f11, f12 = f1
    pt0, pt1, pt2 = pt
    # [sdot] = (K_p pt + v_w w1 + eta_hat - v_t t1 - om x p_d) . f1, in {T} coordinates.
    vd0 = o1 * pd2 - o2 * pd1
    vd1 = o2 * pd0 - o0 * pd2
    vd2 = o0 * pd1 - o1 * pd0
    pF1 = pt0 * f10 + pt1 * f11 + pt2 * f12
    sdot = gains.K_p * pF1 + ((c0 - vd0) * f10 + (c1 - vd1) * f11 + (c2 - vd2) * f12)

    # Exact feedforward: central differences of R_D^T along the flow, in {T}:
    # qdot = c - om x q; d/dt uu = R_T^T a_t - om x uu (eta_hat constant); omdot from the target.
    qd0 = c0 - (o1 * q2 - o2 * q1)
    qd1 = c1 - (o2 * q0 - o0 * q2)
    qd2 = c2 - (o0 * q1 - o1 * q0)
    ud0 = at0 - (o1 * uu2 - o2 * uu1)
    ud1 = at1 - (o2 * uu0 - o0 * uu2)
    ud2 = at2 - (o0 * uu1 - o1 * uu0)
    h = fd_step
    A10, A11, A12, A20, A21, A22, A30, A31, A32, _ = _frame(
        s + h * sdot,
        q0 + h * qd0, q1 + h * qd1, q2 + h * qd2,
        uu0 + h * ud0, uu1 + h * ud1, uu2 + h * ud2,
        o0 + h * od0, o1 + h * od1, o2 + h * od2,
        peval, v_w, alpha,
    )  # fmt: skip
    B10, B11, B12, B20, B21, B22, B30, B31, B32, _ = _frame(
        s - h * sdot,
        q0 - h * qd0, q1 - h * qd1, q2 - h * qd2,
        uu0 - h * ud0, uu1 - h * ud1, uu2 - h * ud2,
        o0 - h * od0, o1 - h * od1, o2 - h * od2,
        peval, v_w, alpha,
    )  # fmt: skip
    inv = 1.0 / (2.0 * h)
    # omega^T = vee(dR R^T), R = [d1 d2 d3]: (dR R^T)_ij = sum_k d(d_k)_i (d_k)_j.
    dA0, dA1, dA2 = A10 - B10, A11 - B11, A12 - B12
    dB0, dB1, dB2 = A20 - B20, A21 - B21, A22 - B22
    dC0, dC1, dC2 = A30 - B30, A31 - B31, A32 - B32
    M21 = (dA2 * D11 + dB2 * D21 + dC2 * D31) * inv
    M12 = (dA1 * D12 + dB1 * D22 + dC1 * D32) * inv
    M02 = (dA0 * D12 + dB0 * D22 + dC0 * D32) * inv
    M20 = (dA2 * D10 + dB2 * D20 + dC2 * D30) * inv
    M10 = (dA1 * D10 + dB1 * D20 + dC1 * D30) * inv
    M01 = (dA0 * D11 + dB0 * D21 + dC0 * D31) * inv
    # omega_DI = omega_DT + omega_TI, then in NED (R_T^I v).
    x0 = 0.5 * (M21 - M12) + o0
    x1 = 0.5 * (M02 - M20) + o1
    x2 = 0.5 * (M10 - M01) + o2
    oI0 = T00 * x0 + T01 * x1 + T02 * x2
    oI1 = T10 * x0 + T11 * x1 + T12 * x2
    oI2 = T20 * x0 + T21 * x1 + T22 * x2
    d10 = T00 * D10 + T01 * D11 + T02 * D12
    d11 = T10 * D10 + T11 * D11 + T12 * D12
    d12 = T20 * D10 + T21 * D11 + T22 * D12
    # Rt = R_W^D: Rt11 = d1.w1, Rt12 = d1.w2, Rt13 = d1.w3.
    R12 = d10 * w20 + d11 * w21 + d12 * w22
    R13 = d10 * w30 + d11 * w31 + d12 * w32
    psi = 0.5 * (1.0 - (d10 * w10 + d11 * w11 + d12 * w12))
    e2, e3 = 0.5 * R13, -0.5 * R12
    # Pi_R Rt^T omega_DI^D is omega_DI expressed on w2, w3.
    ff2 = oI0 * w20 + oI1 * w21 + oI2 * w22
    ff3 = oI0 * w30 + oI1 * w31 + oI2 * w32
    K_R = gains.K_R
    cm2 = -K_R * e2 + ff2
    cm3 = -K_R * e3 + ff3
    law2, law3 = cm2, cm3
    mode = "law"
    if ext.psi_turn and psi >= ext.psi_turn_threshold:
        rate = ext.psi_turn_rate if ext.psi_turn_rate is not None else 0.5 * K_R
        w1: Vec = (w10, w11, w12)
        w2: Vec = (w20, w21, w22)
        w3: Vec = (w30, w31, w32)
        ax = _cross(w1, (d10, d11, d12))
        na = math.sqrt(_dot(ax, ax))
        if na > 1e-3:
            v2, v3 = _dot(ax, w2) / na, _dot(ax, w3) / na
        else:
            # Antipodal: a right turn about the local vertical (down), projected on w2, w3.
            v2, v3 = w22, w32
            nu = math.hypot(v2, v3)
            v2, v3 = (v2 / nu, v3 / nu) if nu > 1e-6 else (0.0, 1.0)
        cm2, cm3 = rate * v2 + ff2, rate * v3 + ff3
        mode = "psi_turn"
    if ext.rate_limit is not None and ext.rate_limit_mode == "per_axis":
        lim = ext.rate_limit
        if abs(cm2) > lim or abs(cm3) > lim:
            cm2, cm3 = max(-lim, min(lim, cm2)), max(-lim, min(lim, cm3))
            mode += "+sat"
    elif ext.rate_limit is not None:
        mag = math.hypot(cm2, cm3)
        if mag > ext.rate_limit:
            k = ext.rate_limit / mag
            cm2, cm3 = cm2 * k, cm3 * k
            mode += "+sat"
    omega_w1 = (cm2 * w20 + cm3 * w30, cm2 * w21 + cm3 * w31, cm2 * w22 + cm3 * w32)
    cmd = MpfCommand(t, cm2, cm3, sdot, omega_w1)
    if not diagnostics:
        return cmd, None
    u0, u1, u2 = u
    wd11, wd21, wd31 = wdF
    f20, f21, f22 = f2
    f30, f31, f32 = f3
    wd0 = wd11 * f10 + wd21 * f20 + wd31 * f30
    wd1 = wd11 * f11 + wd21 * f21 + wd31 * f31
    wd2 = wd11 * f12 + wd21 * f22 + wd31 * f32
    diag = MpfDiagnostics(
        t,
        s,
        (
            T00 * pt0 + T01 * pt1 + T02 * pt2,
            T10 * pt0 + T11 * pt1 + T12 * pt2,
            T20 * pt0 + T21 * pt1 + T22 * pt2,
        ),
        math.sqrt(pt0 * pt0 + pt1 * pt1 + pt2 * pt2),
        (pF1, pF2, pF3),
        (
            tp0 + (T00 * pd0 + T01 * pd1 + T02 * pd2),
            tp1 + (T10 * pd0 + T11 * pd1 + T12 * pd2),
            tp2 + (T20 * pd0 + T21 * pd1 + T22 * pd2),
        ),
        psi,
        (e2, e3),
        y_w,
        z_w,
        (d10, d11, d12),
        (
            T00 * wd0 + T01 * wd1 + T02 * wd2,
            T10 * wd0 + T11 * wd1 + T12 * wd2,
            T20 * wd0 + T21 * wd1 + T22 * wd2,
        ),
        (
            T00 * f10 + T01 * f11 + T02 * f12,
            T10 * f10 + T11 * f11 + T12 * f12,
            T20 * f10 + T21 * f11 + T22 * f12,
        ),
        (oI0, oI1, oI2),
        (ff2, ff3),
        (law2, law3),
        v_w - math.sqrt(u0 * u0 + u1 * u1 + u2 * u2),
        mode,
        k1,
        k2,
    )
    return cmd, diag


def reference_path_eval(
    self: TabulatedPath, s: float
) -> tuple[Tuple3, Tuple3, Tuple3, Tuple3, float, float]:
    """Fast evaluation: (position, f1, f2, f3, k1, k2) at arc length s, in {T}."""
    L = self.length
    if self.closed:
        s = s % L
    elif s <= 0.0 or s >= L:
        # Beyond an open end the path continues straight along the end tangent.
        j = 0 if s <= 0.0 else self.n
        p, t, f2 = self._Pl[j], self._Tl[j], self._F2l[j]
        ds = s if j == 0 else s - L
        f3 = (
            t[1] * f2[2] - t[2] * f2[1],
            t[2] * f2[0] - t[0] * f2[2],
            t[0] * f2[1] - t[1] * f2[0],
        )
        return (p[0] + ds * t[0], p[1] + ds * t[1], p[2] + ds * t[2]), t, f2, f3, 0.0, 0.0
    h = self.ds
    x = s / h
    i = int(x)
    if i >= self.n:
        i = self.n - 1
    w = x - i
    Pl, Tl = self._Pl, self._Tl
    pa0, pa1, pa2 = Pl[i]
    pb0, pb1, pb2 = Pl[i + 1]
    ta0, ta1, ta2 = Tl[i]
    tb0, tb1, tb2 = Tl[i + 1]
    w2 = w * w
    w3 = w2 * w
    h00 = 2 * w3 - 3 * w2 + 1
    h10 = (w3 - 2 * w2 + w) * h
    h01 = -2 * w3 + 3 * w2
    h11 = (w3 - w2) * h
    g00 = (6 * w2 - 6 * w) / h
    g10 = 3 * w2 - 4 * w + 1
    g01 = (-6 * w2 + 6 * w) / h
    g11 = 3 * w2 - 2 * w
    p = (
        h00 * pa0 + h10 * ta0 + h01 * pb0 + h11 * tb0,
        h00 * pa1 + h10 * ta1 + h01 * pb1 + h11 * tb1,
        h00 * pa2 + h10 * ta2 + h01 * pb2 + h11 * tb2,
    )
    dx = g00 * pa0 + g10 * ta0 + g01 * pb0 + g11 * tb0
    dy = g00 * pa1 + g10 * ta1 + g01 * pb1 + g11 * tb1
    dz = g00 * pa2 + g10 * ta2 + g01 * pb2 + g11 * tb2
    nn = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    a0, a1, a2 = dx * nn, dy * nn, dz * nn  # f1
    # _mrot(F2[i], ta, f1) inlined: f2_i carried by the minimal rotation ta -> f1
    v0, v1, v2 = self._F2l[i]
    cx = ta1 * a2 - ta2 * a1
    cy = ta2 * a0 - ta0 * a2
    cz = ta0 * a1 - ta1 * a0
    d = ta0 * a0 + ta1 * a1 + ta2 * a2
    ux = cy * v2 - cz * v1
    uy = cz * v0 - cx * v2
    uz = cx * v1 - cy * v0
    k = 1.0 / (1.0 + d) if d > -0.999999 else 0.0
    r0 = v0 + ux + k * (cy * uz - cz * uy)
    r1 = v1 + uy + k * (cz * ux - cx * uz)
    r2 = v2 + uz + k * (cx * uy - cy * ux)
    nr = 1.0 / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    r0, r1, r2 = r0 * nr, r1 * nr, r2 * nr
    q0 = a1 * r2 - a2 * r1
    q1 = a2 * r0 - a0 * r2
    q2 = a0 * r1 - a1 * r0
    ang = w * self._C[i]
    ca, sa = math.cos(ang), math.sin(ang)
    f2 = (ca * r0 + sa * q0, ca * r1 + sa * q1, ca * r2 + sa * q2)
    f3 = (ca * q0 - sa * r0, ca * q1 - sa * r1, ca * q2 - sa * r2)
    K1, K2 = self._K1l, self._K2l
    k1 = (1 - w) * K1[i] + w * K1[i + 1]
    k2 = (1 - w) * K2[i] + w * K2[i + 1]
    return p, (a0, a1, a2), f2, f3, k1, k2
