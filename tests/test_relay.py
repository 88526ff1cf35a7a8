"""The UDP impairment relay (lab/soak/relay.py) on real loopback sockets.

A "vehicle" socket sends numbered datagrams to the relay's vehicle port; a "bridge" socket
listens where the relay forwards them (and answers back through it). Counts are exact; timing
bounds are loose upward (a shared 2-core machine) and strict downward (a delayed datagram can
never arrive early)."""

from __future__ import annotations

import socket
import struct
import threading
import time

import pytest

from lab.soak.relay import DOWN, UP, Blackout, Impairment, UdpRelay, mavlink_sysid, split_frames

N = 400


def _sock() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.5)
    return s


class Pair:
    """vehicle -> relay -> bridge, with the relay configured by ``kw``."""

    def __init__(self, **kw) -> None:
        self.bridge = _sock()
        self.vehicle = _sock()
        self.relay = UdpRelay(0, self.bridge.getsockname()[1], **kw).start()
        self.dest = ("127.0.0.1", self.relay.vehicle_port)

    def send(self, payload: bytes) -> None:
        self.vehicle.sendto(payload, self.dest)

    def recv_all(self, sock: socket.socket, idle_s: float = 0.2) -> list[tuple[float, bytes]]:
        out = []
        sock.settimeout(idle_s)
        while True:
            try:
                data, _ = sock.recvfrom(65536)
            except TimeoutError:
                return out
            out.append((time.monotonic(), data))

    def close(self) -> None:
        self.relay.stop()
        self.bridge.close()
        self.vehicle.close()


def numbered(k: int) -> bytes:
    return struct.pack("<Id", k, time.monotonic()) + b"x" * 20


def seqs(got: list[tuple[float, bytes]]) -> list[int]:
    return [struct.unpack_from("<I", d)[0] for _, d in got]


def run_stream(n: int = N, spacing_s: float = 0.0, **kw) -> tuple[Pair, list[tuple[float, bytes]]]:
    p = Pair(**kw)
    for k in range(n):
        p.send(numbered(k))
        if spacing_s:
            time.sleep(spacing_s)
    got = p.recv_all(p.bridge)
    p.close()
    return p, got


def test_clean_relay_forwards_everything_in_order_both_ways():
    p = Pair()
    try:
        for k in range(50):
            p.send(numbered(k))
        got = p.recv_all(p.bridge)
        # the bridge answers the address it got them from: the relay, which knows the vehicle
        p.bridge.sendto(b"answer", ("127.0.0.1", p.relay.bsock.getsockname()[1]))
        back = p.recv_all(p.vehicle)
    finally:
        p.close()
    assert seqs(got) == list(range(50))
    assert [d for _, d in back] == [b"answer"]
    c = p.relay.counters()
    assert (c[DOWN]["received"], c[DOWN]["delivered"], c[UP]["delivered"]) == (50, 50, 1)


def test_loss_is_counted_exactly_and_near_its_rate():
    p, got = run_stream(loss_n := 1000, down=Impairment(loss=0.3), seed=3)
    c = p.relay.counters()[DOWN]
    assert c["received"] == loss_n and c["dropped_loss"] + c["delivered"] == loss_n
    assert len(got) == c["delivered"]  # loopback loses nothing of its own
    # binomial(1000, 0.3): mean 300, sd 14.5; 5 sd either way
    assert 227 <= c["dropped_loss"] <= 373


def test_same_seed_same_fate_other_seed_other_fate():
    _, a = run_stream(300, down=Impairment(loss=0.5), seed=11)
    _, b = run_stream(300, down=Impairment(loss=0.5), seed=11)
    _, c = run_stream(300, down=Impairment(loss=0.5), seed=12)
    assert seqs(a) == seqs(b)
    assert seqs(a) != seqs(c)


def test_delay_is_never_early_and_jitter_reorders():
    # 50 ms fixed + uniform 0..30 ms: every datagram 50..80 ms late (upper bound padded for load)
    p = Pair(down=Impairment(delay_s=0.05, jitter_s=0.03), seed=1)
    sent = {}
    got: list[tuple[float, bytes]] = []
    rx = threading.Thread(target=lambda: got.extend(p.recv_all(p.bridge, 0.5)))  # arrival times
    rx.start()
    try:
        for k in range(100):
            sent[k] = time.monotonic()
            p.send(numbered(k))
            time.sleep(0.002)
        rx.join(5.0)
    finally:
        p.close()
    lat = [t - sent[k] for (t, _), k in zip(got, seqs(got), strict=True)]
    assert len(got) == 100
    assert min(lat) >= 0.05 and max(lat) < 0.08 + 0.1
    # 2 ms apart with 30 ms of jitter: many overtake each other
    order = seqs(got)
    assert order != sorted(order) and sorted(order) == list(range(100))
    assert p.relay.counters()[DOWN]["delayed"] == 100


def test_no_jitter_keeps_order_even_with_delay():
    _, got = run_stream(200, down=Impairment(delay_s=0.02), seed=1)
    assert seqs(got) == list(range(200))


def test_duplication_delivers_exact_copies():
    p, got = run_stream(300, down=Impairment(duplicate=0.5), seed=5)
    c = p.relay.counters()[DOWN]
    assert len(got) == 300 + c["duplicated"] and 90 <= c["duplicated"] <= 210
    by_seq: dict[int, set[bytes]] = {}
    for _, d in got:
        by_seq.setdefault(struct.unpack_from("<I", d)[0], set()).add(d)
    assert all(len(v) == 1 for v in by_seq.values())  # copies are byte-identical


