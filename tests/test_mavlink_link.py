"""Link against real pymavlink peers: UDP loopback, a pseudo-terminal 'serial' port, TCP."""

from __future__ import annotations

import math
import os
import socket
import statistics
import struct
import time

import pytest

from mpf_mavlink.core import frames
from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink import dialect as mavlink
from mpf_mavlink.mavlink import mavutil, read_tlog
from mpf_mavlink.mavlink.encode import (
    encode_set_attitude_target_quat,
    encode_set_attitude_target_rates,
)
from mpf_mavlink.mavlink.link import open_link, parse_url, wait_heartbeat
from mpf_mavlink.mavlink.modes import px4_custom_mode
from mpf_mavlink.mavlink.wire_limits import TYPE_MASK_ARDUPLANE_ATTITUDE, TYPE_MASK_PX4_RATES
from mpf_mavlink.quaternion import quat_of_euler


def free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def free_tcp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def vehicle_peer(port: int, sysid: int = 1, compid: int = 1):
    """A pymavlink endpoint playing the autopilot, sending to our udpin port."""
    return mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=compid
    )


def px4_heartbeat(peer, main: int = 6, sub: int = 0) -> None:
    peer.mav.heartbeat_send(
        mavlink.MAV_TYPE_FIXED_WING,
        mavlink.MAV_AUTOPILOT_PX4,
        mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
        px4_custom_mode(main, sub),
        mavlink.MAV_STATE_ACTIVE,
    )


def peer_recv(peer, mtype: str, timeout_s: float = 2.0):
    return peer.recv_match(type=mtype, blocking=True, timeout=timeout_s)


@pytest.fixture
def udp_pair(tmp_path):
    port = free_udp_port()
    link = open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1, tlog_path=tmp_path / "link.tlog")
    peer = vehicle_peer(port)
    yield link, peer, port, tmp_path / "link.tlog"
    peer.close()
    link.close()


# --------------------------------------------------------------------------------------------
def test_udp_heartbeat_and_rate_setpoint_round_trip(udp_pair):
    link, peer, _, _ = udp_pair
    px4_heartbeat(peer)
    hb = wait_heartbeat(link, 2.0)
    # the vehicle said PX4 (12), OFFBOARD: custom_mode = 6 << 16 = 393216
    assert (hb.autopilot, hb.custom_mode) == (12, 393216)
    assert hb.get_msgbuf()[0] == 0xFD  # the peer talks MAVLink 2 (MAVLINK20 forced)

    # udpin replies to the address the vehicle sent from
    link.send(encode_set_attitude_target_rates(link.mav, 1234, 1, 1, 0.1, -0.2, 0.3, 0.6))
    sat = peer_recv(peer, "SET_ATTITUDE_TARGET")
    assert sat is not None
    assert sat.get_msgbuf()[0] == 0xFD  # we send MAVLink 2
    assert (sat.get_srcSystem(), sat.get_srcComponent()) == (1, 191)  # companion identity
    assert (sat.target_system, sat.target_component, sat.time_boot_ms) == (1, 1, 1234)
    # 128 = attitude ignore: PX4 uses the three rates AND the thrust (bit 64 clear)
    assert sat.type_mask == TYPE_MASK_PX4_RATES == 128
    assert list(sat.q) == [1.0, 0.0, 0.0, 0.0]  # identity, w first
    # rad/s as float32 on the wire: equal to 1e-7 relative
    assert sat.body_roll_rate == pytest.approx(0.1, rel=1e-6)
    assert sat.body_pitch_rate == pytest.approx(-0.2, rel=1e-6)
    assert sat.body_yaw_rate == pytest.approx(0.3, rel=1e-6)
    assert sat.thrust == pytest.approx(0.6, rel=1e-6)
    assert link.counters.tx_by_type["SET_ATTITUDE_TARGET"] == 1
    assert link.counters.rx_by_type["HEARTBEAT"] == 1


