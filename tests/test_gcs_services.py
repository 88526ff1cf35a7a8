"""What a ground station asks of the SIL vehicle (sim/vehicle/gcs_services.py), driven with
pymavlink's own ground-station helpers (mavutil's parameter fetch, mavwp's mission loader) over
loopback UDP.

The vehicle is stepped frame by frame in the test's thread (as tests/test_sim_vehicle.py does):
loopback UDP delivers a datagram before ``sendto`` returns, so a request sent before a frame is
answered in that frame's datagrams. The expected answers are those of the real firmware (ArduPlane
4.7-dev SITL's own replies; PX4 v1.16 from its source and parameter reference).
"""

from __future__ import annotations

import math
import os
import struct

import numpy as np
import pytest

from mpf_mavlink.bridge.px4_fallback import PX4_FALLBACK_PARAMS

os.environ.setdefault("MAVLINK20", "1")
pytest.importorskip("pymavlink")

from pymavlink import mavwp  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: E402

from sim.vehicle.vehicle import SimVehicle  # noqa: E402
from tests.test_sim_vehicle import Gcs, ack_for, frames, free_port  # noqa: E402


def make(flavour: str, **kw):
    port = free_port()
    v = SimVehicle.build(
        flavour, f"udpin:127.0.0.1:{port}", plant="kinematic", trim_seconds=2.0, **kw
    )
    g = Gcs(port)
    frames(v, g, 2)
    return v, g


@pytest.fixture(params=["px4", "ardupilot"])
def vg(request):
    v, g = make(request.param)
    yield v, g
    g.close()
    v.close()


def px4_int(value: float) -> int:
    """PX4's byte-wise integer parameter encoding, decoded."""
    return struct.unpack("<i", struct.pack("<f", value))[0]


def wire(v, p) -> float:
    """A PARAM_VALUE's value as the flavour's ground station decodes it."""
    ints = (M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32)
    return float(px4_int(p.param_value)) if v.px4 and p.param_type in ints else p.param_value


# --------------------------------------------------------------------------- parameters
def test_param_fetch_all_streams_every_parameter_once_with_index_and_count(vg):
    v, g = vg
    g.c.param_fetch_all()  # pymavlink's PARAM_REQUEST_LIST
    frames(v, g, 2)
    pv = g.of("PARAM_VALUE")
    n = len(v.gcs.params)
    assert n >= 7  # the flavour's tunables (module docstring of sim.vehicle.gcs_services)
    assert len(pv) == n and {p.param_count for p in pv} == {n}
    assert sorted(p.param_index for p in pv) == list(range(n))
    for p in pv:  # what the GCS shows is the vehicle's value (float32 on the wire)
        assert wire(v, p) == pytest.approx(v.gcs.value_of(p.param_id), rel=1e-6)
    names = {p.param_id for p in pv}
    if v.px4:
        assert {"COM_OF_LOSS_T", "COM_OBL_RC_ACT", "NAV_LOITER_RAD", "FW_AIRSPD_TRIM"} <= names
        # every parameter the bridge reads before engaging (real PX4 has them all: a missing
        # one costs the bridge its re-asks, ~1.2 s of a real-time-paced hand-over)
        assert set(PX4_FALLBACK_PARAMS) <= names
    else:  # names as ArduPlane 4.7's own PARAM_REQUEST_LIST spells them
        assert {"WP_LOITER_RAD", "AIRSPEED_CRUISE", "MAV1_EXTRA1", "SIM_WIND_SPD"} <= names
    # pymavlink's own parameter store has the full set
    assert len(g.c.param_state[(1, 1)].params) == n


def test_param_read_by_name_and_index_and_unknown_is_silent(vg):
    v, g = vg
    name = "COM_OF_LOSS_T" if v.px4 else "GUIDED_TIMEOUT"
    g.c.mav.param_request_read_send(1, 1, name.encode(), -1)
    g.c.mav.param_request_read_send(1, 1, b"", 0)
    g.c.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1)
    frames(v, g, 2)
    pv = g.of("PARAM_VALUE")
    assert [p.param_id for p in pv] == [name, v.gcs.params[0].name]
    # ArduPilot answers a read by name with index 65535 (its SITL does), PX4 with the index
    assert pv[0].param_index == (v.gcs._by_name[name] if v.px4 else 65535)
    assert pv[1].param_index == 0


