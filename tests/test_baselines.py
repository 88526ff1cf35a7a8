"""The baseline guidance laws (core/guidance/baselines.py) in the paper's kinematic plant with
perfect rate tracking: each expectation is derived by hand from the law's published equations."""

from __future__ import annotations

import math

import numpy as np

from mpf_mavlink.core.frames import euler_to_matrix
from mpf_mavlink.core.guidance.baselines import (
    BaselineParams,
    l1_loiter_lateral_accel,
    npfg_lateral_accel,
)
from mpf_mavlink.core.guidance.law import Extensions, Gains
from mpf_mavlink.core.paths import shapes
from mpf_mavlink.core.target import ConstantTurn, Stationary
from sim.plant.kinematic import ClosedLoop, initial_state

V = 16.0


def fly(  # noqa: ANN201
    law: str,
    path,
    target,
    p0,
    yaw0: float,
    T: float,
    dt: float = 0.05,  # noqa: ANN001
):
    loop = ClosedLoop(path, target, Gains(), Extensions(), V, None, law=law)
    x = initial_state(path, target, np.asarray(p0, float), euler_to_matrix(0.0, 0.0, yaw0), None)
    ts, ps, ss = [], [], []
    for _ in range(int(round(T / dt))):
        x = loop.step(x, dt)
        ts.append(x.t)
        ps.append(x.p.copy())
        ss.append(x.s)
    return np.array(ts), np.array(ps)


def test_npfg_on_a_static_straight_line_is_the_second_order_loop_of_px4s_period_and_damping() -> (
    None
):
    # Near the track the look-ahead angle pi/2 (1 - e/e_b)^2 leaves an approach angle
    # chi_ref = -pi e / e_b (e_b = V T zeta) and the heading loop is chi' = k_p (chi_ref - chi)
    # with k_p = 4 pi zeta / T; with e' = V chi: e'' + k_p e' + (k_p pi V / e_b) e = 0, i.e.
    # omega_n = 2 pi / T and damping exactly zeta (that is what NPFG_PERIOD / NPFG_DAMPING mean).
    # So at the default 0.7 it DOES overshoot, by exp(-pi zeta / sqrt(1 - zeta^2)) = 4.60 %,
    # and the envelope exp(-zeta omega_n t) is 1.4e-6 at 30 s. (5 m << e_b = 112 m: linear.)
    zeta, T = 0.7, 10.0
    path = shapes.line((-2000.0, 0.0, -100.0), (4000.0, 0.0, -100.0))
    t, p = fly("npfg", path, Stationary(), (0.0, 5.0, -100.0), 0.0, 40.0)
    east = p[:, 1]
    over = -east.min() / 5.0
    expected = math.exp(-math.pi * zeta / math.sqrt(1 - zeta * zeta))
    # the linearisation drops sin(chi) - chi and the ne^2 term of the look-ahead (~ 5/112)
    assert abs(over - expected) < 0.005
    # first crossing at the damped half-period minus the phase: t where e = 0 of
    # e(t) = e0 exp(-zeta w t) (cos(wd t) + zeta w / wd sin(wd t)), wd = w sqrt(1 - zeta^2)
    w = 2 * math.pi / T
    wd = w * math.sqrt(1 - zeta * zeta)
    t_cross = (math.pi - math.atan(wd / (zeta * w))) / wd
    t_meas = t[np.argmax(east < 0.0)]
    assert abs(t_meas - t_cross) < 0.2
    assert abs(east[t >= 30.0]).max() < 0.01


def test_npfg_holds_a_static_circle_it_starts_on() -> None:
    # On the circle, tangent, in still air: the feedback term is zero (air velocity = the
    # reference) and the curvature feedforward is V * 1 * (1/R) * V = V^2 / R exactly.
    R = 80.0
    path = shapes.circle((0.0, 0.0, -100.0), R, clockwise=True)
    t, p = fly("npfg", path, Stationary(), (R, 0.0, -100.0), math.pi / 2, 60.0)
    r = np.hypot(p[:, 0], p[:, 1])
    assert abs(r - R).max() < 0.05


