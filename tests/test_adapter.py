"""The setpoint adapter.

The law's angular velocity of w1 -> bank, body rates, quaternion, thrust.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.core.adapter import (
    AdapterParams,
    AdapterState,
    adapt,
    bank_and_load_factor,
    reserve_airspeed,
    safe_setpoint,
)
from mpf_mavlink.core.energy import EnergyState
from mpf_mavlink.core.frames import euler_to_matrix, quat_wxyz_to_matrix

P = AdapterParams()
LEVEL = np.eye(3)
NORTH = (1.0, 0.0, 0.0)


def test_level_flight_gives_zero_rates_and_trim_thrust():
    # omega = 0 at the set airspeed: no turn, no load beyond 1 g, zero airspeed error
    sp, st_ = adapt((0.0, 0.0, 0.0), 15.0, LEVEL, NORTH, 0.02, P)
    assert sp.body_rates_frd == (0.0, 0.0, 0.0)
    assert sp.bank_rad == 0.0 and sp.load_factor == pytest.approx(1.0)
    assert sp.thrust == pytest.approx(P.trim_thrust)  # trim + 0 * kp + 0 integrator + 0 * k_n
    assert st_.energy.integ == 0.0
    # ArduPlane quaternion: roll 0, pitch = flight-path angle 0 + trim alpha, yaw 0
    a = P.trim_pitch_rad / 2
    assert sp.q_wxyz == pytest.approx((math.cos(a), 0.0, math.sin(a), 0.0), abs=1e-12)
    assert not sp.safe


def test_right_turn_gives_positive_bank_and_yaw_rate():
    # heading rate 0.3 rad/s at 15 m/s: centripetal 4.5 m/s^2 -> bank atan(4.5/g) = 24.6 deg,
    # n = sqrt(1 + (4.5/g)^2) = 1.100; wings still level so r = cos(0) cos(0) psid = 0.3 and
    # p = (bank - 0) / tau_roll = 0.860 rad/s (under the 1.22 rad/s limit)
    sp, _ = adapt((0.0, 0.0, 0.3), 15.0, LEVEL, NORTH, 0.02, P)
    bank = math.atan(4.5 / GRAVITY_M_S2)
    assert sp.bank_rad == pytest.approx(bank, rel=1e-9)
    assert sp.load_factor == pytest.approx(math.hypot(1.0, 4.5 / GRAVITY_M_S2), rel=1e-9)
    p, q, r = sp.body_rates_frd
    assert p == pytest.approx(bank / P.tau_roll_s) and r == pytest.approx(0.3) and q == 0.0
    # the quaternion's roll is the bank, yaw 0 (ArduPlane writes yaw to the rudder)
    R = quat_wxyz_to_matrix(sp.q_wxyz)
    assert math.atan2(R[2, 1], R[2, 2]) == pytest.approx(bank)
    assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(0.0, abs=1e-12)
    # extra load -> more thrust: (n - 1) k_n = 0.1003 * 0.2
    assert sp.thrust == pytest.approx(P.trim_thrust + P.load_factor_ff * (sp.load_factor - 1.0))


def test_coordinated_turn_in_body_axes():
    # Banked at phi = 30 deg in a steady level turn psid = g tan(phi)/V: the bank set-point
    # equals phi, so p = 0; q = sin(phi) psid, r = cos(phi) psid (sil-vehicle.md formulas)
    phi = math.radians(30.0)
    psid = GRAVITY_M_S2 * math.tan(phi) / 15.0
    sp, _ = adapt((0.0, 0.0, psid), 15.0, euler_to_matrix(phi, 0.0, 0.0), NORTH, 0.02, P)
    p, q, r = sp.body_rates_frd
    assert p == pytest.approx(0.0, abs=1e-9)
    assert q == pytest.approx(math.sin(phi) * psid) and r == pytest.approx(math.cos(phi) * psid)


def test_bank_is_clipped_and_climb_raises_pitch():
    sp, _ = adapt((0.0, 0.0, 3.0), 15.0, LEVEL, NORTH, 0.02, P)  # asks for ~78 deg
    assert sp.bank_rad == pytest.approx(P.max_bank_rad)
    # pull-up: omega = +0.1 about east turns w1 = north upward ((0,0.1,0) x (1,0,0) = (0,0,-0.1),
    # i.e. up in NED): gamma_dot = +0.1 rad/s; pitch = 0 + 0.1 * tau_pitch + trim
    sp, _ = adapt((0.0, 0.1, 0.0), 15.0, LEVEL, NORTH, 0.02, P)
    assert sp.pitch_rad == pytest.approx(0.1 * P.tau_pitch_s + P.trim_pitch_rad)
    assert sp.body_rates_frd[1] == pytest.approx(0.1)  # q = cos(0) thetad


def test_airspeed_hold_integrates_and_anti_windup():
    # the airspeed PI (energy control off): 2 m/s slow: kp e = 0.1, integrator +ki e dt each call
    P = dataclasses.replace(globals()["P"], energy_control=False)
    sp, s1 = adapt((0.0, 0.0, 0.0), 13.0, LEVEL, NORTH, 0.5, P)
    assert s1.energy.integ == pytest.approx(P.airspeed_ki * 2.0 * 0.5)
    assert sp.thrust == pytest.approx(P.trim_thrust + 0.1 + s1.energy.integ)
    # 20 m/s slow for a long time: output saturates at thrust_max and the integrator freezes
    s = AdapterState()
    for _ in range(200):
        sp, s = adapt((0.0, 0.0, 0.0), 1.0, LEVEL, NORTH, 0.1, P, s)
    assert sp.thrust == P.thrust_max
    assert (
        s.energy.integ < P.integrator_limit
    )  # frozen as soon as the output saturated (0.5 + 0.7 > 1)


finite = st.floats(-1e6, 1e6)
anyf = st.one_of(finite, st.sampled_from([math.nan, math.inf, -math.inf]))


@settings(max_examples=300, deadline=None)
@given(
    om=st.tuples(anyf, anyf, anyf), v=anyf, rpy=st.tuples(anyf, anyf, anyf),
    w1=st.tuples(anyf, anyf, anyf), dt=anyf, integ=st.floats(-0.3, 0.3),
)  # fmt: skip
def test_limits_never_exceeded(om, v, rpy, w1, dt, integ):
    with np.errstate(all="ignore"):
        try:
            R = euler_to_matrix(*rpy)
        except ValueError:  # cos(inf): an attitude that is all NaN
            R = np.full((3, 3), math.nan)
        n = math.sqrt(sum(x * x for x in w1)) if all(math.isfinite(x) for x in w1) else 1.0
    w1n = tuple(x / n for x in w1) if n > 1e-9 and math.isfinite(n) else w1
    sp, s = adapt(om, v, R, w1n, dt, P, AdapterState(energy=EnergyState(integ)))
    vals = (*sp.body_rates_frd, *sp.q_wxyz, sp.thrust, sp.bank_rad, sp.pitch_rad)
    assert all(math.isfinite(x) for x in vals)
    assert abs(sp.body_rates_frd[0]) <= P.max_roll_rate_rad_s
    assert abs(sp.body_rates_frd[1]) <= P.max_pitch_rate_rad_s
    assert abs(sp.body_rates_frd[2]) <= P.max_yaw_rate_rad_s
    assert P.thrust_min <= sp.thrust <= P.thrust_max
    assert abs(sp.bank_rad) <= P.max_bank_rad
    assert P.min_pitch_rad <= sp.pitch_rad <= P.max_pitch_rad
    assert abs(s.energy.integ) <= P.integrator_limit
    assert math.isclose(sum(x * x for x in sp.q_wxyz), 1.0, rel_tol=1e-9)
    # roll and pitch come from R's last row (yaw does not enter it, nor the adapter)
    bad = not all(math.isfinite(x) for x in (*om, v, *w1n, dt, *R[2]))
    if bad:
        assert sp.safe and sp.bank_rad == 0.0 and sp.thrust == P.trim_thrust


def test_safe_setpoint_levels_the_wings():
    sp = safe_setpoint(P, roll=0.3)
    assert sp.safe and sp.body_rates_frd == (pytest.approx(-0.6), 0.0, 0.0)  # -0.3 / tau 0.5
    assert sp.thrust == P.trim_thrust


def test_bank_and_load_factor_unchanged():
    assert bank_and_load_factor((1.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == (0.0, 1.0)


# ----------------------------------------------------------------------------- learned loops
def test_pitch_offset_starts_at_the_measured_theta_minus_gamma_then_integrates_the_demand():
    """trim_hat starts at theta - gamma (level flight at -1.8 deg pitch: -0.0314 rad, what real
    ArduPlane SITL flies at 15 m/s), then d trim_hat / dt = (tau_pitch / trim_tau) gamma_dot_cmd:
    a steady 0.01 rad/s climb demand for 2 s adds 1.0 / 4.0 * 0.01 * 2 = 0.005 rad."""
    theta = math.radians(-1.8)
    R = euler_to_matrix(0.0, theta, 0.0)
    meas = (R, (0.0, 0.0, 0.0))
    _, st0 = adapt((0.0, 0.0, 0.0), 15.0, R, NORTH, 0.0, P, meas=meas)
    assert st0.trim_hat == pytest.approx(theta, abs=1e-12)
    # omega about east (y): w1 = north pitches up at 0.01 rad/s (gamma_dot = +0.01)
    st_ = st0
    for _ in range(100):
        _, st_ = adapt((0.0, 0.01, 0.0), 15.0, R, NORTH, 0.02, P, st_, meas=meas)
    assert st_.trim_hat == pytest.approx(theta + 1.0 / 4.0 * 0.01 * 2.0, rel=1e-9)
    # the pitch set-point carries it: gamma 0 + tau 0.01 + trim_hat
    sp, _ = adapt((0.0, 0.01, 0.0), 15.0, R, NORTH, 0.02, P, st_, meas=meas)
    assert sp.pitch_rad == pytest.approx(0.01 + st_.trim_hat + 1.0 / 4.0 * 0.01 * 0.02, abs=1e-12)
    # no demand, no change: the offset that held the path stays
    _, st2 = adapt((0.0, 0.0, 0.0), 15.0, R, NORTH, 0.02, P, st_, meas=meas)
    assert st2.trim_hat == st_.trim_hat


def test_pitch_offset_does_not_wind_up_against_the_pitch_limit():
    R = LEVEL
    st_ = AdapterState(trim_hat=P.max_pitch_rad)  # set-point already at the limit
    _, st2 = adapt((0.0, 0.2, 0.0), 15.0, R, NORTH, 0.02, P, st_, meas=(R, (0, 0, 0)))
    assert st2.trim_hat == P.max_pitch_rad  # a climb demand cannot push it further


def test_turn_gain_learns_an_airframe_that_turns_less_per_bank_and_banks_more():
    """An aircraft that turns at 0.7 x g tan(bank) / V for the bank it was sent (the wide
    circles of real ArduPlane SITL with the rudder pinned), asked for 0.2 rad/s: turn_gain
    integrates the relative turn-rate error down to 0.7, the bank becomes atan(tan(ideal) /
    0.7) and the turn achieved is the one commanded."""
    v, chid = 15.0, 0.2
    ideal = math.atan(v * chid / GRAVITY_M_S2)
    st_ = AdapterState(trim_hat=0.0)
    psid = 0.0
    for _ in range(6000):  # 120 s >> turn_gain_tau_s = 8 s
        bank = st_.bank_prev or 0.0
        psid = 0.7 * GRAVITY_M_S2 * math.tan(bank) / v
        meas = (
            euler_to_matrix(bank, 0.0, 0.0),
            (0.0, psid * math.sin(bank), psid * math.cos(bank)),
        )
        sp, st_ = adapt((0.0, 0.0, chid), v, LEVEL, NORTH, 0.02, P, st_, meas=meas)
    assert st_.turn_gain == pytest.approx(0.7, rel=1e-3)
    assert sp.bank_rad == pytest.approx(math.atan(math.tan(ideal) / st_.turn_gain), abs=1e-9)
    assert psid == pytest.approx(chid, rel=1e-3)
    # below 5 deg of bank flown nothing is learned (the ratio would be noise)
    phi3 = math.radians(3.0)
    psid3 = 0.7 * GRAVITY_M_S2 * math.tan(phi3) / v
    meas3 = (euler_to_matrix(phi3, 0.0, 0.0), (0.0, psid3 * math.sin(phi3), psid3 * math.cos(phi3)))
    st3 = AdapterState(trim_hat=0.0, turn_gain=1.0, bank_prev=math.radians(20.0), chid_prev=0.2)
    _, st4 = adapt((0.0, 0.0, 0.0), v, LEVEL, NORTH, 0.02, P, st3, meas=meas3)
    assert st4.turn_gain == 1.0
    # a clipped bank (the aircraft cannot turn as asked) teaches nothing either
    big = AdapterState(trim_hat=0.0, turn_gain=1.0)
    _, st5 = adapt((0.0, 0.0, 2.0), v, LEVEL, NORTH, 0.02, P, big)
    assert st5.chid_prev is None and st5.bank_prev == P.max_bank_rad


def test_airspeed_integrator_can_reach_the_thrust_ceiling():
    """PX4's SIH airplane needs ~0.8+ throttle: the integrator is bounded by the output range
    (thrust_max - trim), not a smaller cap, so a slow aircraft gets full thrust and the
    saturation shows."""
    st_ = AdapterState()
    for _ in range(5000):
        sp, st_ = adapt((0.0, 0.0, 0.0), 12.0, LEVEL, NORTH, 0.02, P, st_)
    assert sp.thrust == P.thrust_max
    assert st_.energy.integ <= P.thrust_max - P.trim_thrust + 1e-12


def test_roll_rate_gain_is_the_zero_order_hold_equivalent_of_the_time_constant():
    """Held T s, the roll-rate set-point closes 1 - exp(-T / tau) of the bank error:
    (1 - exp(-2/3)) / 0.1 = 4.866 1/s at 10 Hz with tau 0.15 s (the continuous 1/tau = 6.667
    closed 67 % per hold); -> 1/tau as T -> 0, and T = 0 is the continuous loop."""
    from mpf_mavlink.core.adapter import roll_rate_gain

    assert roll_rate_gain(0.15, 0.1) == pytest.approx(4.8658, abs=1e-4)
    assert roll_rate_gain(0.15, 0.0) == 1.0 / 0.15
    assert roll_rate_gain(0.15, 1e-6) == pytest.approx(1.0 / 0.15, rel=1e-5)
    assert roll_rate_gain(0.15, float("nan")) == 1.0 / 0.15
    sp, _ = adapt((0.0, 0.0, 0.3), 15.0, LEVEL, NORTH, 0.1, P, hold_s=0.1)
    assert sp.body_rates_frd[0] == pytest.approx(sp.bank_rad * roll_rate_gain(P.tau_roll_s, 0.1))


def test_body_rates_keep_the_pitch_limits_the_attitude_set_point_has():
    # PX4 body rates carried no pitch limit: a capture from 33 m below the path pitched a
    # vehicle to 37 deg. The flight-path rate is cut so the pitch aimed at one tau_pitch ahead
    # stays within [min_pitch, max_pitch] (0.35 rad = 20 deg by default), both ways.
    up = (0.0, 0.5, 0.0)  # gamma_dot = +0.5 rad/s (see test_bank_is_clipped_and_climb_raises_pitch)
    theta = 0.3  # 17 deg nose up, level flight path (alpha 17 deg, as in a steep capture)
    sp, _ = adapt(up, 15.0, euler_to_matrix(0.0, theta, 0.0), NORTH, 0.02, P)
    assert sp.body_rates_frd[1] == pytest.approx((P.max_pitch_rad - theta) / P.tau_pitch_s)
    sp, _ = adapt(up, 15.0, euler_to_matrix(0.0, 0.4, 0.0), NORTH, 0.02, P)  # beyond: pitch down
    q = sp.body_rates_frd[1]
    assert q == pytest.approx((P.max_pitch_rad - 0.4) / P.tau_pitch_s) and q < 0.0
    down = (0.0, -0.5, 0.0)
    sp, _ = adapt(down, 15.0, euler_to_matrix(0.0, -0.3, 0.0), NORTH, 0.02, P)
    assert sp.body_rates_frd[1] == pytest.approx((P.min_pitch_rad + 0.3) / P.tau_pitch_s)
    # well inside the limits the law's demand passes unchanged
    sp, _ = adapt((0.0, 0.1, 0.0), 15.0, LEVEL, NORTH, 0.02, P)
    assert sp.body_rates_frd[1] == pytest.approx(0.1)


def _turn(phi: float, v: float) -> tuple[tuple[float, float, float], float]:
    """The law's omega for a level turn at bank phi and v, and that turn's body pitch rate
    g sin(phi) tan(phi) / v (the rate a rate loop must fly with the wings at phi)."""
    chid = GRAVITY_M_S2 * math.tan(phi) / v
    return (0.0, 0.0, chid), math.sin(phi) * chid


def test_pitch_rate_bias_makes_an_autopilot_that_over_flies_the_turn_fly_it():
    """SIL X8 (wind 6 m/s, 41 deg of bank): its PX4 rate loop flew 0.32 rad/s for 0.29 sent,
    1.1x (a pull-up's feed-forward in a turn, module comment). An autopilot flying 1.1 x the
    pitch rate sent: the estimate b_k of (flown - sent) obeys b' = b + a (0.1 (q_law - b) - b),
    a = dt / tau_b, so the error to its fixed point 0.1 q_law / 1.1 shrinks by 1 - 1.1 a per
    step: (1 - 0.022)^50 = 0.329 after tau_b = 1 s at 50 Hz; there the sent rate is q_law / 1.1
    and the rate flown is the law's."""
    phi, v = math.radians(41.0), 16.0
    om, q_law = _turn(phi, v)
    R = euler_to_matrix(phi, 0.0, 0.0)
    st_ = AdapterState(trim_hat=0.0)
    sp, st_ = adapt(om, v, R, NORTH, 0.02, P, st_)
    assert sp.body_rates_frd[1] == pytest.approx(q_law, rel=1e-9)  # nothing measured yet
    fixed = 0.1 * q_law / 1.1
    errs = []
    for _ in range(50):
        flown = 1.1 * sp.body_rates_frd[1]
        sp, st_ = adapt(om, v, R, NORTH, 0.02, P, st_, meas=(R, (0.0, flown, 0.0)))
        errs.append(st_.q_bias - fixed)
    assert errs[-1] / (0.0 - fixed) == pytest.approx((1 - 1.1 * 0.02) ** 50, rel=1e-9)
    for _ in range(1500):  # 30 tau_b more
        flown = 1.1 * sp.body_rates_frd[1]
        sp, st_ = adapt(om, v, R, NORTH, 0.02, P, st_, meas=(R, (0.0, flown, 0.0)))
    assert st_.q_bias == pytest.approx(fixed, rel=1e-9)
    assert 1.1 * sp.body_rates_frd[1] == pytest.approx(q_law, rel=1e-9)
    # off: the law's pitch rate is sent as it is, whatever was flown
    off = dataclasses.replace(P, rate_bias_tau_s=0.0)
    sp0, st0 = adapt(om, v, R, NORTH, 0.02, off, st_, meas=(R, (0.0, 1.0, 0.0)))
    assert st0.q_bias == 0.0 and sp0.body_rates_frd[1] == pytest.approx(q_law, rel=1e-9)


def test_pitch_rate_bias_settles_through_the_link_delay_without_ringing():
    """The estimate's loop F (H - 1) has gain below 1 at every frequency when tau_b exceeds
    the delay plus the rate loop's lag (module comment). A level turn at 30 deg and 15 m/s
    (the turn's pitch rate g sin tan(30 deg) / 15 = 0.18873 rad/s), a 60 ms link (3 frames at
    50 Hz) and a rate loop lagging 0.1 s that flies its set-point 0.03 rad/s high: tau_b = 1 s
    >> 0.16 s, so the rate flown comes to the turn's with no overshoot beyond 2 % of the bias,
    and stays."""
    phi, v = math.radians(30.0), 15.0
    om, q_turn = _turn(phi, v)
    assert q_turn == pytest.approx(0.18873, abs=1e-5)
    R = euler_to_matrix(phi, 0.0, 0.0)

    def fly(params: AdapterParams) -> tuple[list[float], AdapterState]:
        pending, q_ap, st_, hist = [0.0, 0.0, 0.0], 0.0, AdapterState(trim_hat=0.0), []
        for _ in range(2000):  # 40 s
            sp, st_ = adapt(om, v, R, NORTH, 0.02, params, st_, meas=(R, (0.0, q_ap, 0.0)))
            pending.append(sp.body_rates_frd[1])
            q_ap += (1.0 - math.exp(-0.02 / 0.1)) * (pending.pop(0) + 0.03 - q_ap)
            hist.append(q_ap)
        return hist, st_

    flown, st_ = fly(P)
    assert flown[-1] == pytest.approx(q_turn, abs=1e-6)
    assert max(flown[500:]) <= q_turn + 0.02 * 0.03  # after 10 s: no ringing above the turn's
    assert st_.q_bias == pytest.approx(0.03, abs=1e-6)
    # tau_b 0.05 s, under the delay plus lag: the bound does not hold and the loop runs away
    # (to the estimate's limit, the turn's own pitch rate)
    flown, _ = fly(dataclasses.replace(P, rate_bias_tau_s=0.05))
    assert abs(flown[-1] - q_turn) > 0.05


def test_pitch_rate_bias_is_the_turns_and_none_with_the_wings_level():
    """The bias is the rate loop's error on the turn's pitch rate, so it is bounded by that rate:
    wings level nothing is taken off whatever the pitch rate flown (moderate turbulence's gusts
    pitched the X8 at +-0.28 rad/s on straights; taken off, they wound the autopilot's own
    integrator against the next pull-up), and in a 10-deg turn at 16 m/s at most
    g sin tan(10 deg) / 16 = 0.01877 rad/s."""
    om = (0.0, 0.05, 0.0)  # a climb, wings level: q_law = 0.05
    st_ = AdapterState(trim_hat=0.0)
    for _ in range(500):
        sp, st_ = adapt(om, 16.0, LEVEL, NORTH, 0.02, P, st_, meas=(LEVEL, (0.0, 0.3, 0.0)))
    assert st_.q_bias == 0.0 and sp.body_rates_frd[1] == pytest.approx(0.05)
    phi = math.radians(10.0)
    om, q_turn = _turn(phi, 16.0)
    R = euler_to_matrix(phi, 0.0, 0.0)
    for _ in range(500):
        sp, st_ = adapt(om, 16.0, R, NORTH, 0.02, P, st_, meas=(R, (0.0, 0.3, 0.0)))
    assert q_turn == pytest.approx(0.01877, abs=1e-5)
    assert st_.q_bias == pytest.approx(q_turn, rel=1e-9)
    assert sp.body_rates_frd[1] == pytest.approx(0.0, abs=1e-12)  # q_turn - q_bias


def test_pitch_rate_bias_learns_nothing_from_a_clipped_set_point():
    # at the pitch limit the law's demand is cut (test_body_rates_keep_the_pitch_limits...):
    # the rate flown then answers the limit, not a bias of the autopilot
    theta = 0.4
    R = euler_to_matrix(0.0, theta, 0.0)
    sp, st_ = adapt((0.0, 0.5, 0.0), 15.0, R, NORTH, 0.02, P, AdapterState(trim_hat=0.0))
    assert st_.q_sent is None
    _, st2 = adapt((0.0, 0.5, 0.0), 15.0, R, NORTH, 0.02, P, st_, meas=(R, (0.0, 0.3, 0.0)))
    assert st2.q_bias == 0.0
    # and a hand-back starts it afresh (the autopilot's own integrators moved meanwhile)
    assert AdapterState(q_bias=0.05, q_sent=0.1).for_reengage().q_bias == 0.0


# ---------------------------------------------------------------- energy control (issue 25)
# Flight along north pitched up by gamma: w1 = (cos g, 0, -sin g); omega = 0 asks for no change.
E = AdapterParams(
    airspeed_sp_m_s=16.0, airspeed_min_m_s=14.0, airspeed_max_m_s=18.0, trim_thrust=0.3,
    thrust_per_gamma=3.0, load_factor_ff=0.0, max_pitch_rad=0.6,  # pitch limit beyond the climbs
)  # fmt: skip


def _climb(gamma):
    return (math.cos(gamma), 0.0, -math.sin(gamma)), euler_to_matrix(0.0, gamma + 0.05, 0.0)


def test_energy_feedforward_flies_a_steady_climb_at_trim_plus_k_gamma():
    # at the set airspeed, no acceleration and the flight path the law asks for: every error
    # term is 0, so thrust = T_trim + k_T gamma (the steady-climb energy balance), to rounding
    g_ = 0.1
    w1, R = _climb(g_)
    s = AdapterState(trim_hat=0.05)
    for _ in range(5):
        sp, s = adapt((0.0, 0.0, 0.0), 16.0, R, w1, 0.02, E, s)
    assert sp.thrust == pytest.approx(E.trim_thrust + E.thrust_per_gamma * g_, abs=1e-9)
    assert s.energy.integ == pytest.approx(0.0, abs=1e-12)
    assert s.energy.balance == 0.0


def test_energy_saturation_anti_windup_and_airspeed_priority():
    # a climb of 0.4 rad needs 0.3 + 3 * 0.4 = 1.5 > thrust_max: thrust pins at 1 and the
    # integrator does not wind up while the error pushes into the limit
    w1, R = _climb(0.4)
    dt, n = 0.02, 500  # 10 s = 10 balance_tau_s
    s = AdapterState(trim_hat=0.05)
    for _ in range(n):
        sp, s = adapt((0.0, 0.0, 0.0), 13.0, R, w1, dt, E, s)  # 13 m/s: below v_min + 1
    assert sp.thrust == E.thrust_max
    assert s.energy.integ <= 1e-12  # never grew (its only move was toward the limit's room)
    # airspeed priority, airspeed at or below v_min + 1 (weight 1): the flight path moves to
    # what full thrust sustains, gamma_c - u, u = (T_raw - 1) / (k_T + k_E) > 0: the offset is
    # negative, and after 10 time constants it has reached its target to exp(-10) ~ 5e-5
    assert s.energy.balance < -0.1
    # the pitch set-point carries it: the same state under "height" keeps the path's demand
    h = dataclasses.replace(E, priority="height")
    sh = AdapterState(trim_hat=0.05)
    for _ in range(n):
        sph, sh = adapt((0.0, 0.0, 0.0), 13.0, R, w1, dt, h, sh)
    assert sh.energy.balance == 0.0
    assert sp.pitch_rad < sph.pitch_rad - 0.1


def test_energy_priority_leaves_the_path_alone_while_the_airspeed_has_room():
    # same saturation at the set airspeed (2 m/s above v_min + 1): weight 0, no offset
    w1, R = _climb(0.4)
    s = AdapterState(trim_hat=0.05)
    for _ in range(100):
        sp, s = adapt((0.0, 0.0, 0.0), 16.0, R, w1, 0.02, E, s)
    assert sp.thrust == E.thrust_max
    assert s.energy.balance == 0.0


def test_energy_updraft_surplus_goes_into_height_near_vmax():
    # descending 0.2 rad at 17.5 m/s (within 1 m/s of v_max): T_raw = 0.3 - 0.6 - ... < 0, thrust
    # at idle, and the surplus raises the flight path (offset > 0)
    w1, R = _climb(-0.2)
    s = AdapterState(trim_hat=0.05)
    for _ in range(200):
        sp, s = adapt((0.0, 0.0, 0.0), 17.5, R, w1, 0.02, E, s)
    assert sp.thrust == E.thrust_min
    assert s.energy.balance > 0.05


def test_energy_reengagement_starts_from_the_autopilots_thrust():
    # the autopilot flies 0.8 where the configured trim is 0.3: the first set-point after
    # (re-)engagement is 0.8 exactly (no step), the integrator holds the difference
    w1, R = _climb(0.0)
    s = AdapterState(trim_hat=0.05, energy=EnergyState(integ=0.4, balance=0.2)).for_reengage(
        thrust_engaged=0.8
    )
    assert s.energy.balance == 0.0 and s.energy.v_prev is None
    sp, s = adapt((0.0, 0.0, 0.0), 16.0, R, w1, 0.02, E, s)
    assert sp.thrust == pytest.approx(0.8, abs=1e-12)
    assert s.energy.integ == pytest.approx(0.5, abs=1e-9)
    assert s.energy.thrust_engaged is None  # used once
    # unknown thrust (no VFR_HUD): the configured trim, integrator at 0
    s2 = AdapterState(energy=EnergyState(integ=0.4)).for_reengage(None)
    sp2, _ = adapt((0.0, 0.0, 0.0), 16.0, R, w1, 0.02, E, AdapterState(trim_hat=0.05))
    assert s2.energy.integ == 0.0 and sp2.thrust == pytest.approx(E.trim_thrust, abs=1e-9)


# ------------------------------------------------------------------ energy reserve (issue 25)
def test_reserve_airspeed_carries_the_design_gusts_height_as_kinetic_energy():
    g = GRAVITY_M_S2
    # a 1.5 m/s climb leaves 4.1 - 1.5 = 2.6 m/s of the full-thrust climb: a 3.0 m/s downdraft
    # for 10 s is (3.0 - 2.6) 10 = 4 m beyond it, which (V^2 - 16^2) / (2 g) = 4 m pays
    v = reserve_airspeed(16.0, 25.0, 1.5, 4.1, 3.0, 10.0, g)
    assert (v * v - 16.0**2) / (2.0 * g) == pytest.approx(4.0, abs=1e-9)
    assert reserve_airspeed(16.0, 18.0, 1.5, 4.1, 3.0, 10.0, g) == 18.0  # within v_max
    # a spare that covers the gust, a descent, or figures that are not finite: the set-point
    assert reserve_airspeed(16.0, 18.0, 0.5, 4.1, 3.0, 10.0, g) == 16.0
    assert reserve_airspeed(16.0, 18.0, -3.0, 4.1, 3.0, 10.0, g) == 16.0
    assert reserve_airspeed(16.0, 18.0, 1.5, math.inf, 3.0, 10.0, g) == 16.0
    assert reserve_airspeed(16.0, 18.0, math.nan, 4.1, 3.0, 10.0, g) == 16.0


R_ = dataclasses.replace(E, max_climb_m_s=4.1, reserve_gust_m_s=3.0, reserve_gust_s=10.0)


def _fly_path(params, climb, seconds, dt=0.02, v=16.0):
    """Level flight at v under a path point that climbs ``climb`` m/s: (set-points, states)."""
    w1, R = _climb(0.0)
    s = AdapterState(trim_hat=0.05)
    sps, sts = [], []
    for k in range(int(round(seconds / dt))):
        sp, s = adapt((0.0, 0.0, 0.0), v, R, w1, dt, params, s, path_down_m=-100.0 - climb * k * dt)
        sps.append(sp)
        sts.append(s)
    return sps, sts


def test_reserve_raises_the_set_point_for_a_sustained_climb_at_its_rate_limit():
    dt, n = 0.02, 1500  # 30 s
    _, sts = _fly_path(R_, 1.5, n * dt, dt)
    # the first difference starts the filter: a steady climb is known from the second step
    assert sts[-1].energy.climb_f == pytest.approx(1.5, rel=1e-9)
    vres = np.array([s.energy.v_res for s in sts])
    # never faster than reserve_rate_m_s2 (0.1 m/s^2): 2 m/s take 20 s ...
    assert np.max(np.abs(np.diff(vres))) <= 0.1 * dt + 1e-12
    assert vres[int(10.0 / dt)] == pytest.approx(16.0 + 0.1 * 10.0, abs=0.1 * dt + 1e-9)
    # ... up to what reserve_airspeed gives: (3.0 - 2.6) 10 = 4 m needs 18.3 m/s, v_max 18
    assert reserve_airspeed(16.0, 18.0, 1.5, 4.1, 3.0, 10.0) == 18.0
    assert vres[-1] == pytest.approx(18.0, abs=1e-9)
    # a path whose climb changes moves the filter by dt / reserve_tau_s of the step each step
    w1, R = _climb(0.0)
    s = sts[-1]
    _, s2 = adapt((0.0, 0.0, 0.0), 16.0, R, w1, dt, R_, s, path_down_m=s.energy.path_down_prev)
    assert s2.energy.climb_f == pytest.approx(1.5 + dt / 20.0 * (0.0 - 1.5), rel=1e-9)


def test_reserve_speed_error_asks_more_thrust_and_nothing_changes_when_off():
    sps, sts = _fly_path(R_, 1.5, 30.0)
    sps0, sts0 = _fly_path(E, 1.5, 30.0)  # no design gust: off, as before
    assert sts0[-1].energy.v_res is None and sts0[-1].energy.climb_f is None
    # flying 16 m/s under a set-point that has risen: the speed error asks for more energy
    assert sts[-1].energy.v_res > 16.5
    assert sps[-1].thrust > sps0[-1].thrust + 0.01
    # a level path keeps the configured set-point
    _, stl = _fly_path(R_, 0.0, 30.0)
    assert stl[-1].energy.v_res == 16.0
    # a hand-back keeps what the path's climb was (the mission's), the step differences afresh
    s = sts[-1].for_reengage(0.5)
    assert s.energy.climb_f == sts[-1].energy.climb_f and s.energy.path_down_prev is None


def test_the_energy_control_is_the_adapters_parameters_of_its_names():
    # AdapterParams is the configuration's surface; Tecs (core/energy.py) takes its fields by
    # name, built once per parameter set.
    params = AdapterParams(energy_kp=0.7, priority="height", reserve_gust_m_s=2.0)
    tecs = params.tecs
    for f in dataclasses.fields(tecs):
        assert getattr(tecs, f.name) == getattr(params, f.name), f.name
    assert params.tecs is tecs


# ----------------------------------------------------------------------------- trim schedule
def _fly_schedule(
    params: AdapterParams,
    v_sp_of_t: Callable[[float], float],
    y_of_vsp: Callable[[float], float],
    t_end: float = 300.0,
) -> tuple[list[float], AdapterState]:
    """A level aircraft whose measured theta - gamma is y_of_vsp(v_sp) (rad) while the airspeed
    set-point is v_sp_of_t(t) (m/s); no law demand, so trim_hat stays where it starts. Returns
    the pitch set-points (rad) and the last state."""
    st_, dt, out = AdapterState(trim_hat=0.0), 0.1, []
    for i in range(int(t_end / dt)):
        vs = v_sp_of_t(i * dt)
        R = euler_to_matrix(0.0, y_of_vsp(vs), 0.0)
        sp, st_ = adapt(
            (0.0, 0.0, 0.0), 22.0, R, NORTH, dt, params, st_, meas=(R, (0.0, 0.0, 0.0)),
            airspeed_sp=vs,
        )  # fmt: skip
        out.append(sp.pitch_rad)
    return out, st_


AP22 = AdapterParams(airspeed_sp_m_s=22.0)


def test_trim_schedule_learns_the_lift_slope_of_a_lap_periodic_set_point():
    """theta - gamma = -0.03 + 0.05 (22 / v_sp)^2 (the lift's 0.05 rad at 22 m/s), the set-point
    swinging 22 +- 2 m/s over a 43 s lap: the regression finds K_hat = 0.05 and the pitch
    set-point carries trim_hat + K_hat (x - mean x), so it follows theta - gamma's swing."""

    def vsp(t: float) -> float:
        return 22.0 + 2.0 * math.sin(2.0 * math.pi * t / 43.0)

    def y(v: float) -> float:
        return -0.03 + 0.05 * (22.0 / v) ** 2

    pitch, st_ = _fly_schedule(AP22, vsp, y)
    # the set-point enters one tau_pitch ahead through a rate low-passed over 2 s: at the lap's
    # frequency that swings x ~5 % wider (and 0.9 s ahead), so K_hat comes out ~5 % lower
    assert st_.sched.k == pytest.approx(0.05 / 1.048, rel=0.02)
    # over the last lap the pitch set-point's swing is theta - gamma's (the mean is trim_hat's)
    n = int(43.0 / 0.1)
    ys = [y(vsp(i * 0.1)) for i in range(3000 - n, 3000)]
    sw = np.ptp(pitch[-n:])
    assert sw == pytest.approx(np.ptp(ys), rel=0.05)
    # scheduled: faster -> less trim
    assert st_.sched.offset((22.0 / 24.0) ** 2) < 0.0 < st_.sched.offset((22.0 / 20.0) ** 2)


def test_trim_schedule_is_nothing_at_a_constant_set_point():
    """A single aircraft at its set airspeed: nothing to regress on, the set-points are those
    without the schedule."""

    def y(v: float) -> float:
        return 0.02

    on, st_on = _fly_schedule(AP22, lambda t: 22.0, y, 30.0)
    off, _ = _fly_schedule(dataclasses.replace(AP22, trim_schedule=False), lambda t: 22.0, y, 30.0)
    assert st_on.sched.k == 0.0 and on == off


def test_trim_schedule_slope_is_never_negative_and_survives_reengagement():
    """A measured offset that rises with speed is no lift curve (K_hat clipped at 0); what was
    learnt is the airframe's and stays over a hand-back."""

    def vsp(t: float) -> float:
        return 22.0 + 2.0 * math.sin(2.0 * math.pi * t / 43.0)

    _, st_ = _fly_schedule(AP22, vsp, lambda v: 0.01 * (v - 22.0), 120.0)
    assert st_.sched.k == 0.0
    _, st2 = _fly_schedule(AP22, vsp, lambda v: 0.05 * (22.0 / v) ** 2, 120.0)
    assert st2.sched.k > 0.0 and st2.for_reengage(0.5).sched == st2.sched
