"""MAVLink 2 framing of the vehicle's per-frame traffic without pymavlink's per-message objects:
the 50 Hz ATTITUDE / LOCAL_POSITION_NED it sends and the SET_ATTITUDE_TARGET it receives each
lockstep frame are most of the vehicle's CPU when framed by pymavlink (an object, a pure-Python
CRC byte loop and a header object per message).

The bytes are pymavlink's own (the tests compare them): the message classes' wire layout and
CRC extra are read from pymavlink; the CRC-16/MCRF4XX is the bridge's fast decoder's
(mpf_mavlink.mavlink.fastparse: fastcrc, or binascii on bit-reversed bytes). Signed links and
messages with text fields go through pymavlink."""

from __future__ import annotations

import struct
from operator import itemgetter
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from mpf_mavlink.mavlink.fastparse import crc_mcrf4xx

_STX2 = 0xFD


class _Layout:
    """One message class's wire layout: the field order and the CRC extra byte; ``ids`` the
    header's system, component and message id bytes for one sender."""

    __slots__ = ("msgid", "packer", "wire_order", "arrays", "in_order", "reorder", "crc_extra",
                 "ids", "pack")  # fmt: skip

    def __init__(self, cls: Any, sysid: int = 0, compid: int = 0) -> None:
        self.msgid = int(cls.id)
        mid = self.msgid
        self.ids = bytes((sysid, compid, mid & 0xFF, (mid >> 8) & 0xFF, mid >> 16))
        self.packer = cls.unpacker
        n = len(cls.orders)
        inv = [0] * n
        for declared, wire in enumerate(cls.orders):
            inv[wire] = declared
        self.wire_order = tuple(inv)
        # numeric array fields (wire position -> length; pymavlink lists them in wire order) are
        # flattened into the struct's values
        self.arrays = {w: k for w, k in enumerate(cls.array_lengths) if k}
        # the arguments are the struct's values as they are (ATTITUDE, LOCAL_POSITION_NED, ...)
        self.in_order = not self.arrays and self.wire_order == tuple(range(n))
        # ... or they are once reordered (GLOBAL_POSITION_INT): one C call
        self.reorder = None if self.in_order or self.arrays else itemgetter(*self.wire_order)
        self.crc_extra = bytes((cls.crc_extra,))
        self.pack = self.packer.pack

    def values(self, args: tuple[Any, ...]) -> Any:
        """The struct's values in wire order from the field values in declared order."""
        if not self.arrays:
            return [args[i] for i in self.wire_order]
        out: list[Any] = []
        for w, i in enumerate(self.wire_order):
            k = self.arrays.get(w)
            if k is None:
                out.append(args[i])
            else:
                out.extend(args[i][:k])
        return out


# a frame's header after the start byte: payload length, incompat and compat flags (0), sequence,
# then the sender's and the message's ids (bytes)
_HEAD = struct.Struct("<BxxB5s").pack
_CRC = struct.Struct("<H").pack


class Framer:
    """Frames messages for one pymavlink ``MAVLink`` object (its ids, sequence counter and
    signing), returning the bytes (the vehicle batches them into datagrams)."""

    def __init__(self, mav: Any) -> None:
        self.mav = mav
        self._layouts: dict[Any, _Layout | None] = {}

    def _layout(self, cls: Any) -> _Layout | None:
        if cls not in self._layouts:  # text (char arrays) is pymavlink's to encode
            mav = self.mav
            self._layouts[cls] = (
                None
                if "char" in cls.fieldtypes
                else _Layout(cls, mav.srcSystem & 0xFF, mav.srcComponent & 0xFF)
            )
        return self._layouts[cls]

    def pack(self, cls: Any, *args: Any) -> bytes:
        """One framed message from the field values in pymavlink's ``*_encode`` order.
        (Three to six of these a lockstep frame: each step is one C call.)"""
        mav = self.mav
        lay = self._layouts.get(cls) or self._layout(cls)
        if lay is None or mav.signing.sign_outgoing:
            buf = bytes(cls(*args).pack(mav))
        else:
            if lay.in_order:
                payload = lay.pack(*args)
            elif lay.reorder is not None:
                payload = lay.pack(*lay.reorder(args))
            else:
                payload = lay.pack(*lay.values(args))
            body = payload.rstrip(b"\0") or payload[:1]  # MAVLink 2 trims trailing zeros
            frame = _HEAD(len(body), mav.seq, lay.ids) + body
            buf = b"\xfd" + frame + _CRC(crc_mcrf4xx(frame + lay.crc_extra, 0xFFFF))
        mav.seq = (mav.seq + 1) & 0xFF  # what MAVLink.send does after packing
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(buf)
        return buf


_SAT = M.MAVLink_set_attitude_target_message
_SAT_LEN = _SAT.unpacker.size
_SAT_CRC_EXTRA = bytes((_SAT.crc_extra,))


class SetAttitudeTarget:
    """A decoded SET_ATTITUDE_TARGET with the attributes and accessors of pymavlink's."""

    __slots__ = (
        "time_boot_ms",
        "q",
        "body_roll_rate",
        "body_pitch_rate",
        "body_yaw_rate",
        "thrust",
        "target_system",
        "target_component",
        "type_mask",
        "_src",
        "_buf",
    )

    def __init__(self, fields: tuple[Any, ...], src: tuple[int, int], buf: bytes) -> None:
        (
            self.time_boot_ms,
            q0,
            q1,
            q2,
            q3,
            self.body_roll_rate,
            self.body_pitch_rate,
            self.body_yaw_rate,
            self.thrust,
            self.target_system,
            self.target_component,
            self.type_mask,
        ) = fields
        self.q = [q0, q1, q2, q3]
        self._src = src
        self._buf = buf

    def get_type(self) -> str:
        return "SET_ATTITUDE_TARGET"

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src[0]

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src[1]

    def get_msgbuf(self) -> bytes:
        return self._buf


def decode_set_attitude_target(data: bytes) -> SetAttitudeTarget | None:
    """The datagram ``data`` as one unsigned MAVLink 2 SET_ATTITUDE_TARGET with a good CRC, or
    None (anything else: let pymavlink parse it)."""
    n = len(data)
    if n < 12 or data[0] != _STX2 or data[2] != 0 or n != data[1] + 12:
        return None
    if data[7] != 82 or data[8] != 0 or data[9] != 0:  # MAVLINK_MSG_ID_SET_ATTITUDE_TARGET
        return None
    body = data[10:-2]
    crc = crc_mcrf4xx(data[1:-2] + _SAT_CRC_EXTRA, 0xFFFF)
    if data[-2] != crc & 0xFF or data[-1] != crc >> 8 or len(body) > _SAT_LEN:
        return None
    fields = _SAT.unpacker.unpack(body + bytes(_SAT_LEN - len(body)))
    return SetAttitudeTarget(fields, (data[5], data[6]), data)