def test_param_set_echoes_and_changes_the_run():
    v, g = make("px4")
    try:
        g.c.param_set_send("NAV_LOITER_RAD", 150.0)
        g.c.param_set_send("COM_OF_LOSS_T", 2.5)
        # integer parameters travel byte-wise on PX4 (MAVProxy and QGC encode them so)
        g.c.mav.param_set_send(
            1,
            1,
            b"COM_OBL_RC_ACT",
            struct.unpack("<f", struct.pack("<i", 2))[0],
            M.MAV_PARAM_TYPE_INT32,
        )
        g.c.param_set_send("FW_AIRSPD_TRIM", 25.0)  # above FW_AIRSPD_MAX (20): clamped to it
        g.c.param_set_send("NAV_LOITER_RAD", float("nan"))  # not flyable: refused
        frames(v, g, 2)
        echo = {p.param_id: p for p in g.of("PARAM_VALUE")}
        assert echo["NAV_LOITER_RAD"].param_value == 150.0  # the NaN left the 150 in force
        assert (
            v.tun.loiter_radius == 150.0 and v.modes.hold_radius == 150.0
        )  # the hold flown takes it
        assert v.tun.com_of_loss_t == 2.5 and echo["COM_OF_LOSS_T"].param_value == 2.5
        assert v.tun.obl_rc_act == 2 and px4_int(echo["COM_OBL_RC_ACT"].param_value) == 2
        assert v.tun.cruise_airspeed == 20.0 and echo["FW_AIRSPD_TRIM"].param_value == 25.0
    finally:
        g.close()
        v.close()


def test_arduplane_param_set_wind_and_stream_rates():
    v, g = make("ardupilot")
    try:
        g.c.param_set_send("SIM_WIND_SPD", 5.0)
        g.c.param_set_send("SIM_WIND_DIR", 90.0)  # blowing FROM the east: air moves west
        g.c.param_set_send("MAV1_EXTRA1", 10.0)  # ATTITUDE at 10 Hz
        g.c.param_set_send("WP_LOITER_RAD", -5.0)  # out of range: refused, 80 echoed
        frames(v, g, 2)
        echo = {p.param_id: p for p in g.of("PARAM_VALUE")}
        assert echo["WP_LOITER_RAD"].param_value == 80.0 and v.tun.loiter_radius == 80.0
        # 2 s of frames: the plant flies in the new wind, ATTITUDE arrives at 10 Hz
        n0 = len(g.of("ATTITUDE"))
        frames(v, g, 100)
        wind = v.truth()["wind_ned"][-1]
        assert wind[0] == pytest.approx(0.0, abs=1e-9) and wind[1] == pytest.approx(-5.0)
        assert len(g.of("ATTITUDE")) - n0 == pytest.approx(20, abs=1)  # 10 Hz x 2 s
        assert echo["SIM_WIND_SPD"].param_value == pytest.approx(5.0)
    finally:
        g.close()
        v.close()


def test_arduplane_sim_wind_turb_sets_the_firmwares_random_wind():
    # the jsbsim plant has the firmware's random wind (sim/plant/sitl_turbulence.py): SIM_WIND_TURB
    # switches it on in flight, on top of the steady SIM_WIND_SPD / SIM_WIND_DIR
    pytest.importorskip("jsbsim")
    port = free_port()
    v = SimVehicle.build("ardupilot", f"udpin:127.0.0.1:{port}", plant="jsbsim", trim_seconds=1.0)
    g = Gcs(port)
    try:
        frames(v, g, 2)
        g.c.param_set_send("SIM_WIND_SPD", 6.0)
        g.c.param_set_send("SIM_WIND_DIR", 180.0)  # FROM the south: the air moves north
        g.c.param_set_send("SIM_WIND_TURB", 2.0)
        frames(v, g, 2)
        echo = {p.param_id: p for p in g.of("PARAM_VALUE")}
        assert echo["SIM_WIND_TURB"].param_value == pytest.approx(2.0)
        n0 = len(v.truth()["t"])
        frames(v, g, 100)
        w = v.truth()["wind_ned"][n0:] - [6.0, 0.0, 0.0]
        # about the steady wind, zero-mean, each step's spread ~0.5 m/s per horizontal axis at
        # 150 Hz (sitl_turbulence.expected_statistics): within a factor 2 over ~100 samples
        assert np.all(np.abs(w.mean(axis=0)[:2]) < 0.3)
        assert 0.25 < w[:, 0].std() < 1.0
    finally:
        g.close()
        v.close()


