"""The simulated MAVLink vehicle (sim/vehicle/vehicle.py) seen from a pymavlink ground station on
loopback UDP.

Most tests drive the vehicle frame by frame with ``step_once()`` in the test's own thread
(loopback UDP delivers a datagram before ``sendto`` returns, so the exchange is deterministic);
the clock tests run it in its thread. Every threshold has its reason next to it.
"""

from __future__ import annotations

import math
import os
import socket
import time

import numpy as np
import pytest

os.environ.setdefault("JSBSIM_DEBUG", "0")
os.environ.setdefault("MAVLINK20", "1")
pytest.importorskip("jsbsim")
pytest.importorskip("pymavlink")

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: E402

from mpf_mavlink.core.frames import geodetic_to_ned, matrix_to_quat_wxyz  # noqa: E402
from mpf_mavlink.core.target import ConstantTurn  # noqa: E402
from mpf_mavlink.mavlink.modes import px4_custom_mode  # noqa: E402
from mpf_mavlink.quaternion import quat_of_euler  # noqa: E402
from sim.plant.kinematic_plant import KinematicMavPlant, ned_to_geodetic_fast  # noqa: E402
from sim.vehicle.clock import LockstepClock  # noqa: E402
from sim.vehicle.vehicle import SimVehicle  # noqa: E402

PX4_LOITER = px4_custom_mode(4, 3)  # (4 << 16) | (3 << 24) = 0x03040000
PX4_OFFBOARD = px4_custom_mode(6)  # 6 << 16 = 0x00060000
RATES_THRUST = 128  # type_mask: attitude ignored -> body rates + thrust
DEG = math.pi / 180.0


def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class Gcs:
    """A pymavlink ground station / bridge stand-in on udpout, collecting what it receives."""

    def __init__(self, port: int, sysid: int = 255, compid: int = 190):
        self.c = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}",
            source_system=sysid,
            source_component=compid,
            dialect="ardupilotmega",
        )
        self.msgs: list = []
        self.hello()

    def hello(self) -> None:
        self.c.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def read(self) -> list:
        new = []
        while True:
            m = self.c.recv_msg()
            if m is None:
                break
            if m.get_type() != "BAD_DATA":
                new.append(m)
        self.msgs += new
        return new

    def of(self, mtype: str, src: int | None = 1) -> list:
        return [
            m
            for m in self.msgs
            if m.get_type() == mtype and (src is None or m.get_srcSystem() == src)
        ]

    def set_mode(self, p2: float, p3: float = 0.0) -> None:
        self.c.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, p2, p3, 0, 0, 0, 0)

    def rates(
        self,
        p: float,
        q: float = 0.0,
        r: float = 0.0,
        thrust: float = 0.25,
        mask: int = RATES_THRUST,
    ):
        self.c.mav.set_attitude_target_send(0, 1, 1, mask, [1.0, 0.0, 0.0, 0.0], p, q, r, thrust)

    def attitude(
        self, roll: float, pitch: float, yaw: float = 0.0, thrust: float = 0.3, mask: int = 0
    ):
        q = list(quat_of_euler(roll, pitch, yaw))
        self.c.mav.set_attitude_target_send(0, 1, 1, mask, q, 0.0, 0.0, 0.0, thrust)

    def close(self) -> None:
        self.c.close()


def frames(v: SimVehicle, g: Gcs, n: int, each=None) -> None:
    """n vehicle frames; the GCS reads after each and may answer (each(i))."""
    for i in range(n):
        v.step_once()
        g.read()
        if each is not None:
            each(i)


def ack_for(g: Gcs, command: int):
    acks = [m for m in g.of("COMMAND_ACK") if m.command == command]
    return acks[-1] if acks else None


@pytest.fixture
def px4():
    port = free_port()
    v = SimVehicle.build("px4", f"udpin:127.0.0.1:{port}")
    g = Gcs(port)
    yield v, g
    g.close()
    v.close()


@pytest.fixture
def ardu():
    port = free_port()
    v = SimVehicle.build("ardupilot", f"udpin:127.0.0.1:{port}")
    g = Gcs(port)
    yield v, g
    g.close()
    v.close()


