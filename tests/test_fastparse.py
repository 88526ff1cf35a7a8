"""The UDP link's decoder of telemetry (mpf_mavlink/mavlink/fastparse.py) against pymavlink:
the same messages for every type without text, and pymavlink's parser for anything it is not sure
of (MAVLink 1, signed, other types, bad CRC, truncated or trailing bytes). Fuzzed datagrams never
raise and never reach the samples as a non-finite value."""

from __future__ import annotations

import math
import random
import socket
from typing import Any

import pytest

from mpf_mavlink.mavlink import decode, dialect
from mpf_mavlink.mavlink.fastparse import HOT_TYPES, HotDecoder, _has_text
from mpf_mavlink.mavlink.link import Link, open_link
from mpf_mavlink.mavlink.url import free_udp_port
from tests.test_fastpack import _message

d = dialect


class _Buf:
    def __init__(self) -> None:
        self.out: list[bytes] = []

    def write(self, b: bytes) -> None:
        self.out.append(bytes(b))


def _mav(sysid: int = 1, compid: int = 1, mavlink1: bool = False) -> tuple[Any, _Buf]:
    buf = _Buf()
    mav = d.MAVLink(buf, srcSystem=sysid, srcComponent=compid)
    if mavlink1:
        mav.WIRE_PROTOCOL_VERSION = "1.0"
    return mav, buf


# one message of every hot type, with values that exercise every field (arrays, negatives,
# extension fields, trimmed trailing zeros)
def _hot_messages() -> dict[str, Any]:
    return {
        "ATTITUDE": d.MAVLink_attitude_message(123456, 0.1, -0.2, 3.0, 0.01, -0.02, 0.03),
        "LOCAL_POSITION_NED": d.MAVLink_local_position_ned_message(
            5000, 10.5, -20.25, -100.0, 15.0, 0.5, -0.25
        ),
        "GLOBAL_POSITION_INT": d.MAVLink_global_position_int_message(
            7000, 411850000, -87600000, 100000, 100000, 1500, -20, 5, 9000
        ),
        "ATTITUDE_TARGET": d.MAVLink_attitude_target_message(
            8000, 7, [0.9, 0.1, -0.2, 0.3], 0.1, 0.2, -0.3, 0.55
        ),
        "VFR_HUD": d.MAVLink_vfr_hud_message(16.0, 15.5, 270, 22, 100.0, -0.5),
        "FOLLOW_TARGET": d.MAVLink_follow_target_message(
            9000,
            3,
            411850000,
            -87600000,
            1.5,
            [3.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.1],
            [0.1, 0.1, 0.1],
            0,
        ),
        "HEARTBEAT": d.MAVLink_heartbeat_message(1, 12, 157, 393216, 4, 3),
        "TIMESYNC": d.MAVLink_timesync_message(0, 123456789012),
        "SYS_STATUS": d.MAVLink_sys_status_message(
            1, 2, 3, 500, 12000, -1, 80, 0, 0, 0, 0, 0, 0, 4, 5, 6
        ),
        "WIND_COV": d.MAVLink_wind_cov_message(10**6, 1.0, -2.0, 0.0, 0.5, 0.5, 100.0, 1.0, 1.0),
        "ATTITUDE_QUATERNION": d.MAVLink_attitude_quaternion_message(
            1000, 1.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3, [1.0, 0.0, 0.0, 0.0]
        ),
        "HOME_POSITION": d.MAVLink_home_position_message(
            411850000, -87600000, 0, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 12345
        ),
    }


def _pack(msg: Any, sysid: int = 1, compid: int = 1) -> bytes:
    mav, buf = _mav(sysid, compid)
    mav.send(msg)
    return buf.out[-1]


def _pymavlink(data: bytes) -> list[Any]:
    return d.MAVLink(None).parse_buffer(bytearray(data)) or []


def _same(fast: Any, slow: Any) -> None:
    """Every attribute pymavlink's decoder sets (the wire's made on demand), every getter."""
    assert isinstance(fast, type(slow)) and type(fast).__name__ == type(slow).__name__
    for k, v in vars(slow).items():  # repr: NaN fields compare equal
        if k == "_header":
            assert vars(fast._header) == vars(v)
            continue
        w = getattr(fast, k)
        if k == "_msgbuf":
            w, v = bytes(w), bytes(v)
        assert type(w) is type(v) and repr(w) == repr(v), k
    for get in ("get_type", "get_srcSystem", "get_srcComponent", "get_seq", "get_msgId",
                "get_msgbuf", "get_crc", "get_payload", "get_signed", "get_link_id",
                "get_fieldnames"):  # fmt: skip
        assert getattr(fast, get)() == getattr(slow, get)(), get
    assert repr(fast.to_dict()) == repr(slow.to_dict())
    assert str(fast) == str(slow)


