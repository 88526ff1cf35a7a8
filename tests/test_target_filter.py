"""The target estimator (mpf_mavlink.core.target_filter) on physical situations.

Reports are the scripted targets' true states plus seeded white noise, stamped with a sender
clock 100 s ahead of ours and received ``LATENCY`` s late. Tolerances come from the noise and
the geometry (each test says how), not from one run's output.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mpf_mavlink.core.target import ConstantTurn
from mpf_mavlink.core.target_filter import (
    Report,
    TargetEstimator,
    TargetFilterParams,
    chi2_quantile,
)

SIG_P = 2.0  # m, per axis
SIG_V = 0.3  # m/s, per axis
LATENCY = 0.3  # s
OFFSET = 100.0  # the sender's clock minus ours (s)
BOAT = ConstantTurn(speed=3.0, turn_rate=0.01)  # the demo's boat: a 300 m circle


def params(**kw: float) -> TargetFilterParams:
    base = dict(position_noise_m=SIG_P, vertical_noise_m=SIG_P, velocity_noise_m_s=SIG_V,
                latency_s=LATENCY)  # fmt: skip
    base.update(kw)
    return TargetFilterParams(**base)  # type: ignore[arg-type]


def reports(motion, t_end: float, rate: float = 1.0, seed: int = 1, drop: float = 0.0):
    """(receive time, report) at ``rate`` Hz from t = 0 to t_end, ``drop`` of them lost."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(int(t_end * rate) + 1):
        t = k / rate
        ts = motion.state(t)
        dp, dv = rng.normal(0.0, SIG_P, 3), rng.normal(0.0, SIG_V, 3)
        if rng.random() < drop:
            continue
        out.append((t + LATENCY, Report(t + OFFSET, ts.position + dp, ts.velocity + dv)))
    return out


def feed(kf: TargetEstimator, reps) -> list[str]:
    return [kf.add(r, rx) for rx, r in reps]


def test_chi2_quantiles_match_tables():
    """Against the tables (99.99 %: 15.137 for 1 dof, 18.421 for 2, 21.108 for 3, 27.856 for 6)."""
    assert chi2_quantile(0.9999, 1) == pytest.approx(15.137, rel=1e-3)
    assert chi2_quantile(0.9999, 2) == pytest.approx(18.421, rel=1e-3)
    assert chi2_quantile(0.9999, 3) == pytest.approx(21.108, rel=0.01)
    assert chi2_quantile(0.9999, 6) == pytest.approx(27.856, rel=0.01)


def test_boat_in_a_constant_turn_turn_rate_converges():
    """A boat at 3 m/s in a constant 0.01 rad/s turn, 1 Hz fixes (2 m, 0.3 m/s noise), 10 %
    lost, no attitude: the turn rate is only seen through the velocity's rotation. The heading
    of one velocity fix has sigma_psi = SIG_V / V = 0.1 rad; the slope of N such headings over
    L seconds has sigma_w = sigma_psi sqrt(12 / N) / L (least squares). After 300 s (N ~ 270)
    that is 2.1e-5 rad/s; positions only add information. The error is within 4 of those sigma
    and within 4 of the filter's own sigma (it is not over-confident by more than that)."""
    kf = TargetEstimator(params(accel_noise_m_s2=0.005, turn_accel_noise_rad_s2=1e-5))
    reps = reports(BOAT, 300.0, drop=0.1)
    feed(kf, reps)
    t = 300.0 + LATENCY
    st = kf.state(t)
    assert not isinstance(st, str)
    n = len(reps)
    sigma_w = (SIG_V / BOAT.speed) * math.sqrt(12.0 / n) / 300.0
    err = abs(st.omega_T[2] - BOAT.turn_rate)
    pr = kf.predicted(t)
    assert pr is not None
    assert err < 4.0 * max(sigma_w, math.sqrt(pr[1][6, 6])), (err, sigma_w)
    # the feedforward's acceleration is the turn's, w x v: its error is bounded by the turn
    # rate's and the velocity's (triangle inequality on w v - w' v')
    truth = BOAT.state(t)
    dv = float(np.linalg.norm(st.velocity - truth.velocity))
    bound = BOAT.speed * err + BOAT.turn_rate * dv + err * dv
    assert np.linalg.norm(st.acceleration - truth.acceleration) <= bound + 1e-12