# --------------------------------------------------------------------------- identity
@pytest.mark.parametrize(
    "flavour, autopilot, custom_mode, mode_string",
    [
        ("px4", M.MAV_AUTOPILOT_PX4, PX4_LOITER, "LOITER"),  # power-on: Hold = AUTO.LOITER
        ("ardupilot", M.MAV_AUTOPILOT_ARDUPILOTMEGA, 12, "LOITER"),  # ArduPlane LOITER = 12
    ],
)
def test_heartbeat_identity_and_mode(flavour, autopilot, custom_mode, mode_string):
    port = free_port()
    with SimVehicle.build(flavour, f"udpin:127.0.0.1:{port}") as v:
        g = Gcs(port)
        frames(v, g, 60)  # 1.2 s: at least one 1 Hz heartbeat
        hbs = g.of("HEARTBEAT")
        assert len(hbs) >= 1
        hb = hbs[-1]
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        assert hb.type == M.MAV_TYPE_FIXED_WING
        assert hb.autopilot == autopilot
        assert hb.custom_mode == custom_mode
        # custom mode enabled and armed (the vehicle starts flying, armed)
        assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        # pymavlink's own decoder agrees (independent check of the encoding)
        assert mavutil.mode_string_v10(hb) == mode_string
        g.close()


def test_starts_trimmed_near_requested_point_and_loiters():
    port = free_port()
    with SimVehicle.build(
        "px4", f"udpin:127.0.0.1:{port}", position_ned=(200.0, -100.0, -120.0), heading=math.pi / 2
    ) as v:
        tr = v.truth()
        # the trim flight starts behind the point (V * trim_seconds) and ends within a few metres
        assert np.linalg.norm(tr["position_ned"][0] - [200.0, -100.0, -120.0]) < 5.0
        assert abs(tr["airspeed"][0] - 16.0) < 0.3  # trimmed at the cruise airspeed
        for _ in range(1500):  # 30 s of Hold
            v.step_once()
        tr = v.truth()
        c = tr["position_ned"][0, :2]
        r = np.hypot(*(tr["position_ned"][-250:, :2] - c).T)
        assert 70.0 < r.min() and r.max() < 92.0  # 80 m loiter circle about the entry point
        assert np.all(np.abs(tr["position_ned"][:, 2] + 120.0) < 3.0)  # altitude held at entry


