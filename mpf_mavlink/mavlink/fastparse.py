"""A decoder for the few message types that make up nearly all of a vehicle's telemetry
datagrams (ATTITUDE and LOCAL_POSITION_NED every frame, then GLOBAL_POSITION_INT, VFR_HUD,
ATTITUDE_TARGET, FOLLOW_TARGET, ...), used by the UDP link before pymavlink's parser.

pymavlink's byte-stream parser costs ~7 us a message (a method call per parsing stage, a header
object, the payload copied three times). Here a datagram's frames are checked and decoded in one
pass from its start: a frame must be MAVLink 2, unsigned (no incompatibility flag), of a hot
type, whole within the datagram, no longer than the type's payload, with the right CRC
(CRC_EXTRA read from the pymavlink dialect's message classes). The first frame that is anything
else (MAVLink 1, signed, another type, a bad CRC, truncated, garbage) ends the pass: from there
on the datagram goes to pymavlink (:meth:`HotDecoder.decode` says where), which then sees the
bytes its own parser would hold after those frames. The messages made are pymavlink's own
classes with the attributes pymavlink's ``MAVLink.decode`` sets (tests/test_fastparse.py
compares them), so every consumer sees the same objects."""

from __future__ import annotations

import binascii
import struct
from collections.abc import Callable
from typing import Any

from mpf_mavlink.mavlink.pymav import dialect

_REV = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))  # bit reversal of a byte


def _mcrf4xx_hqx(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/MCRF4XX as CRC-CCITT (``binascii.crc_hqx``, in C) on bit-reversed bytes."""
    c = binascii.crc_hqx(data.translate(_REV), _REV[crc >> 8] | (_REV[crc & 0xFF] << 8))
    return (_REV[c & 0xFF] << 8) | _REV[c >> 8]


def _crc_function() -> Callable[[bytes, int], int]:
    try:  # what pymavlink itself uses when its wheel brought it
        from fastcrc.crc16 import mcrf4xx

        return mcrf4xx
    except ImportError:  # pragma: no cover - exercised only without fastcrc
        return _mcrf4xx_hqx


_mcrf4xx = _crc_function()


#: Types decoded here; every other type goes through pymavlink.
HOT_TYPES = (
    "ATTITUDE",
    "LOCAL_POSITION_NED",
    "GLOBAL_POSITION_INT",
    "ATTITUDE_TARGET",
    "VFR_HUD",
    "FOLLOW_TARGET",
    "HEARTBEAT",
    "TIMESYNC",
    "SYS_STATUS",
    "WIND_COV",
    "ATTITUDE_QUATERNION",
    "HOME_POSITION",
)

_STX2 = 0xFD
_HEADER_LEN = 10  # stx, len, incompat, compat, seq, sys, comp, msgid (3 bytes)


class _Type:
    """One message class: its payload layout, CRC extra and how pymavlink orders its fields."""

    __slots__ = ("cls", "size", "unpacker", "crc_extra", "names", "order", "arrays", "base")

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.unpacker = cls.unpacker
        self.size = int(cls.unpacker.size)
        self.crc_extra = bytes((int(cls.crc_extra),))
        self.names = tuple(cls.fieldnames)
        lengths = list(cls.lengths)
        # pymavlink's MAVLink.decode: field i (declared order) is t[order[i]] when the message
        # has no arrays, else the slice of the struct's values at the field's wire offset
        self.order = tuple(cls.orders)
        self.arrays: tuple[tuple[int, int], ...] | None = None
        if sum(lengths) != len(lengths):
            self.arrays = tuple((sum(lengths[:o]), lengths[o]) for o in cls.orders)
        # what the generated constructor sets besides the fields (ids, names, instance info)
        proto = cls(*[[0] * n if n > 1 else 0 for n in self._declared_lengths(cls)])
        self.base = {k: v for k, v in vars(proto).items() if k not in self.names}

    @staticmethod
    def _declared_lengths(cls: Any) -> list[int]:
        lengths = list(cls.lengths)
        return [lengths[o] for o in cls.orders]


def _has_text(cls: Any) -> bool:
    """Whether the payload carries characters (pymavlink strips their NULs: not done here)."""
    fmt = cls.unpacker.format
    fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
    return "s" in fmt or "c" in fmt


def _table() -> dict[int, _Type]:
    out: dict[int, _Type] = {}
    for cls in dialect.mavlink_map.values():
        if cls.msgname in HOT_TYPES and not _has_text(cls):
            out[int(cls.id)] = _Type(cls)
    return out


class HotDecoder:
    """Decodes the leading hot, unsigned MAVLink 2 frames of a datagram (module docstring)."""

    def __init__(self) -> None:
        self.types = _table()
        self._new_header = dialect.MAVLink_header
        self._crc_unpack = struct.Struct("<H").unpack_from

    def decode(self, data: bytes) -> tuple[list[Any], int]:
        """(messages, end): the datagram's leading hot frames as messages, in order, and the
        offset where they end (``len(data)``: all of it; pymavlink parses the rest). Never
        raises."""
        out: list[Any] = []
        try:
            return out, self._decode(data, out)
        except Exception:  # noqa: BLE001 - any doubt: pymavlink decides (and counts)
            return [], 0

    def _decode(self, data: bytes, out: list[Any]) -> int:
        types, n, i = self.types, len(data), 0
        while i < n:
            if data[i] != _STX2 or i + _HEADER_LEN > n or data[i + 2] != 0:
                return i  # MAVLink 1, garbage, a cut header, signed or unknown flags
            mlen = data[i + 1]
            end = i + _HEADER_LEN + mlen + 2
            msgid = data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16)
            ty = types.get(msgid)
            if ty is None or end > n or mlen > ty.size:
                return i
            crc = self._crc_unpack(data, end - 2)[0]
            if _mcrf4xx(data[i + 1 : end - 2] + ty.crc_extra, 0xFFFF) != crc:
                return i
            start = i + _HEADER_LEN
            if mlen == ty.size:
                t = ty.unpacker.unpack_from(data, start)
            else:  # MAVLink 2 trims trailing zero bytes of the payload
                t = ty.unpacker.unpack(data[start : end - 2] + bytes(ty.size - mlen))
            if ty.arrays is None:
                fields: list[Any] = [t[k] for k in ty.order]
            else:
                fields = [t[a] if k == 1 else list(t[a : a + k]) for a, k in ty.arrays]
            m = ty.cls.__new__(ty.cls)
            d = m.__dict__
            d.update(ty.base)
            d.update(zip(ty.names, fields, strict=True))
            buf = bytearray(data[i:end])
            d["_signed"] = False
            d["_msgbuf"] = buf
            d["_payload"] = buf[6:-2]  # what pymavlink stores (its v1 offset, kept as is)
            d["_crc"] = crc
            d["_header"] = self._new_header(msgid, 0, data[i + 3], mlen, data[i + 4],
                                            data[i + 5], data[i + 6])  # fmt: skip
            out.append(m)
            i = end
        return i
