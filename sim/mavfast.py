"""Cheap MAVLink 2 framing for the simulated vehicle's hot path (telemetry out, setpoints in).

pymavlink builds a message object, packs it and runs the X.25 checksum byte by byte in Python:
about 50-80 us per message, which at 50 Hz x several streams is a large part of a lockstep
frame. Here a message is one ``struct.pack`` plus a checksum computed in C, and the bytes are
IDENTICAL to pymavlink's (tests/test_sil.py compares them), sharing the sequence counter of the
pymavlink ``MAVLink`` object the vehicle also uses for rare messages (acks, status texts).

Checksum: MAVLink's CRC-16/MCRF4XX (X.25: reflected polynomial 0x1021, init 0xFFFF, no final
xor) equals the bit-reversal of the non-reflected CRC-CCITT of the bit-reversed bytes, which is
:func:`binascii.crc_hqx` (C) on ``bytes.translate`` (C) input.

Unsigned MAVLink 2 only; a signing link falls back to pymavlink.
"""

from __future__ import annotations

import binascii
import struct
from typing import Any

_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))
_HDR = struct.Struct("<BBBBBBBHB")


def x25crc(data: bytes) -> int:
    """MAVLink's CRC-16/MCRF4XX of ``data`` (init 0xFFFF)."""
    c = binascii.crc_hqx(data.translate(_REV8), 0xFFFF)
    return (_REV8[c & 0xFF] << 8) | _REV8[c >> 8]


class MsgSpec:
    """How one message type goes on the wire: id, CRC extra, payload struct in wire order and the
    permutation from pymavlink's ``*_encode`` argument order (``fieldnames``) to wire order."""

    __slots__ = ("cls", "msgid", "crc_extra", "struct", "perm", "arrays", "size")

    def __init__(self, cls: Any):
        self.cls = cls  # pymavlink's message class (signed links are packed by pymavlink)
        self.msgid: int = cls.id
        self.crc_extra: int = cls.crc_extra
        self.struct = struct.Struct(cls.unpacker.format)
        self.size = self.struct.size
        # wire order = ordered_fieldnames; encode() takes fieldnames order
        self.perm = tuple(cls.fieldnames.index(n) for n in cls.ordered_fieldnames)
        lengths = dict(zip(cls.fieldnames, cls.array_lengths, strict=True))
        self.arrays = any(lengths[n] for n in cls.ordered_fieldnames)


class FastPacker:
    """Frames messages for one pymavlink ``MAVLink`` object (its ids and sequence counter)."""

    def __init__(self, mav: Any):
        self.mav = mav

    def pack(self, spec: MsgSpec, *args: Any) -> bytes:
        """One framed message from the field values in pymavlink's ``*_encode`` order (arrays
        as sequences). Advances the sequence number like ``MAVLink.send``."""
        mav = self.mav
        # the module's promise: a signing link falls back to pymavlink (this packer cannot sign)
        if mav.signing.sign_outgoing:
            buf = spec.cls(*args).pack(mav)
            mav.seq = (mav.seq + 1) & 0xFF
            mav.total_packets_sent += 1
            mav.total_bytes_sent += len(buf)
            return buf
        vals = [args[i] for i in spec.perm]
        if spec.arrays:
            flat: list[Any] = []
            for v in vals:
                if isinstance(v, list | tuple):
                    flat.extend(v)
                else:
                    flat.append(v)
            vals = flat
        return self.frame(spec, spec.struct.pack(*vals))

    def frame(self, spec: MsgSpec, payload: bytes) -> bytes:
        """Header + payload (trailing zeros cut as MAVLink 2 does, at least one byte kept) + CRC."""
        mav = self.mav
        body = payload.rstrip(b"\0") or b"\0"
        seq = mav.seq
        hdr = _HDR.pack(
            253,
            len(body),
            0,
            0,
            seq,
            mav.srcSystem,
            mav.srcComponent,
            spec.msgid & 0xFFFF,
            spec.msgid >> 16,
        )
        crc = x25crc(hdr[1:] + body + bytes((spec.crc_extra,)))
        mav.seq = (seq + 1) & 0xFF
        mav.total_packets_sent += 1
        buf = hdr + body + bytes((crc & 0xFF, crc >> 8))
        mav.total_bytes_sent += len(buf)
        return buf


class FastSetAttitudeTarget:
    """A decoded SET_ATTITUDE_TARGET with the attributes pymavlink's message has that the vehicle
    reads (fields, ``get_type``, ``get_srcSystem``, ``get_srcComponent``)."""

    __slots__ = (
        "time_boot_ms", "q", "body_roll_rate", "body_pitch_rate", "body_yaw_rate", "thrust",
        "target_system", "target_component", "type_mask", "_src",
    )  # fmt: skip
    time_boot_ms: int
    q: list[float]
    body_roll_rate: float
    body_pitch_rate: float
    body_yaw_rate: float
    thrust: float
    target_system: int
    target_component: int
    type_mask: int
    _src: tuple[int, int]

    def get_type(self) -> str:
        return "SET_ATTITUDE_TARGET"

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src[0]

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src[1]


_SAT_ID = 82
_SAT_CRC_EXTRA = 49
_SAT = struct.Struct("<I4fffffBBB")


def decode_set_attitude_target(data: bytes) -> FastSetAttitudeTarget | None:
    """The message if ``data`` is exactly one valid, unsigned MAVLink 2 SET_ATTITUDE_TARGET,
    else None (the caller hands the datagram to pymavlink)."""
    n = len(data)
    if n < 13 or data[0] != 0xFD or data[2] != 0:
        return None
    plen = data[1]
    if (
        n != 12 + plen
        or plen > _SAT.size
        or (data[7] | (data[8] << 8) | (data[9] << 16)) != _SAT_ID
    ):
        return None
    crc = x25crc(data[1 : 10 + plen] + bytes((_SAT_CRC_EXTRA,)))
    if crc != data[10 + plen] | (data[11 + plen] << 8):
        return None
    tb, q0, q1, q2, q3, p, q, r, thrust, ts, tc, tm = _SAT.unpack(
        data[10 : 10 + plen] + bytes(_SAT.size - plen)
    )
    m = FastSetAttitudeTarget()
    m.time_boot_ms, m.q = tb, [q0, q1, q2, q3]
    m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate, m.thrust = p, q, r, thrust
    m.target_system, m.target_component, m.type_mask = ts, tc, tm
    m._src = (data[5], data[6])
    return m