def test_boat_position_is_better_than_one_fix():
    """The same boat: one fix is 2 m per axis (3.5 m radial 1-sigma); the filter averages
    many along the model, so its radial error at the control time stays below one fix's
    1-sigma at every second of the last 100 s, and its mean below half of it."""
    kf = TargetEstimator(params(accel_noise_m_s2=0.005, turn_accel_noise_rad_s2=1e-5))
    reps = reports(BOAT, 300.0, drop=0.1, seed=2)
    errs = []
    k = 0
    for i in range(3000):
        tc = i * 0.1
        while k < len(reps) and reps[k][0] <= tc:
            kf.add(reps[k][1], reps[k][0])
            k += 1
        if tc >= 200.0:
            st = kf.state(tc)
            assert not isinstance(st, str)
            errs.append(float(np.linalg.norm(st.position - BOAT.state(tc).position)))
    one_fix = SIG_P * math.sqrt(3.0)
    assert max(errs) < one_fix
    assert float(np.mean(errs)) < 0.5 * one_fix


def test_out_of_order_report_gives_the_same_estimate_as_in_order():
    """Two reports swapped by the link: the late one is inserted in time order and the filter
    re-run from the posterior before it, i.e. the same arithmetic as in order: identical."""
    reps = reports(BOAT, 60.0, seed=3)
    a, b = TargetEstimator(params()), TargetEstimator(params())
    feed(a, reps)
    swapped = list(reps)
    swapped[30], swapped[31] = swapped[31], swapped[30]
    outcomes = feed(b, swapped)
    assert b.counts["out_of_order"] == 1 and outcomes.count("fused") == len(reps)
    sa, sb = a.state(61.0), b.state(61.0)
    assert not isinstance(sa, str) and not isinstance(sb, str)
    assert np.array_equal(sa.position, sb.position)
    assert np.array_equal(sa.velocity, sb.velocity)
    assert np.array_equal(sa.omega_T, sb.omega_T)


def test_outlier_50_sigma_away_is_rejected():
    """A fix 50 sigma (100 m) off the track after a minute of good ones: its squared
    Mahalanobis distance (~2500 / (1 + P/R)) is far beyond the 99.99 % chi-square gate of 6
    dof (27.9): gated, and the estimate is exactly what it was without it."""
    reps = reports(BOAT, 60.0, seed=4)
    a, b = TargetEstimator(params()), TargetEstimator(params())
    feed(a, reps)
    feed(b, reps)
    rx, good = reps[-1]
    bad = Report(good.t + 0.5, good.position + np.array([50.0 * SIG_P, 0.0, 0.0]), good.velocity)
    assert b.add(bad, rx + 0.5) == "gated"
    sa, sb = a.state(61.0), b.state(61.0)
    assert not isinstance(sa, str) and not isinstance(sb, str)
    assert np.array_equal(sa.position, sb.position)


def test_a_target_that_really_jumps_is_taken_after_reinit_after_reports():
    """A target that moves 200 m between fixes (a relay switching boats): the first
    ``reinit_after`` - 1 fixes are gated, the next re-initialises the filter on the new place."""
    reps = reports(BOAT, 60.0, seed=5)
    kf = TargetEstimator(params(reinit_after=3))
    feed(kf, reps)
    rx, last = reps[-1]
    jump = np.array([0.0, 200.0, 0.0])
    out = []
    for k in range(1, 4):
        ts = BOAT.state(60.0 + k)
        out.append(kf.add(Report(last.t + k, ts.position + jump, ts.velocity), rx + k))
    assert out == ["gated", "gated", "reinit"]
    st = kf.state(rx + 3)
    assert not isinstance(st, str)
    # re-initialised on one fix: within 4 sigma of it (radial, 3 axes)
    assert np.linalg.norm(st.position - (BOAT.state(63.0).position + jump)) < 4 * SIG_P * math.sqrt(
        3
    )


