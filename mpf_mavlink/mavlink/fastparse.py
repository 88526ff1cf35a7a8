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
    ``hot`` is the class of the messages made here (the pymavlink class with :class:`_Wire`),
    ``make(data, i, end)`` the message of the frame ``data[i:end]`` (CRC checked by the
    caller)."""

    __slots__ = ("cls", "hot", "size", "full", "unpacker", "crc_extra", "names", "make")

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.unpacker = cls.unpacker
        self.size = int(cls.unpacker.size)
        self.full = self.size + _HEADER_LEN + 2  # the frame of an untrimmed payload (bytes)
        self.crc_extra = bytes((int(cls.crc_extra),))
        self.names = tuple(cls.fieldnames)
        # what the generated constructor sets besides the fields and the wire (the type's name,
        # field names, instance info) is the same for every message: class attributes here
        proto = cls(*[[0] * n if n > 1 else 0 for n in self._declared_lengths(cls)])
        wire = ("_header", "_payload", "_msgbuf", "_crc")
        same = {k: v for k, v in vars(proto).items() if k not in self.names and k not in wire}
        self.hot: Any = type(cls.__name__, (_Wire, cls), {**same, "__module__": __name__})
        # compiled when the first frame of the type comes (a few types of the ~260 ever do)
        self.make: Callable[[bytes, int, int], Any] = self._first

    def _first(self, data: bytes, i: int, end: int) -> Any:
        self.make = self._maker(self.cls)
        return self.make(data, i, end)

    def _maker(self, cls: Any) -> Callable[[bytes, int, int], Any]:
        """One compiled constructor per type (as pymavlink's generator writes one decoder per
        type): the instance's ``__dict__`` made in one dict display costs half of filling it
        field by field. Field i (declared order) is what pymavlink's ``MAVLink.decode`` makes
        of the struct's values ``t``: ``t[order[i]]`` when the message has no arrays, else the
        value (or the list of values) at the field's wire offset. The text is made of the
        dialect's field names (identifiers) only."""
        lengths = list(cls.lengths)
        order = list(cls.orders)
        items = []
        for name, o in zip(self.names, order, strict=True):
            if not name.isidentifier():  # pragma: no cover - generated names always are
                raise ValueError(f"odd field name {name!r}")
            if sum(lengths) == len(lengths):
                value = f"t[{o}]"
            else:
                a, k = sum(lengths[:o]), lengths[o]
                value = f"t[{a}]" if k == 1 else f"[{', '.join(f't[{a + j}]' for j in range(k))}]"
            items.append(f"{name!r}: {value}")
        items.append("'_msgbuf': data[i:end]")
        full, head = self.full, _HEADER_LEN
        source = (
            "def make(data, i, end):\n"
            f"    if end - i == {full}:\n"
            f"        t = unpack_from(data, i + {head})\n"
            "    else:  # MAVLink 2 trims trailing zero bytes of the payload\n"
            f"        t = unpack(data[i + {head} : end - 2] + bytes({full} - end + i))\n"
            "    o = new(hot)\n"
            f"    o.__dict__ = {{{', '.join(items)}}}\n"
            "    return o\n"
        )
        scope: dict[str, Any] = {
            "unpack_from": cls.unpacker.unpack_from,
            "unpack": cls.unpacker.unpack,
            "new": object.__new__,
            "hot": self.hot,
        }
        exec(source, scope)  # noqa: S102
        make: Callable[[bytes, int, int], Any] = scope["make"]
        return make

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
        crc_of, append = crc_mcrf4xx, out.append
        while i < n:
            if data[i] != _STX2 or i + _HEADER_LEN > n or data[i + 2] != 0:
                return i  # MAVLink 1, garbage, a cut header, signed or unknown flags
            end = i + _HEADER_LEN + 2 + data[i + 1]
            ty = types.get(data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16))
            if ty is None or end > n or end - i > ty.full:
                return i
            # the CRC of the frame (STX excluded) and then of the type's CRC_EXTRA
            if crc_of(ty.crc_extra, crc_of(data[i + 1 : end - 2], 0xFFFF)) != (
                data[end - 2] | (data[end - 1] << 8)
            ):
                return i
            append(ty.make(data, i, end))
            i = end
        return i
