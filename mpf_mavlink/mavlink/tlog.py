"""Telemetry logs (.tlog): a writer that survives SIGKILL and a reader that survives corruption.

Format (MAVProxy / Mission Planner / QGroundControl): a sequence of records, each an 8-byte
big-endian unsigned count of microseconds since the Unix epoch (wall-clock time of the event,
some writers put a link number in the low 2 bits) followed by one raw MAVLink v1 (0xFE) or v2
(0xFD) packet. There is no file header and no index, so a reader must find record boundaries
from the packet headers themselves.
"""

from __future__ import annotations

import math
import mmap
import os
import struct
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from pymavlink.generator.mavcrc import x25crc

from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink.pymav import dialect as _d

STX_V1 = 0xFE
STX_V2 = 0xFD
_TS = struct.Struct(">Q")
_TS_PACK = _TS.pack
# plausible record timestamps: 2000-01-01 .. 2100-01-01 (us since the Unix epoch)
TS_MIN_US = 946_684_800_000_000
TS_MAX_US = 4_102_444_800_000_000
_SIGNED = 0x01  # MAVLINK_IFLAG_SIGNED
_MAX_RECORD = 8 + 10 + 255 + 2 + 13  # time stamp + the longest MAVLink 2 packet (bytes)
#: A holding writer (TlogWriter(hold=True)) writes its records out at this many bytes at most.
HOLD_MAX_BYTES = 16384
#: A mapped writer (TlogWriter(mapped=True)) maps the file this many bytes at a time: the most
#: of zeros a crash can leave after its last record (pymavlink's reader and ours skip them).
MAP_BYTES = 65536
_PAGE = mmap.PAGESIZE


