"""Reading telemetry logs (.tlog, the format of :mod:`.tlog`) in a way that survives corruption:
corrupt stretches skipped and counted, a truncated tail and a mapped writer's zeros accounted for.
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from pymavlink.generator.mavcrc import x25crc

from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink.pymav import dialect as _d
from mpf_mavlink.mavlink.tlog import (
    _MAX_RECORD,
    _SIGNED,
    _TS,
    STX_V1,
    STX_V2,
    TS_MAX_US,
    TS_MIN_US,
)


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
