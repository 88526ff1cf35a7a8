"""What a link writes and counts: its packets to the socket, every packet both ways to its tlog.

The tlog is written ahead of the socket: a process killed between the two (SIGKILL) never leaves
a packet the vehicle received out of the record (a packet the socket then refuses stays in the
tlog, counted in ``io_errors``).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mpf_mavlink.mavlink.tlog import TlogWriter


@dataclass
class LinkCounters:
    """What a link received, refused and sent (counts)."""

    rx_packets: int = 0  # frames with a good CRC (before filtering)
    rx_by_type: Counter[str] = field(default_factory=Counter)  # accepted messages by type
    tx_packets: int = 0
    tx_by_type: Counter[str] = field(default_factory=Counter)
    bad_data: int = 0  # framing / CRC / length errors (pymavlink BAD_DATA)
    rejected_sysid: int = 0  # from a system/component we were not told to trust ("spoofed ids")
    rejected_by_source: Counter[tuple[int, int]] = field(
        default_factory=Counter
    )  # (sysid, compid) -> count
    rejected_unsigned: int = 0  # unsigned while signing is on
    rejected_bad_signature: int = 0  # signed, but wrong key / forged
    rejected_replay: int = 0  # right key, timestamp not newer than the stream's last one
    rejected_identity: int = 0  # HEARTBEAT from the autopilot's ids claiming another autopilot type
    rejected_time: int = 0  # vehicle time_boot_ms inconsistent with its clock (absurd, or a reboot)
    rejected_stale: int = (
        0  # vehicle sample not newer than the last of its type (reordered, duplicate)
    )
    clock_resets: int = 0  # the vehicle's boot clock restarted (a reboot) and was adopted
    clock_settling: int = 0  # samples dropped before the vehicle's clock was established
    unknown_msgid: int = 0  # ids this dialect does not know (CRC cannot be checked)
    io_errors: int = 0
    tlog_write_errors: int = 0  # records the tlog could not take (disk full, I/O error): lost

    def as_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["rx_by_type"] = dict(self.rx_by_type)
        d["tx_by_type"] = dict(self.tx_by_type)
        d["rejected_by_source"] = {f"{s}/{c}": n for (s, c), n in self.rejected_by_source.items()}
        return d


class VehicleTimeStamps:
    """Record times (s since the epoch) that follow the vehicle's boot clock, for a link to a
    lockstep simulation (``mavlink.lockstep``): its time runs at whatever speed the host allows,
    so wall-clock record times would squeeze a minute of flight into the seconds it took to
    compute, and every MAVLink log tool (mavflightmodes, mavsummarize, MAVExplorer) would report
    those seconds. Here a record's time is the wall time of the first time-stamped vehicle
    sample plus the vehicle time elapsed since (``time_boot_ms``); untimed messages (HEARTBEAT,
    VFR_HUD, the target's, ours) take the latest vehicle instant. Only samples the boot-clock
    gate did not reject as another clock move it (:meth:`commit`), it never goes back, and one
    sample moves it by at most ``max_step_s``: a forged time stays a rejected sample instead of
    becoming "now". A real autopilot's link keeps wall-clock record times."""

    def __init__(self, wall: Callable[[], float] = time.time, max_step_s: float = 5.0) -> None:
        self._wall = wall
        self.max_step_s = float(max_step_s)
        self.offset: float | None = None  # record time - vehicle boot time (s)
        self.t_last: float | None = None  # the latest committed instant (s since the epoch)

    def now(self) -> float:
        """The latest vehicle instant as a record time (the wall clock before any sample)."""
        return self._wall() if self.t_last is None else self.t_last

    def stamp(self, t_boot_s: float | None) -> float:
        """The record time of a message stamped ``t_boot_s`` (s, vehicle boot clock; None for
        an untimed message)."""
        if t_boot_s is None or not math.isfinite(t_boot_s):
            return self.now()
        if self.offset is None or self.t_last is None:
            self.offset = self._wall() - t_boot_s
            self.t_last = self.offset + t_boot_s
            return self.t_last
        t = self.offset + t_boot_s
        return min(t, self.t_last + self.max_step_s) if t > self.t_last else self.t_last

    def commit(self, t: float) -> None:
        """A sample stamped ``t`` (from :meth:`stamp`) was accepted: time moves on to it."""
        self.t_last = t if self.t_last is None else max(self.t_last, t)


class LinkRecord:
    """A link's record times (s since the epoch: its clock, or the vehicle's in lockstep) and
    its tlog; a failed tlog write is counted in ``counters``, never raised into the loop."""

    def __init__(
        self,
        tlog: TlogWriter | None,
        clock: Callable[[], float],
        counters: LinkCounters,
        vehicle_time: bool,
    ) -> None:
        self.tlog = tlog
        self._clock = clock
        self.counters = counters
        self.vehicle_time = VehicleTimeStamps(clock) if vehicle_time else None
        self.last_tx_s: float | None = None  # record time (s) of the latest packet sent

    def clock(self) -> float:
        return float(self._clock())

    def rx(self, msg: Any, tb_s: float | None) -> float:
        """Stamp ``msg`` (its vehicle time ``tb_s``, s, or None) with its receive time and
        write it to the tlog; the time (s)."""
        # one receive time for the record and the clock gate, quantised as the tlog stores it
        # (us): a replay of the tlog can then take exactly the gate's decisions
        vt = self.vehicle_time
        t_rec: float = round((self._clock() if vt is None else vt.stamp(tb_s)) * 1e6) * 1e-6
        # the receive time a consumer sees, with or without a tlog: the record's time exactly
        msg._timestamp = t_rec
        if self.tlog is not None:
            try:
                self.tlog.write(msg.get_msgbuf(), t_rec)
            except (OSError, ValueError):
                self._failed()
        return t_rec

    def tx(self, packet: bytes | bytearray, flush: bool = True) -> None:
        """Log one packet about to be written; ``flush``: the held records go in the file
        first (write-ahead)."""
        vt = self.vehicle_time
        t = self._clock() if vt is None else vt.now()
        # what a tlog reader computes from its microseconds, kept with or without a tlog
        self.last_tx_s = round(t * 1e6) * 1e-6
        if self.tlog is None:
            return
        try:
            self.tlog.write(packet, t)
            if flush:
                self.tlog.flush()
        except (OSError, ValueError):
            self._failed()

    def flush(self) -> None:
        if self.tlog is None:
            return
        try:
            self.tlog.flush()
        except (OSError, ValueError):
            self._failed()

    def idle(self) -> None:
        """Nothing left to read: the held records go out now, and a mapped tlog's next page
        is made ready (off any path)."""
        if self.tlog is not None:
            self.flush()
            self.tlog.ahead()

    def close(self) -> None:
        if self.tlog is not None:
            self.flush()  # held records: a failed write is counted, not lost unseen
            self.tlog.close()

    def _failed(self) -> None:
        self.counters.io_errors += 1
        self.counters.tlog_write_errors += 1


class _LogThenWrite:
    """Stands in for ``mav.file`` during one send: logs the packed bytes, then writes them."""

    def __init__(self, file: Any, log: Callable[[bytes | bytearray], None]) -> None:
        self._file, self._log = file, log

    def write(self, buf: bytes | bytearray) -> Any:
        self._log(buf)
        return self._file.write(buf)


def _pack(mav: Any, msg: Any) -> bytes | None:
    """The unsigned packet pymavlink's ``mav.send(msg)`` would write (its packer, ``mav``'s
    sequence number and ids), without writing it; None when ``mav.send`` must do it itself
    (signing, a send callback). Does not advance ``mav.seq`` (:func:`_sent` does)."""
    if mav.signing.sign_outgoing or mav.send_callback is not None:
        return None
    return bytes(msg.pack(mav))


def _sent(mav: Any, buf: bytes) -> None:
    """The bookkeeping pymavlink's ``MAVLink.send`` does after writing ``buf``."""
    mav.seq = (mav.seq + 1) % 256
    mav.total_packets_sent += 1
    mav.total_bytes_sent += len(buf)


def _advance_signing_timestamp(mav: Any) -> None:
    """MAVLink signing timestamps are 10 us ticks since 2015-01-01 and must follow the wall
    clock: pymavlink only adds 1 per packet, so a long session would fall behind and a rebooted
    autopilot would reject us as a stale stream (> 60 s old)."""
    now_ticks = int((time.time() - 1420070400) * 100_000)
    mav.signing.timestamp = max(mav.signing.timestamp, now_ticks)


class LinkSender:
    """Packs (MAVLink 2, signed when ``signing_enabled``), logs and writes a link's packets
    through pymavlink's connection ``conn``; ``udp``: ``conn`` is a ``mavudp``."""

    def __init__(self, conn: Any, record: LinkRecord, counters: LinkCounters, udp: bool) -> None:
        self.conn, self.record, self.counters, self._udp = conn, record, counters, udp
        self.signing_enabled = False  # set by signing.enable_signing
        self._tx_file: _LogThenWrite | None = None  # mav.file during a send

    def send(self, msg: Any) -> None:
        mav = self.conn.mav
        if self.signing_enabled:
            _advance_signing_timestamp(mav)
        buf = _pack(mav, msg)
        if buf is None:  # signed (or a send callback): pymavlink packs and writes
            if not self._send_pymavlink(mav, msg):
                return
        else:
            self.record.tx(buf)
            try:
                self._write(buf)
            except OSError:
                self.counters.io_errors += 1
                return
            _sent(mav, buf)
        self.counters.tx_packets += 1
        self.counters.tx_by_type[msg.get_type()] += 1

    def send_many(self, msgs: list[Any]) -> None:
        """Several messages in one write (on UDP one datagram, as PX4 bundles its telemetry)
        and one tlog write: a burst that wakes the peer once, not once per packet. Packed,
        logged and counted as :meth:`send` does; with signing on they go one by one."""
        mav = self.conn.mav
        bufs: list[bytes] = []
        for i, msg in enumerate(msgs):
            buf = None if self.signing_enabled else _pack(mav, msg)
            if buf is None:  # pymavlink must send this one: it and the rest one by one
                self._send_bufs(bufs, msgs[:i])
                for m in msgs[i:]:
                    self.send(m)
                return
            _sent(mav, buf)  # the next packet's sequence number
            bufs.append(buf)
        self._send_bufs(bufs, msgs)

    def _send_bufs(self, bufs: list[bytes], msgs: list[Any]) -> None:
        """Log then write packed ``bufs`` (of ``msgs``) in one go."""
        if not bufs:
            return
        for buf in bufs:
            self.record.tx(buf, flush=False)
        self.record.flush()  # write-ahead, as send
        try:
            self._write(b"".join(bufs))
        except OSError:
            self.counters.io_errors += 1
            return
        self.counters.tx_packets += len(bufs)
        for msg in msgs:
            self.counters.tx_by_type[msg.get_type()] += 1

    def _send_pymavlink(self, mav: Any, msg: Any) -> bool:
        """pymavlink packs (seq, signing) and hands the bytes to ``mav.file.write``: they are
        logged there, before the socket (write-ahead, as :meth:`send`). False: not written."""
        file = mav.file
        tx = self._tx_file
        if tx is None or tx._file is not file:
            tx = self._tx_file = _LogThenWrite(file, self.record.tx)
        mav.file = tx
        try:
            mav.send(msg)
        except OSError:
            self.counters.io_errors += 1
            return False
        finally:
            mav.file = file
        return True

    def _write(self, buf: bytes) -> None:
        """Write one packet as pymavlink's connection would (a UDP server: to every client it
        heard from; a refused datagram is dropped, as mavudp does)."""
        conn = self.conn
        if self._udp and conn.udp_server:
            clients = conn.clients
            if len(clients) == 1:
                for addr in clients:
                    try:
                        conn.port.sendto(buf, addr)
                    except OSError:
                        pass
                return
        conn.write(buf)