def test_reorder_holds_datagrams_back():
    _, got = run_stream(200, spacing_s=0.001, down=Impairment(reorder=0.2, reorder_s=0.02), seed=2)
    order = seqs(got)
    assert sorted(order) == list(range(200)) and order != list(range(200))


def test_corruption_changes_exactly_the_configured_bytes():
    p = Pair(down=Impairment(corrupt=1.0, corrupt_bytes=1), seed=9)
    originals = [numbered(k) for k in range(100)]
    try:
        for d in originals:
            p.send(d)
        got = [d for _, d in p.recv_all(p.bridge)]
    finally:
        p.close()
    assert len(got) == 100
    diffs = [
        sum(a != b for a, b in zip(o, g, strict=True)) for o, g in zip(originals, got, strict=True)
    ]
    assert diffs == [1] * 100  # XOR with a non-zero value: the byte always changes
    assert p.relay.counters()[DOWN]["corrupted"] == 100
    assert all(
        d.corrupted and d.sent != d.data for d in p.relay.datagrams(DOWN)
    )  # the log keeps both


def test_blackout_window_drops_only_inside_it():
    p = Pair(blackouts=[Blackout(0.3, 0.6, DOWN)])
    try:
        t0 = p.relay.t0
        sent = []
        while time.monotonic() - t0 < 0.9:
            k = len(sent)
            sent.append((k, time.monotonic() - t0))
            p.send(numbered(k))
            time.sleep(0.005)
        got = set(seqs(p.recv_all(p.bridge)))
    finally:
        p.close()
    # margins of 20 ms around the edges for scheduling; inside: all dropped; outside: none
    inside = {k for k, t in sent if 0.32 < t < 0.58}
    outside = {k for k, t in sent if t < 0.28 or t > 0.62}
    assert inside and not (inside & got)
    assert outside <= got
    assert p.relay.counters()[DOWN]["dropped_blackout"] >= len(inside)


def _v2(sysid: int, payload: bytes = b"\x01\x02", signed: bool = False) -> bytes:
    hdr = bytes([0xFD, len(payload), 0x01 if signed else 0, 0, 7, sysid, 1, 0, 0, 0])
    return hdr + payload + b"\xaa\xbb" + (bytes(13) if signed else b"")


def _v1(sysid: int, payload: bytes = b"\x05") -> bytes:
    return bytes([0xFE, len(payload), 3, sysid, 1, 0]) + payload + b"\xcc\xdd"


def test_split_frames_and_sysid():
    frames = [_v2(1), _v1(2, b"abc"), _v2(3, b"", signed=True), _v2(2, b"x" * 40)]
    assert split_frames(b"".join(frames)) == frames
    assert [mavlink_sysid(f) for f in frames] == [1, 2, 3, 2]
    assert split_frames(b"") == []
    assert split_frames(_v2(1)[:-1]) is None  # truncated
    assert split_frames(b"\x00" + _v2(1)) is None  # not a frame boundary
    assert mavlink_sysid(b"junk") is None


def test_per_system_blackout_cuts_frames_out_of_shared_datagrams():
    p = Pair(blackouts=[Blackout(0.0, 1e6, DOWN, sysid=2)])
    try:
        p.send(_v2(1) + _v2(2) + _v1(1))  # vehicle, target, vehicle in one datagram
        p.send(_v2(2))  # the target alone
        p.send(_v2(1))
        got = [d for _, d in p.recv_all(p.bridge)]
    finally:
        p.close()
    assert got == [_v2(1) + _v1(1), _v2(1)]
    c = p.relay.counters()[DOWN]
    assert (c["filtered_frames"], c["dropped_blackout"], c["delivered"]) == (2, 1, 2)


def test_runtime_blackout_and_injection():
    p = Pair()
    try:
        p.send(numbered(0))
        p.recv_all(p.bridge, 0.2)
        b = p.relay.blackout(10.0, DOWN)
        assert b.end_s - b.start_s == pytest.approx(10.0)
        p.send(numbered(1))  # dropped
        assert p.relay.inject(DOWN, b"injected")  # injections ignore blackouts and impairments
        assert p.relay.inject(UP, b"to the vehicle")
        got = [d for _, d in p.recv_all(p.bridge)]
        back = [d for _, d in p.recv_all(p.vehicle)]
    finally:
        p.close()
    assert got == [b"injected"] and back == [b"to the vehicle"]
    c = p.relay.counters()
    assert (c[DOWN]["dropped_blackout"], c[DOWN]["injected"], c[UP]["injected"]) == (1, 1, 1)


def test_vehicle_restarting_from_a_new_port_is_followed():
    p = Pair()
    try:
        p.send(b"first life")
        p.recv_all(p.bridge, 0.2)
        p.vehicle.close()
        p.vehicle = _sock()  # a restarted vehicle process: new source port
        p.send(b"second life")
        p.recv_all(p.bridge, 0.2)
        p.bridge.sendto(b"for the new one", ("127.0.0.1", p.relay.bsock.getsockname()[1]))
        back = [d for _, d in p.recv_all(p.vehicle)]
    finally:
        p.close()
    assert back == [b"for the new one"]


def test_up_before_the_vehicle_spoke_has_no_destination():
    p = Pair()
    try:
        assert not p.relay.inject(UP, b"too early")
    finally:
        p.close()
    assert p.relay.counters()[UP]["no_destination"] == 1


@pytest.mark.parametrize(
    "kw",
    [
        {"loss": 1.5},
        {"loss": -0.1},
        {"delay_s": -1.0},
        {"jitter_s": float("nan")},
        {"corrupt_bytes": 0},
    ],
)
def test_impairment_rejects_impossible_values(kw):
    with pytest.raises(ValueError):
        Impairment(**kw)