class TlogWriter:
    """Append MAVLink packets to a tlog, one ``os.write`` per record.

    The file is opened unbuffered, so a record is in the kernel's page cache as soon as
    :meth:`write` returns: a SIGKILL of this process cannot lose or half-write it. A power cut
    can; ``fsync_every_s`` decides how much: 0 fsyncs after every record (on the caller's
    thread, so its latency), > 0 fsyncs at most that often (wall time) from a background
    thread when records were written since the last one, so a control loop that logs never
    waits for the disk; None (default) leaves it to the OS.

    ``hold``: records wait in memory until :meth:`flush` (or :data:`HOLD_MAX_BYTES` of them,
    or :meth:`close`), which writes them in one ``os.write``: a link that flushes before each
    packet it sends and whenever it has nothing left to read (:class:`~.link.Link`) writes a
    control frame's records in one system call instead of one each, and a SIGKILL still never
    loses a record of anything that was sent (only the records received since the link's last
    send or pause, whose answer had not gone out).

    ``mapped``: records are copied into a shared memory map of the file (:data:`MAP_BYTES` at a
    time, its disk blocks reserved first with ``posix_fallocate``) instead of written: a record
    is in the kernel's page cache once :meth:`write` returns, as with ``os.write``, for the
    cost of a copy (a control frame's records no longer wait for a system call before the
    setpoint they answer goes out). A SIGKILL keeps every record written; the file then ends
    in up to :data:`MAP_BYTES` of zeros, which :func:`iter_tlog` counts as
    ``zero_tail_bytes`` and pymavlink's reader passes as one BAD_DATA. :meth:`close`
    truncates the file to its records. :meth:`ahead` (called after a packet went out) touches
    the next page and maps the next stretch, so that the page faults and the mapping happen
    off the path between a telemetry datagram and its setpoint. With ``fsync_every_s`` 0, or
    where the file cannot be mapped or its blocks reserved (a full disk), records are
    written as without it (``mapped`` reads False then): a full disk never reaches the map,
    where it would be a SIGBUS instead of an error.

    ``last_us`` / ``last_packet``: timestamp (us) and packet of the latest record, so that a
    caller can use the exact time a reader will see (``last_us * 1e-6`` s).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        append: bool = False,
        fsync_every_s: float | None = None,
        clock: Callable[[], float] = time.time,
        hold: bool = False,
        mapped: bool = False,
    ) -> None:
        self.path = os.fspath(path)
        self._hold = hold
        self._held = bytearray()
        self._clock = clock
        self._fsync_every_s = fsync_every_s
        mapped = mapped and fsync_every_s != 0
        # a mapping needs the file open for reading too; it writes at offsets, not appends
        flags = (os.O_RDWR if mapped else os.O_WRONLY) | os.O_CREAT
        flags |= os.O_TRUNC if not append else 0 if mapped else os.O_APPEND
        try:
            self._fd: int | None = os.open(self.path, flags, 0o644)
        except OSError as e:
            raise MpfError(f"cannot open tlog {self.path} for writing: {e.strerror}") from None
        self._map: mmap.mmap | None = None
        self._base = 0  # file offset of the map's first byte
        self._pos = os.lseek(self._fd, 0, os.SEEK_END)  # file offset of the records' end
        self._touched = 0  # map offset from which the pages were not written to yet
        self._synced = False  # an fsync wrote the pages back since ahead() last ran
        if mapped:
            self._remap()
        self.records = 0
        self.bytes = 0
        self.fsyncs = 0
        self.last_us: int | None = None
        self.last_packet: bytes | bytearray | None = None
        self._dirty = False
        self._stop = threading.Event()
        self._syncer: threading.Thread | None = None
        if fsync_every_s is not None and fsync_every_s > 0:
            self._syncer = threading.Thread(target=self._sync_loop, name="tlog-fsync", daemon=True)
            self._syncer.start()

    def write(self, packet: bytes | bytearray, t_unix_s: float | None = None) -> None:
        """Log one raw packet. ``t_unix_s``: wall-clock time of the event (s since the epoch);
        None takes it from the writer's clock."""
        if self._fd is None:
            raise MpfError(f"tlog {self.path} is closed")
        t = self._clock() if t_unix_s is None else float(t_unix_s)
        if not 0.0 <= t < math.inf:  # NaN fails the comparison too
            raise ValueError(f"tlog timestamp must be a finite time >= 0, got {t_unix_s!r}")
        us = round(t * 1e6)
        self.records += 1
        self.bytes += 8 + len(packet)
        self.last_us, self.last_packet = us, packet
        m = self._map
        if m is not None:
            off = self._pos - self._base
            end = off + 8 + len(packet)
            if end > MAP_BYTES:
                self._remap()
                m = self._map
                if m is None:  # no longer mapped (no room): written
                    self._write(_TS_PACK(us) + bytes(packet))
                    return
                off = self._pos - self._base
                end = off + 8 + len(packet)
            # one copy: a process killed in it leaves at most this record cut off
            m[off:end] = _TS_PACK(us) + packet
            self._pos += end - off
            self._dirty = True
            return
        if self._hold:
            held = self._held
            held += _TS_PACK(us)
            held += packet
            if len(held) >= HOLD_MAX_BYTES:
                self.flush()
            return
        self._write(_TS_PACK(us) + bytes(packet))

    @property
    def mapped(self) -> bool:
        """Whether records go into a memory map of the file (``mapped``) now."""
        return self._map is not None

    def ahead(self) -> None:
        """A mapped writer: make the page after the records' end writable now (its page fault:
        ~1 every 4 kB of records, and again after an fsync cleaned the pages) and map the next
        stretch of the file when the records near the end of this one, so that neither happens
        inside :meth:`write`. Otherwise nothing."""
        m = self._map
        if m is None:
            return
        off = self._pos - self._base
        if self._synced:  # written back: the pages from the records' end on fault again
            self._synced = False
            self._touched = off
        t = max(self._touched, off)  # never below the records' end: those bytes are records
        if t > off + _PAGE:
            return
        if t < MAP_BYTES:
            m[t] = 0  # beyond the records: a zero where a zero was
            self._touched = t - t % _PAGE + _PAGE
        elif off + 2 * _PAGE > MAP_BYTES:
            self._remap()

    def _remap(self) -> None:
        """Map MAP_BYTES of the file from the page holding the records' end, its blocks
        reserved first. Falls back to writing (the map dropped, the file cut to its records)
        when that fails: the disk is full, or the file cannot be mapped."""
        assert self._fd is not None
        old, self._map = self._map, None
        if old is not None:
            old.close()
        base = self._pos - self._pos % mmap.ALLOCATIONGRANULARITY
        try:
            os.posix_fallocate(self._fd, base, MAP_BYTES)  # not on macOS: AttributeError
            self._map = mmap.mmap(self._fd, MAP_BYTES, offset=base)
        except (OSError, ValueError, AttributeError):
            try:
                os.ftruncate(self._fd, self._pos)
                os.lseek(self._fd, self._pos, os.SEEK_SET)
            except OSError:
                pass
            return
        self._base = base
        self._touched = self._pos - base  # map offset from which pages were not written to

    def _write(self, rec: bytes | bytearray) -> None:
        assert self._fd is not None
        n = os.write(self._fd, rec)
        while n < len(rec):  # regular files write fully; loop only on exotic filesystems
            n += os.write(self._fd, rec[n:])
        self._pos += len(rec)
        if self._fsync_every_s == 0:
            os.fsync(self._fd)
            self.fsyncs += 1
        else:
            self._dirty = True

    def _sync_loop(self) -> None:
        """Background fsync: os.fsync releases the GIL, so the writer thread runs meanwhile."""
        period = float(self._fsync_every_s or 1.0)
        while not self._stop.wait(period):
            if not self._dirty:
                continue
            self._dirty = False
            fd = self._fd
            if fd is None:
                return
            try:
                os.fsync(fd)
                self.fsyncs += 1
                self._synced = True
            except OSError:  # a full or vanished disk: the records are still in the page cache
                pass

    def flush(self) -> None:
        """Write the held records (``hold``); nothing is buffered otherwise. A failed write
        drops them (OSError raised: the caller counts the loss) rather than retry them for
        ever."""
        if not self._held or self._fd is None:
            return
        rec, self._held = self._held, bytearray()
        self._write(rec)

    def fsync(self) -> None:
        if self._fd is not None:
            os.fsync(self._fd)
            self.fsyncs += 1
            self._synced = True

    def close(self) -> None:
        # stop the syncer before the fd goes: it must never fsync a closed (or reused) fd
        self._stop.set()
        if self._syncer is not None:
            self._syncer.join()
            self._syncer = None
        if self._fd is not None:
            try:
                self.flush()
            except OSError:
                pass
            if self._map is not None:  # the file ends where its records do
                self._map.close()
                self._map = None
                try:
                    os.ftruncate(self._fd, self._pos)
                except OSError:
                    pass
            try:
                os.fsync(self._fd)
            except OSError:
                pass
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---------------------------------------------------------------------------------------------
# Reader
# ---------------------------------------------------------------------------------------------
@dataclass
class TlogStats:
    records: int = 0  # good records yielded or counted
    skipped_regions: int = 0  # corrupt stretches skipped (each ends at a resync point)
    skipped_bytes: int = 0  # bytes inside those stretches, the truncated tail included
    truncated_tail_bytes: int = 0  # bytes at the end too short to hold the record they start
    unknown_msgids: int = 0  # records whose message id this dialect does not know (no CRC check)
    # zeros after the last record: the unused end of a mapped writer's file after a crash
    zero_tail_bytes: int = 0
    counts: Counter[str] = field(default_factory=Counter)  # message type -> good records
    t_first_s: float | None = None
    t_last_s: float | None = None


