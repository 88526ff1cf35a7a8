"""Delay compensation: the prediction (guidance/predict.py) and the delay the controller measures
from the autopilot's ATTITUDE_TARGET echo (controller.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mpf_mavlink.bridge.controller import Controller, ControlSetup, mission_time_at
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.core.guidance.law import VehicleState
from mpf_mavlink.core.guidance.predict import (
    MAX_PREDICTION_S,
    predict,
    predict_segments,
    prediction_horizon,
)
from mpf_mavlink.mavlink.codec import AttitudeTargetSample

DEMO = Path(__file__).resolve().parents[1] / "configs" / "default.yaml"


def _level(yaw: float, V: float = 16.0, wind=(0.0, 0.0, 0.0)) -> VehicleState:
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return VehicleState(3.0, np.array([10.0, -5.0, -100.0]), R, V, np.array(wind, float))


def test_horizon_is_the_delay_and_bounded():
    """The state is predicted to when the setpoint starts acting, t + d (guidance/predict.py)."""
    assert prediction_horizon(0.06) == pytest.approx(0.06)
    assert prediction_horizon(0.02) == pytest.approx(0.02)
    assert prediction_horizon(float("nan")) == 0.0
    assert prediction_horizon(-0.1) == 0.0
    assert prediction_horizon(1.0) == MAX_PREDICTION_S


def _roll_loop(predict_to: str, hold: float, T: float = 0.1, d: float = 0.02) -> list[float]:
    """Bank errors of the adapter's roll loop, step by step, against a roll that follows the
    rate set-points exactly (phi += d p_prev + (T - d) p: the previous set-point acts until d
    into the period). A level right turn at 0.1 rad/s and 15 m/s wants atan(1.5 / g) of bank;
    the attitude the adapter sees is predicted by the set-point in flight to t + d ("start") or
    t + d + T/2 ("middle")."""
    from mpf_mavlink.constants import GRAVITY_M_S2
    from mpf_mavlink.core.adapter import AdapterParams, adapt
    from mpf_mavlink.core.frames import euler_to_matrix

    P = AdapterParams(tau_roll_s=0.15, adaptive=False)
    bank = math.atan(1.5 / GRAVITY_M_S2)
    c = d if predict_to == "start" else d + 0.5 * T
    phi, p_prev, errs = 0.0, 0.0, []
    for _ in range(8):
        R = euler_to_matrix(phi + c * p_prev, 0.0, 0.0)
        sp, _ = adapt((0.0, 0.0, 0.1), 15.0, R, (1.0, 0.0, 0.0), T, P, hold_s=hold)
        p = sp.body_rates_frd[0]
        assert abs(p) < P.max_roll_rate_rad_s  # the linear loop, not the clip
        phi += d * p_prev + (T - d) * p
        p_prev = p
        errs.append(bank - phi)
    return errs


def test_roll_loop_at_10_hz_decays_like_its_time_constant_without_ringing():
    """Predicted to the start of the hold with the zero-order-hold gain, the roll loop's poles
    are 0 and exp(-T / tau_roll) (core/adapter.py roll_rate_gain): from the second step the
    error shrinks by exactly exp(-0.1 / 0.15) = 0.513 per step, never changing sign. The
    middle-of-the-hold prediction with the continuous gain 1/tau (the code before) has the
    poles +-sqrt(T / (2 tau)) = +-0.577: its step ratios alternate (0.71, 0.47, ...: the
    negative pole, which the rate loop's lag pushed out of the unit circle in SIL, a +-70 deg/s
    roll-rate chatter at 5 Hz), two steps always giving the square of the pole, 1/3."""
    e = _roll_loop("start", 0.1)
    for a, b in zip(e[1:], e[2:], strict=False):
        assert b / a == pytest.approx(math.exp(-0.1 / 0.15), rel=1e-9)
    assert all(x > 0.0 for x in e)
    old = _roll_loop("middle", 0.0)
    ratios = [b / a for a, b in zip(old[1:], old[2:], strict=False)]
    assert all(abs(x - y) > 0.2 for x, y in zip(ratios, ratios[1:], strict=False))
    assert [x * y for x, y in zip(ratios, ratios[1:], strict=False)] == pytest.approx(
        [0.1 / 0.3] * 5, rel=1e-6
    )


def test_level_turn_is_predicted_on_its_arc():
    """A level turn at yaw rate r: the exact position after tau is on the circle of radius V/r;
    the midpoint rule's error is V tau (r tau)^2 / 24 (< 1 mm here); heading advances r tau."""
    V, r, tau = 16.0, 0.5, 0.1
    vs = _level(0.3, V, wind=(0.0, 4.0, 0.0))
    vp, R = predict(vs, vs.R_W_I, (0.0, 0.0, r), tau)
    chord = 2.0 * V / r * math.sin(0.5 * r * tau)
    h = 0.3 + 0.5 * r * tau
    want = vs.position + np.array([chord * math.cos(h), chord * math.sin(h), 0.0])
    want[1] += 4.0 * tau  # the wind carries it
    assert np.linalg.norm(vp.position - want) < V * tau * (r * tau) ** 2 / 24 + 1e-9
    assert math.atan2(vp.R_W_I[1, 0], vp.R_W_I[0, 0]) == pytest.approx(0.3 + r * tau, abs=1e-12)
    assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(0.3 + r * tau, abs=1e-12)
    assert vp.t == pytest.approx(vs.t + tau)


