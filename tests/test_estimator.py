"""The estimator (telemetry samples -> the law's VehicleState), fed decoded samples directly:
no sockets, no clock. Receive times (``t_rx``) are given explicitly.

Messages are built as pymavlink message objects and go through the real decoders
(:func:`mpf_mavlink.mavlink.decode`), so units and conventions are those of the wire.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpf_mavlink.bridge.estimator import Estimator, EstimatorParams
from mpf_mavlink.mavlink import decode, mavutil
from mpf_mavlink.mavlink import dialect as mavlink
from mpf_mavlink.mavlink.codec import (
    AttitudeSample,
    GlobalPositionSample,
    HomeSample,
    LocalPositionSample,
    VfrHudSample,
    WindSample,
)

# A real ArduPlane SITL recording kept in the repository (provenance: tests/data/README.md).
SHARED_TLOG = Path(__file__).resolve().parent / "data" / "arduplane-quadplane-sitl-vtol.tlog"
HOME = (47.397742, 8.545594, 488.0)  # lat deg, lon deg, alt m AMSL


# ----------------------------------------------------------------------------- helpers
def ms(t: float) -> int:
    return int(round(t * 1000.0))


class Feed:
    """Builds MAVLink messages, decodes them and feeds the estimator (t_rx = t by default)."""

    def __init__(self, params: EstimatorParams | None = None) -> None:
        self.est = Estimator(params or EstimatorParams())

    def _put(self, msg, t_rx: float | None) -> None:
        sample = decode(msg)
        assert sample is not None, msg
        self.est.update(sample, t_rx)

    def att(self, t, roll=0.0, pitch=0.0, yaw=0.0, rates=(0.0, 0.0, 0.0), rx=None):
        m = mavlink.MAVLink_attitude_message(ms(t), roll, pitch, yaw, *rates)
        self._put(m, t if rx is None else rx)

    def att_q(self, t, q, rates=(0.0, 0.0, 0.0), rx=None):
        m = mavlink.MAVLink_attitude_quaternion_message(ms(t), *q, *rates, [0.0, 0.0, 0.0, 0.0])
        self._put(m, t if rx is None else rx)

    def local(self, t, pos, vel, rx=None):
        m = mavlink.MAVLink_local_position_ned_message(ms(t), *pos, *vel)
        self._put(m, t if rx is None else rx)

    def glob(self, t, lat, lon, alt, vel=(0.0, 0.0, 0.0), rx=None):
        m = mavlink.MAVLink_global_position_int_message(
            ms(t), int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)), 0,
            int(round(vel[0] * 100)), int(round(vel[1] * 100)), int(round(vel[2] * 100)), 0,
        )  # fmt: skip
        self._put(m, t if rx is None else rx)

    def home(self, lat, lon, alt, pos=(0.0, 0.0, 0.0), rx=0.0):
        m = mavlink.MAVLink_home_position_message(
            int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)), *pos,
            [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
        )  # fmt: skip
        self._put(m, rx)

    def vfr(self, airspeed, rx, alt=0.0):
        # at sea level EAS = TAS: the airspeed goes through unscaled
        self._put(mavlink.MAVLink_vfr_hud_message(airspeed, airspeed, 0, 50, alt, 0.0), rx)

    def wind(self, from_deg, speed, speed_z, rx):
        self._put(mavlink.MAVLink_wind_message(from_deg, speed, speed_z), rx)

    def wind_cov(self, wn, we, wd, rx):
        m = mavlink.MAVLink_wind_cov_message(ms(rx) * 1000, wn, we, wd, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._put(m, rx)

    def estimate(self):
        return self.est.estimate()


def zyx_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R_B^N for ZYX Euler angles, written out (independent of mpf_mavlink.core.frames)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def zyx_quat_wxyz(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Hamilton quaternion (w, x, y, z) of ZYX Euler angles (the textbook half-angle formula)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def level_flight(f: Feed, t: float, yaw: float, v_air: float, wind=(0.0, 0.0), pitch=0.0):
    """A trimmed vehicle at t: nose along the air-relative velocity (zero sideslip), level."""
    vn = v_air * math.cos(yaw) + wind[0]
    ve = v_air * math.sin(yaw) + wind[1]
    f.local(t, (0.0, 0.0, -100.0), (vn, ve, 0.0))
    f.vfr(v_air, rx=t)
    f.att(t, 0.0, pitch, yaw)


def assert_finite_estimate(e) -> None:
    vs = e.vehicle
    for arr in (vs.position, vs.R_W_I, vs.wind, e.R_B_N, e.rates_frd, e.ground_velocity):
        assert np.all(np.isfinite(arr))
    assert math.isfinite(vs.t) and math.isfinite(vs.airspeed) and vs.airspeed > 0


# ----------------------------------------------------------------------------- attitude
def test_attitude_and_attitude_quaternion_give_the_same_known_rotation():
    roll, pitch, yaw = 0.3, -0.2, 2.5
    expected = zyx_matrix(roll, pitch, yaw)
    got = []
    for use_q in (False, True):
        f = Feed()
        f.local(10.0, (0.0, 0.0, -100.0), (10.0, 0.0, 0.0))
        f.vfr(15.0, rx=10.0)
        if use_q:
            f.att_q(10.0, zyx_quat_wxyz(roll, pitch, yaw), rates=(0.1, -0.2, 0.3))
        else:
            f.att(10.0, roll, pitch, yaw, rates=(0.1, -0.2, 0.3))
        e, why = f.estimate()
        assert e is not None, why
        np.testing.assert_allclose(e.R_B_N, expected, atol=1e-12)
        np.testing.assert_allclose(e.rates_frd, [0.1, -0.2, 0.3])
        got.append(e.R_B_N)
    np.testing.assert_allclose(got[0], got[1], atol=1e-12)


def test_quaternion_is_w_first_and_body_axes_point_where_they_should():
    # yaw 90 deg, roll 30 deg right wing down: nose East, right wing South-ish and down
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    f = Feed()
    f.local(1.0, (0.0, 0.0, 0.0), (0.0, 15.0, 0.0))
    f.vfr(15.0, rx=1.0)
    f.att_q(1.0, (c, 0.0, 0.0, s))  # (w, x, y, z): a pure +90 deg yaw
    e, _ = f.estimate()
    np.testing.assert_allclose(e.R_B_N[:, 0], [0.0, 1.0, 0.0], atol=1e-12)  # nose East
    np.testing.assert_allclose(e.R_B_N[:, 1], [-1.0, 0.0, 0.0], atol=1e-12)  # right wing South
    f.att_q(1.02, zyx_quat_wxyz(math.radians(30), 0.0, math.pi / 2))
    e, _ = f.estimate()
    assert e.R_B_N[2, 1] == pytest.approx(0.5)  # right wing down by sin(30 deg)


unit_quats = (
    st.tuples(*[st.floats(-1.0, 1.0) for _ in range(4)])
    .filter(lambda q: math.sqrt(sum(v * v for v in q)) > 0.2)
    .map(lambda q: tuple(v / math.sqrt(sum(x * x for x in q)) for v in q))
)


@settings(max_examples=200, deadline=None)
@given(q=unit_quats, scale=st.floats(0.95, 1.05))
def test_r_b_n_is_a_rotation_for_any_valid_quaternion(q, scale):
    f = Feed()
    f.local(5.0, (0.0, 0.0, 0.0), (12.0, 3.0, 0.0))
    f.vfr(14.0, rx=5.0)
    f.att_q(5.0, tuple(scale * v for v in q))  # float noise in |q| is normalised away
    e, why = f.estimate()
    assert e is not None, why
    R = e.R_B_N
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-9)
    # q and -q are the same attitude
    f.att_q(5.02, tuple(-scale * v for v in q))
    np.testing.assert_allclose(f.estimate()[0].R_B_N, R, atol=1e-9)


# ----------------------------------------------------------------------------- position
def test_local_position_preferred_while_fresh_then_global_then_local_again():
    f = Feed()
    f.home(*HOME)
    lat, lon, alt = pymap3d.ned2geodetic(300.0, -400.0, -120.0, *HOME)
    f.local(10.0, (10.0, 20.0, -30.0), (0.0, 0.0, 0.0))
    f.glob(10.0, lat, lon, alt)
    f.vfr(15.0, rx=10.0)
    f.att(10.0)
    e, _ = f.estimate()
    assert e.position_source == "local"
    np.testing.assert_allclose(e.vehicle.position, [10.0, 20.0, -30.0], atol=1e-6)
    # LOCAL stops; GLOBAL goes on: after position_stale_s the global position takes over
    for t in (10.2, 10.4, 10.6):
        f.glob(t, lat, lon, alt)
        f.vfr(15.0, rx=t)
        f.att(t)
    e, _ = f.estimate()
    assert e.position_source == "global"
    np.testing.assert_allclose(e.vehicle.position, [300.0, -400.0, -120.0], atol=0.02)
    f.local(10.62, (11.0, 20.0, -30.0), (0.0, 0.0, 0.0))
    f.att(10.62)
    e, _ = f.estimate()
    assert e.position_source == "local"
    np.testing.assert_allclose(e.vehicle.position, [11.0, 20.0, -30.0], atol=1e-6)


def test_global_position_about_home_position_matches_pymap3d_not_flat_earth():
    # 3 km away and 250 m up: the earth's curvature alone is ~0.7 m of "down" at this range
    lat, lon, alt = 47.42, 8.57, 740.0
    home_local = (12.0, -7.0, 3.0)  # HOME_POSITION x, y, z: home in the autopilot's local frame
    f = Feed()
    f.home(*HOME, pos=home_local)
    f.glob(20.0, lat, lon, alt, vel=(0.0, 0.0, 0.0))
    f.vfr(15.0, rx=20.0)
    f.att(20.0)
    e, why = f.estimate()
    assert e is not None, why
    lat_q, lon_q, alt_q = round(lat * 1e7) * 1e-7, round(lon * 1e7) * 1e-7, alt  # the wire's degE7
    n, ea, d = pymap3d.geodetic2ned(
        lat_q, lon_q, alt_q, round(HOME[0] * 1e7) * 1e-7, round(HOME[1] * 1e7) * 1e-7, HOME[2]
    )
    expected = np.array([n, ea, d]) + home_local
    np.testing.assert_allclose(e.vehicle.position, expected, atol=1e-3)
    assert e.position_source == "global"
    # a flat-earth conversion would be off by decimetres in "down": make sure we are not that
    flat_d = -(alt_q - HOME[2]) + home_local[2]
    assert abs(e.vehicle.position[2] - flat_d) > 0.3


def test_local_frame_is_pymap3d_to_the_last_bit():
    """The scalar conversion (every target fix goes through it) does pymap3d's geodetic2ned
    operations in pymap3d's order on its ellipsoid with the same sin, cos and hypot: the same
    floats, for origins all over the earth and points up to ~5 km and 200 m off them."""
    from mpf_mavlink.bridge.estimator import LocalFrame
    from mpf_mavlink.core.frames import geodetic_to_ned

    rng = np.random.default_rng(5)
    for _ in range(300):
        lat0, lon0, alt0 = rng.uniform(-89, 89), rng.uniform(-180, 180), rng.uniform(-100, 3000)
        off = tuple(rng.uniform(-50, 50, 3).tolist())
        frame = LocalFrame(lat0, lon0, alt0, off)
        for _ in range(10):
            lat, lon = lat0 + rng.uniform(-0.05, 0.05), lon0 + rng.uniform(-0.05, 0.05)
            alt = alt0 + rng.uniform(-200, 200)
            expected = geodetic_to_ned(lat, lon, alt, lat0, lon0, alt0) + np.array(off)
            assert list(frame.ned(lat, lon, alt)) == expected.tolist()


def test_a_new_home_position_moves_the_local_frame():
    """The conversion's origin is kept between fixes; a new HOME_POSITION replaces it."""
    lat, lon, alt = 47.40, 8.55, 500.0
    est = Estimator()
    assert est.origin.ned(lat, lon, alt) is None and not est.origin.known()
    for home, pos in ((HOME, (0.0, 0.0, 0.0)), ((47.39, 8.54, 480.0), (5.0, -3.0, 1.0))):
        est.update(HomeSample(*home, np.array(pos)), 1.0)
        n, e, d = pymap3d.geodetic2ned(lat, lon, alt, *home)
        assert est.origin.ned(lat, lon, alt).tolist() == (np.array([n, e, d]) + pos).tolist()


