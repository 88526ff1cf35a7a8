"""Baseline guidance laws a PX4 or ArduPlane user would fly instead of MPF (pure: no I/O, no clock).

All three are written here from the published equations (no autopilot source is copied):

- ``npfg``: PX4's nonlinear path following guidance (Stastny & Siegwart, "On flying backwards:
  preventing run-away of small, low-speed, fixed-wing UAVs in strong winds", IROS 2019; as
  implemented in PX4-Autopilot ``src/lib/npfg/npfg.cpp``, read at commit 0b40586 for the
  look-ahead angle, track-error bound, bearing feasibility, wind triangle, period bounds and
  curvature feedforward). PX4 defaults: NPFG_PERIOD 10 s, NPFG_DAMPING 0.7, NPFG_LB_PERIOD and
  NPFG_UB_PERIOD on, NPFG_ROLL_TC 0.5 s; the feasibility buffer 1.5 m/s (npfg.hpp's
  airspeed_buffer_, not re-verified). Track keeping / minimum ground speed are off (their
  PX4 defaults only matter when the wind exceeds the airspeed, which ``check`` refuses).
- ``l1_loiter``: ArduPlane's L1 loiter (Park, Deyst & How 2004; ArduPilot
  ``libraries/AP_L1_Control/AP_L1_Control.cpp`` update_loiter: capture by L1 pursuit of the
  centre, circle by a PD on the radial error plus the centripetal term, switch where the two
  demands cross). NAVL1_PERIOD 17 s, NAVL1_DAMPING 0.75 (the parameter table's defaults).
  The centre is re-sent every step (the target's current position plus the circle's centre);
  ArduPlane's own ground velocity is inertial, so the moving centre is not fed forward.
- ``pursuit``: carrot chasing (Sujit, Saripalli & Sousa, IEEE CSM 2014): the carrot is the
  point ``lookahead_m`` ahead of the closest point along the moving path; pure pursuit of it,
  a_lat = 2 V^2 sin(eta) / D (eta: angle between the ground course and the line of sight, D:
  distance to the carrot), in the ground-velocity frame.

All three are horizontal laws. Their vertical channel is the same stated simple law (a
TECS-like altitude loop, not TECS): climb-rate demand h_dot = (h_ref - h) / vertical_tau_s +
(careful) the path point's own climb rate, gamma_ref = asin(h_dot / V), and a flight-path
rate gamma_dot = (gamma_ref - gamma) / gamma_tau_s.

Output: the SAME command as MPF (:class:`MpfCommand`), so the same adapter turns it into the
same SET_ATTITUDE_TARGET. MPF's command is the angular velocity of the wind frame; a lateral
acceleration demand a_lat (air-mass frame, > 0 to the right) is a heading rate a_lat / V_air
about NED down (NPFG and L1 both command a roll of atan(a_lat / g), which in a coordinated
turn is that heading rate), and the flight-path-rate demand is a rotation about the horizontal
right axis: omega_w1 = chi_dot e_down + gamma_dot e_right.

Diagnostics: |pt| of a baseline is the distance to the CLOSEST point of the moving path (MPF's
|pt| is to its virtual point, never smaller), and ``s`` tracks that closest point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.core.guidance.law import (
    MpfCommand,
    MpfDiagnostics,
    VehicleState,
)
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetState

LAWS = ("mpf", "npfg", "npfg_static", "l1_loiter", "pursuit")
EPS = 1e-6


@dataclass(frozen=True)
class BaselineParams:
    """Parameters of the baselines (PX4 / ArduPlane defaults, module docstring)."""

    npfg_period_s: float = 10.0
    npfg_damping: float = 0.7
    npfg_roll_tc_s: float = 0.5
    npfg_period_lb: bool = True
    npfg_period_ub: bool = True
    npfg_airspeed_buffer_m_s: float = 1.5
    l1_period_s: float = 17.0
    l1_damping: float = 0.75
    pursuit_lookahead_m: float = 25.0
    vertical_tau_s: float = 5.0
    gamma_tau_s: float = 1.0
    max_gamma_rad: float = 0.35
    # both autopilots clip the roll set-point atan(a_lat / g) (PX4 FW_R_LIM, ArduPlane
    # ROLL_LIMIT_DEG); 45 deg = vehicle.max_bank_rad's default
    max_bank_rad: float = 0.785398


_DEFAULT = BaselineParams()


# --------------------------------------------------------------------------- NPFG (2D)
def _cross2(a: tuple[float, float], b: tuple[float, float]) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _feasibility(w_cross: float, w_dot: float, airspeed: float, wind: float, buf: float) -> float:
    """Continuous bearing feasibility in [0, 1] (sin^2 ramp over the airspeed buffer)."""
    wc = wind if w_dot < 0.0 else abs(w_cross)
    x = min(max((airspeed - wc) / buf, 0.0), 1.0)
    return math.sin(0.5 * math.pi * x) ** 2


def _npfg_look_ahead(e: float, vg: float, tc: float) -> float:
    """The look-ahead angle (rad) at track error e (m): the track-error bound at time constant
    tc (s) normalises e, pi/2 on the path, 0 beyond the bound."""
    bound = vg * tc if vg > 1.0 else 0.5 * tc * (vg * vg + 1.0)
    ne = min(max(e / bound, 0.0), 1.0)
    return 0.5 * math.pi * (ne - 1.0) ** 2


def _npfg_period(
    p: BaselineParams, curvature: float, va: float, vg: float, ws: float, e: float, feas_t: float
) -> float:
    """NPFG's period (s): the nominal one within its bounds (lower: the roll time constant;
    upper: track keeping on curved paths in wind), blended in with the track proximity."""
    zeta = p.npfg_damping
    period = p.npfg_period_s
    if p.npfg_period_lb and p.npfg_roll_tc_s > 0.0:
        turn = abs(curvature * va)
        wf = 2.0 if ws > va else 2.0 * (1.0 - math.sqrt(1.0 - min(1.0, ws / va)))
        lb = math.pi * p.npfg_roll_tc_s / zeta
        if turn * wf >= EPS and zeta >= 0.5:
            lb = 4.0 * math.pi * p.npfg_roll_tc_s * zeta * feas_t + (1.0 - feas_t) * lb
        period = max(lb * 1.5, period)  # PERIOD_SAFETY_FACTOR 1.5
        if p.npfg_period_ub and turn * wf * feas_t > EPS:
            ub = 4.0 * math.pi * zeta / (turn * wf * feas_t)
            if period > ub:
                adapted = max(lb * 1.5, ub)
                prox = math.sin(_npfg_look_ahead(e, vg, period * zeta)) ** 2
                period = adapted * prox + (1.0 - prox) * period
    return period


def _npfg_air_ref(
    b: tuple[float, float],
    wind_vel: tuple[float, float],
    va: float,
    ws: float,
    w_cross_b: float,
    w_dot_b: float,
) -> tuple[float, float]:
    """The air velocity (m/s, NE) that makes good the bearing b in the wind; PX4's mitigation
    law when the bearing is infeasible."""
    if abs(w_cross_b) < va and (w_dot_b > 0.0 or ws < va):
        along = math.sqrt(max(va * va - w_cross_b * w_cross_b, 0.0))
        return (along * b[0] - w_cross_b * b[1], w_cross_b * b[0] + along * b[1])
    k = math.sqrt(max(ws * ws - va * va, 0.0))
    r = (k * b[0] - wind_vel[0], k * b[1] - wind_vel[1])
    n = math.hypot(*r) or 1.0
    return (r[0] / n * va, r[1] / n * va)


def npfg_lateral_accel(
    ground_vel: tuple[float, float],
    wind_vel: tuple[float, float],
    tangent: tuple[float, float],
    signed_track_error: float,
    curvature: float,
    p: BaselineParams = _DEFAULT,
) -> float:
    """NPFG's lateral acceleration demand (m/s^2, > 0 to the right) in a horizontal NE plane.

    tangent: unit path tangent (N, E); signed_track_error (m): > 0 when the vehicle is to the
    RIGHT of the path (the side of the tangent rotated +90 deg, N-E-down convention);
    curvature (1/m): > 0 for a path turning right. Nominal airspeed = the current airspeed
    (the airspeed loop is the adapter's, not NPFG's).
    """
    gv = ground_vel
    air = (gv[0] - wind_vel[0], gv[1] - wind_vel[1])
    va = math.hypot(*air)
    if va < EPS:
        return 0.0
    vg = math.hypot(*gv)
    ws = math.hypot(*wind_vel)
    e = abs(signed_track_error)
    # on-track feasibility and the period bounds (lower: roll time constant; upper: track keeping
    # on curved paths in wind), blended in with the track proximity at the nominal period
    w_cross_t = _cross2(wind_vel, tangent)
    w_dot_t = wind_vel[0] * tangent[0] + wind_vel[1] * tangent[1]
    feas_t = _feasibility(w_cross_t, w_dot_t, va, ws, p.npfg_airspeed_buffer_m_s)
    zeta = p.npfg_damping
    period = _npfg_period(p, curvature, va, vg, ws, e, feas_t)
    k_p = 4.0 * math.pi * zeta / period
    lam = _npfg_look_ahead(e, vg, period * zeta)
    # bearing: toward the path (against the signed error) blended into the tangent
    nrm = (-tangent[1], tangent[0])
    sgn = -1.0 if signed_track_error >= 0.0 else 1.0
    to_path = (sgn * nrm[0], sgn * nrm[1])
    c, s_ = math.cos(lam), math.sin(lam)
    b = (c * to_path[0] + s_ * tangent[0], c * to_path[1] + s_ * tangent[1])
    w_cross_b = _cross2(wind_vel, b)
    w_dot_b = wind_vel[0] * b[0] + wind_vel[1] * b[1]
    feas = _feasibility(w_cross_b, w_dot_b, va, ws, p.npfg_airspeed_buffer_m_s)
    ref = _npfg_air_ref(b, wind_vel, va, ws, w_cross_b, w_dot_b)
    dot = air[0] * ref[0] + air[1] * ref[1]
    cr = _cross2(air, ref)
    if dot < 0.0:
        a_fb = k_p * (va if cr >= 0.0 else -va)
    else:
        a_fb = k_p * cr / max(math.hypot(*ref), EPS)
    # curvature feedforward at the closest point (path-frame curvature at this offset)
    # (PX4 guards the denominator with curvature * MIN_RADIUS 0.5 m; |curvature| here, so the
    # guard also holds for left turns)
    kc = curvature / max(1.0 - curvature * signed_track_error, abs(curvature) * 0.5)
    vt = max(gv[0] * tangent[0] + gv[1] * tangent[1], 0.0)
    ratio = 1.0 + w_dot_t / max(math.sqrt(max(va * va - w_cross_t * w_cross_t, 0.0)), EPS)
    a_ff = va * ratio * kc * vt
    return a_fb + feas * feas_t * math.sin(lam) ** 2 * a_ff


# --------------------------------------------------------------------------- L1 loiter (2D)
def l1_loiter_lateral_accel(
    ground_vel: tuple[float, float],
    centre_to_vehicle: tuple[float, float],
    radius: float,
    direction: int,
    p: BaselineParams = _DEFAULT,
) -> float:
    """ArduPlane's L1 loiter demand (m/s^2, > 0 right) about a centre, N-E plane.

    direction +1 clockwise seen from above (right turns), -1 counter-clockwise.
    """
    vg = max(math.hypot(*ground_vel), 1.0)
    omega = 2.0 * math.pi / p.l1_period_s
    kx, kv = omega * omega, 2.0 * p.l1_damping * omega
    k_l1 = 4.0 * p.l1_damping * p.l1_damping
    l1 = max(p.l1_damping * p.l1_period_s * vg / math.pi, 1.0)
    r = math.hypot(*centre_to_vehicle)
    u = (centre_to_vehicle[0] / r, centre_to_vehicle[1] / r) if r > 0.1 else (1.0, 0.0)
    x_cap = _cross2(u, ground_vel)  # tangential speed (clockwise positive)
    l_cap = -(ground_vel[0] * u[0] + ground_vel[1] * u[1])  # inbound radial speed
    nu = max(-0.5 * math.pi, min(0.5 * math.pi, math.atan2(x_cap, l_cap)))
    a_cap = k_l1 * vg * vg / l1 * math.sin(nu)
    x_err = r - radius
    a_pd = x_err * kx + (-l_cap) * kv
    v_tan = x_cap * direction
    if l_cap < 0.0 and v_tan < 0.0:
        a_pd = max(a_pd, 0.0)
    a_ctr = v_tan * v_tan / max(0.5 * radius, radius + x_err)
    a_circ = direction * (a_pd + a_ctr)
    if x_err > 0.0 and direction * a_cap < direction * a_circ:
        return a_cap
    return a_circ


# --------------------------------------------------------------------------- pursuit (2D)
def pursuit_lateral_accel(ground_vel: tuple[float, float], to_carrot: tuple[float, float]) -> float:
    """Pure pursuit of a carrot: a_lat = 2 V^2 sin(eta) / D (m/s^2, > 0 right)."""
    v = math.hypot(*ground_vel)
    d = math.hypot(*to_carrot)
    if v < EPS or d < EPS:
        return 0.0
    eta = math.atan2(
        _cross2(ground_vel, to_carrot), ground_vel[0] * to_carrot[0] + ground_vel[1] * to_carrot[1]
    )
    eta = max(-0.5 * math.pi, min(0.5 * math.pi, eta))
    return 2.0 * v * v * math.sin(eta) / d


# --------------------------------------------------------------------------- the common wrapper
def _mv(R: list[list[float]], v: tuple[float, float, float]) -> tuple[float, float, float]:
    return (
        R[0][0] * v[0] + R[0][1] * v[1] + R[0][2] * v[2],
        R[1][0] * v[0] + R[1][1] * v[1] + R[1][2] * v[2],
        R[2][0] * v[0] + R[2][1] * v[1] + R[2][2] * v[2],
    )


def _cross(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


_CIRCLES: dict[int, tuple[TabulatedPath, tuple[float, float, float], float]] = {}


def _loiter_circle(path: TabulatedPath) -> tuple[tuple[float, float, float], float]:
    """The loiter an ArduPlane user would send for this path: centre = centroid of the path's
    nodes in {T}, radius = their mean horizontal distance from it (exact for a circle; for a
    helix its axis and radius, the altitude coming from the vertical channel). Cached: a pure
    function of the (immutable) path."""
    hit = _CIRCLES.get(id(path))
    if hit is not None and hit[0] is path:
        return hit[1], hit[2]
    import numpy as np

    P = path.positions()
    c = (float(P[:, 0].mean()), float(P[:, 1].mean()), float(P[:, 2].mean()))
    r = float(np.mean(np.hypot(P[:, 0] - c[0], P[:, 1] - c[1])))
    _CIRCLES[id(path)] = (path, c, r)
    return c, r


def _closest_near(path: TabulatedPath, q: tuple[float, float, float], s: float) -> float:
    """The closest point near the previous one (m): Newton steps on (q - p(s)) . f1 = 0 from s,
    each capped at 2 m, pure float arithmetic (the global search of TabulatedPath.closest costs a
    numpy pass over every node; consecutive evaluations move the point by centimetres)."""
    for _ in range(8):
        p, f1, _f2, _f3, _k1, _k2 = path.eval(s)
        step = (q[0] - p[0]) * f1[0] + (q[1] - p[1]) * f1[1] + (q[2] - p[2]) * f1[2]
        step = max(-2.0, min(2.0, step))
        s += step
        if abs(step) < 1e-6:
            break
    if path.closed:
        s %= path.length
    return s


def _baseline_lateral_accel(
    law: str,
    params: BaselineParams,
    path: TabulatedPath,
    s_c: float,
    RT: list[list[float]],
    target: TargetState,
    p: Any,  # the vehicle's position (NED, m)
    gv: tuple[float, float, float],
    wind: tuple[float, ...],
    vp: tuple[float, ...],
    tan2: tuple[float, float],
    pt: tuple[float, float, float],
    curv: float,
) -> float:
    """The baseline's lateral acceleration demand (m/s^2, > 0 to the right, before the bank
    limit) at the closest point s_c of the moving path (NED, vp its velocity)."""
    if law in ("npfg", "npfg_static"):
        # careful user: the path's frame moves with the closest point, so the vehicle's velocity
        # relative to it and the wind relative to it (the air mass seen from the path) go in
        if law != "npfg_static":
            g2 = (gv[0] - vp[0], gv[1] - vp[1])
            w2d = (wind[0] - vp[0], wind[1] - vp[1])
        else:
            g2, w2d = (gv[0], gv[1]), (wind[0], wind[1])
        ste = _cross2(tan2, (pt[0], pt[1]))  # > 0: vehicle right of the path
        return npfg_lateral_accel(g2, w2d, tan2, ste, curv, params)
    if law == "l1_loiter":
        # the loiter centre: the horizontal centroid of the path's nodes (a circle's centre)
        c_T, radius = _loiter_circle(path)
        cI = _mv(RT, c_T)
        rel = (p[0] - target.position[0] - cI[0], p[1] - target.position[1] - cI[1])
        direction = 1 if curv >= 0.0 else -1
        return l1_loiter_lateral_accel(
            (gv[0], gv[1]), (float(rel[0]), float(rel[1])), radius, direction, params
        )
    if law == "pursuit":
        pc, *_ = path.eval(s_c + params.pursuit_lookahead_m)
        cI = _mv(RT, pc)
        to_c = (target.position[0] + cI[0] - p[0], target.position[1] + cI[1] - p[1])
        return pursuit_lateral_accel((gv[0], gv[1]), (float(to_c[0]), float(to_c[1])))
    raise ValueError(f"unknown guidance law {law!r} (one of {', '.join(LAWS)})")


def _wind_frame_rates(
    params: BaselineParams,
    a_lat: float,
    hdot: float,
    v_w: float,
    w1: tuple[float, float, float],
    w2: tuple[float, float, float],
    w3: tuple[float, float, float],
) -> tuple[tuple[float, float, float], float, float]:
    """(omega of w1 (NED, rad/s), its w2 and w3 components): the turn rate a_lat / v_w about
    down and the flight-path rate towards the climb rate hdot (m/s, up) about the right axis."""
    chi_dot = a_lat / max(v_w, EPS)
    gam_ref = math.asin(max(-1.0, min(1.0, hdot / max(v_w, EPS))))
    gam_ref = max(-params.max_gamma_rad, min(params.max_gamma_rad, gam_ref))
    gamma = math.asin(max(-1.0, min(1.0, -w1[2])))
    gam_dot = (gam_ref - gamma) / params.gamma_tau_s
    hn = math.hypot(w1[0], w1[1])
    right = (-w1[1] / hn, w1[0] / hn, 0.0) if hn > EPS else (w2[0], w2[1], w2[2])
    om_w = (gam_dot * right[0], gam_dot * right[1], chi_dot + gam_dot * right[2])
    c2 = om_w[0] * w2[0] + om_w[1] * w2[1] + om_w[2] * w2[2]
    c3 = om_w[0] * w3[0] + om_w[1] * w3[1] + om_w[2] * w3[2]
    return om_w, c2, c3


def baseline_law(
    law: str,
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    params: BaselineParams = _DEFAULT,
) -> tuple[MpfCommand, MpfDiagnostics]:
    """One evaluation of a baseline (``npfg``, ``npfg_static``, ``l1_loiter``, ``pursuit``).

    s: the previous closest point's arc length (m), the hint for the local closest-point search.
    Returns MPF's command type (angular velocity of w1, NED) and its diagnostics record (pt to
    the closest point of the moving path; psi/e/feedforward fields zero).
    """
    import numpy as np

    t = float(vehicle.t)
    v_w = float(vehicle.airspeed)
    R = vehicle.R_W_I.tolist()
    w1 = (R[0][0], R[1][0], R[2][0])
    w2 = (R[0][1], R[1][1], R[2][1])
    w3 = (R[0][2], R[1][2], R[2][2])
    wind = tuple(float(x) for x in vehicle.wind)
    p = vehicle.position
    RT = target.R_T_I.tolist()
    RTt = [[RT[j][i] for j in range(3)] for i in range(3)]
    q = _mv(RTt, tuple((p - target.position).tolist()))
    s_c = _closest_near(path, q, s) if math.isfinite(s) else path.closest(np.asarray(q))
    pd, f1, f2, f3, k1, k2 = path.eval(s_c)
    om = tuple(target.omega_T.tolist())
    # path point in NED, its velocity (target velocity + omega x p_d), its tangent
    pdI = _mv(RT, pd)
    tp = target.position
    pf = (float(tp[0]) + pdI[0], float(tp[1]) + pdI[1], float(tp[2]) + pdI[2])
    vpd = _mv(RT, _cross(om, pd))
    vp = tuple(float(target.velocity[i]) + vpd[i] for i in range(3))
    t1 = _mv(RT, f1)
    # horizontal tangent and horizontal curvature of the path (right-positive, 1/m)
    kap = _mv(RT, tuple(k1 * f2[i] + k2 * f3[i] for i in range(3)))  # type: ignore[arg-type]
    th = math.hypot(t1[0], t1[1])
    tan2 = (t1[0] / th, t1[1] / th) if th > EPS else (w1[0], w1[1])
    curv = (t1[0] * kap[1] - t1[1] * kap[0]) / max(th, EPS) ** 3 if th > EPS else 0.0
    pt = (p[0] - pf[0], p[1] - pf[1], p[2] - pf[2])
    gv = (v_w * w1[0] + wind[0], v_w * w1[1] + wind[1], v_w * w1[2] + wind[2])
    careful = law != "npfg_static"
    a_lat = _baseline_lateral_accel(
        law, params, path, s_c, RT, target, p, gv, wind, vp, tan2, pt, curv
    )
    a_max = GRAVITY_M_S2 * math.tan(params.max_bank_rad)
    mode = law
    if abs(a_lat) > a_max:
        a_lat = math.copysign(a_max, a_lat)
        mode += "+sat"  # the autopilot's roll limit acted (the table's "time saturated")
    # vertical: altitude loop on the closest point's height (+ its climb rate when careful)
    h_err = p[2] - pf[2]  # h_ref - h, heights up: (-pf_d) - (-p_d)
    hdot = h_err / params.vertical_tau_s + (-vp[2] if careful else 0.0)
    om_w, c2, c3 = _wind_frame_rates(params, a_lat, hdot, v_w, w1, w2, w3)
    # the closest point's progression: relative velocity along the tangent (in {T} arc length)
    # d s_c / dt = (v_rel . f1) / (1 - pt . kappa) for the closest point of a curve (in {T}; the
    # path's own rotation omega x p_d is in vp, the frame's rotation of pt is second order here)
    kap_pt = sum(pt[i] * kap[i] for i in range(3))
    sdot = sum((gv[i] - vp[i]) * t1[i] for i in range(3)) / max(1.0 - kap_pt, 0.1)
    cmd = MpfCommand(t, c2, c3, sdot, (om_w[0], om_w[1], om_w[2]))
    ptn = math.sqrt(pt[0] ** 2 + pt[1] ** 2 + pt[2] ** 2)
    f1I = t1
    ptF = (
        sum(pt[i] * f1I[i] for i in range(3)),
        sum(pt[i] * _mv(RT, f2)[i] for i in range(3)),
        sum(pt[i] * _mv(RT, f3)[i] for i in range(3)),
    )
    u = tuple(vp[i] - wind[i] for i in range(3))
    diag = MpfDiagnostics(
        t, s_c, pt, ptn, ptF, pf, 0.0, (0.0, 0.0), ptF[1], ptF[2], w1, f1I, f1I,
        (0.0, 0.0, 0.0), (0.0, 0.0), (c2, c3), v_w - math.sqrt(sum(x * x for x in u)),
        mode, k1, k2,
    )  # fmt: skip
    return cmd, diag