def test_segments_compose_like_one_turn():
    """Two segments at the same rates give the single segment's prediction."""
    vs = _level(-1.0)
    a = predict(vs, vs.R_W_I, (0.2, 0.1, 0.4), 0.08)
    b = predict_segments(vs, vs.R_W_I, [(0.03, (0.2, 0.1, 0.4)), (0.05, (0.2, 0.1, 0.4))])
    np.testing.assert_allclose(a[1], b[1], atol=1e-12)
    np.testing.assert_allclose(a[0].R_W_I, b[0].R_W_I, atol=1e-12)
    # positions differ only by the midpoint rule's second-order term
    assert np.linalg.norm(a[0].position - b[0].position) < 1e-3


def test_loop_delay_is_measured_from_the_attitude_target_echo():
    """The echo carries our body rates as float32 and the autopilot's receive time: the delay is
    that time minus the ATTITUDE time the setpoint answered (median of the last 9)."""
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    assert ctl.delay.delay_s == 0.0  # mavlink.known_delay_s until measured
    ctl.est.t0 = 100.0
    for k in range(12):
        ctl.delay.sent.append((1.0 + 0.02 * k, (0.1 + 0.01 * k, -0.2, 0.3)))
    for k in range(12):
        rates = tuple(float(np.float32(v)) for v in (0.1 + 0.01 * k, -0.2, 0.3))
        late = 0.065 if k != 5 else 0.4  # one late echo does not move the median
        ctl.feed_vehicle(AttitudeTargetSample(101.0 + 0.02 * k + late, rates, 0.3, 128), None)
    assert ctl.delay.delay_s == pytest.approx(0.065, abs=1e-9)
    # an echo of rates never sent is no measurement
    ctl.feed_vehicle(AttitudeTargetSample(102.0, (9.0, 9.0, 9.0), 0.3, 128), None)
    assert ctl.delay.delay_s == pytest.approx(0.065, abs=1e-9)


def test_look_ahead_grows_only_where_the_hold_costs_phase():
    """alpha is kept where the guidance crossover wc = v/alpha + K_R/2 loses at most
    HOLD_PHASE_RAD to T/2 + delay/4, and widened until it does (never narrowed)."""
    from mpf_mavlink.core.guidance.predict import HOLD_PHASE_RAD, look_ahead

    v, K_R = 16.0, 3.0
    assert look_ahead(5.0, K_R, v, 0.02, 0.02) == 5.0  # the demo: 50 Hz, 20 ms
    assert look_ahead(5.0, K_R, v, 0.02, 0.04) == 5.0  # 25 Hz
    a = look_ahead(5.0, K_R, v, 0.02, 0.1)  # 10 Hz: widened
    lag = 0.05 + 0.005
    assert (v / a + K_R / 2) * lag == pytest.approx(HOLD_PHASE_RAD)
    assert look_ahead(20.0, K_R, v, 0.02, 0.1) == 20.0  # a wider configured alpha stands
    assert look_ahead(5.0, K_R, v, float("nan"), 0.0) == 5.0


