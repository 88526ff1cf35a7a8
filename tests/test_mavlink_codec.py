"""codec: units, frames and rejection of malformed values; modes tables."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpf_mavlink.core import frames
from mpf_mavlink.mavlink import codec, encode, read_tlog
from mpf_mavlink.mavlink import dialect as mavlink
from mpf_mavlink.mavlink.modes import (
    Flavour,
    flavour_from_heartbeat,
    is_offboard,
    mode_name,
    px4_custom_mode,
    px4_decode_custom_mode,
)

# A real ArduPlane SITL recording kept in the repository (provenance: tests/data/README.md).
SHARED_TLOG = str(Path(__file__).resolve().parent / "data" / "arduplane-quadplane-sitl-vtol.tlog")
MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)


def wire(msg):
    """Pack with MAVLink 2 and parse back, as a peer would see it (float32 on the wire)."""
    parser = mavlink.MAVLink(None)
    out = parser.parse_char(msg.pack(MAV))
    assert out is not None and out.get_type() == msg.get_type()
    return out


# --- decoders ------------------------------------------------------------------------------
def test_attitude_euler_to_matrix_and_rates():
    m = wire(mavlink.MAVLink_attitude_message(2500, 0.1, -0.2, 3.0, 0.01, 0.02, -0.03))
    s = codec.decode_attitude(m)
    assert s.t_boot_s == 2.5  # 2500 ms
    np.testing.assert_allclose(s.R_B_N, frames.euler_to_matrix(0.1, -0.2, 3.0), atol=1e-6)
    np.testing.assert_allclose(s.rates_frd, [0.01, 0.02, -0.03], atol=1e-7)
    assert not s.R_B_N.flags.writeable  # frozen sample, frozen arrays


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-math.pi, math.pi), st.floats(-1.5, 1.5), st.floats(-math.pi, math.pi),
    st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0),
)  # fmt: skip
def test_scalar_attitude_decoders_match_frames(r, p, y, qw, qx, qy, qz):
    """The decoders' scalar matrices are frames' (Euler: to rounding; quaternion: bit for bit)."""
    m = SimpleNamespace(roll=r, pitch=p, yaw=y, rollspeed=0.1, pitchspeed=-0.2, yawspeed=0.3,
                        time_boot_ms=7)  # fmt: skip
    s = codec.decode_attitude(m)
    # Each entry is a sum of at most two products of three sines/cosines (each within 1 ulp of 1,
    # 1.1e-16, on any libm): <= 2 * (3 + 1) ulp + 1 for the sum ~ 1e-15; 2e-15 bounds it with room.
    np.testing.assert_allclose(s.R_B_N, frames.euler_to_matrix(r, p, y), rtol=0, atol=2e-15)
    assert s.rates_frd.tolist() == [0.1, -0.2, 0.3] and not s.rates_frd.flags.writeable
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if n < 0.5:
        return
    q = (qw / n, qx / n, qy / n, qz / n)
    m = SimpleNamespace(q1=q[0], q2=q[1], q3=q[2], q4=q[3], rollspeed=0.0, pitchspeed=0.0,
                        yawspeed=0.0, time_boot_ms=7)  # fmt: skip
    s = codec.decode_attitude_quaternion(m)
    assert np.array_equal(s.R_B_N, frames.quat_wxyz_to_matrix(q))
    assert not s.R_B_N.flags.writeable


def test_attitude_quaternion_w_first():
    # yaw +90 deg: q = (cos 45, 0, 0, sin 45); body x (nose) points East in NED
    c = math.cos(math.pi / 4)
    m = wire(
        mavlink.MAVLink_attitude_quaternion_message(10, c, 0.0, 0.0, c, 0.0, 0.0, 0.5, [0, 0, 0, 0])
    )
    s = codec.decode_attitude_quaternion(m)
    np.testing.assert_allclose(s.R_B_N @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-6)
    assert s.rates_frd[2] == pytest.approx(0.5)
    assert s.source == "ATTITUDE_QUATERNION"


@pytest.mark.parametrize(
    "q",
    [(0.0, 0.0, 0.0, 0.0), (math.nan, 0, 0, 1), (0.5, 0.0, 0.0, 0.0), (math.inf, 0, 0, 0)],
    ids=["zero-norm", "nan", "half-norm", "inf"],
)
def test_attitude_quaternion_rejects_non_unit(q):
    m = mavlink.MAVLink_attitude_quaternion_message(10, *q, 0.0, 0.0, 0.0, [0, 0, 0, 0])
    assert codec.decode_attitude_quaternion(m) is None


def test_attitude_rejects_nan_and_absurd_rates():
    assert (
        codec.decode_attitude(mavlink.MAVLink_attitude_message(1, math.nan, 0, 0, 0, 0, 0)) is None
    )
    # 100 rad/s > MAX_RATE_RAD_S = 50
    assert codec.decode_attitude(mavlink.MAVLink_attitude_message(1, 0, 0, 0, 100.0, 0, 0)) is None


def test_local_position_ned():
    m = wire(mavlink.MAVLink_local_position_ned_message(1000, 10.0, -20.0, -100.0, 15.0, 2.0, -1.0))
    s = codec.decode_local_position_ned(m)
    np.testing.assert_allclose(s.pos_ned, [10, -20, -100])
    np.testing.assert_allclose(s.vel_ned, [15, 2, -1])
    bad = mavlink.MAVLink_local_position_ned_message(1000, 0, 0, 0, math.nan, 0, 0)
    assert codec.decode_local_position_ned(bad) is None
    fast = mavlink.MAVLink_local_position_ned_message(1000, 0, 0, 0, 250.0, 0, 0)  # > 200 m/s
    assert codec.decode_local_position_ned(fast) is None


def test_global_position_int_units():
    # lat/lon degE7, alt/relative_alt mm, v cm/s, hdg cdeg
    m = wire(mavlink.MAVLink_global_position_int_message(
        5000, 473977420, 85455940, 584090, 100000, 1500, -200, 50, 27000))  # fmt: skip
    s = codec.decode_global_position_int(m)
    assert (s.lat_deg, s.lon_deg) == pytest.approx((47.397742, 8.545594), abs=1e-9)
    assert (s.alt_amsl_m, s.rel_alt_m) == pytest.approx((584.09, 100.0))
    np.testing.assert_allclose(s.vel_ned, [15.0, -2.0, 0.5])
    assert s.heading_rad == pytest.approx(math.radians(270.0))
    assert s.src_system == 1


@pytest.mark.parametrize(
    "lat,lon,vx",
    [(910000000, 0, 0), (100, 1810000000, 0), (0, 0, 0), (473977420, 85455940, 30000)],
    ids=["lat>90", "lon>180", "no-fix-0-0", "300m/s"],
)
def test_global_position_int_rejects_absurd(lat, lon, vx):
    m = mavlink.MAVLink_global_position_int_message(1, lat, lon, 500000, 0, vx, 0, 0, 65535)
    assert codec.decode_global_position_int(m) is None


def test_vfr_hud_throttle_percent_to_fraction():
    s = codec.decode_vfr_hud(wire(mavlink.MAVLink_vfr_hud_message(18.5, 20.0, 90, 55, 600.0, 1.5)))
    assert s.throttle_frac == pytest.approx(0.55)
    assert s.heading_rad == pytest.approx(math.pi / 2)
    assert (s.airspeed_m_s, s.groundspeed_m_s, s.climb_m_s) == pytest.approx((18.5, 20.0, 1.5))
    assert (
        codec.decode_vfr_hud(mavlink.MAVLink_vfr_hud_message(math.inf, 20, 90, 55, 600, 0)) is None
    )


@pytest.mark.parametrize(
    "direction,speed,speed_z,expected",
    [
        (0.0, 10.0, 0.0, (-10.0, 0.0, 0.0)),  # from the north -> air moves south
        (90.0, 5.0, 0.0, (0.0, -5.0, 0.0)),  # from the east -> air moves west
        (225.0, math.sqrt(2), 0.0, (1.0, 1.0, 0.0)),  # from the south-west -> toward NE
        (180.0, 5.0, 3.0, (4.0, 0.0, 3.0)),  # |w| = 5 in 3-D, 3 down -> 4 horizontal, north
    ],
)
def test_ardupilot_wind_from_direction(direction, speed, speed_z, expected):
    s = codec.decode_wind(mavlink.MAVLink_wind_message(direction, speed, speed_z))
    np.testing.assert_allclose(s.wind_ned, expected, atol=1e-9)
    assert s.source == "WIND"


def test_px4_wind_cov_is_already_ned_and_nan_vertical_means_zero():
    m = mavlink.MAVLink_wind_cov_message(123_000_000, 3.0, 4.0, math.nan, 0, 0, 0, 0, 0)
    s = codec.decode_wind_cov(m)
    np.testing.assert_allclose(s.wind_ned, [3.0, 4.0, 0.0])
    assert s.t_boot_s == 123.0
    assert (
        codec.decode_wind_cov(mavlink.MAVLink_wind_cov_message(1, math.nan, 4, 0, 0, 0, 0, 0, 0))
        is None
    )


def test_home_position():
    m = wire(mavlink.MAVLink_home_position_message(
        -353632620, 1491652300, 584000, 1.0, 2.0, -3.0, [1, 0, 0, 0], 0, 0, 0))  # fmt: skip
    s = codec.decode_home_position(m)
    assert (s.lat_deg, s.lon_deg, s.alt_amsl_m) == pytest.approx((-35.363262, 149.16523, 584.0))
    np.testing.assert_allclose(s.pos_ned, [1, 2, -3])


def test_heartbeat_and_modes_px4():
    cm = px4_custom_mode(4, 3)  # AUTO.LOITER = (4 << 16) | (3 << 24) = 262144 + 50331648
    assert cm == 50593792
    assert px4_decode_custom_mode(cm) == (4, 3)
    hb = codec.decode_heartbeat(wire(mavlink.MAVLink_heartbeat_message(1, 12, 129, cm, 4, 3)))
    assert hb.armed is True  # 129 = 128 armed | 1 custom mode
    assert flavour_from_heartbeat(hb) is Flavour.PX4
    assert mode_name(Flavour.PX4, hb) == "AUTO.LOITER"
    assert not is_offboard("px4", hb)
    off = codec.decode_heartbeat(mavlink.MAVLink_heartbeat_message(1, 12, 1, 6 << 16, 4, 3))
    assert mode_name("px4", off) == "OFFBOARD" and is_offboard("px4", off)


@pytest.mark.parametrize(
    "number,name,offboard",
    [(15, "GUIDED", True), (1, "CIRCLE", False), (18, "QHOVER", False), (21, "QRTL", False),
     (99, "MODE(99)", False)],
)  # fmt: skip
def test_heartbeat_and_modes_arduplane(number, name, offboard):
    hb = codec.decode_heartbeat(mavlink.MAVLink_heartbeat_message(1, 3, 1, number, 4, 3))
    assert flavour_from_heartbeat(hb) is Flavour.ARDUPILOT
    assert mode_name(Flavour.ARDUPILOT, hb) == name
    assert is_offboard(Flavour.ARDUPILOT, hb) is offboard


def test_custom_mode_flag_clear_means_not_offboard():
    hb = codec.decode_heartbeat(mavlink.MAVLink_heartbeat_message(1, 3, 0, 15, 4, 3))
    assert not is_offboard("ardupilot", hb)  # GUIDED's number without the custom-mode flag


def test_command_ack():
    a = codec.decode_command_ack(mavlink.MAVLink_command_ack_message(176, 0))
    assert (a.command, a.accepted, a.result_name) == (176, True, "MAV_RESULT_ACCEPTED")
    d = codec.decode_command_ack(mavlink.MAVLink_command_ack_message(400, 4))
    assert (d.accepted, d.result_name) == (False, "MAV_RESULT_FAILED")


def _ft(caps, lat=473977420, lon=85455940, vel=(1, 2, 0), acc=(0, 0, 0), q=(1, 0, 0, 0)):
    return mavlink.MAVLink_follow_target_message(
        1500, caps, lat, lon, 500.0, list(vel), list(acc), list(q), [0, 0, 0.1], [4, 4, 9], 0
    )


def test_follow_target_capability_bits():
    s = codec.decode_follow_target(wire(_ft(caps=3)))  # position + velocity
    assert s.t_s == 1.5 and s.alt_amsl_m == 500.0
    np.testing.assert_allclose(s.vel_ned, [1, 2, 0])
    assert s.acc_ned is None and s.R_B_N is None  # bits 2, 3 clear
    s8 = codec.decode_follow_target(_ft(caps=1 | 8))
    np.testing.assert_allclose(s8.R_B_N, np.eye(3))
    assert s8.rates_frd[2] == pytest.approx(0.1)
    assert codec.decode_follow_target(_ft(caps=1 | 8, q=(0, 0, 0, 0))) is None  # zero-norm q


def test_follow_target_zero_caps_means_infer_from_nonzero_fields():
    s = codec.decode_follow_target(_ft(caps=0, acc=(0, 0, 0)))
    assert s.vel_ned is not None  # vel (1, 2, 0) is not all zero
    assert s.acc_ned is None  # all zero = unknown
    assert codec.decode_follow_target(_ft(caps=0, lat=0, lon=0)) is None  # no position


def test_decode_dispatch_and_unknown_type():
    assert codec.decode(mavlink.MAVLink_wind_message(0, 1, 0)).source == "WIND"
    assert codec.decode(mavlink.MAVLink_sys_status_message(*([0] * 13))) is None


# --- property: never raise, never non-finite -------------------------------------------------
FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.sampled_from([0.0, -0.0, 1e30, -1e30, math.nan, math.inf]),
)


def _finite_sample(s) -> bool:
    for v in vars(s).values():
        if isinstance(v, np.ndarray) and not np.all(np.isfinite(v)):
            return False
        if isinstance(v, float) and not math.isfinite(v):
            return False
    return True


@settings(max_examples=150, deadline=None)
@given(
    vals=st.lists(FLOATS, min_size=7, max_size=7),
    ints=st.lists(st.integers(-(2**31), 2**31 - 1), min_size=9, max_size=9),
)
def test_decoders_never_raise_nor_emit_non_finite(vals, ints):
    a, b, c, d, e, f, g = vals
    fakes = {
        "ATTITUDE": SimpleNamespace(
            time_boot_ms=abs(ints[0]), roll=a, pitch=b, yaw=c, rollspeed=d, pitchspeed=e, yawspeed=f
        ),
        "ATTITUDE_QUATERNION": SimpleNamespace(
            time_boot_ms=1, q1=a, q2=b, q3=c, q4=d, rollspeed=e, pitchspeed=f, yawspeed=g
        ),
        "LOCAL_POSITION_NED": SimpleNamespace(time_boot_ms=1, x=a, y=b, z=c, vx=d, vy=e, vz=f),
        "GLOBAL_POSITION_INT": SimpleNamespace(
            time_boot_ms=1,
            lat=ints[1],
            lon=ints[2],
            alt=ints[3],
            relative_alt=ints[4],
            vx=ints[5] % 65536 - 32768,
            vy=0,
            vz=0,
            hdg=ints[6] % 65536,
        ),
        "VFR_HUD": SimpleNamespace(
            airspeed=a, groundspeed=b, heading=ints[7] % 360, throttle=ints[8] % 200, alt=c, climb=d
        ),
        "WIND": SimpleNamespace(direction=a, speed=b, speed_z=c),
        "WIND_COV": SimpleNamespace(time_usec=abs(ints[0]), wind_x=a, wind_y=b, wind_z=c),
        "FOLLOW_TARGET": SimpleNamespace(
            timestamp=1,
            est_capabilities=ints[8] % 16,
            lat=ints[1],
            lon=ints[2],
            alt=a,
            vel=[b, c, d],
            acc=[e, f, g],
            attitude_q=[a, b, c, d],
            rates=[e, f, g],
            position_cov=[0, 0, 0],
        ),
        "HOME_POSITION": SimpleNamespace(
            latitude=ints[1], longitude=ints[2], altitude=ints[3], x=a, y=b, z=c
        ),
    }
    for mtype, fake in fakes.items():
        fake.get_type = lambda t=mtype: t
        s = codec.decode(fake)
        assert s is None or _finite_sample(s), (mtype, s)


def test_real_tlog_decodes_finite_everywhere():
    res = read_tlog(SHARED_TLOG, types=sorted(codec.DECODED_TYPES))
    by_type: dict[str, int] = {}
    for _, m in res:
        s = codec.decode(m)
        if s is not None:
            assert _finite_sample(s)
            by_type[m.get_type()] = by_type.get(m.get_type(), 0) + 1
    # every ATTITUDE, WIND and VFR_HUD of the recording is sane (counts from the file itself)
    assert by_type["ATTITUDE"] == res.counts["ATTITUDE"] == 888
    assert by_type["WIND"] == res.counts["WIND"] == 810
    assert by_type["VFR_HUD"] == res.counts["VFR_HUD"] == 878
    assert by_type["HEARTBEAT"] == 199
    assert by_type["HOME_POSITION"] == 6


# --- encoders -------------------------------------------------------------------------------
def test_encode_rates_wire_values():
    m = wire(encode.encode_set_attitude_target_rates(MAV, 100, 1, 1, 0.5, -0.25, 0.125, 0.8))
    assert m.type_mask == 128 and list(m.q) == [1.0, 0.0, 0.0, 0.0]
    # exact in float32 (powers of two)
    assert (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate) == (0.5, -0.25, 0.125)
    assert m.thrust == pytest.approx(0.8, rel=1e-7)


@pytest.mark.parametrize(
    "args",
    [
        (math.nan, 0, 0, 0.5),
        (0, math.inf, 0, 0.5),
        (0, 0, 0, math.nan),
        (0, 0, 0, 1.5),
        (0, 0, 99.0, 0.5),
    ],
    ids=["nan-p", "inf-q", "nan-thrust", "thrust>1", "rate>50"],
)
def test_encode_rates_refuses_bad_values(args):
    with pytest.raises(ValueError):
        encode.encode_set_attitude_target_rates(MAV, 1, 1, 1, *args)


def test_encode_quat_normalises_and_refuses():
    m = wire(encode.encode_set_attitude_target_quat(MAV, 1, 1, 1, (2.0, 0.0, 0.0, 0.0), 0.3))
    assert (
        list(m.q) == [1.0, 0.0, 0.0, 0.0] and m.type_mask == 132
    )  # roll+pitch, rudder left to ArduPlane
    for q in [(0, 0, 0, 0), (math.nan, 0, 0, 1), (1, 0, 0)]:
        with pytest.raises(ValueError):
            encode.encode_set_attitude_target_quat(MAV, 1, 1, 1, q, 0.3)
    with pytest.raises(ValueError):
        encode.encode_set_attitude_target_quat(MAV, 1, 1, 1, (1, 0, 0, 0), 0.3, (0, math.nan, 0))


def test_encode_set_mode_px4_and_arduplane():
    m = wire(encode.encode_set_mode(MAV, 1, 1, Flavour.PX4, "OFFBOARD"))
    assert (m.command, m.param1, m.param2, m.param3) == (176, 1.0, 6.0, 0.0)
    m = wire(encode.encode_set_mode(MAV, 1, 1, "px4", "AUTO.LOITER"))
    assert (m.param2, m.param3) == (4.0, 3.0)
    m = wire(encode.encode_set_mode(MAV, 1, 1, "ardupilot", "GUIDED"))
    assert (m.command, m.param1, m.param2, m.param3) == (176, 1.0, 15.0, 0.0)
    with pytest.raises(ValueError):
        encode.encode_set_mode(MAV, 1, 1, "ardupilot", "WARP")


def test_encode_arm_and_companion_heartbeat():
    m = wire(encode.encode_arm(MAV, 1, 1, arm=True))
    assert (m.command, m.param1, m.param2) == (400, 1.0, 0.0)
    m = wire(encode.encode_arm(MAV, 1, 1, arm=False, force=True))
    assert (m.param1, m.param2) == (0.0, 21196.0)  # the force-disarm magic number
    hb = wire(encode.encode_companion_heartbeat(MAV))
    assert (hb.type, hb.autopilot) == (18, 8)  # ONBOARD_CONTROLLER, INVALID
