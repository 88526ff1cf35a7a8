"""Pre-flight checks: the gain condition by hand, Assumption 1, feasibility."""

import math

import pytest

from mpf_mavlink.core.guidance import Gains
from mpf_mavlink.core.guidance.checks import assumption1, feasibility, gain_condition
from mpf_mavlink.core.paths import circle, lemniscate
from mpf_mavlink.core.target import ConstantTurn, Stationary


def test_gain_condition_by_hand():
    # K_p = 0.5, alpha = 3, c1 = 4, v = 10, c2 = 0.25:
    # sqrt(alpha^2 + c1^2) = 5, v/5 = 2, so K = min(0.5, 2) = 0.5;
    # needed K_R > v^2 / (c1^2 (1 - 2 c2)^2 K) = 100 / (16 * 0.25 * 0.5) = 50.
    # k1 = 1/64; W = [[2 k1 K, -2 k1 v/(1-2c2)], [., K_R/2]] = [[1/64, -0.625], [-0.625, 30]]
    # for K_R = 60: trace 30.015625, det 30/64 - 0.390625 = 0.078125,
    # lambda_min = (30.015625 - sqrt(30.015625^2 - 0.3125)) / 2 = 0.0026030368;
    # M2 = diag(1/64, 1/0.75): lambda_max = 4/3, so lambda_MPF = 0.0019522776.
    r = gain_condition(Gains(0.5, 60.0, 3.0), 10.0, 10.0, 4.0, 0.25)
    assert r.figures["K"] == pytest.approx(0.5)
    assert r.figures["K_R_needed"] == pytest.approx(50.0)
    assert r.figures["lambda_mpf"] == pytest.approx(0.0019522776, rel=1e-6)
    assert r.status == "pass"
    assert gain_condition(Gains(0.5, 49.0, 3.0), 10.0, 10.0, 4.0, 0.25).status == "fail"


def test_initial_state_outside_region_is_a_warning():
    r = gain_condition(Gains(0.5, 60.0, 3.0), 10.0, 10.0, 4.0, 0.25, pt0=5.0, psi0=0.1)
    assert r.status == "warn" and r.figures["initial_inside_region"] is False


def test_assumption1_fails_when_the_target_outruns_the_vehicle():
    path = circle((0, 0, 0), 50.0)
    slow = assumption1(path, ConstantTurn((0, 0, 0), 5.0), 15.0, 10.0)
    fast = assumption1(path, ConstantTurn((0, 0, 0), 16.0), 15.0, 10.0)
    # Straight-moving target: the worst path point moves at exactly the target speed.
    assert slow.figures["max_path_point_speed_m_s"] == pytest.approx(5.0, abs=1e-6)
    assert slow.ok and not fast.ok
    # A turning target adds omega x p_d: 0.1 rad/s at 50 m radius = 5 m/s more at most.
    turning = assumption1(path, ConstantTurn((0, 0, 0), 5.0, 0.0, 0.1), 15.0, 10.0)
    assert turning.figures["max_path_point_speed_m_s"] == pytest.approx(10.0, abs=0.05)


def test_feasibility_of_a_circle_about_a_stationary_target():
    # Circle of radius R at v: turn rate v/R, bank atan(v^2 / (g R)).
    v, R = 15.0, 40.0
    r = feasibility(circle((0, 0, 0), R), Stationary(), v, 20.0, math.radians(45))
    assert r.figures["peak_turn_rate_rad_s"] == pytest.approx(v / R, rel=0.01)
    assert r.figures["peak_bank_rad"] == pytest.approx(math.atan(v * v / (9.80665 * R)), rel=0.01)
    assert r.ok
    tight = feasibility(circle((0, 0, 0), 15.0), Stationary(), v, 20.0, math.radians(45))
    assert not tight.ok  # needs 57 deg of bank


def test_feasibility_of_the_paper_scenario_needs_steep_bank():
    from mpf_mavlink.core.target import PaperProfile

    r = feasibility(lemniscate(50.0), PaperProfile(), 15.0, 100.0, math.radians(45))
    # The lemniscate's lobes at 15 m/s ask for more than 45 deg: fine for the paper's
    # kinematic vehicle, infeasible for a real small UAV.
    assert not r.ok and r.figures["peak_bank_rad"] > math.radians(45)


# ---------------------------------------------------------------- climb (issue 25)
def _const_climb(c, v=16.0, T=600.0, dt=0.5):
    import numpy as np

    ts = np.arange(0.0, T + dt / 2, dt)
    g = math.asin(c / v)
    W1 = np.tile([math.cos(g), 0.0, -math.sin(g)], (len(ts), 1))
    return ts, W1


