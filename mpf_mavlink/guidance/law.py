"""The 3D moving-path-following law (Jain, de Sousa, Aguiar, Theorem 1), pure and exact.

One function per equation of the paper is kept in :func:`desired_frame` (sdot, W_d, D) and
:func:`mpf_law` (Psi, e, the feedforward omega_DI and the command). Everything is plain float
arithmetic for speed (one evaluation is a few tens of microseconds). No I/O, no clock.

Frames (see ../shared/spec/mpf-law.md): {I} NED; {W} wind frame (w1 along the air-relative
velocity); {T} target; {F} parallel-transport frame at p_d(s); {W_d} steady-state desired
velocity frame; {D} transient desired frame.

The feedforward omega_DI (angular velocity of {D} relative to {I}) is the exact derivative
of R_D^I along the closed-loop flow: R_D^I is a pure function of (t, s, p, target) and we
difference it along the known kinematics (pdot = v_w w1 + eta_hat, sdot from the law, the
target's velocity, acceleration, angular velocity and its rate), never along telemetry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..paths import TabulatedPath
from ..target import TargetState

Vec = tuple[float, float, float]


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

    rate_limit: max |[w2, w3]| (rad/s); a larger command is scaled down along its own
      direction (the turn keeps its sense, only its rate is capped). None = off.
    psi_turn: when Psi >= psi_turn_threshold (heading more than 90 deg from d1 by default),
      replace the feedback by a turn of constant rate psi_turn_rate (rad/s; None = K_R/2, which
      equals the law's own feedback magnitude at Psi = 1/2, so the command is continuous there)
      about w1 x d1; at the antipode (w1 = -d1) the turn is a right turn about the local
      vertical. The feedforward is kept.
    wind_compensation: use the vehicle's wind estimate eta_hat in sdot and W_d (the paper's
      Remark); off = eta_hat is ignored (the paper's simulations).
    """

    rate_limit: float | None = None
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


@dataclass(frozen=True)
class MpfCommand:
    """The law's output at time t (s).

    w2, w3: commanded angular velocity of the wind frame about w2 and w3 (rad/s);
    sdot: progression of the virtual point (m/s); omega_w1_I: the same command as the
    angular velocity of w1 in NED (rad/s), which is what the fixed-wing adapter needs.
    """

    t: float
    w2: float
    w3: float
    sdot: float
    omega_w1_I: tuple[float, float, float]