@dataclass
class TlogReadResult:
    path: str
    messages: list[tuple[float, Any]]  # (timestamp s since the epoch, pymavlink message)
    counts: dict[str, int]  # message type -> good records (all types, even if not in messages)
    records: int  # good records
    skipped_regions: int  # corrupt stretches skipped ("skipped records")
    skipped_bytes: int
    truncated_tail_bytes: int
    unknown_msgids: int
    t_first_s: float | None
    t_last_s: float | None
    elapsed_s: float  # wall time the read took
    zero_tail_bytes: int = 0  # zeros after the last record (a mapped writer's, after a crash)

    def __iter__(self) -> Iterator[tuple[float, Any]]:
        return iter(self.messages)

    def __len__(self) -> int:
        return len(self.messages)

    @property
    def duration_s(self) -> float:
        if self.t_first_s is None or self.t_last_s is None:
            return 0.0
        return self.t_last_s - self.t_first_s


def _packet_len(data: bytes | memoryview, p: int) -> int:
    """Length of the MAVLink packet whose STX is at p (caller checked that 3 bytes exist)."""
    if data[p] == STX_V1:
        return 6 + data[p + 1] + 2
    return 10 + data[p + 1] + 2 + (13 if data[p + 2] & _SIGNED else 0)


def _msgid(pkt: bytes) -> int:
    if pkt[0] == STX_V1:
        return pkt[5]
    return pkt[7] | (pkt[8] << 8) | (pkt[9] << 16)


