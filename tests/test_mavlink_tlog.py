"""tlog reader and writer.

The reader on the shared real recording (whole, truncated, corrupted); the writer under SIGKILL.
"""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from collections import Counter
from pathlib import Path

import pytest

from mpf_mavlink.mavlink import (
    codec,
    dialect,
    encode_set_attitude_target_rates,
    mavutil,
    open_link,
    read_tlog,
)
from mpf_mavlink.mavlink.tlog import MAP_BYTES, TlogWriter

# A real ArduPlane SITL recording kept in the repository (provenance: tests/data/README.md).
SHARED_TLOG = Path(__file__).resolve().parent / "data" / "arduplane-quadplane-sitl-vtol.tlog"
REPO = Path(__file__).resolve().parents[1]


def record_offsets(data: bytes) -> list[tuple[int, int]]:
    """(offset, length) of every record of a clean tlog, framed from the packet headers."""
    out, i = [], 0
    while i < len(data):
        stx, plen = data[i + 8], data[i + 9]
        n = 8 + (6 + plen + 2 if stx == 0xFE else 10 + plen + 2 + (13 if data[i + 10] & 1 else 0))
        out.append((i, n))
        i += n
    return out


@pytest.fixture(scope="module")
def shared_bytes() -> bytes:
    return SHARED_TLOG.read_bytes()


@pytest.fixture(scope="module")
def shared_result():
    return read_tlog(SHARED_TLOG)


def test_shared_tlog_reads_fully_and_matches_pymavlink(shared_result):
    res = shared_result
    print(
        f"read_tlog: {res.records} records in {res.elapsed_s:.3f} s, {res.duration_s:.1f} s of "
        "flight"
    )
    ref = mavutil.mavlink_connection(str(SHARED_TLOG))
    ref_counts: Counter = Counter()
    while (m := ref.recv_msg()) is not None:
        ref_counts[m.get_type()] += 1
    ref.close()
    # same message counts, type by type, as pymavlink's own tlog reader (23894 in total)
    assert res.counts == dict(ref_counts)
    assert res.records == len(res) == 23894
    assert (res.skipped_regions, res.skipped_bytes, res.truncated_tail_bytes) == (0, 0, 0)
    # ~208 s recording at ~4 Hz: the spec's description of the file
    assert res.duration_s == pytest.approx(207.6, abs=0.1)
    assert res.counts["ATTITUDE"] == 888 and res.counts["WIND"] == 810
    # no wall-clock bound (res.elapsed_s, printed above: ~0.45 s against ~0.9 s for pymavlink
    # alone on an idle box, 4.5 s on a loaded one): speed is a benchmark figure, not a test
    # msg._timestamp carries the record time (s since the epoch), monotonic in this file
    ts = [t for t, _ in res]
    assert all(m._timestamp == t for t, m in res.messages[:100])
    assert all(b >= a for a, b in zip(ts, ts[1:], strict=False))


def test_replay_of_shared_tlog_with_codec_decodes_every_record():
    t0 = time.perf_counter()
    res = read_tlog(SHARED_TLOG, types=sorted(codec.DECODED_TYPES))
    samples = [codec.decode(m) for _, m in res]
    dt = time.perf_counter() - t0
    print(f"replay read+decode: {len(samples)} messages in {dt:.3f} s")
    assert res.records == 23894  # every record still framed and CRC-checked
    # the time is printed, not bounded (a loaded CI box makes any bound flaky)
    assert len(samples) == len(res) > 0  # decode ran on every message read, none raised


def test_truncated_copy_reads_every_complete_record(tmp_path, shared_bytes):
    offs = record_offsets(shared_bytes)
    k = 10000
    cut = offs[k][0] + offs[k][1] // 2  # half of record k survives
    p = tmp_path / "cut.tlog"
    p.write_bytes(shared_bytes[:cut])
    res = read_tlog(p, types=())  # frame + CRC only: counting needs no decoding
    assert res.records == k  # records 0..k-1 are complete
    assert res.truncated_tail_bytes == offs[k][1] // 2
    assert res.skipped_regions == 1


@pytest.mark.parametrize("cut_in", [3, 8, 9])  # inside the timestamp, right after it, after STX
def test_truncation_at_record_edges(tmp_path, shared_bytes, cut_in):
    offs = record_offsets(shared_bytes)
    cut = offs[500][0] + cut_in
    p = tmp_path / "edge.tlog"
    p.write_bytes(shared_bytes[:cut])
    res = read_tlog(p, types=())
    assert res.records == 500 and res.truncated_tail_bytes == cut_in