def test_udp_quaternion_order_and_ardupilot_type_mask(udp_pair):
    link, peer, _, _ = udp_pair
    px4_heartbeat(peer)
    wait_heartbeat(link, 2.0)
    # roll 30 deg, pitch 0, yaw 0 -> q = (cos 15deg, sin 15deg, 0, 0) in (w, x, y, z)
    q = quat_of_euler(math.radians(30.0), 0.0, 0.0)
    link.send(encode_set_attitude_target_quat(link.mav, 50, 1, 1, q, 0.45))
    sat = peer_recv(peer, "SET_ATTITUDE_TARGET")
    assert sat.q[0] == pytest.approx(math.cos(math.radians(15)), abs=1e-7)  # 0.9659258 first
    assert sat.q[1] == pytest.approx(math.sin(math.radians(15)), abs=1e-7)  # 0.2588190
    assert sat.q[2] == pytest.approx(0.0, abs=1e-7) and sat.q[3] == pytest.approx(0.0, abs=1e-7)
    # 132 = attitude ignore + yaw-rate ignore, throttle ignore clear: ArduPlane takes roll and
    # pitch from q (the rate bits pick the angles), leaves the rudder to its own coordinated-turn
    # output and uses the thrust
    assert sat.type_mask == TYPE_MASK_ARDUPLANE_ATTITUDE == 132
    assert sat.thrust == pytest.approx(0.45, rel=1e-6)
    # the peer's view of the attitude: roll back to 30 deg through the same frames helper
    roll, pitch, yaw = frames.matrix_to_euler(frames.quat_wxyz_to_matrix(sat.q))
    assert math.degrees(roll) == pytest.approx(30.0, abs=1e-4)
    assert (pitch, yaw) == pytest.approx((0.0, 0.0), abs=1e-6)


def test_spoofed_system_ids_are_dropped_and_counted(udp_pair):
    link, peer, port, _ = udp_pair
    link.allow_sysid(7)  # a moving target that publishes FOLLOW_TARGET
    spoofer = vehicle_peer(port, sysid=42, compid=1)
    target = vehicle_peer(port, sysid=7, compid=1)
    try:
        for _ in range(3):
            px4_heartbeat(spoofer, main=1)  # a fake vehicle claiming MANUAL
            spoofer.mav.attitude_send(1, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        target.mav.follow_target_send(
            1000,
            3,
            473977420,
            85455940,
            500.0,
            [1, 2, 0],
            [0, 0, 0],
            [1, 0, 0, 0],
            [0, 0, 0],
            [0, 0, 0],
            0,
        )
        px4_heartbeat(peer)
        got = []
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end and len(got) < 2:
            m = link.recv(0.2)
            if m is not None:
                got.append(m)
        srcs = sorted((m.get_srcSystem(), m.get_type()) for m in got)
        # only the vehicle (1) and the allowed target (7) come through
        assert srcs == [(1, "HEARTBEAT"), (7, "FOLLOW_TARGET")]
        # 3 heartbeats + 3 attitudes from system 42 were dropped, and counted by source
        assert link.counters.rejected_sysid == 6
        assert link.counters.rejected_by_source[(42, 1)] == 6
    finally:
        spoofer.close()
        target.close()


def test_vehicle_component_filter(tmp_path):
    port = free_udp_port()
    with open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1, vehicle_compid=1) as link:
        gimbal = vehicle_peer(port, sysid=1, compid=154)
        ap = vehicle_peer(port, sysid=1, compid=1)
        px4_heartbeat(gimbal)
        px4_heartbeat(ap)
        hb = wait_heartbeat(link, 2.0)
        assert hb.get_srcComponent() == 1  # the gimbal's heartbeat (compid 154) was refused
        time.sleep(0.05)
        link.recv(0.05)
        assert link.counters.rejected_by_source[(1, 154)] == 1
        gimbal.close()
        ap.close()


def test_malformed_bytes_are_counted_never_raised(udp_pair):
    link, peer, port, _ = udp_pair
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        raw.sendto(b"\x00\x11garbage without any start byte", ("127.0.0.1", port))
        good = mavlink.MAVLink_heartbeat_message(1, 12, 1, 0, 4, 3).pack(
            mavlink.MAVLink(None, 1, 1)
        )
        bad_crc = bytearray(good)
        bad_crc[-1] ^= 0xFF
        raw.sendto(bytes(bad_crc), ("127.0.0.1", port))
        raw.sendto(good, ("127.0.0.1", port))
        msg = link.recv(1.0)
        # the only thing that comes out is the good heartbeat
        assert msg is not None and msg.get_type() == "HEARTBEAT"
        # one "bad prefix" stretch + one CRC failure
        assert link.counters.bad_data == 2
    finally:
        raw.close()