def test_every_type_without_text_is_decoded_as_pymavlink_does() -> None:
    """Random values (and all zeros: a payload trimmed to one byte) in every message class of
    the dialect without text fields; the classes with text are left to pymavlink."""
    rng = random.Random(11)
    hot = HotDecoder()
    texts = {c.msgname for c in d.mavlink_map.values() if _has_text(c)}
    assert {"STATUSTEXT", "PARAM_VALUE", "NAMED_VALUE_FLOAT"} <= texts
    assert {c.cls.msgname for c in hot.types.values()} == {
        c.msgname for c in d.mavlink_map.values()
    } - texts
    for ty in hot.types.values():
        for zero in (False, True):
            data = _pack(_message(ty.cls, rng, zero), sysid=rng.randrange(256))
            fast, used = hot.decode(data)
            assert len(fast) == 1 and used == len(data), ty.cls.msgname
            (slow,) = _pymavlink(data)
            _same(fast[0], slow)
    text = _pack(d.MAVLink_statustext_message(6, b"hello"))
    assert hot.decode(text) == ([], 0)


def test_every_hot_type_is_covered_and_decodes_as_pymavlink_does() -> None:
    msgs = _hot_messages()
    assert set(msgs) == set(HOT_TYPES)
    hot = HotDecoder()
    assert set(HOT_TYPES) <= {c.cls.msgname for c in hot.types.values()}
    for name, msg in msgs.items():
        data = _pack(msg, sysid=7, compid=42)
        fast, used = hot.decode(data)
        assert len(fast) == 1 and used == len(data), name
        (slow,) = _pymavlink(data)
        assert slow.get_type() == name
        _same(fast[0], slow)


def test_several_frames_in_one_datagram_and_trimmed_payloads() -> None:
    hot = HotDecoder()
    zeros = d.MAVLink_attitude_message(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # payload trimmed to 1
    data = b"".join(_pack(m) for m in [zeros, *_hot_messages().values()])
    assert data[1] == 1  # MAVLink 2 kept a single byte of the all-zero ATTITUDE payload
    fast, used = hot.decode(data)
    slow = _pymavlink(data)
    assert used == len(data) and len(fast) == len(slow) == 1 + len(HOT_TYPES)
    for f, s in zip(fast, slow, strict=True):
        _same(f, s)


def _att() -> bytes:
    return _pack(_hot_messages()["ATTITUDE"])


def _split(hot: HotDecoder, data: bytes) -> tuple[list[str], int]:
    msgs, used = hot.decode(data)
    return [m.get_type() for m in msgs], used


def test_bad_crc_truncated_trailing_bytes_go_to_pymavlink() -> None:
    """A doubtful frame and everything after it are left to pymavlink."""
    hot = HotDecoder()
    good = _att()
    n = len(good)
    bad_crc = good[:-1] + bytes([good[-1] ^ 0x01])
    bad_payload = good[:12] + bytes([good[12] ^ 0x80]) + good[13:]
    for data in (
        bad_crc,
        bad_payload,
        good[:-1],  # truncated frame
        good[:5],  # truncated header
        b"\x55" + good,  # garbage before it
        b"",
    ):
        assert _split(hot, data) == ([], 0)
    assert _split(hot, good + b"\x00") == (["ATTITUDE"], n)  # a stray byte after the frame
    assert _split(hot, good + good[:8]) == (["ATTITUDE"], n)  # a second frame cut short
    assert _split(hot, good + bad_crc + good) == (["ATTITUDE"], n)


def test_mavlink1_signed_and_other_types_fall_back() -> None:
    hot = HotDecoder()
    mav1, buf1 = _mav(mavlink1=True)
    mav1.send(_hot_messages()["ATTITUDE"], force_mavlink1=True)
    v1 = buf1.out[-1]
    assert v1[0] == 0xFE and _pymavlink(v1)[0].get_type() == "ATTITUDE"
    assert _split(hot, v1) == ([], 0)
    mav, buf = _mav()
    mav.signing.secret_key = bytes(range(32))
    mav.signing.link_id = 1
    mav.signing.sign_outgoing = True
    mav.send(_hot_messages()["ATTITUDE"])
    signed = buf.out[-1]
    assert signed[2] & 0x01
    assert _split(hot, signed) == ([], 0)
    text = _pack(d.MAVLink_statustext_message(6, b"hello"))
    att = _att()
    assert _split(hot, text) == ([], 0)
    assert _split(hot, att + text + att) == (["ATTITUDE"], len(att))  # the rest: pymavlink
    assert _split(hot, att + signed) == (["ATTITUDE"], len(att))
    # a hot message id under a frame too long for it (a newer dialect's extensions)
    long = bytearray(att)
    assert _split(hot, bytes(long[:1] + bytes([long[1] + 1]) + long[2:])) == ([], 0)


def _link_pair() -> tuple[Link, socket.socket, tuple[str, int]]:
    port = free_udp_port()
    link = open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=None)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    return link, tx, ("127.0.0.1", port)


def _drain(link: Link) -> list[Any]:
    out = []
    while (m := link.recv(0.05)) is not None:
        out.append(m)
    return out


