"""MAVLink I/O boundary: the only package of mpf_mavlink that imports pymavlink.

Wire protocol and dialect
-------------------------
pymavlink picks its wire protocol when a dialect is loaded: ``MAVLINK20`` in the environment
selects ``pymavlink.dialects.v20`` (MAVLink 2: signing, 24-bit message ids, trimmed payloads).
We set it here, before the first import of ``pymavlink.mavutil`` from this package, and load the
dialect explicitly with ``mavutil.set_dialect`` (which reads the variable at call time, so this
also works when another module imported mavutil first).

Dialect: ``ardupilotmega``. It is a superset of ``common`` (PX4 only needs ``common``) and adds
ArduPilot's WIND (#168), SIMSTATE, AHRS2... that the SITL recordings and ArduPlane stream. Both
MAVLink 1 (0xFE) and MAVLink 2 (0xFD) frames are parsed; we always *send* MAVLink 2.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from mpf_mavlink.mavlink.codec import (
    AttitudeSample,
    CommandAckSample,
    FollowTargetSample,
    GlobalPositionSample,
    HeartbeatSample,
    HomeSample,
    LocalPositionSample,
    VfrHudSample,
    WindSample,
    decode,
)
from mpf_mavlink.mavlink.encode import (
    encode_arm,
    encode_companion_heartbeat,
    encode_do_reposition,
    encode_get_home_position,
    encode_request_data_stream,
    encode_request_message,
    encode_set_attitude_target_quat,
    encode_set_attitude_target_rates,
    encode_set_message_interval,
    encode_set_mode,
)
from mpf_mavlink.mavlink.link import Link, open_link, wait_heartbeat
from mpf_mavlink.mavlink.link_send import LinkCounters
from mpf_mavlink.mavlink.modes import (
    Flavour,
    flavour_from_heartbeat,
    is_offboard,
    mode_name,
)
from mpf_mavlink.mavlink.pymav import DIALECT_NAME, dialect, mavutil
from mpf_mavlink.mavlink.url import parse_url

if TYPE_CHECKING:
    from mpf_mavlink.mavlink.signing import enable_signing, load_signing_key
    from mpf_mavlink.mavlink.tlog import TlogWriter
    from mpf_mavlink.mavlink.tlog_read import TlogReadResult, iter_tlog, read_tlog

#: the tlog's and signing's names, imported when first asked for: a flight that does not record
#: loads no tlog module, one unsigned no signing
_LAZY = {
    "enable_signing": "mpf_mavlink.mavlink.signing",
    "load_signing_key": "mpf_mavlink.mavlink.signing",
    "TlogWriter": "mpf_mavlink.mavlink.tlog",
    "TlogReadResult": "mpf_mavlink.mavlink.tlog_read",
    "iter_tlog": "mpf_mavlink.mavlink.tlog_read",
    "read_tlog": "mpf_mavlink.mavlink.tlog_read",
}


def __getattr__(name: str) -> Any:
    """The tlog's names of :data:`_LAZY`, from their module (PEP 562)."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "DIALECT_NAME",
    "dialect",
    "mavutil",
    "AttitudeSample",
    "CommandAckSample",
    "FollowTargetSample",
    "GlobalPositionSample",
    "HeartbeatSample",
    "HomeSample",
    "LocalPositionSample",
    "VfrHudSample",
    "WindSample",
    "decode",
    "encode_arm",
    "encode_companion_heartbeat",
    "encode_do_reposition",
    "encode_get_home_position",
    "encode_request_data_stream",
    "encode_request_message",
    "encode_set_message_interval",
    "encode_set_attitude_target_quat",
    "encode_set_attitude_target_rates",
    "encode_set_mode",
    "Link",
    "LinkCounters",
    "open_link",
    "parse_url",
    "wait_heartbeat",
    "Flavour",
    "flavour_from_heartbeat",
    "is_offboard",
    "mode_name",
    "enable_signing",
    "load_signing_key",
    "TlogReadResult",
    "TlogWriter",
    "iter_tlog",
    "read_tlog",
]
