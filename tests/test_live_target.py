"""The bridge's live target before the estimator.

target_estimator.mode: last_sample: FOLLOW_TARGET / GLOBAL_POSITION_INT from one system,
extrapolated.

The messages are real MAVLink frames (pymavlink's encoder, the bridge's decoder), built from the
scripted boat of the demo as the SIL vehicle sends them.
"""

from __future__ import annotations

import math

import numpy as np

from mpf_mavlink.bridge.estimator import Estimator, EstimatorParams
from mpf_mavlink.bridge.target_sources import ExtrapolatedTarget as LiveTarget
from mpf_mavlink.core.frames import matrix_to_quat_wxyz, ned_to_geodetic
from mpf_mavlink.core.target import ConstantTurn
from mpf_mavlink.mavlink import dialect
from mpf_mavlink.mavlink.codec import decode_follow_target, decode_global_position_int

ORIGIN = (41.185, -8.76, 0.0)
BOAT = ConstantTurn(speed=3.0, turn_rate=0.01)  # the demo's boat
TIMEOUT_S = 1.0


def _frames(t: float) -> tuple[object, object]:
    """FOLLOW_TARGET and GLOBAL_POSITION_INT of the boat at time t, as the SIL sends them."""
    mav = dialect.MAVLink(None, srcSystem=2, srcComponent=1)
    ts = BOAT.state(t)
    lat, lon, alt = ned_to_geodetic(ts.position, *ORIGIN)
    lat7, lon7 = int(round(lat * 1e7)), int(round(lon * 1e7))
    ms = int(round(t * 1000))
    ft = mav.follow_target_encode(
        ms, 15, lat7, lon7, float(alt), ts.velocity.tolist(), ts.acceleration.tolist(),
        list(matrix_to_quat_wxyz(ts.R_T_I)), ts.omega_T.tolist(), [0.0] * 3, 0,
    )  # fmt: skip
    yaw = math.atan2(ts.R_T_I[1, 0], ts.R_T_I[0, 0])
    v = ts.velocity
    gpi = mav.global_position_int_encode(
        ms, lat7, lon7, int(round(alt * 1000)), int(round(alt * 1000)),
        int(round(v[0] * 100)), int(round(v[1] * 100)), int(round(v[2] * 100)),
        int(round(math.degrees(yaw) * 100)) % 36000,
    )  # fmt: skip
    # through the wire format, so the decoder sees what the bridge sees
    ft = mav.decode(bytearray(ft.pack(mav)))
    gpi = mav.decode(bytearray(gpi.pack(mav)))
    return decode_follow_target(ft), decode_global_position_int(gpi)


def _target() -> LiveTarget:
    return LiveTarget(Estimator(EstimatorParams(origin=ORIGIN)), TIMEOUT_S)


def test_global_position_does_not_erase_follow_target_turn():
    """FOLLOW_TARGET then GLOBAL_POSITION_INT of the same instant: the turn rate and the
    acceleration of the FOLLOW_TARGET stay (GLOBAL_POSITION_INT has neither; taken, it zeroed
    both and the law's feedforward lost the boat's turn)."""
    lt = _target()
    for k in range(5):  # the SIL sends both at 10 Hz, FOLLOW_TARGET first
        t = 10.0 + 0.1 * k
        ft, gpi = _frames(t)
        lt.update(ft, t)
        lt.update(gpi, t + 1e-4)
    st = lt.state(10.45)
    assert not isinstance(st, str)
    truth = BOAT.state(10.45)
    # FOLLOW_TARGET carries float32 rates and accelerations: ~1e-7 relative
    assert abs(st.omega_T[2] - 0.01) < 1e-8
    # the acceleration is held from the last sample (10.4 s): the boat's, as float32
    np.testing.assert_allclose(st.acceleration, BOAT.state(10.4).acceleration, atol=1e-7)
    # the prediction 50 ms ahead: positions are 1e-7 deg (1.1 cm) apart at most, plus mm of
    # altitude (FOLLOW_TARGET's is a float32 metre value)
    np.testing.assert_allclose(st.position, truth.position, atol=0.02)


def test_global_position_is_used_once_follow_target_is_stale():
    """Without a fresh FOLLOW_TARGET (older than the timeout) GLOBAL_POSITION_INT moves the
    target again: a feed that falls back to GLOBAL_POSITION_INT alone is still followed."""
    lt = _target()
    ft, _ = _frames(10.0)
    lt.update(ft, 10.0)
    t = 10.0 + TIMEOUT_S + 0.1
    _, gpi = _frames(t)
    lt.update(gpi, t)
    st = lt.state(t)
    assert not isinstance(st, str)
    assert st.t == t
    # GLOBAL_POSITION_INT: 1e-7 deg, 1 mm, 1 cm/s
    np.testing.assert_allclose(st.position, BOAT.state(t).position, atol=0.02)
    np.testing.assert_allclose(st.velocity, BOAT.state(t).velocity, atol=0.01)


def test_follow_target_without_turn_state_does_not_shadow_global_position():
    """A FOLLOW_TARGET with position and velocity only is not richer than GLOBAL_POSITION_INT:
    the later GLOBAL_POSITION_INT still updates the state."""
    lt = _target()
    mav = dialect.MAVLink(None, srcSystem=2, srcComponent=1)
    lat, lon, alt = ned_to_geodetic(np.zeros(3), *ORIGIN)
    ft = mav.decode(
        bytearray(mav.follow_target_encode(
            10000, 3, int(round(lat * 1e7)), int(round(lon * 1e7)), float(alt),
            [3.0, 0.0, 0.0], [0.0] * 3, [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3, 0,
        ).pack(mav))
    )  # fmt: skip
    lt.update(decode_follow_target(ft), 10.0)
    _, gpi = _frames(10.5)
    lt.update(gpi, 10.5)
    st = lt.state(10.5)
    assert not isinstance(st, str)
    assert st.t == 10.5