def _crc_ok(pkt: bytes, msgid: int) -> bool | None:
    """True/False for known ids; None when the id is unknown (no CRC_EXTRA to check with)."""
    cls = _d.mavlink_map.get(msgid)
    if cls is None:
        return None
    sig = 13 if (pkt[0] == STX_V2 and pkt[2] & _SIGNED) else 0
    end = len(pkt) - 2 - sig
    crc = x25crc(pkt[1:end])
    crc.accumulate(bytes((cls.crc_extra,)))
    return bool(crc.crc == (pkt[end] | (pkt[end + 1] << 8)))


def _valid_header(data: bytes, i: int, n: int) -> tuple[int, int] | None:
    """(timestamp_us, packet_len) if a record plausibly starts at i, else None."""
    if i + 8 + 3 > n:
        return None
    stx = data[i + 8]
    if stx != STX_V1 and stx != STX_V2:
        return None
    ts = _TS.unpack_from(data, i)[0]
    if not TS_MIN_US <= ts <= TS_MAX_US:
        return None
    # an unknown incompat flag: not MAVLink 2 as we know it
    if stx == STX_V2 and data[i + 10] & ~_SIGNED:
        return None
    return ts, _packet_len(data, i + 8)


def _resync(data: bytes, start: int, n: int) -> int:
    """First offset >= start where a complete record with a known id and a good CRC begins
    (n if none). Candidates are found by scanning for the STX bytes with bytes.find."""
    p = start + 8
    while True:
        a = data.find(b"\xfe", p)
        b = data.find(b"\xfd", p)
        cands = [x for x in (a, b) if x >= 0]
        if not cands:
            return n
        s = min(cands)
        i = s - 8
        hdr = _valid_header(data, i, n)
        if hdr is not None:
            plen = hdr[1]
            if i + 8 + plen <= n:
                pkt = data[s : s + plen]
                if _crc_ok(pkt, _msgid(pkt)):
                    return i
        p = s + 1


def _count_skip(st: TlogStats, i: int, j: int, n: int, zeros: int) -> None:
    """Count in ``st`` the bytes [i, j) skipped of a tlog of ``n`` bytes whose trailing zeros
    begin at ``zeros``."""
    if j >= n and n - zeros and zeros - i <= _MAX_RECORD:
        # the record a crashed mapped writer was copying when it died, then its zeros: a
        # cut-off tail (never sent: a record is whole before its packet leaves), not a
        # corrupt stretch
        st.truncated_tail_bytes += zeros - i
        st.skipped_bytes += zeros - i
        st.zero_tail_bytes += n - zeros
        return
    st.skipped_regions += 1
    st.skipped_bytes += j - i
    if j >= n:  # nothing decodable after i: a cut-off or garbled end of file
        st.truncated_tail_bytes += n - i