def test_link_tlog_is_readable_by_pymavlink_and_read_tlog(udp_pair):
    link, peer, _, tlog_path = udp_pair
    for _ in range(5):
        px4_heartbeat(peer)
    n_rx = 0
    t_end = time.monotonic() + 2.0
    while n_rx < 5 and time.monotonic() < t_end:
        if link.recv(0.2) is not None:
            n_rx += 1
    for k in range(4):
        link.send(encode_set_attitude_target_rates(link.mav, k, 1, 1, 0.0, 0.0, 0.1 * k, 0.5))
    link.close()

    ours = read_tlog(tlog_path)
    # 5 received heartbeats + 4 sent setpoints, nothing skipped
    assert ours.counts == {"HEARTBEAT": 5, "SET_ATTITUDE_TARGET": 4}
    assert (ours.skipped_regions, ours.skipped_bytes) == (0, 0)
    yaw_rates = [m.body_yaw_rate for _, m in ours if m.get_type() == "SET_ATTITUDE_TARGET"]
    assert yaw_rates == pytest.approx([0.0, 0.1, 0.2, 0.3], abs=1e-7)
    # timestamps: wall clock of the event, within this test's minute
    assert abs(ours.t_last_s - time.time()) < 60

    theirs = mavutil.mavlink_connection(str(tlog_path))
    types = []
    while (m := theirs.recv_msg()) is not None:
        types.append(m.get_type())
    theirs.close()
    assert types.count("HEARTBEAT") == 5 and types.count("SET_ATTITUDE_TARGET") == 4


def test_loopback_round_trip_time(udp_pair):
    """Setpoint out, vehicle answers: median RTT on loopback well under one 20 Hz period."""
    link, peer, _, _ = udp_pair
    px4_heartbeat(peer)
    wait_heartbeat(link, 2.0)
    for k in range(5):  # the link establishes the vehicle's boot clock on its 5th sample
        peer.mav.attitude_send(k + 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    m = link.recv(1.0)
    assert m is not None and m.time_boot_ms == 5 and link.counters.clock_settling == 4
    rtts = []
    for k in range(10, 60):
        t0 = time.perf_counter()
        link.send(encode_set_attitude_target_rates(link.mav, k, 1, 1, 0.0, 0.0, 0.0, 0.5))
        sat = peer_recv(peer, "SET_ATTITUDE_TARGET", 1.0)
        assert sat is not None
        peer.mav.attitude_send(k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        m = link.recv(1.0)
        assert m is not None and m.get_type() == "ATTITUDE"
        rtts.append(time.perf_counter() - t0)
    med = statistics.median(rtts)
    print(f"loopback UDP round trip: median {med * 1e3:.2f} ms, max {max(rtts) * 1e3:.2f} ms")
    assert med < 0.05  # 50 ms = one period at 20 Hz; loopback is typically ~0.2 ms


def test_pty_serial_exchange(tmp_path):
    master, slave = os.openpty()
    path = os.ttyname(slave)
    link = open_link(f"{path}:115200", vehicle_sysid=1, tlog_path=tmp_path / "pty.tlog")
    os.close(slave)  # the link holds its own descriptor
    try:
        vehicle = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        hb = mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15, mavlink.MAV_STATE_ACTIVE, 3,
        )  # fmt: skip
        os.write(master, hb.pack(vehicle))
        got = wait_heartbeat(link, 2.0)
        assert (got.autopilot, got.custom_mode) == (3, 15)  # ArduPilot, GUIDED

        q = quat_of_euler(0.0, math.radians(5.0), 0.0)
        link.send(encode_set_attitude_target_quat(link.mav, 77, 1, 1, q, 0.7))
        parser = mavlink.MAVLink(None)
        msg = None
        t_end = time.monotonic() + 2.0
        while msg is None and time.monotonic() < t_end:
            try:
                chunk = os.read(master, 512)
            except BlockingIOError:
                chunk = b""
            for m in parser.parse_buffer(chunk) or []:
                if m.get_type() == "SET_ATTITUDE_TARGET":
                    msg = m
        assert msg is not None
        assert msg.type_mask == 132 and msg.time_boot_ms == 77
        # pitch 5 deg -> q = (cos 2.5deg, 0, sin 2.5deg, 0)
        assert list(msg.q) == pytest.approx(
            [math.cos(math.radians(2.5)), 0.0, math.sin(math.radians(2.5)), 0.0], abs=1e-7
        )
        assert msg.thrust == pytest.approx(0.7, rel=1e-6)
    finally:
        link.close()
        os.close(master)
    # both directions: the vehicle's HEARTBEAT and ours, sent while waiting for it
    assert read_tlog(tmp_path / "pty.tlog").counts == {"HEARTBEAT": 2, "SET_ATTITUDE_TARGET": 1}


def test_tcp_link_to_listening_peer():
    port = free_tcp_port()
    server = mavutil.mavlink_connection(
        f"tcpin:127.0.0.1:{port}", source_system=1, source_component=1
    )
    try:
        link = open_link(f"tcp:127.0.0.1:{port}", vehicle_sysid=1, timeout_s=1.0)
        try:
            link.send_heartbeat()
            got = peer_recv(server, "HEARTBEAT")  # accept() happens inside recv
            # companion heartbeat: MAV_TYPE_ONBOARD_CONTROLLER (18), MAV_AUTOPILOT_INVALID (8)
            assert (got.type, got.autopilot) == (18, 8)
            px4_heartbeat(server)
            assert wait_heartbeat(link, 2.0).custom_mode == 393216
        finally:
            link.close()
    finally:
        server.close()


# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("url", "culprit"),
    [
        ("udpin:nonsense", "udpin:nonsense"),
        ("foo:1.2.3.4:1", "unknown scheme 'foo'"),
        ("/dev/does-not-exist", "/dev/does-not-exist does not exist"),
        ("udpout:127.0.0.1:0", "port 0"),
        ("udpout:127.0.0.1:99999", "port 99999"),
        ("udpin:127.0.0.1:abc", "port 'abc'"),
        ("tcp:1.2.3:5760", "'1.2.3'"),
        ("/dev/ttyUSB0:12345", "unsupported baud rate 12345"),
        ("/dev/ttyUSB0:fast", "baud rate 'fast'"),
        ("14550", "expected SCHEME:HOST:PORT"),
        ("", "empty MAVLink URL"),
    ],
)
def test_bad_urls_give_one_clear_line(url, culprit):
    with pytest.raises(MpfError) as ei:
        open_link(url)
    text = str(ei.value)
    assert culprit in text
    assert "\n" not in text