def test_configured_origin_wins_over_home_and_missing_origin_is_a_reason():
    origin = (47.40, 8.55, 500.0)
    lat, lon, alt = 47.401, 8.551, 520.0
    f = Feed(EstimatorParams(origin=origin))
    f.home(*HOME, pos=(50.0, 50.0, 0.0))  # ignored: the configured origin comes first
    f.glob(3.0, lat, lon, alt)
    f.vfr(15.0, rx=3.0)
    f.att(3.0)
    e, _ = f.estimate()
    n, ea, d = pymap3d.geodetic2ned(round(lat * 1e7) * 1e-7, round(lon * 1e7) * 1e-7, alt, *origin)
    np.testing.assert_allclose(e.vehicle.position, [n, ea, d], atol=1e-3)

    g = Feed()  # no origin configured, no HOME_POSITION
    g.glob(3.0, lat, lon, alt)
    g.vfr(15.0, rx=3.0)
    g.att(3.0)
    e, why = g.estimate()
    assert e is None and "GLOBAL_POSITION_INT" in why and "HOME_POSITION" in why


@pytest.mark.parametrize("source", ["local", "global"])
def test_position_is_extrapolated_to_the_attitude_time(source):
    vel = (12.0, -5.0, 1.5)
    f = Feed()
    f.home(*HOME)
    if source == "local":
        f.local(50.0, (100.0, 200.0, -80.0), vel)
        p0 = np.array([100.0, 200.0, -80.0])
    else:
        lat, lon, alt = pymap3d.ned2geodetic(100.0, 200.0, -80.0, *HOME)
        f.glob(50.0, lat, lon, alt, vel=vel)
        p0 = np.array([100.0, 200.0, -80.0])
    f.vfr(15.0, rx=50.08)
    f.att(50.08)  # 80 ms after the position sample
    e, why = f.estimate()
    assert e is not None, why
    assert e.position_source == source
    np.testing.assert_allclose(e.vehicle.position, p0 + 0.08 * np.array(vel), atol=0.02)
    np.testing.assert_allclose(e.ground_velocity, vel, atol=1e-9)
    assert e.t_boot_s == pytest.approx(50.08)