# --------------------------------------------------------------------------- missions
def test_mission_list_upload_download_and_refusal(vg):
    v, g = vg
    c = g.c
    c.waypoint_request_list_send()
    frames(v, g, 2)
    (count,) = g.of("MISSION_COUNT")
    home = not v.px4  # ArduPlane counts home as item 0 (its SITL answers 1 with no mission)
    assert count.count == (1 if home else 0)
    if home:
        c.mav.mission_request_int_send(1, 1, 0)
        frames(v, g, 2)
        (it,) = g.of("MISSION_ITEM_INT")
        assert it.x == round(v.home_lla[0] * 1e7) and it.y == round(v.home_lla[1] * 1e7)

    # upload a plain mission (pymavlink's loader) answering the vehicle's MISSION_REQUEST_INTs
    wp = mavwp.MAVWPLoader(target_system=1, target_component=1)
    lat, lon, _ = v.home_lla
    for i in range(3):
        wp.add(
            M.MAVLink_mission_item_int_message(
                1,
                1,
                i,
                M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                M.MAV_CMD_NAV_WAYPOINT,
                0,
                1,
                0,
                0,
                0,
                math.nan,
                int((lat + 0.001 * i) * 1e7),
                int(lon * 1e7),
                100.0,
            )
        )
    c.waypoint_count_send(wp.count())
    for _ in range(10):
        frames(v, g, 1)
        asked = g.of("MISSION_REQUEST_INT")
        for r in asked:
            c.mav.send(wp.wp(r.seq))
        g.msgs = [m for m in g.msgs if m.get_type() != "MISSION_REQUEST_INT"]
    (ack,) = g.of("MISSION_ACK")
    assert ack.type == M.MAV_MISSION_ACCEPTED
    assert [it.x for it in v.gcs.missions.items()] == [wp.wp(i).x for i in range(3)]

    # a command the vehicle does not store: refused with UNSUPPORTED, the stored mission stays
    g.msgs.clear()
    c.waypoint_count_send(1)
    frames(v, g, 1)
    c.mav.mission_item_int_send(
        1, 1, 0, M.MAV_FRAME_MISSION, M.MAV_CMD_DO_DIGICAM_CONTROL, 0, 1, 0, 0, 0, 0, 0, 0, 0
    )
    frames(v, g, 2)
    if home:  # ArduPilot's item 0 is home whatever it says: the upload completes
        assert g.of("MISSION_ACK")[-1].type == M.MAV_MISSION_ACCEPTED
    else:
        assert g.of("MISSION_ACK")[-1].type == M.MAV_MISSION_UNSUPPORTED
        assert len(v.gcs.missions.items()) == 3
    # fence and rally: empty, and not taken
    g.msgs.clear()
    c.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_FENCE)
    c.mav.mission_count_send(1, 1, 2, M.MAV_MISSION_TYPE_RALLY)
    frames(v, g, 2)
    assert g.of("MISSION_COUNT")[-1].count == 0
    assert g.of("MISSION_ACK")[-1].type == M.MAV_MISSION_UNSUPPORTED


# --------------------------------------------------------------------------- version, commands
def test_autopilot_version_unsupported_commands_and_ftp_nak(vg):
    v, g = vg
    c = g.c
    c.mav.command_long_send(
        1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0
    )
    c.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 0, 1, 0, 0, 0, 0, 0, 0)
    c.mav.command_long_send(1, 1, M.MAV_CMD_VIDEO_START_CAPTURE, 0, 0, 0, 0, 0, 0, 0, 0)
    c.mav.command_long_send(1, 1, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 600.0)
    c.mav.file_transfer_protocol_send(0, 1, 1, [7, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0] + [0] * 239)
    frames(v, g, 2)
    av = g.of("AUTOPILOT_VERSION")
    assert len(av) == 2  # one per request
    caps = av[0].capabilities
    assert (
        caps & M.MAV_PROTOCOL_CAPABILITY_MISSION_INT and caps & M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    )
    assert not caps & M.MAV_PROTOCOL_CAPABILITY_FTP  # it NAKs: do not invite clients to use it
    assert av[0].flight_sw_version >> 24 == (1 if v.px4 else 4)
    assert ack_for(g, M.MAV_CMD_REQUEST_MESSAGE).result == M.MAV_RESULT_ACCEPTED
    assert ack_for(g, M.MAV_CMD_VIDEO_START_CAPTURE).result == M.MAV_RESULT_UNSUPPORTED
    # NAV_TAKEOFF in the air: PX4 enters AUTO.TAKEOFF; ArduPlane answers FAILED (as its SITL)
    tk = ack_for(g, M.MAV_CMD_NAV_TAKEOFF).result
    assert tk == (M.MAV_RESULT_ACCEPTED if v.px4 else M.MAV_RESULT_FAILED)
    if v.px4:
        assert v.mode_name == "AUTO.TAKEOFF" and v.modes.alt_sp == pytest.approx(
            600.0 - v.home_lla[2]
        )
    (ftp,) = g.of("FILE_TRANSFER_PROTOCOL")
    p = bytes(ftp.payload)
    # seq + 1, NAK (129) of OpenFileRO (4), one data byte: FileNotFound (10)
    assert (int.from_bytes(p[0:2], "little"), p[3], p[4], p[5], p[12]) == (8, 129, 1, 4, 10)