# --------------------------------------------------------------------------- PX4 offboard
def test_px4_offboard_rules_rates_and_loss(px4):
    v, g = px4
    frames(v, g, 5)
    # 1. no setpoints yet: OFFBOARD refused (PX4 commander answers TEMPORARILY_REJECTED)
    g.set_mode(6)
    frames(v, g, 2)
    ack = ack_for(g, M.MAV_CMD_DO_SET_MODE)
    assert ack is not None and ack.result == M.MAV_RESULT_TEMPORARILY_REJECTED
    assert ack.target_system == 255 and ack.target_component == 190  # answered to the sender
    assert v.custom_mode == PX4_LOITER

    # 2. NaN setpoints are dropped and do not count as an offboard signal
    frames(v, g, 60, lambda i: g.rates(float("nan"), 0.0, 0.0))
    assert (
        v.autopilot.setpoints.dropped["nonfinite"] == 59
    )  # the 60th is answered after the last frame: still queued
    g.msgs.clear()
    g.set_mode(6)
    frames(v, g, 2)
    assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_TEMPORARILY_REJECTED

    # 3. 0.8 s of 50 Hz level setpoints: still < 1 s of stream -> refused
    frames(v, g, 40, lambda i: g.rates(0.0))
    g.msgs.clear()
    g.set_mode(6)
    frames(v, g, 1, lambda i: g.rates(0.0))
    assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_TEMPORARILY_REJECTED
    # ... 0.3 s more (>= 1 s in all): accepted, heartbeat shows OFFBOARD
    frames(v, g, 15, lambda i: g.rates(0.0))
    g.msgs.clear()
    g.set_mode(6)
    frames(v, g, 55, lambda i: g.rates(0.0))
    assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED
    assert v.custom_mode == PX4_OFFBOARD
    assert g.of("HEARTBEAT")[-1].custom_mode == PX4_OFFBOARD
    assert mavutil.mode_string_v10(g.of("HEARTBEAT")[-1]) == "OFFBOARD"

    # 4. body rates roll the aircraft: +0.4 rad/s for 0.4 s, then -0.4 rad/s for 0.8 s
    g.msgs.clear()
    frames(v, g, 20, lambda i: g.rates(0.4))
    att = g.of("ATTITUDE")
    assert att[-1].rollspeed > 0.3  # roll rate follows p (sign and ~size)
    roll_after_right = att[-1].roll
    assert roll_after_right > 5 * DEG  # ~0.4 rad/s x 0.3 s after the rise
    g.msgs.clear()
    frames(v, g, 40, lambda i: g.rates(-0.4))
    att = g.of("ATTITUDE")
    assert att[-1].rollspeed < -0.3
    assert att[-1].roll < roll_after_right - 10 * DEG

    # 5. "throttle ignore" (64): PX4 fixed-wing gets ZERO throttle
    frames(v, g, 25, lambda i: g.rates(0.0, thrust=0.8, mask=RATES_THRUST | 64))
    assert v.plant.state().throttle < 0.01
    frames(v, g, 10, lambda i: g.rates(0.0, thrust=0.3))
    assert abs(v.plant.state().throttle - 0.3) < 0.01  # thrust passes through to the throttle

    # 6. setpoints stop: Hold after COM_OF_LOSS_T = 1.0 s of sim time, with a STATUSTEXT
    t_last = v.t  # the last setpoint was applied at the start of the last frame (<= v.t)
    g.msgs.clear()
    frames(v, g, 45)  # 0.9 s
    assert v.custom_mode == PX4_OFFBOARD
    frames(v, g, 15)  # 1.2 s in all
    assert v.custom_mode == PX4_LOITER
    t_switch = [t for t, name in v.modes.changes if name == "AUTO.LOITER"][-1]
    assert (
        1.0 - 0.02 <= t_switch - t_last <= 1.0 + 0.03
    )  # within one 20 ms frame of the 1 s timeout
    assert any("offboard" in m.text.lower() for m in g.of("STATUSTEXT"))
    frames(v, g, 50)
    assert g.of("HEARTBEAT")[-1].custom_mode == PX4_LOITER


# --------------------------------------------------------------------------- ArduPlane guided
def test_ardupilot_guided_attitude_timeout_and_loiter(ardu):
    v, g = ardu
    frames(v, g, 5)
    g.set_mode(15)
    frames(v, g, 2)
    assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED
    assert v.custom_mode == 15
    center = np.array(v.modes.center)
    t0 = v.t
    roll_cmd, pitch_cmd = 30 * DEG, 3 * DEG
    frames(v, g, 150, lambda i: g.attitude(roll_cmd, pitch_cmd, 0.0, thrust=0.3))  # 3 s at 50 Hz
    tr = v.truth()
    t, roll = tr["t"] - t0, tr["euler"][:, 0]
    hit = t[np.abs(roll - roll_cmd) < 2 * DEG]
    assert (
        hit.size and hit[0] < 1.5
    )  # 30 deg reached (within 2 deg) in < 1.5 s (ArduPlane SITL ~1 s)
    held = roll[(t > 1.5) & (t <= 3.0)]
    assert np.all(np.abs(held - roll_cmd) < 1.5 * DEG)
    # commands stop: the attitude is held GUIDED_TIMEOUT = 3 s, then ArduPlane's own guidance
    t_stop = v.t
    frames(v, g, 140)  # 2.8 s
    tr = v.truth()
    sel = tr["t"] > t_stop + 0.2
    assert np.all(np.abs(tr["euler"][sel, 0] - roll_cmd) < 1.5 * DEG)  # still held at 2.8 s
    frames(v, g, 1250)  # 25 s more: loiter about the GUIDED entry point, mode stays GUIDED
    tr = v.truth()
    r = np.hypot(*(tr["position_ned"][-250:, :2] - center).T)
    assert 65.0 < r.min() and r.max() < 95.0  # on the 80 m loiter circle
    assert g.of("HEARTBEAT")[-1].custom_mode == 15
    assert v.custom_mode == 15