# ----------------------------------------------------------------------------- staleness
def _fresh(f: Feed, t: float, *, att=True, pos=True, vfr=True) -> None:
    if pos:
        f.local(t, (0.0, 15.0 * t, -100.0), (0.0, 15.0, 0.0))
    if vfr:
        f.vfr(15.0, rx=t)
    if att:
        f.att(t, 0.0, 0.0, math.pi / 2)


@pytest.mark.parametrize("stream", ["attitude", "position", "airspeed"])
def test_each_stream_going_stale_stops_the_estimate_naming_it_and_recovers(stream):
    f = Feed()
    t = 100.0
    while t < 101.0:  # 50 Hz, all fresh
        _fresh(f, t)
        e, why = f.estimate()
        assert e is not None, why
        t = round(t + 0.02, 3)
    # the stream stops; the others go on. Within its limit (0.5 s) nothing changes ...
    t_stop = t - 0.02
    while t <= t_stop + 0.8:
        _fresh(f, t, att=stream != "attitude", pos=stream != "position", vfr=stream != "airspeed")
        e, why = f.estimate()
        if t - t_stop <= 0.45:
            assert e is not None, (t - t_stop, why)
        elif t - t_stop > 0.55:
            assert e is None and why.startswith(stream), (t - t_stop, why)
        t = round(t + 0.02, 3)
    # ... and it recovers at the first new sample
    _fresh(f, t)
    e, why = f.estimate()
    assert e is not None, why
    assert e.t_boot_s == pytest.approx(t)