def test_target_samples_are_stamped_from_the_newest_vehicle_time():
    """A live target's sample is stamped with the vehicle's time at receipt: the newest
    time-stamped sample's autopilot time plus the receive time since. With ATTITUDE at 10 Hz
    and LOCAL_POSITION_NED at 50 Hz the position is newer by up to 80 ms (under a lockstep clock
    the receive times barely move, so the older ATTITUDE stamped targets 80 ms early)."""
    from mpf_mavlink.mavlink.codec import AttitudeSample, LocalPositionSample

    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    ctl.feed_vehicle(AttitudeSample(1.0, np.eye(3), np.zeros(3)), 10.0)
    assert mission_time_at(ctl.est, 10.002) == pytest.approx(1.002)
    ctl.feed_vehicle(LocalPositionSample(1.08, np.zeros(3), np.array([16.0, 0.0, 0.0])), 10.001)
    assert mission_time_at(ctl.est, 10.002) == pytest.approx(1.081)
    # an older position sample (received later) does not pull the stamp back
    ctl.feed_vehicle(AttitudeSample(1.1, np.eye(3), np.zeros(3)), 10.003)
    ctl.feed_vehicle(LocalPositionSample(1.06, np.zeros(3), np.zeros(3)), 10.004)
    assert mission_time_at(ctl.est, 10.005) == pytest.approx(1.102)


def test_scalar_prediction_matches_matrix_exponentials():
    """predict_rows (scalars, the controller's path) against an independent evaluation with
    scipy's matrix exponential: R_k+1 = expm(hat(R_k w dt)) R_k, w1 turned by expm of half of it
    for the position. Both are exact formulas rounded differently (Rodrigues on the vector and
    FMA-free 3x3 products against expm's Pade approximant and BLAS), so they agree to rounding:
    rotation entries (<= 1) within 1e-14 (~45 eps for 3 compounded segments; 2 eps seen) and
    positions (~1e2 m) within 1e-12 (the same relative error). A formula error (a sign, a
    transposed product, the full turn instead of the half for the position) shows as >= 1e-5."""
    from scipy.linalg import expm

    from mpf_mavlink.core.frames import euler_to_matrix
    from mpf_mavlink.core.guidance.predict import predict_rows

    def hat(v: np.ndarray) -> np.ndarray:
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])

    rng = np.random.default_rng(3)
    for _ in range(50):
        yaw, pitch, roll = (
            rng.uniform(-math.pi, math.pi),
            rng.uniform(-0.5, 0.5),
            rng.uniform(-1, 1),
        )
        R_B = np.asarray(euler_to_matrix(roll, pitch, yaw), float)
        R_W = R_B @ np.asarray(euler_to_matrix(0.0, 0.05, 0.02), float)  # alpha, beta
        vs = VehicleState(2.0, rng.uniform(-100, 100, 3), R_W, 16.0, rng.uniform(-5, 5, 3))
        segs = [(float(rng.uniform(0.0, 0.04)), tuple(rng.uniform(-1.0, 1.0, 3))) for _ in range(3)]
        vp, R_rows, w1 = predict_rows(vs, R_B, segs)
        R, Rw, p = R_B.copy(), R_W.copy(), vs.position.copy()
        for dur, rates in segs:
            k = R @ np.array(rates) * dur
            p = p + dur * (16.0 * (expm(hat(0.5 * k)) @ Rw[:, 0]) + vs.wind)
            R, Rw = expm(hat(k)) @ R, expm(hat(k)) @ Rw
        np.testing.assert_allclose(np.array(R_rows), R, rtol=0, atol=1e-14)
        np.testing.assert_allclose(vp.R_W_I, Rw, rtol=0, atol=1e-14)
        np.testing.assert_allclose(w1, Rw[:, 0], rtol=0, atol=1e-14)
        np.testing.assert_allclose(vp.position, p, rtol=0, atol=1e-12)
        assert vp.t == pytest.approx(2.0 + sum(d for d, _ in segs), abs=1e-15)