def test_ardupilot_attitude_target_dropped_outside_guided(ardu):
    v, g = ardu
    g.set_mode(6)  # FBWB: wings level, course and altitude hold
    frames(v, g, 100)
    assert v.custom_mode == 6
    g.msgs.clear()
    frames(v, g, 75, lambda i: g.attitude(30 * DEG, 0.0))
    assert (
        v.autopilot.setpoints.dropped["not_guided"] == 74
    )  # the 75th answers the last frame: not yet read
    assert np.max(np.abs(v.truth()["euler"][-75:, 0])) < 3 * DEG  # the 30 deg target had no effect
    # dropped without a reply: the only acks are none (the mode change ack was cleared)
    assert g.of("COMMAND_ACK") == []


def test_ardupilot_mode_refusal_and_yaw_to_rudder(ardu):
    v, g = ardu
    g.set_mode(99)  # no such ArduPlane mode
    frames(v, g, 2)
    assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_FAILED
    g.set_mode(15)
    # yaw 22.5 deg in the quaternion -> half rudder (ArduPlane: +-45 deg = +-4500 cdeg = full)
    frames(v, g, 3, lambda i: g.attitude(0.0, 0.0, 22.5 * DEG))
    st = v._st
    assert abs(v.autopilot._guided(st)[2] - 0.5) < 1e-6  # q travels as float32
    # type_mask 134: roll alone from the quaternion (pitch, yaw not forced)
    frames(v, g, 1)  # consume the message answering the last frame
    v.autopilot.setpoints.forced_t = [None, None, None, None]
    frames(v, g, 1, lambda i: g.attitude(10 * DEG, 20 * DEG, 30 * DEG, mask=134))
    frames(v, g, 1)
    assert (
        v.autopilot.setpoints.forced_t[0] is not None
        and v.autopilot.setpoints.forced_t[1] is None
        and v.autopilot.setpoints.forced_t[2] is None
    )
    assert abs(v.autopilot.setpoints.forced[0] - 10 * DEG) < 1e-6


# --------------------------------------------------------------------------- target system
def test_follow_target_from_system_2_matches_motion():
    port = free_port()
    target = ConstantTurn(position=(150.0, -40.0, 0.0), speed=4.0, heading=0.6, turn_rate=0.05)
    with SimVehicle.build(
        "ardupilot", f"udpin:127.0.0.1:{port}", plant="kinematic", target=target
    ) as v:
        g = Gcs(port)
        frames(v, g, 60)
        ft = g.of("FOLLOW_TARGET", src=2)
        assert len(ft) >= 5  # 10 Hz for 1.2 s
        assert all(m.get_srcComponent() == 1 for m in ft)
        hb2 = g.of("HEARTBEAT", src=2)
        assert hb2 and hb2[-1].type == M.MAV_TYPE_GROUND_ROVER
        gpi2 = g.of("GLOBAL_POSITION_INT", src=2)
        assert len(gpi2) == len(ft)
        boot_offset = v.time_boot_s - v.t  # FOLLOW_TARGET.timestamp is the vehicle boot clock (ms)
        lat0, lon0, alt0 = v.home_lla
        for m in ft[1:]:
            ts = target.state(m.timestamp / 1000.0 - boot_offset)
            assert m.est_capabilities == 15  # position | velocity | acceleration | attitude+rates
            ned = geodetic_to_ned(m.lat / 1e7, m.lon / 1e7, m.alt, lat0, lon0, alt0)
            assert np.linalg.norm(ned - ts.position) < 0.02  # degE7 quantisation ~1.1 cm
            assert np.allclose(m.vel, ts.velocity, atol=1e-5)  # float32
            assert np.allclose(m.acc, ts.acceleration, atol=1e-5)
            assert np.allclose(m.attitude_q, matrix_to_quat_wxyz(ts.R_T_I), atol=1e-6)
            assert np.allclose(m.rates, ts.omega_T, atol=1e-6)
        tr = v.truth()
        assert np.allclose(tr["target_position"][-1], target.state(tr["t"][-1]).position)
        g.close()