def test_attitude_staleness_without_receive_times_uses_the_position_boot_time():
    f = Feed()
    f.local(10.0, (0.0, 0.0, -100.0), (15.0, 0.0, 0.0), rx=None)
    f.att(10.0, rx=None)
    assert f.estimate()[0] is not None
    f.local(10.45, (6.75, 0.0, -100.0), (15.0, 0.0, 0.0), rx=None)
    assert f.estimate()[0] is not None  # 0.45 s behind: still fresh
    f.local(10.6, (9.0, 0.0, -100.0), (15.0, 0.0, 0.0), rx=None)
    e, why = f.estimate()
    assert e is None and why.startswith("attitude stale")


def test_a_stream_that_stopped_does_not_hold_the_attitude_hostage_after_a_reboot():
    """The autopilot reboots (boot time restarts near 0) and stops sending GLOBAL_POSITION_INT:
    its last sample, far 'ahead' in boot time, must not make the new attitude stale."""
    f = Feed()
    f.home(*HOME)
    lat, lon, alt = pymap3d.ned2geodetic(0.0, 0.0, -100.0, *HOME)
    for k in range(10):
        t = 500.0 + 0.02 * k
        f.glob(t, lat, lon, alt)
        _fresh(f, t)
    rx = 500.0 + 0.02 * 10 + 1.0  # 1 s later, on the same receive clock
    for k in range(10):
        t, r = 2.0 + 0.02 * k, rx + 0.02 * k
        f.local(t, (0.0, 30.0, -100.0), (0.0, 15.0, 0.0), rx=r)
        f.vfr(15.0, rx=r)
        f.att(t, 0.0, 0.0, math.pi / 2, rx=r)
    e, why = f.estimate()
    assert e is not None, why
    assert e.position_source == "local" and e.t_boot_s == pytest.approx(2.18)