def test_climb_check_against_capability_and_energy_reserve():
    from mpf_mavlink.core.guidance.checks import climb_feasibility

    # reserve of slowing from 16 to 14 m/s: (16^2 - 14^2) / (2 g) = 3.06 m of height
    ts, W1 = _const_climb(1.0)
    assert climb_feasibility(ts, W1, 16.0, 14.0, 18.0, 4.0, 1.5).status == "pass"
    # 0.5 m/s more than the aircraft climbs, for 600 s: 300 m of deficit >> 3.06 m: refused
    ts, W1 = _const_climb(4.5)
    r = climb_feasibility(ts, W1, 16.0, 14.0, 18.0, 4.0, 1.5)
    assert r.status == "fail" and r.figures["deficit_climb_m"] == pytest.approx(300.0, rel=0.01)
    # a short excess the kinetic energy covers: 0.5 m/s over for 4 s = 2 m < 3.06 m (marginal)
    ts, W1 = _const_climb(4.5, T=4.0)
    assert climb_feasibility(ts, W1, 16.0, 14.0, 18.0, 4.0, 1.5).status == "warn"
    # descent beyond idle sink: 2 m/s against 1.5 for 600 s
    ts, W1 = _const_climb(-2.0)
    assert climb_feasibility(ts, W1, 16.0, 14.0, 18.0, 4.0, 1.5).status == "fail"
    # capability unknown: a warning when the path climbs
    ts, W1 = _const_climb(1.0)
    assert climb_feasibility(ts, W1, 16.0, 14.0, 18.0, None, None).status == "warn"


def test_climb_check_counts_the_turbulence_downdrafts():
    import numpy as np

    from mpf_mavlink.core.guidance.checks import climb_feasibility, vertical_gusts

    # 1.5 m/s of climb at 1000 m (3281 ft) above sea level in "light" turbulence: MIL-F-8785C
    # above 2000 ft, sigma_w between the table's 6.9 (1750 ft) and 7.4 ft/s (3750 ft): 7.28 ft/s
    # (2.2 m/s), L_w 1750 ft (533 m, 33 s at 16 m/s): a 2-sigma downdraft of 4.4 m/s for 33 s
    # needs 5.9 m/s against 4.1: (5.9 - 4.1) 33 = 60 m >> 3 m
    ts, W1 = _const_climb(1.5)
    w, T = vertical_gusts("light", np.full(len(ts), 1000.0), 16.0)
    sig_fps = 6.9 + 0.5 * (1000.0 / 0.3048 - 1750.0) / 2000.0
    assert w[0] == pytest.approx(2 * sig_fps * 0.3048, rel=1e-6)
    assert T[0] == pytest.approx(1750 * 0.3048 / 16.0, rel=1e-6)
    r = climb_feasibility(ts, W1, 16.0, 14.0, 18.0, 4.1, 1.5, gusts=(w, T))
    assert r.status == "fail" and r.figures["deficit_climb_m"] == pytest.approx(
        (1.5 + w[0] - 4.1) * T[0], rel=0.02
    )
    # near the sea: below 1000 ft, sigma_w = 0.1 W20 = 2.5 ft/s and L_w = h: no deficit
    w, T = vertical_gusts("light", np.full(len(ts), 100.0), 16.0)
    assert w[0] == pytest.approx(2 * 0.762, rel=0.01) and T[0] == pytest.approx(100 / 16.0)
    assert climb_feasibility(ts, W1, 16.0, 14.0, 18.0, 4.1, 1.5, gusts=(w, T)).status == "pass"


def test_demanded_directions_read_a_target_built_from_arrays_as_one_that_kept_its_floats():
    # The integration reads the target's floats; a motion whose states carry arrays only (no
    # TargetState.floats) goes through the arrays' values, which are the same numbers: the
    # results must be identical, not merely close.
    import dataclasses

    import numpy as np

    from mpf_mavlink.core.guidance.checks import demanded_directions

    path = lemniscate(150.0)
    boat = ConstantTurn(position=(10.0, -5.0, -120.0), speed=6.0, heading=0.4, turn_rate=0.02,
                        climb_rate=0.5)  # fmt: skip

    class ArraysOnly:
        def state(self, t: float):  # type: ignore[no-untyped-def]
            return dataclasses.replace(boat.state(t))  # replace drops the floats

    assert ArraysOnly().state(3.0).floats is None and boat.state(3.0).floats is not None
    a = demanded_directions(path, boat, 16.0, 60.0, 5.0, (1.0, -2.0, 0.0), with_positions=True)
    b = demanded_directions(
        path, ArraysOnly(), 16.0, 60.0, 5.0, (1.0, -2.0, 0.0), with_positions=True
    )
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)
    # unit demanded directions (the a11 clamp only bites beyond Assumption 1)
    assert np.allclose(np.linalg.norm(a[1], axis=1), 1.0, atol=1e-12)