def test_l1_loiter_on_a_static_circle_captures_from_inside_and_holds_the_radius() -> None:
    # Inside the circle L1 is in circle mode: radial error e'' = -Kv e' - Kx e with Kx = w^2,
    # Kv = 2 zeta w (w = 2 pi / 17 s, zeta 0.75): overshoot exp(-pi zeta / sqrt(1 - zeta^2))
    # = 2.8 % of the 10 m start; the envelope exp(-zeta w t) is 6e-8 at 60 s.
    R = 80.0
    path = shapes.circle((0.0, 0.0, -100.0), R, clockwise=True)
    t, p = fly("l1_loiter", path, Stationary(), (R - 10.0, 0.0, -100.0), math.pi / 2, 90.0)
    r = np.hypot(p[:, 0], p[:, 1])
    assert (r - R).max() < 0.6  # 0.28 m linear; the centripetal term is nonlinear in e
    assert abs(r[t >= 60.0] - R).max() < 0.05


def test_l1_loiter_demand_directions() -> None:
    # 200 m north of the centre flying east (clockwise tangent) outside: capture turns right.
    a = l1_loiter_lateral_accel((0.0, V), (200.0, 0.0), 80.0, 1)
    assert a > 0.0
    # on the circle, tangent, clockwise: exactly the centripetal V^2 / R
    a = l1_loiter_lateral_accel((0.0, V), (80.0, 0.0), 80.0, 1)
    assert math.isclose(a, V * V / 80.0, rel_tol=1e-12)


def test_npfg_far_from_the_path_flies_straight_at_it() -> None:
    # Beyond the track-error bound e_b = V T zeta = 112 m the look-ahead angle is 0: the
    # bearing points straight at the path, so with the heading already there the demand is 0,
    # and heading along the path (90 deg off the bearing) gives sin(90) k_p V = 4 pi 0.7 / 10 * 16.
    # an eastbound line; the vehicle 200 m to its right (south), heading north straight at it
    a = npfg_lateral_accel((V, 0.0), (0.0, 0.0), (0.0, 1.0), 200.0, 0.0, BaselineParams())
    assert abs(a) < 1e-9
    a = npfg_lateral_accel((0.0, V), (0.0, 0.0), (0.0, 1.0), 200.0, 0.0, BaselineParams())
    assert math.isclose(abs(a), 4 * math.pi * 0.7 / 10.0 * V, rel_tol=1e-9)


def test_pursuit_holds_a_static_circle() -> None:
    # Pure pursuit a = 2 V^2 sin(eta) / D toward any point of the circle from a point of it,
    # heading along the tangent, is the circle's curvature: sin(eta) = D / (2 R) (chord angle).
    R = 80.0
    path = shapes.circle((0.0, 0.0, -100.0), R, clockwise=True)
    t, p = fly("pursuit", path, Stationary(), (R, 0.0, -100.0), math.pi / 2, 60.0)
    r = np.hypot(p[:, 0], p[:, 1])
    assert abs(r - R).max() < 0.1


def test_pursuit_lags_a_line_moving_across_itself_by_the_derivable_distance() -> None:
    # A north-south line carried east at u = 3 m/s. In steady state the vehicle keeps pace
    # (V sin(beta) = u) and heads straight at the carrot L = 25 m ahead along the line, so it
    # trails the line by d = L tan(beta) = L u / sqrt(V^2 - u^2) = 4.772 m.
    u, L = 3.0, 25.0
    target = ConstantTurn((0.0, 0.0, 0.0), speed=u, heading=math.pi / 2)
    # {T}: x east (the target's heading), y south; the line along y, 100 m up
    path = shapes.line((0.0, -6000.0, -100.0), (0.0, 6000.0, -100.0))
    t, p = fly("pursuit", path, target, (0.0, 0.0, -100.0), math.pi, 60.0)
    lag = u * t - p[:, 1]  # the line's east position minus the vehicle's
    d = L * u / math.sqrt(V * V - u * u)
    assert abs(lag[t >= 40.0] - d).max() < 0.05


def test_a_baseline_starting_20_m_above_the_path_descends_to_it_on_the_altitude_loop() -> None:
    # The stated vertical law: h_dot = (h_ref - h) / 5 s, gamma following with 1 s: the height
    # error decays like a critically-damped-ish pair of first-order lags (5 s and 1 s), from 20 m
    # to 20 * (5 e^{-t/5} - e^{-t}) / 4 = 0.0084 m at t = 40 s; never below the path.
    R = 80.0
    path = shapes.circle((0.0, 0.0, -100.0), R, clockwise=True)
    t, p = fly("npfg", path, Stationary(), (R, 0.0, -120.0), math.pi / 2, 40.0)
    above = -100.0 - p[:, 2]
    assert above.min() > -0.05
    assert abs(above[-1]) < 0.05
