"""THE flight-mode tables of PX4 and ArduPlane, the MAV_CMD numbers the project sends or
answers, and HEARTBEAT helpers: every other module (bridge, SIL vehicle, rigs) takes its modes and
commands from here.

PX4 packs its mode into HEARTBEAT.custom_mode as ``(main << 16) | (sub << 24)``
(src/modules/commander/px4_custom_mode.h); ArduPilot sends the mode number itself
(ArduPlane/mode.h ``Mode::Number``). Both set MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (1) in
base_mode. The tables are plain data: no pymavlink needed (works on HeartbeatSample too);
tests/test_modes.py checks them against pymavlink's own tables and the MAVLink dialect.
"""

from __future__ import annotations

import enum
from typing import Any, Protocol

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_MODE_FLAG_AUTO_ENABLED = 4
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_STABILIZE_ENABLED = 16

# --- MAV_CMD (common.xml MAV_CMD) the bridge sends and the SIL vehicle answers -----------------
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_REPOSITION = 192
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_GET_HOME_POSITION = 410
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
#: param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces arming/disarming (PX4 and ArduPilot)
ARM_FORCE_MAGIC = 21196


class Flavour(enum.StrEnum):
    """Which autopilot family we talk to (decides mode encoding and setpoint type_mask)."""

    PX4 = "px4"
    ARDUPILOT = "ardupilot"
    UNKNOWN = "unknown"


class _HeartbeatLike(Protocol):
    autopilot: int
    base_mode: int
    custom_mode: int


# --- PX4 (px4_custom_mode.h) -----------------------------------------------------------------
PX4_MAIN_MODES: dict[str, int] = {
    "MANUAL": 1,
    "ALTCTL": 2,
    "POSCTL": 3,
    "AUTO": 4,
    "ACRO": 5,
    "OFFBOARD": 6,
    "STABILIZED": 7,
    "RATTITUDE_LEGACY": 8,
}
PX4_AUTO_SUB_MODES: dict[str, int] = {
    "READY": 1,
    "TAKEOFF": 2,
    "LOITER": 3,  # "Hold" in QGroundControl
    "MISSION": 4,
    "RTL": 5,
    "LAND": 6,
    "FOLLOW_TARGET": 8,
    "PRECLAND": 9,
    "VTOL_TAKEOFF": 10,
}
_PX4_MAIN_BY_NUM = {v: k for k, v in PX4_MAIN_MODES.items()}
_PX4_AUTO_SUB_BY_NUM = {v: k for k, v in PX4_AUTO_SUB_MODES.items()}
#: number -> name, the tables above turned round
PX4_MAIN_MODE_NAMES: dict[int, str] = dict(_PX4_MAIN_BY_NUM)
PX4_AUTO_SUB_MODE_NAMES: dict[int, str] = dict(_PX4_AUTO_SUB_BY_NUM)

# --- ArduPlane (ArduPlane/mode.h, Mode::Number) -----------------------------------------------
ARDUPLANE_MODES: dict[str, int] = {
    "MANUAL": 0,
    "CIRCLE": 1,
    "STABILIZE": 2,
    "TRAINING": 3,
    "ACRO": 4,
    "FBWA": 5,
    "FBWB": 6,
    "CRUISE": 7,
    "AUTOTUNE": 8,
    "AUTO": 10,
    "RTL": 11,
    "LOITER": 12,
    "TAKEOFF": 13,
    "AVOID_ADSB": 14,
    "GUIDED": 15,
    "INITIALISING": 16,
    "QSTABILIZE": 17,
    "QHOVER": 18,
    "QLOITER": 19,
    "QLAND": 20,
    "QRTL": 21,
    "QAUTOTUNE": 22,
    "QACRO": 23,
    "THERMAL": 24,
    "LOITER_ALT_QLAND": 25,
    "AUTOLAND": 26,
}
_ARDUPLANE_BY_NUM = {v: k for k, v in ARDUPLANE_MODES.items()}
ARDUPLANE_MODE_NAMES: dict[int, str] = dict(_ARDUPLANE_BY_NUM)

PX4_OFFBOARD_MAIN = PX4_MAIN_MODES["OFFBOARD"]
ARDUPLANE_GUIDED = ARDUPLANE_MODES["GUIDED"]
ARDUPLANE_LOITER = ARDUPLANE_MODES["LOITER"]


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """PX4 HEARTBEAT.custom_mode from main and sub mode: ``(main << 16) | (sub << 24)``."""
    if not (0 <= main <= 255 and 0 <= sub <= 255):
        raise ValueError(f"PX4 main/sub mode out of range: main={main} sub={sub}")
    return (main << 16) | (sub << 24)