def test_corrupted_payload_bytes_lose_exactly_those_records(tmp_path, shared_bytes):
    offs = record_offsets(shared_bytes)
    data = bytearray(shared_bytes)
    victims = [5, 1000, 1001, 12345, 23000]
    for k in victims:
        o, n = offs[k]
        data[o + 8 + 7] ^= 0x5A  # a payload byte (v1 header is 6 bytes): the CRC no longer matches
    p = tmp_path / "corrupt.tlog"
    p.write_bytes(bytes(data))
    res = read_tlog(p, types=())
    assert res.records == 23894 - len(victims)
    # adjacent victims 1000 and 1001 form one skipped stretch
    assert res.skipped_regions == 4
    assert res.skipped_bytes == sum(offs[k][1] for k in victims)


def test_garbage_inserted_between_records_is_skipped(tmp_path, shared_bytes):
    offs = record_offsets(shared_bytes)
    at = offs[777][0]
    garbage = bytes([0xFE, 0x00, 0xFD, 0x12] * 25)  # 100 bytes full of fake start bytes
    p = tmp_path / "garbage.tlog"
    p.write_bytes(shared_bytes[:at] + garbage + shared_bytes[at:])
    res = read_tlog(p, types=())
    assert res.records == 23894
    assert (res.skipped_regions, res.skipped_bytes) == (1, 100)


def test_implausible_timestamp_record_is_skipped(tmp_path, shared_bytes):
    offs = record_offsets(shared_bytes)
    data = bytearray(shared_bytes)
    o, n = offs[4242]
    data[o : o + 8] = struct.pack(">Q", 12345)  # 1970: not a tlog record time
    p = tmp_path / "ts.tlog"
    p.write_bytes(bytes(data))
    res = read_tlog(p, types=())
    assert res.records == 23893 and res.skipped_bytes == n


def test_random_bytes_and_empty_file(tmp_path):
    p = tmp_path / "noise.tlog"
    p.write_bytes(os.urandom(4096))
    res = read_tlog(p)
    assert res.records == 0 and res.skipped_bytes == 4096  # never raises, counts everything
    e = tmp_path / "empty.tlog"
    e.write_bytes(b"")
    assert read_tlog(e).records == 0


def test_writer_record_layout_and_both_versions(tmp_path):
    from mpf_mavlink.mavlink import dialect as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    hb = mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)
    v2 = hb.pack(mav)
    v1 = hb.pack(mav, force_mavlink1=True)
    p = tmp_path / "w.tlog"
    with TlogWriter(p) as w:
        w.write(v2, 1_700_000_000.0)
        w.write(v1, 1_700_000_000.5)
    data = p.read_bytes()
    assert data[:8] == struct.pack(">Q", 1_700_000_000_000_000) and data[8] == 0xFD
    res = read_tlog(p)
    assert [t for t, _ in res] == [1_700_000_000.0, 1_700_000_000.5]
    assert [bytes(m.get_msgbuf())[0] for _, m in res] == [0xFD, 0xFE]  # v2 then v1


WRITER_SCRIPT = textwrap.dedent(
    """
    import sys, time
    from mpf_mavlink.mavlink import open_link
    from mpf_mavlink.mavlink.encode import encode_set_attitude_target_rates
    link = open_link(sys.argv[2], tlog_path=sys.argv[1])
    k = 0
    while True:
        rate = 0.01 * (k % 100)
        link.send(encode_set_attitude_target_rates(link.mav, k, 1, 1, 0.0, 0.0, rate, 0.5))
        k += 1
        if k % 200 == 0:
            time.sleep(0.001)
    """
)


