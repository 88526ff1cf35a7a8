"""The bridge's packer of outgoing messages (mpf_mavlink/mavlink/fastpack.py) against pymavlink:
the same bytes for every message class of the dialect, sequence numbers and tallies as
pymavlink keeps them, and pymavlink itself for what the packer must not do (signing)."""

from __future__ import annotations

import random
from typing import Any

from mpf_mavlink.mavlink import dialect as d
from mpf_mavlink.mavlink import encode_set_attitude_target_rates
from mpf_mavlink.mavlink.fastpack import pack_v2, sent


class _Buf:
    def __init__(self) -> None:
        self.out: list[bytes] = []

    def write(self, b: bytes) -> None:
        self.out.append(bytes(b))


def _value(ftype: str, n: int, rng: random.Random, zero: bool) -> Any:
    """A value of a field of type ``ftype`` (array length ``n``, 0: scalar)."""

    def one() -> Any:
        if zero:
            return 0.0 if ftype in ("float", "double") else 0
        if ftype in ("float", "double"):
            return rng.uniform(-1e3, 1e3)
        bits = int("".join(c for c in ftype if c.isdigit()) or 8)
        if ftype.startswith("u") or ftype.startswith("char"):
            return rng.randrange(0, 2**bits)
        return rng.randrange(-(2 ** (bits - 1)), 2 ** (bits - 1))

    if ftype.startswith("char"):
        return b"" if zero else bytes(rng.randrange(32, 127) for _ in range(rng.randrange(1, n)))
    return [one() for _ in range(n)] if n else one()


def _message(cls: Any, rng: random.Random, zero: bool = False) -> Any:
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    return cls(*[_value(types[f], lengths[f], rng, zero) for f in cls.fieldnames])


def test_every_message_class_packs_to_pymavlinks_bytes() -> None:
    """Random values (and all zeros: MAVLink 2 keeps one payload byte) in every class of the
    dialect: the same packet, sequence number and tallies as pymavlink's ``send``."""
    rng = random.Random(3)
    ours, theirs = d.MAVLink(None, srcSystem=1, srcComponent=191), _Buf()
    ref = d.MAVLink(theirs, srcSystem=1, srcComponent=191)
    n = 0
    for cls in d.mavlink_map.values():
        for zero in (False, True):
            msg = _message(cls, rng, zero)
            buf = pack_v2(ours, msg)
            assert buf is not None, cls.msgname
            sent(ours, buf)
            ref.send(msg)
            assert buf == theirs.out[-1], cls.msgname
            assert msg.get_msgbuf() == buf
            n += 1
    assert n == 2 * len(d.mavlink_map) > 300
    assert (ours.seq, ours.total_packets_sent, ours.total_bytes_sent) == (
        ref.seq, ref.total_packets_sent, ref.total_bytes_sent
    )  # fmt: skip


def test_the_setpoint_packs_to_pymavlinks_bytes_and_parses_back() -> None:
    mav = d.MAVLink(None, srcSystem=1, srcComponent=191)
    msg = encode_set_attitude_target_rates(mav, 123456, 1, 1, 0.1, -0.2, 0.3, 0.55)
    buf = pack_v2(mav, msg)
    assert buf is not None
    (back,) = d.MAVLink(None).parse_buffer(bytearray(buf))
    assert back.get_type() == "SET_ATTITUDE_TARGET"
    assert (back.time_boot_ms, back.type_mask, list(back.q)) == (123456, 128, [1.0, 0.0, 0.0, 0.0])
    assert (back.get_srcSystem(), back.get_srcComponent()) == (1, 191)


def test_signing_and_send_callbacks_stay_with_pymavlink() -> None:
    mav = d.MAVLink(None, srcSystem=1, srcComponent=191)
    msg = d.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)
    mav.signing.secret_key = bytes(range(32))
    mav.signing.sign_outgoing = True
    assert pack_v2(mav, msg) is None
    mav.signing.sign_outgoing = False
    mav.set_send_callback(lambda m: None)
    assert pack_v2(mav, msg) is None
