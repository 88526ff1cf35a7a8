"""The multi-rate loop (mavlink.position_instants): a LOCAL_POSITION_NED between two ATTITUDE
samples is a control instant; the state there is the position sample's, the attitude carried
to its time by the ATTITUDE's body rates (bridge/estimator.py, bridge/controller.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mpf_mavlink.bridge.controller import Controller, ControlSetup
from mpf_mavlink.bridge.estimator import Estimator
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.core.frames import euler_to_matrix
from mpf_mavlink.mavlink.codec import AttitudeSample, LocalPositionSample, VfrHudSample

DEMO = Path(__file__).resolve().parents[1] / "configs" / "default.yaml"


def _expm_series(A: np.ndarray, terms: int = 40) -> np.ndarray:
    """exp(A) by its power series (independent of the code's Rodrigues formula)."""
    out, term = np.eye(3), np.eye(3)
    for k in range(1, terms):
        term = term @ A / k
        out = out + term
    return out


def _hat(w) -> np.ndarray:
    x, y, z = w
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def test_attitude_at_a_position_instant_is_the_exact_rotation_at_constant_rates():
    """R_dot = R hat(w_body): at constant body rates R(t) = R(t_att) exp(hat(w (t - t_att))).
    Checked against the power series of the matrix exponential (float64: 1e-14), against a
    pure roll (R0 Rx(p dt), closed form) and on the position: that of the newer sample itself,
    not the older one extrapolated."""
    R0 = euler_to_matrix(0.3, -0.1, 2.0)
    w = np.array([0.6, -0.25, 0.4])
    est = Estimator()
    est.update(AttitudeSample(5.00, R0, w), 1.0)
    est.update(LocalPositionSample(5.00, np.zeros(3), np.array([16.0, 0.0, 0.0])), 1.0)
    est.update(VfrHudSample(16.0, 16.0, 0.5, 0.0, 100.0, 0.0), 1.0)
    p_new = np.array([1.3, 0.02, -0.01])
    v_new = np.array([15.5, 2.0, -0.3])
    est.update(LocalPositionSample(5.08, p_new, v_new), 1.001)
    e_att, _ = est.estimate()
    e_pos, _ = est.estimate(at_position=True)
    assert e_att is not None and e_pos is not None
    # at the attitude's instant: the position extrapolated back from the newer sample
    assert e_att.t_boot_s == 5.00
    np.testing.assert_allclose(e_att.vehicle.position, p_new - 0.08 * v_new, atol=1e-12)
    np.testing.assert_array_equal(e_att.R_B_N, R0)
    # at the position's instant: that sample, and the attitude rotated by w over 80 ms
    assert e_pos.t_boot_s == 5.08
    np.testing.assert_array_equal(e_pos.vehicle.position, p_new)
    np.testing.assert_array_equal(e_pos.ground_velocity, v_new)
    want = R0 @ _expm_series(_hat(w * 0.08))
    np.testing.assert_allclose(e_pos.R_B_N, want, atol=1e-14)
    np.testing.assert_array_equal(e_pos.rates_frd, w)
    # a pure roll rate: R0 Rx(p dt)
    est.update(AttitudeSample(5.10, R0, np.array([0.9, 0.0, 0.0])), 1.002)
    est.update(LocalPositionSample(5.14, p_new, v_new), 1.003)
    e, _ = est.estimate(at_position=True)
    assert e is not None
    np.testing.assert_allclose(e.R_B_N, R0 @ euler_to_matrix(0.9 * 0.04, 0.0, 0.0), atol=1e-14)
    # a position older than the attitude: the attitude's instant, as without at_position
    est.update(AttitudeSample(5.20, R0, w), 1.004)
    e2, _ = est.estimate(at_position=True)
    e3, _ = est.estimate()
    assert e2 is not None and e3 is not None and e2.t_boot_s == e3.t_boot_s == 5.20
    np.testing.assert_array_equal(e2.vehicle.position, e3.vehicle.position)


def _feed(
    ctl: Controller, att_hz: float, pos_hz: float, seconds: float, pos_lag_ms: int = 0
) -> list[tuple[str, int]]:
    """Feed ATTITUDE and LOCAL_POSITION_NED on one 1 ms clock (the SIL's frames: the position
    first when both fall on one instant; ``pos_lag_ms``: the position stream that much later,
    as independent stream schedules give); the control instants as (type, ms)."""
    out: list[tuple[str, int]] = []
    na, np_ = round(1000 / att_hz), round(1000 / pos_hz)  # in 1 ms ticks
    R = euler_to_matrix(0.2, 0.05, 1.0)
    for k in range(round(seconds * 1000)):
        tb = 1.0 + 0.001 * k
        rx = 10.0 + 0.001 * k
        if k >= pos_lag_ms and (k - pos_lag_ms) % np_ == 0:
            pos = np.array([16.0 * 0.001 * k, 0.0, -100.0])
            s = LocalPositionSample(tb, pos, np.array([16.0, 0.0, 0.0]))
            if ctl.feed_vehicle(s, rx):
                out.append(("pos", k))
        if k % na == 0:
            if ctl.feed_vehicle(AttitudeSample(tb, R, np.array([0.1, 0.0, 0.05])), rx):
                out.append(("att", k))
    return out


def test_position_instants_fall_between_attitude_samples_only():
    """ATTITUDE 10 Hz, position 50 Hz: the positions at 20, 40, 60, 80 ms after each ATTITUDE
    are control instants (80 ms < T - T_pos/2 = 90 ms); the one at 100 ms is not, it comes
    with the next ATTITUDE (which the SIL sends after it). 25 Hz: one between each pair.
    50 Hz each: none, so the loop is the ATTITUDE-only one, whatever the phase between the
    streams (a position 5 or 15 ms after the ATTITUDE is within half a position period of it
    or of the next one). Not before the ATTITUDE period is known (two samples), and not at
    all with position_instants off."""
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    inst = _feed(ctl, 10.0, 50.0, 1.0)
    pos_ms = [ms for kind, ms in inst if kind == "pos"]
    att_ms = [ms for kind, ms in inst if kind == "att"]
    assert att_ms == list(range(0, 1000, 100))
    # the first period has no instants (period unknown until the second ATTITUDE)
    assert pos_ms == [a + d for a in range(100, 1000, 100) for d in (20, 40, 60, 80)]
    assert ctl.instants.att_period_s == pytest.approx(
        0.1
    ) and ctl.instants.pos_period_s == pytest.approx(0.02)
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    inst = _feed(ctl, 25.0, 50.0, 1.0)
    assert [ms for kind, ms in inst if kind == "pos"] == list(range(60, 1000, 40))
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    inst = _feed(ctl, 50.0, 50.0, 1.0)
    assert [kind for kind, _ in inst] == ["att"] * 50
    for lag in (3, 5, 15, 17):
        ctl = Controller(ControlSetup.of(load_config(DEMO)))
        inst = _feed(ctl, 50.0, 50.0, 1.0, pos_lag_ms=lag)
        assert [kind for kind, _ in inst] == ["att"] * 50, lag
    # 10 Hz ATTITUDE, 30 Hz position 7 ms behind (PX4's onboard default rate): positions
    # 7 + 33.3 k ms after each ATTITUDE step when 10 <= delta < 100 - 16.7 (half a period each)
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    inst = _feed(ctl, 10.0, 30.0, 1.0, pos_lag_ms=7)
    deltas = sorted({ms % 100 for kind, ms in inst if kind == "pos"})
    assert deltas and all(16.6 <= d < 100 - 16.6 for d in deltas)
    ctl = Controller(ControlSetup.of(load_config(DEMO, ["mavlink.position_instants=false"])))
    inst = _feed(ctl, 10.0, 50.0, 1.0)
    assert [kind for kind, _ in inst] == ["att"] * 10


def test_a_step_at_a_position_instant_uses_the_newer_position_and_its_time():
    """The step's time, the setpoint's time_boot_ms (what the SIL's lockstep keys on) and the
    law's position are the position sample's; the next ATTITUDE steps again 20 ms later."""
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    R = euler_to_matrix(0.0, 0.0, 0.0)
    rates = np.array([0.0, 0.0, 0.1])
    for k in range(6):  # ATTITUDE at 1.0 and 1.1 s, positions every 20 ms
        tb = 1.0 + 0.02 * k
        ctl.feed_vehicle(VfrHudSample(16.0, 16.0, 0.5, 0.0, 100.0, 0.0), 10.0 + tb)
        ctl.feed_vehicle(LocalPositionSample(tb, np.array([0.32 * k, 0.0, -100.0]),
                                             np.array([16.0, 0.0, 0.0])), 10.0 + tb)  # fmt: skip
        if k in (0, 5):
            assert ctl.feed_vehicle(AttitudeSample(tb, R, rates), 10.0 + tb)
    ctl.set_origin()
    ctl.init_s()
    assert ctl.step() is not None
    p = np.array([2.0, 0.3, -100.2])
    assert ctl.feed_vehicle(LocalPositionSample(1.12, p, np.array([16.0, 0.5, 0.0])), 11.12)
    st = ctl.step()
    assert st is not None
    assert st.time_boot_ms == 1120 and st.t == pytest.approx(0.02, abs=1e-12)
    np.testing.assert_array_equal(st.estimate.vehicle.position, p)
    yaw = math.atan2(st.estimate.R_B_N[1, 0], st.estimate.R_B_N[0, 0])
    assert yaw == pytest.approx(0.1 * 0.02, abs=1e-15)  # carried by r = 0.1 rad/s over 20 ms
    # the same instant again is no new step; the next position is
    assert not ctl.feed_vehicle(LocalPositionSample(1.12, p, np.array([16.0, 0.5, 0.0])), 11.13)
    assert ctl.feed_vehicle(LocalPositionSample(1.14, p, np.array([16.0, 0.5, 0.0])), 11.14)
    st2 = ctl.step()
    assert st2 is not None and st2.dt == pytest.approx(0.02, abs=1e-12)