def iter_tlog(
    path: str | os.PathLike[str],
    *,
    types: Iterable[str] | None = None,
    stats: TlogStats | None = None,
) -> Iterator[tuple[float, Any]]:
    """Yield ``(timestamp_s, msg)`` for every good record (``msg._timestamp`` is set too).

    ``types``: only decode (and yield) these message types; the others are still framed and
    CRC-checked and appear in ``stats.counts``, which is much faster for replay.
    Corrupt stretches are skipped and counted in ``stats``; never raises on content.
    """
    p = os.fspath(path)
    try:
        with open(p, "rb") as f:
            data = f.read()
    except OSError as e:
        raise MpfError(f"cannot read tlog {p}: {e.strerror}") from None
    st = stats if stats is not None else TlogStats()
    want: set[int] | None = None
    if types is not None:
        names = {t.upper() for t in types}
        want = {mid for mid, cls in _d.mavlink_map.items() if cls.msgname in names}
    mav = _d.MAVLink(None)
    mmap = _d.mavlink_map
    counts = st.counts
    n = len(data)
    # where the file's trailing zeros begin: a record never starts there (its time stamp is
    # not 0), so a record boundary at or past it is the end of a crashed mapped writer's records
    zeros = len(data.rstrip(b"\0"))
    if n - zeros < 8:  # fewer than a time stamp's: the end of a record (a CRC byte), or cut
        zeros = n
    i = 0
    while i < n:
        if i >= zeros:
            st.zero_tail_bytes += n - i
            break
        hdr = _valid_header(data, i, n)
        end = i + 8 + hdr[1] if hdr is not None else n + 1
        if hdr is None or end > n:
            j = _resync(data, i + 1, n)
            _count_skip(st, i, j, n, zeros)
            i = j
            continue
        pkt = data[i + 8 : end]
        mid = _msgid(pkt)
        ok = _crc_ok(pkt, mid)
        if ok is None:
            # unknown id: no CRC to trust, so accept the framing only if the next record
            # starts where this one ends (or the file ends there)
            if end == n or _valid_header(data, end, n) is not None:
                st.unknown_msgids += 1
                counts[f"UNKNOWN_{mid}"] += 1
                i = end
                continue
            ok = False
        if not ok:
            j = _resync(data, i + 1, n)
            _count_skip(st, i, j, n, zeros)
            i = j
            continue
        t = hdr[0] * 1e-6
        counts[mmap[mid].msgname] += 1
        st.records += 1
        if st.t_first_s is None:
            st.t_first_s = t
        st.t_last_s = t
        i = end
        if want is not None and mid not in want:
            continue
        try:
            msg = mav.decode(bytearray(pkt))
        except Exception:  # noqa: BLE001 - CRC passed but the payload is unusable
            continue
        msg._timestamp = t
        yield t, msg


def read_tlog(
    path: str | os.PathLike[str], *, types: Iterable[str] | None = None
) -> TlogReadResult:
    """Read a whole tlog; see :func:`iter_tlog`. Raises MpfError only if the file cannot be read."""
    t0 = time.perf_counter()
    st = TlogStats()
    msgs = list(iter_tlog(path, types=types, stats=st))
    return TlogReadResult(
        path=os.fspath(path),
        messages=msgs,
        counts=dict(st.counts),
        records=st.records,
        skipped_regions=st.skipped_regions,
        skipped_bytes=st.skipped_bytes,
        truncated_tail_bytes=st.truncated_tail_bytes,
        unknown_msgids=st.unknown_msgids,
        t_first_s=st.t_first_s,
        t_last_s=st.t_last_s,
        elapsed_s=time.perf_counter() - t0,
        zero_tail_bytes=st.zero_tail_bytes,
    )
