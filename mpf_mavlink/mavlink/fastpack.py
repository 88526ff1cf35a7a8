"""Framing of the messages the bridge sends (an unsigned MAVLink 2 packet) in one pass.

pymavlink's ``MAVLink.send`` costs ~4 us a packet (a header object, a CRC object, the buffer
built three times): a fifth of what the bridge's link spends per control frame. Here the same
bytes come from the message class's own struct (``unpacker``, fields in ``ordered_fieldnames``
order, arrays expanded), the trimmed payload (MAVLink 2 drops trailing zero bytes, keeping one),
the header and the CRC with the class's ``crc_extra``; tests/test_fastpack.py holds them to
pymavlink's bytes for every type the bridge sends. Signed packets, MAVLink 1 and a ``mav`` with a
send callback stay with pymavlink (:func:`pack_v2` returns None), as does anything this module
cannot pack (pymavlink then packs it or raises its own error)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from mpf_mavlink.mavlink.fastparse import crc_mcrf4xx
from mpf_mavlink.mavlink.pymav import dialect

_HEADER = struct.Struct("<BBBBBBBHB").pack  # stx, len, incompat, compat, seq, sys, comp, id
_CRC = struct.Struct("<H").pack
_V2 = float(dialect.WIRE_PROTOCOL_VERSION) == 2.0


class _Layout:
    """How one message class packs: its struct, its CRC extra and its values in wire order."""

    __slots__ = ("tail", "lo", "hi", "payload")

    def __init__(self, cls: Any) -> None:
        self.tail = bytes((int(cls.crc_extra),))
        mid = int(cls.id)
        self.lo, self.hi = mid & 0xFFFF, mid >> 16
        names = list(cls.ordered_fieldnames)
        types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
        # the generated ``pack`` method's argument list: the fields in wire order, a char[n]
        # field as one struct item ("ns": the bytes pymavlink keeps as ``_<name>_raw``), any
        # other array as its first n elements
        items: list[str] = []
        for name, k in zip(names, cls.array_lengths, strict=True):
            if not name.isidentifier():  # pragma: no cover - generated names always are
                raise ValueError(f"odd field name {name!r}")
            if types[name].startswith("char"):
                items.append(f"getattr(m, '_{name}_raw', m.{name})")
            elif k:
                items.extend(f"m.{name}[{i}]" for i in range(int(k)))
            else:
                items.append(f"m.{name}")
        # one compiled expression per class, as pymavlink's generator writes its pack methods
        # (a generic loop over the fields costs more than the packing itself): the untrimmed
        # payload; its text is made of the dialect's identifiers only
        source = f"lambda m: pack({', '.join(items)})"
        scope = {"pack": cls.unpacker.pack}
        self.payload: Callable[[Any], bytes] = eval(source, scope)  # noqa: S307


_LAYOUTS: dict[type, _Layout] = {}


def pack_v2(mav: Any, msg: Any) -> bytes | None:
    """The unsigned MAVLink 2 packet pymavlink's ``mav.send(msg)`` would write, with ``mav``'s
    sequence number and ids; None when pymavlink must do it (signing, a send callback, MAVLink 1,
    not a generated message class, values it cannot pack). Does not advance ``mav.seq`` (the
    caller does, once the packet is written, as pymavlink does)."""
    if not _V2 or mav.signing.sign_outgoing or mav.send_callback is not None:
        return None
    cls = type(msg)
    lay = _LAYOUTS.get(cls)
    if lay is None:
        if getattr(cls, "unpacker", None) is None or not hasattr(cls, "ordered_fieldnames"):
            return None
        lay = _LAYOUTS[cls] = _Layout(cls)
    try:
        payload = lay.payload(msg).rstrip(b"\x00") or b"\x00"
    except Exception:  # noqa: BLE001 - pymavlink packs it, or raises its own error
        return None
    body = (
        _HEADER(0xFD, len(payload), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent, lay.lo, lay.hi)
        + payload
    )
    buf = body + _CRC(crc_mcrf4xx(body[1:] + lay.tail, 0xFFFF))
    msg._msgbuf = buf  # what pymavlink leaves on a sent message (get_msgbuf)
    return buf


def sent(mav: Any, buf: bytes) -> None:
    """The bookkeeping pymavlink's ``MAVLink.send`` does after writing ``buf``."""
    mav.seq = (mav.seq + 1) % 256
    mav.total_packets_sent += 1
    mav.total_bytes_sent += len(buf)
