"""MAVLink 2 message signing for a Link (pymavlink's ``setup_signing``, hardened).

What pymavlink does with a key set (dialects/v20/*.py ``MAVLink.decode/check_signature``):
- unsigned packets, and signed packets whose check fails, become BAD_DATA "Invalid signature"
  unless ``allow_unsigned_callback(mav, msgid)`` returns True. Our callback allows NOTHING by
  default: a packet that the callback lets through is accepted without any check, so a
  replayed or forged copy of it would be too. Never put a control message id in there.
- replay: per (link_id, sysid, compid) stream the 48-bit timestamp must increase, so a
  verbatim replay of a packet already seen is rejected; a new stream is accepted only if its
  timestamp is at most 60 s behind ours.

Weakness we fix (``hardened=True``, the default): stock pymavlink stores the stream timestamp
BEFORE it verifies the signature, so one forged packet carrying a far-future timestamp makes
every later genuine packet of that stream look like a replay (a denial of service that needs
no key). Our check verifies the HMAC first and only then advances the stream timestamp.
"""

from __future__ import annotations

import hashlib
import os
import string
import struct
from collections.abc import Callable, Iterable
from typing import Any

from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink.link import Link

KEY_LEN = 32
SIGNING_EPOCH_UNIX_S = 1420070400  # 2015-01-01T00:00:00Z; timestamps are 10 us ticks since then
NEW_STREAM_MAX_AGE_TICKS = 6000 * 1000  # 60 s, as in pymavlink and the C library
_SIGN_TS = struct.Struct("<IH")


def load_signing_key(path: str | os.PathLike[str]) -> bytes:
    """A 32-byte key from a file holding exactly 32 raw bytes or 64 hex characters
    (surrounding whitespace / newline tolerated). MpfError naming the file otherwise."""
    p = os.fspath(path)
    try:
        with open(p, "rb") as f:
            raw = f.read(4096)
    except OSError as e:
        raise MpfError(f"signing key {p}: cannot read ({e.strerror})") from None
    if len(raw) == KEY_LEN:
        return raw
    text = raw.strip()
    if len(text) == 2 * KEY_LEN and all(chr(c) in string.hexdigits for c in text):
        return bytes.fromhex(text.decode("ascii"))
    raise MpfError(
        f"signing key {p}: expected 32 raw bytes or 64 hex characters, found {len(raw)} bytes"
    )


def _hardened_check_signature(link: Link) -> Callable[[bytearray, int, int], bool]:
    mav = link.conn.mav
    signing = mav.signing
    counters = link.counters

    def check_signature(msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        key = signing.secret_key
        if key is None or len(msgbuf) < 13:
            counters.rejected_bad_signature += 1
            return False
        if hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6] != bytes(msgbuf[-6:]):
            counters.rejected_bad_signature += 1  # forged or wrong key: leave stream state alone
            return False
        link_id = msgbuf[-13]
        tlow, thigh = _SIGN_TS.unpack(bytes(msgbuf[-12:-6]))
        ts = tlow + (thigh << 32)
        stream = (link_id, src_system, src_component)
        last = signing.stream_timestamps.get(stream)
        if last is not None:
            if ts <= last:
                counters.rejected_replay += 1
                return False
        elif ts + NEW_STREAM_MAX_AGE_TICKS < signing.timestamp:
            counters.rejected_replay += 1  # a "new" stream older than 60 s: a recorded replay
            return False
        signing.stream_timestamps[stream] = ts
        signing.timestamp = max(signing.timestamp, ts)
        return True

    return check_signature


def enable_signing(
    link: Link,
    key: bytes,
    link_id: int,
    initial_timestamp: int | None = None,
    *,
    allow_unsigned_ids: Iterable[int] = (),
    hardened: bool = True,
) -> None:
    """Sign everything we send and reject unsigned / badly signed / replayed input.

    ``link_id`` (0..255) names our outgoing stream. ``initial_timestamp`` in 10 us ticks since
    2015-01-01 (None = now). ``allow_unsigned_ids``: message ids accepted unsigned; empty by
    default. A reasonable exception is RADIO_STATUS (109) from a SiK radio, which cannot sign
    and carries no command; never allow anything that moves the vehicle or changes its mode.
    """
    if not isinstance(key, (bytes, bytearray)) or len(key) != KEY_LEN:
        raise MpfError(f"signing key must be {KEY_LEN} bytes")
    if not 0 <= int(link_id) <= 255:
        raise MpfError(f"signing link_id must be 0..255, got {link_id}")
    allowed = frozenset(int(i) for i in allow_unsigned_ids)

    def allow_unsigned(_mav: Any, msg_id: int) -> bool:
        return msg_id in allowed

    link.conn.setup_signing(
        bytes(key),
        sign_outgoing=True,
        allow_unsigned_callback=allow_unsigned,
        initial_timestamp=initial_timestamp,
        link_id=int(link_id),
    )
    if hardened:
        # decode() calls self.check_signature(...): an instance attribute shadows the method
        link.conn.mav.check_signature = _hardened_check_signature(link)
    link._signing_counts_itself = hardened
    link.sender.signing_enabled = True


def disable_signing(link: Link) -> None:
    link.conn.disable_signing()
    link.conn.mav.__dict__.pop("check_signature", None)
    link._signing_counts_itself = False
    link.sender.signing_enabled = False