def test_no_attitude_and_no_position_reasons():
    f = Feed()
    assert f.estimate() == (None, "no attitude yet")
    f.att(1.0)
    e, why = f.estimate()
    assert e is None and "no position" in why


# ----------------------------------------------------------------------------- wind
def test_own_wind_estimate_converges_to_a_steady_wind_through_a_turn():
    """A trimmed vehicle (zero sideslip, small angle of attack) circling at 15 m/s airspeed in
    a 5 m/s wind; then the wind steps. The low-pass has time constant wind_tau_s = 2 s."""
    tau = 2.0
    f = Feed(EstimatorParams(wind_tau_s=tau))
    wind_a, wind_b = np.array([4.0, -3.0, 0.0]), np.array([-2.0, 5.0, 0.0])
    dt, V, r = 0.02, 15.0, 0.15  # yaw rate 0.15 rad/s: a full turn in 42 s
    errs: dict[float, float] = {}
    for k in range(int(40.0 / dt) + 1):
        t = round(10.0 + k * dt, 3)
        wind = wind_a if t < 30.0 else wind_b
        level_flight(f, t, yaw=r * (t - 10.0), v_air=V, wind=wind[:2], pitch=0.04)
        e, why = f.estimate()
        assert e is not None, why
        assert e.wind_source == "estimated"
        errs[t] = float(np.linalg.norm(e.vehicle.wind - wind))
        if t >= 30.0:
            # during the step response, the error decays like exp(-(t - 30) / tau)
            expected = np.linalg.norm(wind_b - wind_a) * math.exp(-(t - 30.0) / tau)
            assert errs[t] == pytest.approx(expected, abs=0.05 + 0.05 * expected), t
    # steady state: within 0.05 m/s (the 0.04 rad angle of attack costs 15(1 - cos 0.04) = 0.012)
    assert max(v for t, v in errs.items() if 20.0 <= t < 30.0) < 0.05
    assert max(v for t, v in errs.items() if t >= 30.0 + 7 * tau) < 0.05


def test_estimate_is_pure_and_the_wind_low_pass_advances_once_per_attitude():
    """The own-wind low-pass advances when an ATTITUDE is stored, from the telemetry received
    before it (tlog order, so a replay reproduces it), exactly the recursion
    w += (1 - exp(-dt / tau)) (measured - w); estimate() only reads it, however often it is
    called, and a position arriving after the ATTITUDE waits for the next one."""
    tau, V = 2.0, 15.0
    f = Feed(EstimatorParams(wind_tau_s=tau))
    # an ATTITUDE before any position: nothing to measure, so no low-pass yet, even once the
    # position and airspeed are in (an estimate is asked for before the next ATTITUDE)
    f.att(9.98, 0.0, 0.0, 0.3)
    f.local(9.98, (0.0, 0.0, -100.0), (V * math.cos(0.3) + 1.0, V * math.sin(0.3) - 2.0, 0.0))
    f.vfr(V, rx=9.98)
    e, _ = f.estimate()
    assert e is not None and e.wind_source == "estimated" and e.vehicle.wind.tolist() == [0.0] * 3
    assert f.est.wind_lp.value is None
    want: np.ndarray | None = None
    for k in range(50):
        t = round(10.0 + 0.02 * k, 3)
        wind = (1.0 + 0.1 * k, -2.0)  # a drifting wind: every sample moves the low-pass
        level_flight(f, t, yaw=0.3, v_air=V, wind=wind)
        # the measurement vg - V x_b is the wind itself (level, zero sideslip)
        meas = np.array([wind[0], wind[1], 0.0])
        gain = 1.0 - math.exp(-0.02 / tau)
        want = meas if want is None else want + gain * (meas - want)
        first, _ = f.estimate()
        again, _ = f.estimate()
        assert first is not None and again is not None
        np.testing.assert_allclose(first.vehicle.wind, want, rtol=0, atol=1e-12)
        assert first.vehicle.wind.tolist() == again.vehicle.wind.tolist()
        assert first.vehicle.position.tolist() == again.vehicle.position.tolist()
    lp = f.est.wind_lp.value
    # a later position (another ground velocity) changes the estimate's frame but not the wind
    f.local(10.99, (0.0, 0.0, -100.0), (0.0, 30.0, 0.0))
    e, _ = f.estimate()
    assert f.est.wind_lp.value == lp and e is not None and e.vehicle.wind.tolist() == list(lp)
    assert e.ground_velocity.tolist() == [0.0, 30.0, 0.0]