def test_tlog_survives_sigkill_of_the_writing_link(tmp_path):
    p = tmp_path / "killed.tlog"
    script = tmp_path / "writer.py"
    script.write_text(WRITER_SCRIPT)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, str(script), str(p), "udpout:127.0.0.1:9"], env=env)
    try:
        t_end = time.monotonic() + 10.0
        # the link's writer maps the file ahead of its records: their count says how far it is
        while time.monotonic() < t_end and (not p.exists() or read_tlog(p).records < 1000):
            time.sleep(0.02)
        assert p.exists() and read_tlog(p).records >= 1000, "writer did not start"
        os.kill(proc.pid, signal.SIGKILL)  # mid-stream, no chance to flush or close
    finally:
        proc.wait(timeout=5)
    assert proc.returncode == -signal.SIGKILL
    size = p.stat().st_size
    res = read_tlog(p)
    # every record is copied into the file's map in one piece, but a SIGKILL can land inside
    # that copy: at most the LAST record is cut off (one that never went out: a record is
    # whole before its packet is written), never a record in the middle (no corrupt stretch)
    # and never more than one record's bytes (8-byte stamp + a MAVLink 2 SET_ATTITUDE_TARGET
    # of at most 12 + 39 bytes); then the zeros of the mapped stretch, at most MAP_BYTES
    assert res.skipped_regions == 0 and res.truncated_tail_bytes < 8 + 12 + 39
    assert res.skipped_bytes == res.truncated_tail_bytes
    assert 0 < res.zero_tail_bytes <= MAP_BYTES
    assert res.counts == {"SET_ATTITUDE_TARGET": res.records}
    assert all(m.type_mask == 128 for _, m in res)
    # SET_ATTITUDE_TARGET v2, unsigned, trailing zeros trimmed: records have the sizes we decode
    assert (
        sum(8 + len(m.get_msgbuf()) for _, m in res)
        + res.truncated_tail_bytes
        + res.zero_tail_bytes
        == size
    )
    assert _pymavlink_messages(p) == res.records  # pymavlink's own reader agrees


def _pymavlink_messages(p: Path) -> int:
    """The messages pymavlink's tlog reader finds in p (a crash's zero tail: one BAD_DATA)."""
    ref = mavutil.mavlink_connection(str(p))
    n = 0
    while (m := ref.recv_msg()) is not None:
        n += m.get_type() != "BAD_DATA"
    ref.close()
    return n


SEND_THEN_DIE = textwrap.dedent(
    """
    import os, signal, socket, sys
    from mpf_mavlink.mavlink import dialect, open_link
    from mpf_mavlink.mavlink.encode import encode_set_attitude_target_rates
    link = open_link(sys.argv[2], tlog_path=sys.argv[1], vehicle_sysid=None)
    peer = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for k in range(int(sys.argv[3])):
        # a telemetry datagram in, its setpoint out (the bridge's frame), then the next
        tx.sendto(peer.attitude_encode(1000 + 20 * k, 0, 0, 0, 0, 0, 0).pack(peer),
                  ("127.0.0.1", link.conn.port.getsockname()[1]))
        while link.recv(1.0) is None:
            pass
        link.send(encode_set_attitude_target_rates(link.mav, 1000 + 20 * k, 1, 1, 0, 0, 0, 0.5))
    os.kill(os.getpid(), signal.SIGKILL)  # right after the last sendto: no close, no flush
    """
)


@pytest.mark.parametrize("frames", [1, 700])  # 700: past the first mapped stretch (64 kB)
def test_a_setpoint_sent_right_before_a_sigkill_is_in_the_tlog(tmp_path, frames):
    """The tlog's guarantee: a packet the link sent (and everything received before it) is in
    the file even if the process is killed the instant its sendto returns."""
    from mpf_mavlink.mavlink.url import free_udp_port

    p = tmp_path / "died.tlog"
    script = tmp_path / "die.py"
    script.write_text(SEND_THEN_DIE)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    url = f"udpin:127.0.0.1:{free_udp_port()}"
    proc = subprocess.run([sys.executable, str(script), str(p), url, str(frames)], env=env,
                          timeout=60)  # fmt: skip
    assert proc.returncode == -signal.SIGKILL
    res = read_tlog(p)
    assert res.counts == {"ATTITUDE": frames, "SET_ATTITUDE_TARGET": frames}
    assert res.skipped_regions == 0 and res.truncated_tail_bytes == 0
    assert 0 < res.zero_tail_bytes <= MAP_BYTES  # the unused end of the mapped stretch
    types = [m.get_type() for _, m in res]
    assert types == ["ATTITUDE", "SET_ATTITUDE_TARGET"] * frames  # in the order they happened
    assert res.messages[-1][1].time_boot_ms == 1000 + 20 * (frames - 1)
    assert _pymavlink_messages(p) == 2 * frames