# --------------------------------------------------------------------------- timestamps, latency
def test_telemetry_timestamps_monotonic_in_sim_time(px4):
    """PX4's onboard link at power-on (MAVLINK_MODE_ONBOARD defaults): ATTITUDE 100 Hz and
    GLOBAL_POSITION_INT 50 Hz, both capped at one per 20 ms frame; WIND_COV 10 Hz."""
    v, g = px4
    frames(v, g, 100)
    att = [m.time_boot_ms for m in g.of("ATTITUDE")]
    gpi = [m.time_boot_ms for m in g.of("GLOBAL_POSITION_INT")]
    assert len(att) >= 98  # one per 20 ms frame (the first frame may precede the GCS hello)
    assert np.all(np.diff(att) == 20)  # 50 Hz exactly, in sim time
    assert np.all(np.diff(gpi) == 20)  # 50 Hz
    assert att[-1] == round(v.time_boot_s * 1000)  # stamped with the sim boot clock
    assert 19 <= len(g.of("WIND_COV")) <= 20  # 10 Hz: 2 s -> 20 (the first may precede the hello)
    assert len(g.of("WIND")) == 0
    usec = [m.time_usec for m in g.of("WIND_COV")]
    assert np.all(np.diff(usec) == 100_000)


def test_arduplane_stock_rates_and_both_rate_requests(ardu):
    """ArduPlane streams every group at 1 Hz and no HOME_POSITION until asked (SRn defaults);
    MAV_CMD_SET_MESSAGE_INTERVAL sets one message, REQUEST_DATA_STREAM a group (EXTRA1 =
    ATTITUDE, POSITION = GLOBAL_POSITION_INT + LOCAL_POSITION_NED), as ArduPilot does."""
    v, g = ardu
    frames(v, g, 100)  # 2 s
    assert 1 <= len(g.of("ATTITUDE")) <= 3 and 1 <= len(g.of("VFR_HUD")) <= 3
    assert len(g.of("HOME_POSITION")) == 0
    g.msgs.clear()
    g.c.mav.command_long_send(
        1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_VFR_HUD, 100_000, 0, 0, 0, 0, 0
    )
    g.c.mav.request_data_stream_send(1, 1, 10, 25, 1)  # EXTRA1 at 25 Hz
    g.c.mav.request_data_stream_send(1, 1, 6, 50, 1)  # POSITION at 50 Hz: capped at 40
    # 50 Hz by interval is refused: ArduPilot caps intervals at 1.25 loop periods (25 ms)
    g.c.mav.command_long_send(
        1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, 20_000, 0, 0, 0, 0, 0
    )
    g.c.mav.command_long_send(
        1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0
    )
    frames(v, g, 3)
    assert len(g.of("HOME_POSITION")) == 1  # sent once, on request
    denied = [a for a in g.of("COMMAND_ACK") if a.command == M.MAV_CMD_SET_MESSAGE_INTERVAL]
    assert [a.result for a in denied] == [M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED]
    g.msgs.clear()
    frames(v, g, 100)  # 2 s at the new rates
    assert 49 <= len(g.of("ATTITUDE")) <= 51  # 25 Hz
    assert 79 <= len(g.of("LOCAL_POSITION_NED")) <= 81  # 40 Hz (the cap)
    assert 79 <= len(g.of("GLOBAL_POSITION_INT")) <= 81
    assert 19 <= len(g.of("VFR_HUD")) <= 21  # 10 Hz
    assert 1 <= len(g.of("WIND")) <= 3  # EXTRA3 untouched: 1 Hz
    g.c.mav.request_data_stream_send(1, 1, 10, 0, 0)  # stop EXTRA1
    frames(v, g, 3)
    g.msgs.clear()
    frames(v, g, 50)
    assert len(g.of("ATTITUDE")) == 0