def test_refused_tcp_is_one_line():
    port = free_tcp_port()  # nobody listens there
    with pytest.raises(MpfError, match="connection refused") as ei:
        open_link(f"tcp:127.0.0.1:{port}", timeout_s=1.0)
    assert "\n" not in str(ei.value)


def test_udp_port_in_use_is_one_line():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    try:
        # pymavlink sets SO_REUSEADDR, which does not allow a second bind on Linux UDP unicast
        with pytest.raises(MpfError, match=f"127.0.0.1:{port}"):
            open_link(f"udpin:127.0.0.1:{port}")
    finally:
        s.close()


def test_parse_url_forms():
    assert parse_url("udp:0.0.0.0:14540").kind == "udpin"  # pymavlink's legacy 'udp' listens
    assert parse_url("udpout:localhost:14550").host == "localhost"
    p = parse_url("/dev/ttyACM0:921600")
    assert (p.kind, p.device, p.baud) == ("serial", "/dev/ttyACM0", 921600)
    p = parse_url("/dev/ttyS1,57600")
    assert (p.device, p.baud) == ("/dev/ttyS1", 57600)
    assert parse_url("/dev/ttyUSB0", baud=115200).baud == 115200
    assert parse_url("/dev/ttyUSB0").baud == 57600  # default


def test_wait_heartbeat_times_out_with_clear_line():
    port = free_udp_port()
    with open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=3) as link:
        t0 = time.monotonic()
        with pytest.raises(MpfError) as ei:
            wait_heartbeat(link, 0.3)
        dt = time.monotonic() - t0
    assert "no HEARTBEAT from system 3" in str(ei.value) and "0.3 s" in str(ei.value)
    assert "\n" not in str(ei.value)
    assert 0.29 <= dt < 1.0  # it waited the timeout, not forever


def test_companion_heartbeat_is_ignored_by_wait_heartbeat():
    port = free_udp_port()
    with open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1) as link:
        other_companion = vehicle_peer(port, sysid=1, compid=195)
        other_companion.mav.heartbeat_send(18, 8, 0, 0, 4)  # ONBOARD_CONTROLLER, INVALID
        with pytest.raises(MpfError):
            wait_heartbeat(link, 0.3)
        other_companion.close()


def test_recv_after_close_and_send_after_close():
    port = free_udp_port()
    link = open_link(f"udpin:127.0.0.1:{port}")
    link.close()
    assert link.recv(0.1) is None
    with pytest.raises(MpfError, match="closed"):
        link.send_heartbeat()