def test_latency_is_taken_from_the_reports_own_timestamps():
    """Noise-free reports 0.3 s late at 3 m/s: stamped at receipt they would be 0.9 m behind.
    With the sender's stamps and the known latency, the estimate at the control time is where
    the boat is (within the model's 1 cm prediction of a 0.3 s turn)."""
    kf = TargetEstimator(
        params(position_noise_m=0.01, vertical_noise_m=0.01, velocity_noise_m_s=0.01)
    )
    for k in range(30):
        ts = BOAT.state(float(k))
        kf.add(Report(k + OFFSET, ts.position, ts.velocity), k + LATENCY)
    st = kf.state(29.0 + LATENCY)
    assert not isinstance(st, str)
    truth = BOAT.state(29.0 + LATENCY).position
    assert np.linalg.norm(st.position - truth) < 0.05
    assert np.linalg.norm(BOAT.state(29.0).position - truth) > 0.85  # what receipt stamping gives


def test_outage_stops_when_the_uncertainty_exceeds_the_bound():
    """The feed stops. The prediction stays usable while sigma_0 + a tau^2 / 2 (the filter's
    radial 1-sigma plus what a target accelerating at a = manoeuvre_accel_m_s2 can do in tau
    unseen) is within the bound, and is refused after: tau_stop = sqrt(2 (bound - sigma_0) / a)."""
    # a quiet model (the demo's boat tuning): its own covariance grows by mm in 5 s
    p = params(max_position_sigma_m=4.0, manoeuvre_accel_m_s2=0.3, accel_noise_m_s2=0.001,
               turn_accel_noise_rad_s2=1e-6, vertical_accel_noise_m_s2=0.001)  # fmt: skip
    kf = TargetEstimator(p)
    reps = reports(BOAT, 120.0, seed=6)
    feed(kf, reps)
    rx_last, last = reps[-1]
    t_last = last.t - OFFSET  # our time of the last fix
    pr = kf.predicted(t_last)
    assert pr is not None
    sigma0 = math.sqrt(float(np.trace(pr[1][:3, :3])))
    tau = math.sqrt(2.0 * (p.max_position_sigma_m - sigma0) / p.manoeuvre_accel_m_s2)
    assert 2.5 < tau < 5.0  # the bound tolerates 1 Hz drop-outs, not a 5 s outage
    assert not isinstance(kf.state(t_last + tau - 0.1), str)
    why = kf.state(t_last + tau + 0.01)
    assert isinstance(why, str) and "uncertainty" in why
    # and the first report after the outage makes it usable again
    ts = BOAT.state(t_last + 6.0)
    kf.add(Report(last.t + 6.0, ts.position, ts.velocity), rx_last + 6.0)
    assert not isinstance(kf.state(t_last + 6.0 + LATENCY), str)


def test_same_fix_in_follow_target_and_global_position_counts_once():
    """A target sending both messages sends each fix twice with one timestamp: fusing it twice
    would halve its variance for nothing. The second is a duplicate."""
    kf = TargetEstimator(params())
    rx, r = reports(BOAT, 0.0)[0]
    assert kf.add(r, rx) == "fused"
    assert kf.add(Report(r.t, r.position, r.velocity), rx + 1e-4) == "duplicate"


def test_sender_clock_restart_resets_the_filter():
    """The target reboots: its stamps restart near 0. Taken as 100 s old reports they would be
    dropped for ever; the filter resets and starts again from the new clock."""
    kf = TargetEstimator(params())
    feed(kf, reports(BOAT, 30.0, seed=7))
    ts = BOAT.state(31.0)
    assert kf.add(Report(1.0, ts.position, ts.velocity), 31.0 + LATENCY) == "fused"
    assert kf.counts["clock_reset"] == 1
    st = kf.state(31.0)
    assert not isinstance(st, str)
    assert np.linalg.norm(st.position - ts.position) < 1e-9


def test_report_older_than_the_history_is_dropped():
    """A report 15 s late with a 10 s history: it cannot be re-ordered any more."""
    kf = TargetEstimator(params(history_s=10.0, max_age_s=20.0))
    reps = reports(BOAT, 40.0, seed=8)
    feed(kf, reps)
    rx = reps[-1][0]
    ts = BOAT.state(25.0)
    assert kf.add(Report(25.0 + OFFSET, ts.position, ts.velocity), rx) == "too_late"