def test_telemetry_latency_in_sim_time():
    port = free_port()
    with SimVehicle.build(
        "px4", f"udpin:127.0.0.1:{port}", plant="kinematic", telemetry_latency_s=0.1
    ) as v:
        g = Gcs(port)
        frames(v, g, 6)  # the queue fills: nothing was sampled 100 ms before the vehicle was ready
        for _ in range(20):
            v.step_once()
            new = [m for m in g.read() if m.get_type() == "ATTITUDE"]
            # what arrives now was sampled 100 ms (5 frames) of sim time ago
            assert [m.time_boot_ms for m in new] == [round(v.time_boot_s * 1000) - 100]
        g.close()


def test_home_position_on_request(ardu):
    v, g = ardu
    g.c.mav.command_long_send(1, 1, M.MAV_CMD_GET_HOME_POSITION, 0, 0, 0, 0, 0, 0, 0, 0)
    frames(v, g, 1)
    assert ack_for(g, M.MAV_CMD_GET_HOME_POSITION).result == M.MAV_RESULT_ACCEPTED
    home = g.of("HOME_POSITION")[-1]
    assert (home.latitude, home.longitude, home.altitude) == (473977420, 85455940, 488000)
    wind = g.of("WIND")  # ArduPilot streams WIND, not WIND_COV
    frames(v, g, 30)
    assert len(g.of("WIND")) >= 1 and not g.of("WIND_COV")
    del wind


# --------------------------------------------------------------------------- clocks
def test_lockstep_frames_advance_on_the_bridges_answers():
    """Lockstep: each telemetry frame ends when the bridge answers, not when the wall clock says.

    Counted, not timed (a wall-clock factor breaks on a loaded CI box): the speed itself is a
    benchmark figure (scripts/bench --only sil_real_time_factor)."""
    port = free_port()
    v = SimVehicle.build("px4", f"udpin:127.0.0.1:{port}", clock="lockstep")
    g = Gcs(port)
    v.start_in_thread()
    try:
        t_sim0, w0 = v.t, time.perf_counter()
        n_ans = 0
        hang_guard = time.monotonic() + 60.0  # a hang guard, not a measurement
        while n_ans < 100 and time.monotonic() < hang_guard:
            if g.c.select(0.1):  # answer each telemetry frame (ATTITUDE) with a setpoint
                for m in g.read():
                    if m.get_type() == "ATTITUDE":
                        g.rates(0.0)
                        n_ans += 1
        factor = (v.t - t_sim0) / (time.perf_counter() - w0)
    finally:
        v.stop()
        v.close()
        g.close()
    print(f"lockstep real-time factor with an answering bridge: {factor:.1f}x (information only)")
    assert n_ans >= 100
    # every answer ends a frame (a few answers cross a frame boundary in flight: 5 of slack); a
    # realtime clock would have counted no answered frames at all
    assert isinstance(v.clock, LockstepClock) and v.clock.answered_frames > 0.9 * n_ans - 5


def test_lockstep_silent_bridge_still_advances_and_realtime_is_paced():
    port = free_port()
    v = SimVehicle.build("px4", f"udpin:127.0.0.1:{port}", plant="kinematic", answer_timeout_s=0.05)
    g = Gcs(port)  # peer known (it said hello) but never answers
    v.start_in_thread()
    hang_guard = time.monotonic() + 60.0  # a hang guard, not a measurement
    while v.clock.timeouts < 10 and time.monotonic() < hang_guard:
        time.sleep(0.05)
    v.stop()
    # counted, not timed: with a known peer that never answers, each frame ends on the 50 ms
    # fallback (a timeout), none on an answer, and the simulation still advances
    assert isinstance(v.clock, LockstepClock)
    assert v.clock.timeouts >= 10 and v.clock.answered_frames == 0 and v.t > 0.0
    v.close()
    g.close()
    v = SimVehicle.build(
        "ardupilot", f"udpin:127.0.0.1:{free_port()}", plant="kinematic", clock="realtime"
    )
    w0 = time.perf_counter()
    v.run(0.5)
    wall = time.perf_counter() - w0
    # paced to the wall clock: 0.5 s of sim cannot take less than 0.5 s of wall (0.05 s of
    # slack: the first frames step before the pacing anchor); no upper bound, a loaded CI box
    # may take longer
    assert wall > 0.45
    v.close()