def test_reposition_per_flavour(vg):
    v, g = vg
    c = g.c
    lat, lon, alt = v.home_lla
    # ArduPlane takes DO_REPOSITION as COMMAND_INT only (its SITL: COMMAND_LONG is UNSUPPORTED)
    c.mav.command_long_send(
        1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1, 1, 120, 0, lat + 0.01, lon, alt + 150
    )
    frames(v, g, 2)
    res = ack_for(g, M.MAV_CMD_DO_REPOSITION).result
    if not v.px4:
        assert res == M.MAV_RESULT_UNSUPPORTED
        return
    assert res == M.MAV_RESULT_ACCEPTED and v.mode_name == "AUTO.LOITER"
    # the hold is about the point (0.01 deg north = 1112 m), at its altitude, radius 120 m
    assert v.modes.center[0] == pytest.approx(1112.0, rel=0.01) and abs(v.modes.center[1]) < 1.0
    # (NED down at 1.1 km includes the earth's curvature, d^2 / 2R = 0.1 m)
    assert v.modes.alt_sp == pytest.approx(150.0 - 1112.0**2 / 2 / 6.371e6, abs=0.01)
    assert v.modes.hold_radius == 120.0


def test_gps_raw_int_and_sys_status(vg):
    v, g = vg
    frames(v, g, 60)  # 1.2 s: both are 1 Hz streams
    gps, gpi = g.of("GPS_RAW_INT")[-1], g.of("GLOBAL_POSITION_INT")[-1]
    assert gps.fix_type == 3 and gps.satellites_visible >= 6
    # the same fix as GLOBAL_POSITION_INT within a frame's flight (16 m/s x 1 s < 2e-4 deg)
    assert abs(gps.lat - gpi.lat) < 2000 and abs(gps.lon - gpi.lon) < 3000
    ss = g.of("SYS_STATUS")[-1]
    # no fence breach: ArduPilot reports the fence it does not have as healthy
    assert ss.onboard_control_sensors_health & M.MAV_SYS_STATUS_GEOFENCE
    assert not ss.onboard_control_sensors_present & M.MAV_SYS_STATUS_GEOFENCE


def test_malformed_requests_never_stop_the_vehicle(vg):
    v, g = vg
    c = g.c
    nan = math.nan
    # NaN where the autopilot reads an integer: DENIED at once (PX4's answer to bad parameters)
    c.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, nan, 0, 0, 0, 0, 0, 0)
    c.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, nan, nan, 0, 0, 0, 0, 0)
    c.mav.command_long_send(1, 1, M.MAV_CMD_DO_REPOSITION, 0, 0, nan, 0, 0, 47.4, 8.5, nan)
    c.mav.param_set_send(
        1, 1, b"COM_OF_LOSS_T" if v.px4 else b"GUIDED_TIMEOUT", math.inf, M.MAV_PARAM_TYPE_REAL32
    )
    c.mav.mission_item_send(1, 1, 0, M.MAV_FRAME_GLOBAL, 16, 0, 1, 0, 0, 0, 0, nan, nan, 100)
    c.mav.file_transfer_protocol_send(0, 1, 1, [255] * 251)
    frames(v, g, 3)
    assert ack_for(g, M.MAV_CMD_REQUEST_MESSAGE).result == M.MAV_RESULT_DENIED
    assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_DENIED
    # the refused PARAM_SET echoes the value in force
    name = "COM_OF_LOSS_T" if v.px4 else "GUIDED_TIMEOUT"
    (echo,) = [p for p in g.of("PARAM_VALUE") if p.param_id == name]
    assert echo.param_value == v.gcs.value_of(name) and math.isfinite(echo.param_value)
    t0 = v.t
    frames(v, g, 5)
    assert v.t > t0  # still flying