def test_stationary_target_keeps_its_yaw():
    """A target at rest: the course is undefined (noise in the velocity would spin the frame);
    below 0.5 m/s the yaw is held (here the reported one)."""
    kf = TargetEstimator(params(velocity_noise_m_s=0.05))
    rng = np.random.default_rng(9)
    for k in range(60):
        r = Report(k + OFFSET, rng.normal(0.0, SIG_P, 3), rng.normal(0.0, 0.05, 3), yaw=1.0)
        kf.add(r, k + LATENCY)
    st = kf.state(60.0)
    assert not isinstance(st, str)
    assert math.atan2(st.R_T_I[1, 0], st.R_T_I[0, 0]) == pytest.approx(1.0, abs=1e-12)


def test_manoeuvring_target_is_followed_with_the_default_tuning():
    """The paper's target (Section V): its speed swings between 3 and 6.7 m/s and its turn rate
    reverses every ~30 s. With the default process noise (a general target, not the demo's
    quiet boat) no report is taken for an outlier: at a 99.99 % gate a consistent filter gates
    0.03 of 300 reports on average (at most 1 allowed), and none re-initialises it. The
    position stays better than one fix (radial 1-sigma 3.5 m) in RMS."""
    from mpf_mavlink.core.target import PaperProfile

    motion = PaperProfile()
    kf = TargetEstimator(params())
    errs = []
    for rx, r in reports(motion, 300.0, seed=10):
        kf.add(r, rx)
        if rx > 60.0:
            st = kf.state(rx)
            assert not isinstance(st, str)
            errs.append(float(np.linalg.norm(st.position - motion.state(rx).position)))
    assert kf.counts["gated"] <= 1 and kf.counts["reinit"] == 0, kf.counts
    assert math.sqrt(float(np.mean(np.square(errs)))) < SIG_P * math.sqrt(3.0)


def test_control_step_prediction_matches_the_full_covariance():
    """state() (every control step) predicts only the mean and the position variance's trace;
    its staleness must equal the one from the full predicted covariance: the bound is crossed at
    the same instant (compared just below and above the crossing found on the full one)."""
    kf = TargetEstimator(params(max_position_sigma_m=3.0))
    feed(kf, reports(BOAT, 60.0, seed=12))
    t0 = 60.0 + LATENCY
    lo, hi = t0, t0 + 10.0
    for _ in range(60):  # bisection on the full covariance's uncertainty
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if kf.position_sigma(mid) <= 3.0 else (lo, mid)
    assert not isinstance(kf.state(lo - 1e-6), str)
    assert isinstance(kf.state(hi + 1e-6), str)