# --------------------------------------------------------------------------- kinematic plant
def test_kinematic_plant_geodetic_and_turn():
    p = KinematicMavPlant(position_ned=(1234.0, -987.0, -150.0), heading=0.3)
    lat, lon, alt = ned_to_geodetic_fast(p.origin, 1234.0, -987.0, -150.0)
    back = geodetic_to_ned(lat, lon, alt, p.origin.lat0_deg, p.origin.lon0_deg, p.origin.alt0_m)
    assert np.allclose(back, [1234.0, -987.0, -150.0], atol=1e-6)  # exact WGS-84 inverse
    # full right aileron for 0.3 s: rolls right, then with the stick neutral heading turns right
    for _ in range(36):
        p.step(0.3, 0.0, 0.0, 0.2)
    st = p.state()
    assert st.pqr[0] > 0.4 and st.euler[0] > 5 * DEG
    psi0 = st.euler[2]
    for _ in range(120):
        p.step(0.0, 0.0, 0.0, 0.2)
    assert p.state().euler[2] > psi0 + 0.05  # bank-to-turn
    assert abs(p.state().airspeed - 16.0) < 1e-12  # constant airspeed


def test_tcpin_link():
    port = free_port()
    with SimVehicle.build("px4", f"tcpin:127.0.0.1:{port}", plant="kinematic") as v:
        c = mavutil.mavlink_connection(
            f"tcp:127.0.0.1:{port}", source_system=255, dialect="ardupilotmega"
        )
        hb = None
        for _ in range(100):
            v.step_once()
            m = c.recv_match(type="HEARTBEAT", blocking=False)
            if m is not None:
                hb = m
                break
            time.sleep(0.001)
        c.close()
        assert hb is not None and hb.autopilot == M.MAV_AUTOPILOT_PX4


def test_lockstep_counts_only_the_answer_to_the_last_attitude():
    # A setpoint stamped with an earlier frame's ATTITUDE time (a late answer) must not release
    # the lockstep frame: counting it would keep every later command one frame late.
    port = free_port()
    v = SimVehicle.build("px4", f"udpin:127.0.0.1:{port}", plant="kinematic", clock="lockstep")
    g = Gcs(port)
    try:
        att_ms = []
        for _ in range(20):
            v.step_once()
            att_ms += [m.time_boot_ms for m in g.read() if m.get_type() == "ATTITUDE"]
            if len(att_ms) >= 2:
                break
        assert len(att_ms) >= 2, "no ATTITUDE from the vehicle"
        v.step_once()  # the next frame's telemetry goes out: the vehicle awaits its answer
        last = max(m.time_boot_ms for m in g.read() if m.get_type() == "ATTITUDE")
        assert not v.poll(0.0)
        g.c.mav.set_attitude_target_send(last - 20, 1, 1, RATES_THRUST, [1, 0, 0, 0], 0, 0, 0, 0.3)
        assert not v.poll(0.2), "a late answer to an earlier ATTITUDE released the frame"
        g.c.mav.set_attitude_target_send(last, 1, 1, RATES_THRUST, [1, 0, 0, 0], 0, 0, 0, 0.3)
        assert v.poll(0.2)
    finally:
        v.close()
        g.close()