@dataclass(frozen=True)
class MpfDiagnostics:
    """What the law saw at time t: errors, frames and the feedforward.

    Vectors are tuples (x, y, z) in NED unless noted (tuples keep the hot path cheap).
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


def _cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


class _Eval:
    """R_D^T and the quantities around it at one (s, q, uu, omega) point, all in {T}."""

    __slots__ = (
        "d1", "d2", "d3", "pt", "f1", "f2", "f3", "pd", "wd1", "pt_F", "y_w", "z_w",
        "margin", "k1", "k2",
    )  # fmt: skip


def desired_frame(
    s: float, q: Vec, uu: Vec, om: Vec, path: TabulatedPath, v_w: float, alpha: float
) -> _Eval:
    """[wdbasis] W_d and the transient frame D at one point, in target coordinates {T}.

    q = R_T^T (p - p_t): vehicle position relative to the target (m);
    uu = R_T^T (v_t - eta_hat): target velocity less the wind estimate (m/s);
    om = omega_TI^T (rad/s). Path point p_d(s), v_d = om x p_d.
    """
    ev = _Eval()
    pd, f1, f2, f3, k1, k2 = path.eval(s)
    pt = (q[0] - pd[0], q[1] - pd[1], q[2] - pd[2])
    # u = v_t t1 + v_d - eta_hat: v_w times the air-relative direction needed in steady state.
    u0 = uu[0] + om[1] * pd[2] - om[2] * pd[1]
    u1 = uu[1] + om[2] * pd[0] - om[0] * pd[2]
    u2 = uu[2] + om[0] * pd[1] - om[1] * pd[0]
    iv = 1.0 / v_w
    wd21 = (u0 * f2[0] + u1 * f2[1] + u2 * f2[2]) * iv
    wd31 = (u0 * f3[0] + u1 * f3[1] + u2 * f3[2]) * iv
    rad = 1.0 - wd21 * wd21 - wd31 * wd31
    ev.margin = v_w - math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    # Assumption 1 keeps rad > 0; outside it we keep the frame defined and report the margin.
    wd11 = math.sqrt(rad) if rad > 1e-12 else 1e-6
    n = 1.0 / math.sqrt(wd11 * wd11 + wd21 * wd21)
    wd12, wd22 = -wd21 * n, wd11 * n
    # wd3 = wd1 x wd2 in {F} components (wd32 = 0).
    wd13 = -wd31 * wd22
    wd23 = wd31 * wd12
    wd33 = wd11 * wd22 - wd21 * wd12
    pF1 = pt[0] * f1[0] + pt[1] * f1[1] + pt[2] * f1[2]
    pF2 = pt[0] * f2[0] + pt[1] * f2[1] + pt[2] * f2[2]
    pF3 = pt[0] * f3[0] + pt[1] * f3[1] + pt[2] * f3[2]
    # Cross-track error pt_x = pt - (pt.f1) f1, projected on wd2 and wd3.
    y_w = pF2 * wd22
    z_w = pF2 * wd23 + pF3 * wd33
    a = alpha
    n1 = 1.0 / math.sqrt(a * a + y_w * y_w + z_w * z_w)
    n2 = 1.0 / math.sqrt(a * a + y_w * y_w)
    a1, b1, c1 = a * n1, -y_w * n1, -z_w * n1  # d1 in {W_d}
    a2, b2 = y_w * n2, a * n2  # d2 in {W_d} (third component 0)
    a3, b3, c3 = -c1 * b2, c1 * a2, a1 * b2 - b1 * a2  # d3 = d1 x d2
    # {W_d} axes in {F}: wd1 = (wd11, wd21, wd31), wd2 = (wd12, wd22, 0), wd3 = (wd13, wd23, wd33);
    # each d_k goes {W_d} -> {F} -> {T}.
    out = []
    for x, y, z in ((a1, b1, c1), (a2, b2, 0.0), (a3, b3, c3)):
        g1 = x * wd11 + y * wd12 + z * wd13
        g2 = x * wd21 + y * wd22 + z * wd23
        g3 = x * wd31 + z * wd33
        out.append(
            (
                g1 * f1[0] + g2 * f2[0] + g3 * f3[0],
                g1 * f1[1] + g2 * f2[1] + g3 * f3[1],
                g1 * f1[2] + g2 * f2[2] + g3 * f3[2],
            )
        )
    ev.d1, ev.d2, ev.d3 = out
    ev.wd1 = (
        wd11 * f1[0] + wd21 * f2[0] + wd31 * f3[0],
        wd11 * f1[1] + wd21 * f2[1] + wd31 * f3[1],
        wd11 * f1[2] + wd21 * f2[2] + wd31 * f3[2],
    )
    ev.pt, ev.f1, ev.f2, ev.f3, ev.pd = pt, f1, f2, f3, pd
    ev.pt_F, ev.y_w, ev.z_w, ev.k1, ev.k2 = (pF1, pF2, pF3), y_w, z_w, k1, k2
    return ev


# Step for differencing R_D^T along the flow (s). Central differences cancel the symmetric
# second-order terms of a first-order state advance, so the error is O(h^2) ~ 1e-8 relative,
# and round-off (~1e-16 / h) is smaller still.
FD_STEP_S = 1e-4


def mpf_law(
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions = Extensions(),
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
    Rw = vehicle.R_W_I.tolist()
    RT = target.R_T_I.tolist()
    eta = vehicle.wind.tolist() if ext.wind_compensation else [0.0, 0.0, 0.0]
    p = vehicle.position.tolist()
    ptp = target.position.tolist()
    ptv = target.velocity.tolist()
    pta = target.acceleration.tolist()
    om: Vec = tuple(target.omega_T.tolist())  # type: ignore[assignment]
    omd = target.omega_dot_T.tolist()
    # The vehicle's ground velocity as the law models it: v_w w1 + eta_hat (NED).
    w1v = [v_w * Rw[0][0] + eta[0], v_w * Rw[1][0] + eta[1], v_w * Rw[2][0] + eta[2]]

    def to_T(v: list[float]) -> Vec:  # R_T^T v
        return (
            RT[0][0] * v[0] + RT[1][0] * v[1] + RT[2][0] * v[2],
            RT[0][1] * v[0] + RT[1][1] * v[1] + RT[2][1] * v[2],
            RT[0][2] * v[0] + RT[1][2] * v[1] + RT[2][2] * v[2],
        )

    def to_I(v: Vec) -> Vec:  # R_T^I v
        return (
            RT[0][0] * v[0] + RT[0][1] * v[1] + RT[0][2] * v[2],
            RT[1][0] * v[0] + RT[1][1] * v[1] + RT[1][2] * v[2],
            RT[2][0] * v[0] + RT[2][1] * v[1] + RT[2][2] * v[2],
        )

    q = to_T([p[0] - ptp[0], p[1] - ptp[1], p[2] - ptp[2]])
    c = to_T([w1v[0] - ptv[0], w1v[1] - ptv[1], w1v[2] - ptv[2]])
    uu = to_T([ptv[0] - eta[0], ptv[1] - eta[1], ptv[2] - eta[2]])
    at = to_T(pta)
    alpha = gains.alpha
    ev = desired_frame(s, q, uu, om, path, v_w, alpha)
    pd, f1 = ev.pd, ev.f1
    # [sdot] = (K_p pt + v_w w1 + eta_hat - v_t t1 - om x p_d) . f1, in {T} coordinates.
    vd = _cross(om, pd)
    sdot = gains.K_p * _dot(ev.pt, f1) + _dot((c[0] - vd[0], c[1] - vd[1], c[2] - vd[2]), f1)

    # Exact feedforward: central differences of R_D^T along the flow, in {T}:
    # qdot = c - om x q; d/dt uu = R_T^T a_t - om x uu (eta_hat constant); omdot from the target.
    oq = _cross(om, q)
    ou = _cross(om, uu)
    qd = (c[0] - oq[0], c[1] - oq[1], c[2] - oq[2])
    ud = (at[0] - ou[0], at[1] - ou[1], at[2] - ou[2])
    h = FD_STEP_S
    ea = desired_frame(
        s + h * sdot,
        (q[0] + h * qd[0], q[1] + h * qd[1], q[2] + h * qd[2]),
        (uu[0] + h * ud[0], uu[1] + h * ud[1], uu[2] + h * ud[2]),
        (om[0] + h * omd[0], om[1] + h * omd[1], om[2] + h * omd[2]),
        path,
        v_w,
        alpha,
    )
    eb = desired_frame(
        s - h * sdot,
        (q[0] - h * qd[0], q[1] - h * qd[1], q[2] - h * qd[2]),
        (uu[0] - h * ud[0], uu[1] - h * ud[1], uu[2] - h * ud[2]),
        (om[0] - h * omd[0], om[1] - h * omd[1], om[2] - h * omd[2]),
        path,
        v_w,
        alpha,
    )
    inv = 1.0 / (2.0 * h)
    D1, D2, D3 = ev.d1, ev.d2, ev.d3
    A1, A2, A3 = ea.d1, ea.d2, ea.d3
    B1, B2, B3 = eb.d1, eb.d2, eb.d3

    # omega^T = vee(dR R^T), R = [d1 d2 d3]: (dR R^T)_ij = sum_k d(d_k)_i (d_k)_j.
    def M(i: int, j: int) -> float:
        return (
            (A1[i] - B1[i]) * D1[j] + (A2[i] - B2[i]) * D2[j] + (A3[i] - B3[i]) * D3[j]
        ) * inv

    odt = (0.5 * (M(2, 1) - M(1, 2)), 0.5 * (M(0, 2) - M(2, 0)), 0.5 * (M(1, 0) - M(0, 1)))
    # omega_DI = omega_DT + omega_TI, then in NED.
    om_I = to_I((odt[0] + om[0], odt[1] + om[1], odt[2] + om[2]))
    w1: Vec = (Rw[0][0], Rw[1][0], Rw[2][0])
    w2: Vec = (Rw[0][1], Rw[1][1], Rw[2][1])
    w3: Vec = (Rw[0][2], Rw[1][2], Rw[2][2])
    d1 = to_I(D1)
    # Rt = R_W^D: Rt11 = d1.w1, Rt12 = d1.w2, Rt13 = d1.w3.
    R12 = _dot(d1, w2)
    R13 = _dot(d1, w3)
    psi = 0.5 * (1.0 - _dot(d1, w1))
    e2, e3 = 0.5 * R13, -0.5 * R12
    # Pi_R Rt^T omega_DI^D is omega_DI expressed on w2, w3.
    ff2, ff3 = _dot(om_I, w2), _dot(om_I, w3)
    K_R = gains.K_R
    c2 = -K_R * e2 + ff2
    c3 = -K_R * e3 + ff3
    law2, law3 = c2, c3
    mode = "law"
    if ext.psi_turn and psi >= ext.psi_turn_threshold:
        rate = ext.psi_turn_rate if ext.psi_turn_rate is not None else 0.5 * K_R
        ax = _cross(w1, d1)
        na = math.sqrt(_dot(ax, ax))
        if na > 1e-3:
            u2, u3 = _dot(ax, w2) / na, _dot(ax, w3) / na
        else:
            # Antipodal: a right turn about the local vertical (down), projected on w2, w3.
            u2, u3 = w2[2], w3[2]
            nu = math.hypot(u2, u3)
            u2, u3 = (u2 / nu, u3 / nu) if nu > 1e-6 else (0.0, 1.0)
        c2, c3 = rate * u2 + ff2, rate * u3 + ff3
        mode = "psi_turn"
    if ext.rate_limit is not None:
        mag = math.hypot(c2, c3)
        if mag > ext.rate_limit:
            k = ext.rate_limit / mag
            c2, c3 = c2 * k, c3 * k
            mode += "+sat"
    omega_w1 = (c2 * w2[0] + c3 * w3[0], c2 * w2[1] + c3 * w3[1], c2 * w2[2] + c3 * w3[2])
    pdI = to_I(pd)
    cmd = MpfCommand(t, c2, c3, sdot, omega_w1)
    if not diagnostics:
        return cmd, None
    diag = MpfDiagnostics(
        t=t,
        s=s,
        pt=to_I(ev.pt),
        pt_norm=math.sqrt(_dot(ev.pt, ev.pt)),
        pt_F=ev.pt_F,
        p_f=(ptp[0] + pdI[0], ptp[1] + pdI[1], ptp[2] + pdI[2]),
        psi=psi,
        e=(e2, e3),
        y_w=ev.y_w,
        z_w=ev.z_w,
        d1=d1,
        wd1=to_I(ev.wd1),
        f1=to_I(f1),
        omega_DI=om_I,
        feedforward=(ff2, ff3),
        w_cmd_law=(law2, law3),
        path_speed_margin=ev.margin,
        mode=mode,
        k1=ev.k1,
        k2=ev.k2,
    )
    return cmd, diag
