"""SO(3) helpers and frame conventions."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mpf_mavlink.core import frames, so3

angles = st.floats(-math.pi + 1e-3, math.pi - 1e-3)


@given(st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-5, 5)))
@settings(max_examples=200, deadline=None)
def test_hat_vee_and_cross(v):
    a = np.array(v)
    b = np.array([0.3, -1.1, 2.0])
    # hat(a) b must equal a x b, and vee must invert hat exactly.
    assert np.allclose(so3.hat(a) @ b, np.cross(a, b), atol=1e-12)
    assert np.allclose(so3.vee(so3.hat(a)), a, atol=0)


@given(st.tuples(angles, angles, angles))
@settings(max_examples=200, deadline=None)
def test_exp_log_round_trip(v):
    w = np.array(v)
    if np.linalg.norm(w) >= math.pi - 1e-3:
        w = w / np.linalg.norm(w) * (math.pi - 1e-3)
    R = so3.exp(w)
    # exp lands on SO(3) and log inverts it for |w| < pi.
    assert so3.is_rotation(R, 1e-12)
    assert np.allclose(so3.log(R), w, atol=1e-7)


def test_log_near_pi_and_identity():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    for th in (math.pi - 1e-7, math.pi - 1e-3, 1e-9):
        w = so3.log(so3.exp(th * axis))
        # Near pi the axis comes from the symmetric part; angle and axis must survive.
        assert abs(np.linalg.norm(w) - th) < 1e-6
        assert abs(abs(np.dot(w / np.linalg.norm(w), axis)) - 1) < 1e-6


def test_quaternion_order_and_euler():
    # A pure 90 deg yaw: q = (cos 45, 0, 0, sin 45) in (w, x, y, z); x_body -> east.
    R = frames.euler_to_matrix(0.0, 0.0, math.pi / 2)
    q = frames.matrix_to_quat_wxyz(R)
    assert np.allclose(q, (math.sqrt(0.5), 0, 0, math.sqrt(0.5)), atol=1e-12)
    assert np.allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    for rpy in [(0.3, -0.2, 2.5), (-1.0, 1.2, -3.0)]:
        R = frames.euler_to_matrix(*rpy)
        assert np.allclose(frames.quat_wxyz_to_matrix(frames.matrix_to_quat_wxyz(R)), R, atol=1e-12)
        assert np.allclose(frames.matrix_to_euler(R), rpy, atol=1e-12)


def test_geodetic_round_trip():
    ned = frames.geodetic_to_ned(47.001, 8.001, 520.0, 47.0, 8.0, 500.0)
    # 0.001 deg of latitude is ~111.2 m; 20 m above is -20 m down (plus earth curvature ~1 mm).
    assert abs(ned[0] - 111.18) < 0.05 and abs(ned[2] + 20.0) < 0.01
    lat, lon, alt = frames.ned_to_geodetic(ned, 47.0, 8.0, 500.0)
    assert abs(lat - 47.001) < 1e-9 and abs(lon - 8.001) < 1e-9 and abs(alt - 520.0) < 1e-6


def test_wind_frame_w1_along_air_velocity():
    R = frames.wind_frame_from_velocity([3.0, 4.0, -1.0])
    assert so3.is_rotation(R)
    assert np.allclose(R[:, 0], np.array([3.0, 4.0, -1.0]) / math.sqrt(26))