def test_a_mode_request_releases_the_lockstep_frames_until_it_is_applied():
    """The hand-back: the bridge asks for Hold instead of answering. The frame that reads the
    request ends at once, and so does every frame until it is applied (a command latency of
    two frames here); then the frames await their answers again."""
    port = free_port()
    v = SimVehicle.build("px4", f"udpin:127.0.0.1:{port}", plant="kinematic", clock="lockstep",
                         command_latency_s=0.04)  # fmt: skip
    g = Gcs(port)
    try:
        for _ in range(20):
            v.step_once()
            if any(m.get_type() == "ATTITUDE" for m in g.read()):
                break
        for _ in range(3):  # the awaited ATTITUDE is two frames old: written by now
            v.step_once()
        g.read()
        assert not v.poll(0.0)  # awaits an answer
        g.set_mode(4, 3)  # PX4 AUTO.LOITER
        assert v.poll(0.5), "the mode request did not end the wait"
        assert v.lockstep.modes_pending == 1
        v.step_once()  # not due yet: still released
        assert v.poll(0.0) and ack_for(g, M.MAV_CMD_DO_SET_MODE) is None
        for _ in range(3):
            v.step_once()
        g.read()
        assert ack_for(g, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED  # applied
        assert v.lockstep.modes_pending == 0
        assert not v.poll(0.0)  # awaits its answer again
    finally:
        v.close()
        g.close()


def test_lockstep_awaits_position_frames_once_the_bridge_answers_them():
    """ATTITUDE 10 Hz, LOCAL_POSITION_NED 50 Hz: the four frames between two ATTITUDE samples
    carry a position only. A bridge that answers ATTITUDE only is not held up by them; once a
    setpoint comes stamped with such a frame's time_boot_ms (a multi-rate bridge,
    mavlink.position_instants), those frames are awaited too, each on its own stamp."""
    port = free_port()
    v = SimVehicle.build(
        "px4",
        f"udpin:127.0.0.1:{port}",
        plant="kinematic",
        clock="lockstep",
        rates={"attitude": 10.0, "local_position": 50.0},
    )
    g = Gcs(port)

    def frame() -> tuple[list[int], list[int]]:
        v.step_once()
        time.sleep(0.01)
        new = g.read()
        return (
            [m.time_boot_ms for m in new if m.get_type() == "ATTITUDE"],
            [m.time_boot_ms for m in new if m.get_type() == "LOCAL_POSITION_NED"],
        )

    def answer(ms: int) -> None:
        g.c.mav.set_attitude_target_send(ms, 1, 1, RATES_THRUST, [1, 0, 0, 0], 0, 0, 0, 0.3)

    try:
        att: list[int] = []
        for _ in range(20):
            att, _pos = frame()
            if att:
                break
        assert att, "no ATTITUDE from the vehicle"
        answer(att[0])
        assert v.poll(0.5)
        a, pos = frame()  # 20 ms later: a position-only frame
        assert not a and pos and pos[0] == att[0] + 20
        assert (
            v.poll(0.0) and not v.lockstep.answers_positions
        )  # not awaited: the ATTITUDE's answer stands
        answer(pos[0])
        v.poll(0.5)
        assert v.lockstep.answers_positions
        a, pos = frame()
        assert not a and pos and pos[0] == att[0] + 40
        answer(pos[0] - 20)  # a late answer to the previous frame does not release this one
        assert not v.poll(0.2), "a position frame of a multi-rate bridge was not awaited"
        answer(pos[0])
        assert v.poll(0.5)
    finally:
        v.close()
        g.close()


def test_reported_wind_lags_the_true_wind_like_an_estimator():
    """sil.wind_estimate_tau_s: the reported wind is a first-order lag of the air-mass velocity.
    A 5 m/s step seen over 50 frames of 20 ms with tau 1 s has closed 1 - exp(-1) of itself:
    each frame multiplies the remaining error by exp(-dt/tau), so after n frames it is
    exp(-n dt/tau) to ~n ulp (float64, 50 products: 1e-13 is ample)."""
    from sim.vehicle.telemetry import WindEstimate

    w = WindEstimate(tau_s=1.0)
    w.update(np.array([0.0, 4.0, 0.0]), 0.0)  # starts at the truth
    assert w.value == (0.0, 4.0, 0.0)
    gust = np.array([0.0, 9.0, -1.0])  # a gust of 5 m/s east and 1 m/s up
    for n in range(1, 51):
        w.update(gust, 0.02 * n)
    left = math.exp(-1.0)
    assert w.value[1] == pytest.approx(9.0 - 5.0 * left, abs=1e-13)
    # no autopilot estimates a vertical wind (PX4 EKF2, ArduPilot EKF2/EKF3: z = 0)
    assert w.value[2] == 0.0
    assert w.value[0] == 0.0