def test_writer_fsyncs_in_the_background_not_in_write(tmp_path, monkeypatch):
    # fsync_every_s > 0: write() never calls fsync (a control loop that logs must not wait for
    # the disk); a background thread does, at most that often, and only after new records
    calls: list[tuple[str, int]] = []
    real_fsync = os.fsync

    def spy(fd: int) -> None:
        import threading

        calls.append((threading.current_thread().name, fd))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", spy)
    from mpf_mavlink.mavlink import dialect as mavlink

    pkt = mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3).pack(mavlink.MAVLink(None, 1, 191))
    w = TlogWriter(tmp_path / "bg.tlog", fsync_every_s=0.05)
    for k in range(20):
        w.write(pkt, 1_700_000_000.0 + k)
    assert calls == []  # nothing on the writer's thread
    t_end = time.monotonic() + 2.0
    while not calls and time.monotonic() < t_end:
        time.sleep(0.01)
    assert calls and all(name == "tlog-fsync" for name, _ in calls)
    n = len(calls)
    time.sleep(0.2)  # no new records: no new fsync
    assert len(calls) == n
    # the exact timestamp of the last record, as a reader computes it (us * 1e-6)
    w.write(pkt, 1_700_000_123.4567891)
    assert w.last_us == 1_700_000_123_456_789 and w.last_packet is pkt
    w.close()  # joins the thread, then one last fsync of its own
    assert calls[-1][0] == "MainThread"
    assert read_tlog(tmp_path / "bg.tlog").t_last_s == w.last_us * 1e-6


def test_writer_fsync_every_record_when_asked(tmp_path):
    from mpf_mavlink.mavlink import dialect as mavlink

    pkt = mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3).pack(mavlink.MAVLink(None, 1, 191))
    with TlogWriter(tmp_path / "each.tlog", fsync_every_s=0) as w:
        for k in range(5):
            w.write(pkt, 1_700_000_000.0 + k)
        assert w.fsyncs == 5 and w._syncer is None


def test_a_holding_writer_writes_at_flush_and_close(tmp_path):
    from mpf_mavlink.mavlink.tlog import HOLD_MAX_BYTES

    p = tmp_path / "held.tlog"
    pkt = bytes.fromhex("fd0900000001010000000000000000000000000000")  # any bytes: not parsed
    w = TlogWriter(p, hold=True)
    w.write(pkt, 1.7e9)
    w.write(pkt, 1.7e9 + 0.02)
    assert p.stat().st_size == 0 and w.records == 2  # held
    w.flush()
    assert p.stat().st_size == 2 * (8 + len(pkt))
    n = HOLD_MAX_BYTES // (8 + len(pkt)) + 1  # the cap writes them out without a flush
    for k in range(n):
        w.write(pkt, 1.7e9 + k)
    assert p.stat().st_size >= HOLD_MAX_BYTES
    w.write(pkt, 1.8e9)
    w.close()  # the rest
    assert p.stat().st_size == (n + 3) * (8 + len(pkt))


def test_the_link_writes_what_it_received_before_each_packet_it_sends(tmp_path):
    """The link holds received records and writes them with the next packet it sends (before the
    socket) or when it has nothing left to read: a SIGKILL between a send and the next cannot
    lose a record of anything received before a command went out."""
    import socket

    from mpf_mavlink.mavlink.url import free_udp_port

    port = free_udp_port()
    p = tmp_path / "link.tlog"
    link = open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=None, tlog_path=p)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        peer = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
        for k in range(3):
            tx.sendto(peer.attitude_encode(1000 + 20 * k, 0, 0, 0, 0, 0, 0).pack(peer),
                      ("127.0.0.1", port))  # fmt: skip
        got = []
        t_end = time.monotonic() + 5.0
        while len(got) < 3 and time.monotonic() < t_end:
            m = link.recv(0.0) if got else link.recv(0.5)
            if m is not None:
                got.append(m)
        assert len(got) == 3
        # the three were read back to back; nothing made the link pause or send yet: the
        # mapped tlog has them already (a holding one, where the file cannot be mapped, would
        # write them with the next packet sent)
        assert link.tlog is not None and link.tlog.mapped
        assert read_tlog(p).counts == {"ATTITUDE": 3}
        link.send(encode_set_attitude_target_rates(link.mav, 1040, 1, 1, 0.0, 0.0, 0.1, 0.5))
        res = read_tlog(p)
        assert res.counts == {"ATTITUDE": 3, "SET_ATTITUDE_TARGET": 1}
        assert [m.get_type() for _, m in res][-1] == "SET_ATTITUDE_TARGET"
    finally:
        tx.close()
        link.close()


def test_a_link_fsyncing_every_record_does_not_hold_them(tmp_path):
    # tlog_fsync_every_s 0 asks for every record on the disk at once: nothing may wait in memory
    from mpf_mavlink.mavlink.url import free_udp_port

    for every, mapped in ((0.0, False), (1.0, True), (None, True)):
        url = f"udpin:127.0.0.1:{free_udp_port()}"
        link = open_link(url, tlog_path=tmp_path / f"{every}.tlog", tlog_fsync_every_s=every)
        try:
            assert link.tlog is not None and link.tlog.mapped is mapped
            assert link.tlog._hold is not (every == 0.0)  # the fallback where it cannot map
        finally:
            link.close()