def test_the_udp_link_takes_hot_and_other_datagrams_in_order() -> None:
    link, tx, dest = _link_pair()
    try:
        msgs = list(_hot_messages().values())
        sent = [_pack(m) for m in msgs]
        sent.insert(3, _pack(d.MAVLink_statustext_message(6, b"between")))
        sent.insert(5, _pack(msgs[0]) + _pack(msgs[1]))  # two hot frames in one datagram
        text = _pack(d.MAVLink_statustext_message(6, b"mid"))
        sent.insert(6, _pack(msgs[0]) + text + _pack(msgs[2]))  # hot, other, hot
        sent.insert(7, _pack(msgs[1]) + _pack(msgs[0])[:-3])  # hot, then a cut frame
        for b in sent:
            tx.sendto(b, dest)
        got = _drain(link)
        want = [m for b in sent for m in _pymavlink(b)]
        assert [m.get_type() for m in got] == [m.get_type() for m in want]
        for g, w in zip(got, want, strict=True):
            assert g.to_dict() == w.to_dict()
        assert link.counters.bad_data == 1  # the cut frame
    finally:
        tx.close()
        link.close()


def _finite(x: Any) -> bool:
    if isinstance(x, float):
        return math.isfinite(x)
    if isinstance(x, (tuple, list)):
        return all(_finite(v) for v in x)
    if hasattr(x, "__dataclass_fields__") or hasattr(x, "_fields"):
        vals = x if hasattr(x, "_fields") else [getattr(x, f) for f in x.__dataclass_fields__]
        return all(_finite(v) for v in vals)
    try:
        import numpy as np

        if isinstance(x, np.ndarray):
            return bool(np.isfinite(x).all())
    except ImportError:  # pragma: no cover
        pass
    return True


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fuzzed_datagrams_never_raise_nor_yield_non_finite_samples(seed: int) -> None:
    """Random bit flips, truncations, splices and NaN/inf payloads (with their CRC fixed up,
    so that the fast decoder accepts them): the decoder never raises, agrees with pymavlink on
    every datagram it takes, and the samples the codec makes of them are finite or None."""
    rng = random.Random(seed)
    hot = HotDecoder()
    base = [_pack(m) for m in _hot_messages().values()]
    nan = d.MAVLink_attitude_message(1, math.nan, math.inf, -math.inf, 0.0, 0.0, 0.0)
    base.append(_pack(nan))
    base.append(_pack(d.MAVLink_local_position_ned_message(1, math.nan, 0, 0, math.inf, 0, 0)))
    taken = 0
    for _ in range(3000):
        data = bytearray(rng.choice(base))
        k = rng.randrange(4)
        if k == 0:
            for _ in range(rng.randint(1, 3)):
                data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        elif k == 1:
            data = data[: rng.randrange(len(data))]
        elif k == 2:
            data += rng.choice(base)[: rng.randrange(1, 30)]
        fast, used = hot.decode(bytes(data))
        assert 0 <= used <= len(data)
        if not fast:
            assert used == 0
            continue
        taken += 1
        # the decoded frames, then pymavlink on the rest: what pymavlink makes of it all
        slow = _pymavlink(bytes(data))
        rest = _pymavlink(bytes(data[used:]))
        assert [m.get_type() for m in fast + rest] == [m.get_type() for m in slow]
        for f, s in zip(fast, slow[: len(fast)], strict=True):
            _same(f, s)
            f._timestamp = 1.0
            assert _finite(decode(f))
    assert taken > 100  # the unchanged and NaN datagrams at least


def test_the_stdlib_crc_fallback_matches_pymavlinks_crc() -> None:
    """Without fastcrc the decoder computes the CRC with binascii.crc_hqx on reversed bytes."""
    from pymavlink.generator.mavcrc import x25crc_slow

    from mpf_mavlink.mavlink.fastparse import _mcrf4xx_hqx

    rng = random.Random(5)
    for n in (0, 1, 9, 40, 280):
        data = bytes(rng.randrange(256) for _ in range(n))
        assert _mcrf4xx_hqx(data, 0xFFFF) == x25crc_slow(data).crc


def test_the_bridge_takes_a_datagrams_messages_before_its_duties() -> None:
    """VehicleLink.spin runs its duties (watchdog, re-sends) once per wake-up, after every
    message of the datagram read: not between a LOCAL_POSITION_NED and the ATTITUDE after it."""
    from types import SimpleNamespace

    from mpf_mavlink.bridge.link_io import VehicleLink

    link, tx, dest = _link_pair()
    try:
        vl = VehicleLink(SimpleNamespace(vehicle_sysid=1, target_sysid=None, lockstep=False))
        vl.link = link
        seen: list[str] = []
        vl.on_vehicle = lambda s, rx: seen.append(type(s).__name__)
        vl.on_tick = lambda: seen.append("tick")
        msgs = _hot_messages()
        tx.sendto(_pack(msgs["LOCAL_POSITION_NED"]) + _pack(msgs["ATTITUDE"]), dest)
        assert vl.spin(1.0, until=lambda: "AttitudeSample" in seen)
        i = seen.index("LocalPositionSample")
        assert seen[i : i + 2] == ["LocalPositionSample", "AttitudeSample"]
        assert not link.buffered()
    finally:
        tx.close()
        link.close()