def test_own_wind_estimate_defines_the_wind_frame_and_airspeed():
    # crab: heading North at 15 m/s airspeed in a 5 m/s wind from the West (blowing East)
    f = Feed(EstimatorParams(wind_tau_s=1.0))
    for k in range(300):
        level_flight(f, 10.0 + 0.02 * k, yaw=0.0, v_air=15.0, wind=(0.0, 5.0))
    e, _ = f.estimate()
    np.testing.assert_allclose(e.vehicle.wind, [0.0, 5.0, 0.0], atol=0.01)
    # w1 along ground velocity minus wind = the nose (North), not along the track (NNE)
    np.testing.assert_allclose(e.vehicle.R_W_I[:, 0], [1.0, 0.0, 0.0], atol=1e-3)
    assert e.vehicle.airspeed == 15.0 and e.airspeed_source == "vfr_hud"


def test_ardupilot_wind_is_where_it_comes_from_and_is_used_when_fresh():
    """ArduPilot WIND.direction is where the wind comes FROM (deg), speed is |wind| (3-D norm,
    ArduPilot sends wind.length()), speed_z its down component: a 5 m/s wind from the West
    (270 deg) is an air mass moving East: NED (0, +5, 0)."""
    f = Feed()
    f.wind(270.0, 5.0, 0.0, rx=10.0)
    f.local(10.0, (0.0, 0.0, -100.0), (12.0, 5.0, 0.0))  # ground velocity North-North-East
    # the autopilot's airspeed (16) differs from |vg - wind| = 12: with its wind fresh, v_w is
    # 12, the air-relative speed of the law's kinematics p_dot = v_w w1 + eta (an EAS/TAS or
    # calibration error in VFR_HUD would otherwise bend every circle; airspeed_from_wind)
    f.vfr(16.0, rx=10.0)
    f.att(10.0, 0.0, 0.0, 0.3)  # the nose is NOT along the air velocity: w1 must not use it
    e, why = f.estimate()
    assert e is not None, why
    assert e.wind_source == "WIND"
    np.testing.assert_allclose(e.vehicle.wind, [0.0, 5.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(e.vehicle.R_W_I[:, 0], [1.0, 0.0, 0.0], atol=1e-9)  # (12,5)-(0,5)
    assert e.vehicle.airspeed == pytest.approx(12.0) and e.airspeed_source == "ground_minus_wind"
    g = Feed(EstimatorParams(airspeed_from_wind=False))  # VFR_HUD as the speed along w1
    g.wind(270.0, 5.0, 0.0, rx=10.0)
    g.local(10.0, (0.0, 0.0, -100.0), (12.0, 5.0, 0.0))
    g.vfr(16.0, rx=10.0)
    g.att(10.0, 0.0, 0.0, 0.3)
    assert g.estimate()[0].vehicle.airspeed == 16.0
    # from the North-East (45 deg) with a 1 m/s updraft (speed_z = -1, NED down):
    f.wind(45.0, math.sqrt(8.0 + 1.0), -1.0, rx=10.02)
    f.att(10.02, 0.0, 0.0, 0.3)
    e, _ = f.estimate()
    np.testing.assert_allclose(e.vehicle.wind, [-2.0, -2.0, -1.0], atol=1e-9)


def test_px4_wind_cov_is_ned_air_velocity_and_used_when_fresh():
    f = Feed()
    f.wind_cov(3.0, -4.0, 0.0, rx=10.0)  # PX4: wind_x = windspeed_north, wind_y = east
    f.local(10.0, (0.0, 0.0, -100.0), (3.0, 11.0, 0.0))
    f.vfr(15.0, rx=10.0)
    f.att(10.0)
    e, _ = f.estimate()
    assert e.wind_source == "WIND_COV"
    np.testing.assert_allclose(e.vehicle.wind, [3.0, -4.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(e.vehicle.R_W_I[:, 0], [0.0, 1.0, 0.0], atol=1e-9)  # (3,11)-(3,-4)


def test_stale_autopilot_wind_falls_back_to_the_own_estimate():
    f = Feed(EstimatorParams(wind_stale_s=2.0, wind_tau_s=0.5))
    f.wind_cov(9.0, 9.0, 0.0, rx=10.0)  # the autopilot's (wrong) wind, then silence
    for k in range(200):  # 4 s; the true wind is 2 m/s North
        t = 10.0 + 0.02 * k
        level_flight(f, t, yaw=math.pi / 2, v_air=15.0, wind=(2.0, 0.0))
        e, _ = f.estimate()
        if t <= 11.9:
            assert e.wind_source == "WIND_COV"
            np.testing.assert_allclose(e.vehicle.wind, [9.0, 9.0, 0.0])
        elif t >= 12.1:
            assert e.wind_source == "estimated"
            np.testing.assert_allclose(e.vehicle.wind, [2.0, 0.0, 0.0], atol=0.02)


# ----------------------------------------------------------------------------- robustness
FLOAT = st.one_of(
    st.floats(-1e3, 1e3), st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300])
)


T = st.one_of(st.floats(9.9, 10.3), FLOAT)  # boot times near the good samples' or anything


def _vec(xs):
    return np.array(xs, dtype=float)


samples = st.one_of(
    st.builds(lambda t, r, w: AttitudeSample(t, _vec(r).reshape(3, 3), _vec(w)),
              T, st.lists(FLOAT, min_size=9, max_size=9), st.lists(FLOAT, min_size=3, max_size=3)),
    st.builds(lambda t, p, v: LocalPositionSample(t, _vec(p), _vec(v)),
              T, st.lists(FLOAT, min_size=3, max_size=3), st.lists(FLOAT, min_size=3, max_size=3)),
    st.builds(lambda t, la, lo, a, v: GlobalPositionSample(t, la, lo, a, 0.0, _vec(v), None),
              T, FLOAT, FLOAT, FLOAT, st.lists(FLOAT, min_size=3, max_size=3)),
    st.builds(lambda a: VfrHudSample(a, 10.0, 0.5, 0.0, 100.0, 0.0), FLOAT),
    st.builds(lambda w: WindSample(_vec(w), "WIND_COV"), st.lists(FLOAT, min_size=3, max_size=3)),
    st.builds(lambda la, lo, a, p: HomeSample(la, lo, a, _vec(p)),
              FLOAT, FLOAT, FLOAT, st.lists(FLOAT, min_size=3, max_size=3)),
)  # fmt: skip


# How long before "now" (the good telemetry's receive time) a junk sample was received: receive
# times come from the link's one monotonic clock, so never after now; or a non-finite time.
RX_AGO = st.one_of(
    st.none(), st.floats(0.0, 0.4), st.floats(0.0, 1e3), st.sampled_from([math.nan, math.inf])
)


@settings(max_examples=300, deadline=None)
@given(junk=st.lists(st.tuples(samples, RX_AGO), min_size=1, max_size=8))
def test_non_finite_samples_never_produce_a_non_finite_estimate(junk):
    """Samples that bypass the decoders (e.g. from a replay tool) may carry NaN/inf: the estimate
    is then either the last good one's kind (finite) or None with a reason, never non-finite."""
    f = Feed()
    f.home(*HOME)
    good_t = 10.0
    for sample, ago in junk:
        level_flight(f, good_t, yaw=0.5, v_air=15.0, wind=(1.0, 2.0))
        t_rx = ago if ago is None or not math.isfinite(ago) else good_t - ago
        f.est.update(sample, t_rx)
        e, why = f.estimate()
        if e is not None:
            assert_finite_estimate(e)
        else:
            assert isinstance(why, str) and why
        good_t = round(good_t + 0.02, 3)
    # good telemetry afterwards always gives a finite estimate again
    for _ in range(3):
        good_t = round(good_t + 0.02, 3)
        level_flight(f, good_t, yaw=0.5, v_air=15.0, wind=(1.0, 2.0))
    e, why = f.estimate()
    assert e is not None, why
    assert_finite_estimate(e)


@settings(max_examples=200, deadline=None)
@given(
    vg=st.tuples(st.floats(-40, 40), st.floats(-40, 40), st.floats(-5, 5)),
    wind=st.tuples(st.floats(-15, 15), st.floats(-15, 15), st.floats(-2, 2)),
)
def test_wind_frame_is_a_rotation_with_w1_along_ground_minus_wind(vg, wind):
    f = Feed()
    f.wind_cov(*wind, rx=1.0)
    f.local(1.0, (0.0, 0.0, 0.0), vg)
    f.vfr(15.0, rx=1.0)
    f.att(1.0, 0.0, 0.0, 1.0)
    e, why = f.estimate()
    assert e is not None, why
    R = e.vehicle.R_W_I
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-9)
    air = np.array(vg) - np.array(wind)
    if np.linalg.norm(air) >= 1.0:
        np.testing.assert_allclose(R[:, 0], air / np.linalg.norm(air), atol=1e-9)
    else:  # air velocity too small to define a direction: the body x-axis
        np.testing.assert_allclose(R[:, 0], [math.cos(1.0), math.sin(1.0), 0.0], atol=1e-9)
    assert R[2, 1] == pytest.approx(0.0, abs=1e-9)  # w2 horizontal (roll about w1 is free)


def test_real_arduplane_log_gives_finite_estimates_and_a_sane_own_wind():
    """A real ArduPlane SITL recording (not written by this project; calm air: its WIND says
    0 m/s): every estimate is finite, ArduPilot's WIND is used while fresh, and our own
    estimate, run alongside, stays within 1.5 m/s of it in forward flight. The bias is mostly
    VFR_HUD's airspeed being equivalent, not true, airspeed (about 2.5 % at 500 m AMSL)."""
    tl = mavutil.mavlink_connection(str(SHARED_TLOG))
    est = Estimator()
    n_att = n_est = n_wind = 0
    own: list[float] = []
    while (m := tl.recv_match()) is not None:
        sample = decode(m)
        if sample is None or not est.update(sample, m._timestamp):
            continue
        n_att += 1
        e, why = est.estimate()
        if e is None:
            assert why
            continue
        n_est += 1
        assert_finite_estimate(e)
        n_wind += e.wind_source == "WIND"
        if e.vehicle.airspeed > 18.0:
            assert e.wind_source == "WIND"
            np.testing.assert_allclose(e.vehicle.wind, 0.0, atol=1e-6)
            own.append(float(np.linalg.norm(est.wind_lp.value)))
    assert n_att > 800 and n_est > n_att // 2 and n_wind >= 0.95 * n_est
    assert len(own) > 100 and max(own) < 1.5


def test_target_extrapolation_matches_the_matrix_formulas():
    # TargetState.extrapolate is written in scalars for speed: it must equal
    # p + h v + h^2/2 a, v + h a, R exp(h w + h^2/2 w'), w + h w' (tiny angles included).
    from mpf_mavlink.core import so3
    from mpf_mavlink.core.target import TargetState

    rng = np.random.default_rng(1)
    for i in range(2000):
        ts = TargetState(
            float(rng.normal() * 100), rng.normal(size=3) * 100, rng.normal(size=3) * 10,
            rng.normal(size=3), so3.exp(rng.normal(size=3) * 2),
            rng.normal(size=3) * (0.5 if i % 2 else 1e-10), rng.normal(size=3) * 0.1,
        )  # fmt: skip
        t = ts.t + float(rng.normal()) * (1.0 if i % 3 else 1e-6)
        h = t - ts.t
        e = ts.extrapolate(t)
        R = ts.R_T_I @ so3.exp(h * ts.omega_T + 0.5 * h * h * ts.omega_dot_T)
        np.testing.assert_allclose(
            e.position, ts.position + h * ts.velocity + 0.5 * h * h * ts.acceleration, atol=1e-9
        )
        np.testing.assert_allclose(e.velocity, ts.velocity + h * ts.acceleration, atol=1e-12)
        # Same formulas evaluated twice, possibly on different numpy paths (a 3-term dot product per
        # entry of unit-size factors, an exp of an angle <= ~10 rad): a few ulp of 1, i.e. ~1e-15;
        # 1e-13 leaves a factor 100 for angle reduction in sin/cos. Positions (~1e3 m) get 1e-9 m.
        np.testing.assert_allclose(e.R_T_I, R, atol=1e-13)
        np.testing.assert_allclose(e.omega_T, ts.omega_T + h * ts.omega_dot_T, atol=1e-13)
        assert e.t == t


def test_vfr_hud_airspeed_is_equivalent_and_becomes_true_airspeed_aloft():
    """VFR_HUD.airspeed is EAS (ArduPilot; PX4's calibrated airspeed is the same at UAV speeds);
    the law's v_w is TAS = EAS sqrt(rho0 / rho). ISA at 1000 m: rho / rho0 = 0.9075 (ICAO
    standard atmosphere table), so TAS = 20 / sqrt(0.9075) = 20.995 m/s; at sea level 20."""
    from mpf_mavlink.bridge.estimator import eas_to_tas

    assert eas_to_tas(0.0) == 1.0
    assert eas_to_tas(1000.0) == pytest.approx(1.0 / math.sqrt(0.9075), rel=2e-4)
    for alt, want, eas in ((1000.0, 20.0 / math.sqrt(0.9075), True), (1000.0, 20.0, False)):
        f = Feed(EstimatorParams(airspeed_is_eas=eas))
        f.local(10.0, (0.0, 0.0, -100.0), (20.0, 0.0, 0.0))
        f.vfr(20.0, rx=10.0, alt=alt)
        f.att(10.0, rx=10.0)
        est, why = f.est.estimate()
        assert est is not None, why
        assert est.vehicle.airspeed == pytest.approx(want, rel=2e-4)