def px4_decode_custom_mode(custom_mode: int) -> tuple[int, int]:
    """PX4 custom_mode -> (main, sub); the low 16 bits are unused by PX4."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


#: PX4 HEARTBEAT.custom_mode of OFFBOARD and of AUTO.LOITER ("Hold", the default hand-back)
PX4_OFFBOARD_CUSTOM_MODE = px4_custom_mode(PX4_OFFBOARD_MAIN)
PX4_LOITER_CUSTOM_MODE = px4_custom_mode(PX4_MAIN_MODES["AUTO"], PX4_AUTO_SUB_MODES["LOITER"])


def px4_mode_from_name(name: str) -> tuple[int, int]:
    """'OFFBOARD' -> (6, 0); 'AUTO.LOITER' or 'LOITER' -> (4, 3). ValueError for unknown names."""
    key = name.strip().upper()
    if key.startswith("AUTO."):
        key = key[5:]
    if key in PX4_MAIN_MODES and key != "AUTO":
        return PX4_MAIN_MODES[key], 0
    if key in PX4_AUTO_SUB_MODES:
        return PX4_MAIN_MODES["AUTO"], PX4_AUTO_SUB_MODES[key]
    raise ValueError(f"unknown PX4 mode {name!r}")


def arduplane_mode_from_name(name: str) -> int:
    """'GUIDED' -> 15. ValueError for unknown names."""
    key = name.strip().upper()
    if key not in ARDUPLANE_MODES:
        raise ValueError(f"unknown ArduPlane mode {name!r}")
    return ARDUPLANE_MODES[key]


def flavour_from_heartbeat(hb: Any) -> Flavour:
    """MAV_AUTOPILOT_PX4 (12) -> PX4, MAV_AUTOPILOT_ARDUPILOTMEGA (3) -> ARDUPILOT, else UNKNOWN."""
    ap = getattr(hb, "autopilot", None)
    if ap == MAV_AUTOPILOT_PX4:
        return Flavour.PX4
    if ap == MAV_AUTOPILOT_ARDUPILOTMEGA:
        return Flavour.ARDUPILOT
    return Flavour.UNKNOWN


def mode_name(flavour: Flavour | str, heartbeat: _HeartbeatLike) -> str:
    """Human name of the mode in a HEARTBEAT, e.g. 'OFFBOARD', 'AUTO.LOITER', 'GUIDED', 'QHOVER'.

    Unknown numbers come back as 'PX4(main,sub)' / 'MODE(n)' rather than raising: a newer
    firmware must not crash the loop.
    """
    flavour = Flavour(flavour)
    cm = int(heartbeat.custom_mode)
    if not (int(heartbeat.base_mode) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
        return f"BASE({int(heartbeat.base_mode)})"
    if flavour is Flavour.PX4:
        main, sub = px4_decode_custom_mode(cm)
        if main == PX4_MAIN_MODES["AUTO"]:
            sub_name = _PX4_AUTO_SUB_BY_NUM.get(sub)
            return f"AUTO.{sub_name}" if sub_name else f"AUTO({sub})"
        name = _PX4_MAIN_BY_NUM.get(main)
        return name if name else f"PX4({main},{sub})"
    if flavour is Flavour.ARDUPILOT:
        return _ARDUPLANE_BY_NUM.get(cm, f"MODE({cm})")
    return f"MODE({cm})"


def is_offboard(flavour: Flavour | str, heartbeat: _HeartbeatLike) -> bool:
    """True when the vehicle is in the mode that obeys our setpoints.

    PX4: main mode OFFBOARD (6). ArduPlane: GUIDED (15), the only mode in which it reads
    SET_ATTITUDE_TARGET. The custom-mode flag must be set in base_mode for either to count.
    """
    flavour = Flavour(flavour)
    if not (int(heartbeat.base_mode) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
        return False
    cm = int(heartbeat.custom_mode)
    if flavour is Flavour.PX4:
        return px4_decode_custom_mode(cm)[0] == PX4_OFFBOARD_MAIN
    if flavour is Flavour.ARDUPILOT:
        return cm == ARDUPLANE_GUIDED
    return False


def is_armed(heartbeat: _HeartbeatLike) -> bool:
    """MAV_MODE_FLAG_SAFETY_ARMED (128) in base_mode."""
    return bool(int(heartbeat.base_mode) & MAV_MODE_FLAG_SAFETY_ARMED)