def test_follow_target_accuracy_fields_set_the_fix_noise():
    """FOLLOW_TARGET's position_cov is "eph epv" (m, 1-sigma): a fix reporting 0.5 m / 1.5 m
    starts the filter with those variances (0.25, 0.25, 2.25 m^2), not the configured 2 m; a
    report without them (zeros) gets the configured noise."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    from mpf_mavlink.bridge.estimator import Estimator, EstimatorParams
    from mpf_mavlink.bridge.target_sources import LiveTarget
    from mpf_mavlink.mavlink.codec import decode_follow_target

    origin = (41.185, -8.76, 0.0)
    mav = M.MAVLink(None, srcSystem=2, srcComponent=1)
    for cov, want in (([0.5, 1.5, 0.0], [0.25, 0.25, 2.25]), ([0.0] * 3, [SIG_P**2] * 3)):
        lt = LiveTarget(Estimator(EstimatorParams(origin=origin)), params())
        m = mav.follow_target_encode(10000, 3, 411850000, -87600000, 0.0, [3.0, 0.0, 0.0],
                                     [0.0] * 3, [1.0, 0.0, 0.0, 0.0], [0.0] * 3, cov,
                                     0)  # fmt: skip
        lt.update(decode_follow_target(mav.decode(bytearray(m.pack(mav)))), 0.3)
        post = lt.kf.latest()
        assert post is not None
        np.testing.assert_allclose(np.diag(post.P)[:3], want, rtol=1e-6)


def test_attitude_alone_does_not_keep_a_lost_target_placed():
    """The target's GPS dies but its ATTITUDE keeps coming at 10 Hz: the turn rate is still
    known, the position is not. The staleness counts from the last fix: whatever sigma_0, the
    unseen-manoeuvre term alone passes the bound after sqrt(2 x 4 m / 0.3 m/s^2) = 5.2 s, so
    9.9 s after the last fix the prediction is refused although reports keep arriving."""
    p = params(max_position_sigma_m=4.0, manoeuvre_accel_m_s2=0.3)
    kf = TargetEstimator(p)
    reps = reports(BOAT, 60.0, seed=13)
    feed(kf, reps)
    rx, last = reps[-1]
    for k in range(1, 100):  # 10 s of attitude-only reports
        kf.add(Report(last.t + 0.1 * k, turn_rate=BOAT.turn_rate, yaw=0.0), rx + 0.1 * k)
    why = kf.state(rx + 9.9)
    assert isinstance(why, str) and "since its last position" in why


def test_reported_attitude_sets_the_frame_while_fresh_then_the_course():
    """A boat crabbing 0.2 rad off its course (current on the beam) reports its yaw: {T} takes
    that yaw (turned on at the estimated turn rate) while the report is younger than
    attitude_timeout_s, then falls back to the course of the estimated velocity."""
    kf = TargetEstimator(params(attitude_timeout_s=1.0))
    reps = reports(BOAT, 30.0, seed=14)
    feed(kf, reps)
    rx, last = reps[-1]
    yaw_true = BOAT.state(30.0).R_T_I
    yaw0 = math.atan2(yaw_true[1, 0], yaw_true[0, 0]) + 0.2
    kf.add(Report(last.t, yaw=yaw0, turn_rate=BOAT.turn_rate, attitude=True), rx)
    # control time rx - LATENCY + age is "age" seconds after the report's own stamp
    st = kf.state(rx - LATENCY + 0.5)
    assert not isinstance(st, str)
    w = st.omega_T[2]
    assert math.atan2(st.R_T_I[1, 0], st.R_T_I[0, 0]) == pytest.approx(yaw0 + 0.5 * w, abs=1e-9)
    st = kf.state(rx - LATENCY + 1.5)  # the attitude is 1.5 s old: the course again
    assert not isinstance(st, str)
    course = math.atan2(st.velocity[1], st.velocity[0])
    assert math.atan2(st.R_T_I[1, 0], st.R_T_I[0, 0]) == pytest.approx(course, abs=1e-9)


def test_state_floats_equal_its_arrays():
    """state() hands the law its numbers twice, as arrays and as floats (TargetState.floats,
    R_T^I by rows, then p, v, a, omega, omega_dot): they must be the same doubles, exactly,
    behind, at and ahead of the latest fix."""
    kf = TargetEstimator(params(accel_noise_m_s2=0.005, turn_accel_noise_rad_s2=1e-5))
    feed(kf, reports(BOAT, 60.0, seed=3))
    for t in (10.0, 60.0 + LATENCY, 61.7):
        st = kf.state(t)
        assert not isinstance(st, str)
        assert st.floats is not None
        arrays = np.concatenate(
            [st.R_T_I.ravel(), st.position, st.velocity, st.acceleration, st.omega_T,
             st.omega_dot_T]
        )  # fmt: skip
        assert list(st.floats) == arrays.tolist()


def test_a_state_of_floats_reads_as_arrays_built_once():
    """state() gives its arrays only when read (the law reads the floats): read-only views of
    one array of the floats, built once, and the state copies, pickles and compares as one
    built with its arrays."""
    import copy
    import pickle

    kf = TargetEstimator(params())
    feed(kf, reports(BOAT, 20.0, seed=5))
    st = kf.state(20.0)
    assert not isinstance(st, str)
    assert "position" not in vars(st)  # nothing built yet
    R = st.R_T_I
    assert R is st.R_T_I and st.position.base is R.base  # built once, views of one array
    assert not st.velocity.flags.writeable
    with pytest.raises(AttributeError):
        st.no_such_field  # noqa: B018
    eager = dataclasses.replace(st)  # through __init__, with the arrays
    for other in (copy.copy(kf.state(20.0)), pickle.loads(pickle.dumps(kf.state(20.0))), eager):
        for name in ("position", "velocity", "acceleration", "R_T_I", "omega_T", "omega_dot_T"):
            assert np.array_equal(getattr(other, name), getattr(st, name)), name
    assert repr(eager) == repr(st)
