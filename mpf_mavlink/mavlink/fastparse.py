"""A decoder of the frames that make up nearly all of a vehicle's telemetry datagrams (ATTITUDE
and LOCAL_POSITION_NED every frame, then GLOBAL_POSITION_INT, VFR_HUD, ATTITUDE_TARGET,
FOLLOW_TARGET, ...: every message type without text fields), used by the UDP link before
pymavlink's parser.

pymavlink's byte-stream parser costs ~7 us a message (a method call per parsing stage, a header
object, the payload copied three times). Here a datagram's frames are checked and decoded in one
pass from its start: a frame must be MAVLink 2, unsigned (no incompatibility flag), of a type
without text (pymavlink post-processes text: STATUSTEXT, PARAM_VALUE, NAMED_VALUE_FLOAT... stay
with it), whole within the datagram, no longer than the type's payload, with the right CRC
(CRC_EXTRA read from the pymavlink dialect's message classes). The first frame that is anything
else (MAVLink 1, signed, text, unknown, a bad CRC, truncated, garbage) ends the pass: from there
on the datagram goes to pymavlink (:meth:`HotDecoder.decode` says where), which then sees the
bytes its own parser would hold after those frames. The messages made are instances of
pymavlink's own classes with the fields, ids, bytes and methods pymavlink's ``MAVLink.decode``
gives them (tests/test_fastparse.py compares them for every type), so every consumer sees the
same messages; only what nothing reads per message (the header object, the payload copy, the
CRC) is made when first asked for."""

from __future__ import annotations

import binascii
import functools
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


# MAVLink's CRC-16/MCRF4XX (data, initial 0xFFFF); also the SIL vehicle's framing's
crc_mcrf4xx = _crc_function()


#: The telemetry a vehicle streams (decoded here with every other type without text).
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


class _Wire:
    """What a pymavlink message holds besides its fields, for a message made from one frame:
    the ids and sequence read from the frame's bytes (``_msgbuf``), and the header object, the
    payload copy and the CRC pymavlink's decoder sets made only if something asks for them
    (nothing in the bridge does: that saves a third of a message's decoding)."""

    _msgbuf: bytes

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's names
        return self._msgbuf[5]

    def get_srcComponent(self) -> int:  # noqa: N802
        return self._msgbuf[6]

    def get_seq(self) -> int:
        return self._msgbuf[4]

    @functools.cached_property
    def _header(self) -> Any:
        b = self._msgbuf
        return dialect.MAVLink_header(b[7] | b[8] << 8 | b[9] << 16, b[2], b[3], b[1], b[4],
                                      b[5], b[6])  # fmt: skip

    @functools.cached_property
    def _payload(self) -> bytearray:
        return bytearray(self._msgbuf[6:-2])  # what pymavlink stores (its v1 offset, kept as is)

    @functools.cached_property
    def _crc(self) -> int:
        return int.from_bytes(self._msgbuf[-2:], "little")


class _Type:
    """One message class: its payload layout, CRC extra and how pymavlink orders its fields;
    ``hot`` is the class of the messages made here (the pymavlink class with :class:`_Wire`)."""

    __slots__ = ("cls", "hot", "size", "unpacker", "crc_extra", "names", "order", "arrays")

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.unpacker = cls.unpacker
        self.size = int(cls.unpacker.size)
        self.crc_extra = bytes((int(cls.crc_extra),))
        self.names = tuple(cls.fieldnames)
        lengths = list(cls.lengths)
        # pymavlink's MAVLink.decode: field i (declared order) is t[order[i]] when the message
        # has no arrays, else the slice of the struct's values at the field's wire offset
        order = tuple(cls.orders)
        self.order: tuple[int, ...] | None = None if order == tuple(range(len(order))) else order
        self.arrays: tuple[tuple[int, int], ...] | None = None
        if sum(lengths) != len(lengths):
            self.arrays = tuple((sum(lengths[:o]), lengths[o]) for o in order)
        # what the generated constructor sets besides the fields and the wire (the type's name,
        # field names, instance info) is the same for every message: class attributes here
        proto = cls(*[[0] * n if n > 1 else 0 for n in self._declared_lengths(cls)])
        wire = ("_header", "_payload", "_msgbuf", "_crc")
        same = {k: v for k, v in vars(proto).items() if k not in self.names and k not in wire}
        self.hot: Any = type(cls.__name__, (_Wire, cls), {**same, "__module__": __name__})

    @staticmethod
    def _declared_lengths(cls: Any) -> list[int]:
        lengths = list(cls.lengths)
        return [lengths[o] for o in cls.orders]


def _has_text(cls: Any) -> bool:
    """Whether the payload carries characters (pymavlink strips their NULs: not done here)."""
    fmt = cls.unpacker.format
    fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
    return "s" in fmt or "c" in fmt


@functools.cache
def _table() -> dict[int, _Type]:
    """Message id -> layout, for every type of the dialect without text (once per process:
    ~25 ms for its ~260 types)."""
    return {int(cls.id): _Type(cls) for cls in dialect.mavlink_map.values() if not _has_text(cls)}


class HotDecoder:
    """Decodes the leading hot, unsigned MAVLink 2 frames of a datagram (module docstring)."""

    def __init__(self) -> None:
        self.types = _table()
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
        crc_of, crc_at, append = crc_mcrf4xx, self._crc_unpack, out.append
        while i < n:
            if data[i] != _STX2 or i + _HEADER_LEN > n or data[i + 2] != 0:
                return i  # MAVLink 1, garbage, a cut header, signed or unknown flags
            mlen = data[i + 1]
            end = i + _HEADER_LEN + mlen + 2
            ty = types.get(data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16))
            if ty is None or end > n or mlen > ty.size:
                return i
            if crc_of(data[i + 1 : end - 2] + ty.crc_extra, 0xFFFF) != crc_at(data, end - 2)[0]:
                return i
            start = i + _HEADER_LEN
            if mlen == ty.size:
                t = ty.unpacker.unpack_from(data, start)
            else:  # MAVLink 2 trims trailing zero bytes of the payload
                t = ty.unpacker.unpack(data[start : end - 2] + bytes(ty.size - mlen))
            if ty.arrays is None:
                fields: Any = t if ty.order is None else [t[k] for k in ty.order]
            else:
                fields = [t[a] if k == 1 else list(t[a : a + k]) for a, k in ty.arrays]
            hot = ty.hot
            m = hot.__new__(hot)
            d = m.__dict__
            d.update(zip(ty.names, fields, strict=True))
            d["_msgbuf"] = data[i:end]
            append(m)
            i = end
        return i
