"""Telemetry logs (.tlog): the format and a writer that survives SIGKILL (the reader that survives
corruption is :mod:`.tlog_read`, which a flight that only records does not load).

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
from collections.abc import Callable

from mpf_mavlink.errors import MpfError

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