def _records(n: int, t0: float = 1.7e9) -> list[tuple[bytes, float]]:
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    return [(mav.attitude_encode(k, 0.1, 0.2, 0.3, 0, 0, 0).pack(mav), t0 + 0.02 * k)
            for k in range(n)]  # fmt: skip


def test_a_mapped_writer_writes_the_same_file_across_its_stretches(tmp_path):
    # > 3 mapped stretches of records, some of them appended to an existing file: the file
    # closed is byte for byte what one write() per record makes, nothing after it
    recs = _records(3 * MAP_BYTES // 44 + 100)
    ref, got = tmp_path / "ref.tlog", tmp_path / "mapped.tlog"
    with TlogWriter(ref) as w:
        for pkt, t in recs:
            w.write(pkt, t)
    half = len(recs) // 2
    with TlogWriter(got, mapped=True) as w:
        assert w.mapped
        for k, (pkt, t) in enumerate(recs[:half]):
            w.write(pkt, t)
            # as a link does at its pauses: often, and after bursts of several pages
            every = 3 if k < half // 2 else 400  # 400 records: 17.6 kB, over four pages
            if k % every == 0:
                w.ahead()
            if k == half // 3:
                w.fsync()  # the pages written back: ahead() makes them writable again
        assert got.stat().st_size > 44 * half  # mapped ahead of its records
    with TlogWriter(got, mapped=True, append=True) as w:
        for pkt, t in recs[half:]:
            w.write(pkt, t)
    assert got.read_bytes() == ref.read_bytes()
    assert read_tlog(got).zero_tail_bytes == 0


def test_a_mapped_writer_prepares_pages_beyond_its_records_only(tmp_path):
    # ahead() after a burst of several pages written without one (a parameter download read
    # back to back): the page it makes writable is past the records' end, never one of them
    recs = _records(400)  # 36-byte records: 14.4 kB, the byte at 4096 is a pitch byte (0x4C)
    ref, got = tmp_path / "ref.tlog", tmp_path / "burst.tlog"
    with TlogWriter(ref) as w:
        for pkt, t in recs:
            w.write(pkt, t)
    with TlogWriter(got, mapped=True) as w:
        w.write(*recs[0])
        w.ahead()
        for pkt, t in recs[1:]:
            w.write(pkt, t)
        w.ahead()
    assert ref.read_bytes()[4096] != 0
    assert got.read_bytes() == ref.read_bytes()


def test_a_mapped_writer_without_room_writes_instead(tmp_path, monkeypatch):
    # a full disk (no blocks to reserve for the next stretch) must never reach the map, where
    # it would be a SIGBUS: the writer goes on with write() from where its records end
    import errno

    recs = _records(2 * MAP_BYTES // 44)
    p = tmp_path / "full.tlog"
    w = TlogWriter(p, mapped=True)
    for pkt, t in recs[: len(recs) // 4]:
        w.write(pkt, t)
    assert w.mapped

    def no_room(fd: int, off: int, n: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "posix_fallocate", no_room)
    for pkt, t in recs[len(recs) // 4 :]:
        w.write(pkt, t)
    assert not w.mapped
    w.close()
    res = read_tlog(p)
    assert res.records == len(recs) and res.skipped_bytes == 0 and res.zero_tail_bytes == 0
    assert p.stat().st_size == sum(8 + len(pkt) for pkt, _ in recs)


def test_the_reader_takes_zeros_after_the_last_record_as_a_crash_tail(tmp_path):
    recs = _records(50)
    body = b"".join(struct.pack(">Q", round(t * 1e6)) + pkt for pkt, t in recs)
    p = tmp_path / "z.tlog"
    for tail, cut in ((4096, 0), (7, 0), (4096, 20)):
        data = body[: len(body) - cut] + bytes(tail)
        p.write_bytes(data)
        res = read_tlog(p)
        if cut:  # a record cut off by the crash, then zeros: a cut-off tail, not corruption
            assert res.records == 49 and res.skipped_regions == 0
            assert res.truncated_tail_bytes == len(body) - cut - (len(body) - 8 - len(recs[-1][0]))
            assert res.zero_tail_bytes == tail
        elif tail >= 8:
            assert (res.records, res.skipped_regions, res.zero_tail_bytes) == (50, 0, tail)
        else:  # fewer zeros than a time stamp: not a writer's tail, a cut-off record
            assert res.records == 50 and res.truncated_tail_bytes == tail
        assert _pymavlink_messages(p) == res.records