def test_a_burst_goes_in_one_datagram_logged_as_single_sends(tmp_path):
    """Link.send_many: one datagram holding the packets pymavlink would send one by one (same
    bytes, consecutive sequence numbers), each its own tlog record, counted per packet."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    link = open_link(f"udpout:127.0.0.1:{rx.getsockname()[1]}", tlog_path=tmp_path / "b.tlog")
    want: list[bytes] = []

    class _Out:
        def write(self, b: bytes) -> None:
            want.append(bytes(b))

    ref = mavlink.MAVLink(_Out(), srcSystem=link.source_system, srcComponent=link.source_component)
    try:
        names = [b"MPF_pt", b"MPF_psi", b"MPF_sdot"]
        link.send_many([link.mav.named_value_float_encode(7, n, 1.5) for n in names])
        data = rx.recv(65536)
        for n in names:
            ref.send(ref.named_value_float_encode(7, n, 1.5))
        assert data == b"".join(want)
        assert link.counters.tx_packets == 3
        assert link.counters.tx_by_type["NAMED_VALUE_FLOAT"] == 3
    finally:
        link.close()
        rx.close()
    got = read_tlog(tmp_path / "b.tlog")
    assert [bytes(m.get_msgbuf()) for _, m in got.messages] == want


def test_struct_of_tlog_record_written_by_link(tmp_path):
    """Record = 8-byte big-endian us since the epoch + the exact packet bytes we sent."""
    port = free_udp_port()
    clock_s = 1_700_000_000.25
    link = open_link(f"udpout:127.0.0.1:{port}", tlog_path=tmp_path / "x.tlog")
    link.record._clock = lambda: clock_s  # controlled wall clock for the log
    msg = encode_set_attitude_target_rates(link.mav, 9, 1, 1, 0.0, 0.0, 0.0, 0.5)
    link.send(msg)
    link.close()
    data = (tmp_path / "x.tlog").read_bytes()
    (ts,) = struct.unpack(">Q", data[:8])
    assert ts == 1_700_000_000_250_000
    assert data[8:] == bytes(msg.get_msgbuf())


def test_waiting_for_the_heartbeat_announces_us_to_a_listening_vehicle():
    # `mpf-mavlink vehicle --serve udpin:...` (and a GCS-facing autopilot port) answers whoever
    # sent first: a bridge on udpout that only listened was never answered. While it waits it
    # sends its companion HEARTBEAT at 1 Hz: 2 within 1.5 s (at 0 s and 1 s).
    srv = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    srv.bind(("127.0.0.1", 0))
    srv.settimeout(0.1)
    port = srv.getsockname()[1]
    parser = mavlink.MAVLink(None)
    with open_link(f"udpout:127.0.0.1:{port}", vehicle_sysid=1) as link:
        with pytest.raises(MpfError, match="no HEARTBEAT"):
            wait_heartbeat(link, 1.5)
    got = []
    while True:
        try:
            data = srv.recv(65535)
        except TimeoutError:
            break
        got += [m for m in parser.parse_buffer(data) or [] if m.get_type() == "HEARTBEAT"]
    srv.close()
    assert len(got) == 2
    assert all(m.autopilot == mavlink.MAV_AUTOPILOT_INVALID for m in got)  # a companion's


def test_a_udpin_link_answers_every_sender_and_keeps_their_times_only_with_a_timeout():
    """pymavlink's udpin bookkeeping, as the link's datagram reader keeps it: every address
    heard from is a client (a second sender is learnt from its first datagram); the time each
    was last heard is what mavudp.write expires clients by, so it follows every datagram when
    the connection has a timeout and is set once per address without one."""
    port = free_udp_port()
    link = open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1)
    a, b = vehicle_peer(port), vehicle_peer(port, sysid=2)
    try:
        conn = link.conn
        assert conn.timeout <= 0
        px4_heartbeat(a)
        assert link.recv(1.0) is not None
        (addr_a,) = conn.clients
        first = conn.clients_last_alive[addr_a]
        time.sleep(0.01)
        px4_heartbeat(a)
        assert link.recv(1.0) is not None
        assert conn.clients_last_alive[addr_a] == first  # no timeout: never read, not kept
        link.allow_sysid(2)
        px4_heartbeat(b)
        assert link.recv(1.0) is not None
        assert len(conn.clients) == 2 and addr_a in conn.clients
        conn.timeout = 5.0
        time.sleep(0.01)
        px4_heartbeat(a)
        assert link.recv(1.0) is not None
        assert conn.clients_last_alive[addr_a] > first  # with a timeout: every datagram
    finally:
        a.close()
        b.close()
        link.close()
