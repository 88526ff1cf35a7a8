"""The mode and command tables of mpf_mavlink/mavlink/modes.py against what we did not write:
pymavlink's own PX4 and ArduPlane mode maps and the MAVLink dialect's enums."""

from __future__ import annotations

from pymavlink import mavutil

import mpf_mavlink.mavlink  # noqa: F401  (loads the MAVLink 2 ardupilotmega dialect)
from mpf_mavlink.mavlink import modes
from mpf_mavlink.mavlink.modes import (
    ARDUPLANE_MODES,
    PX4_AUTO_SUB_MODES,
    PX4_MAIN_MODES,
    px4_custom_mode,
    px4_decode_custom_mode,
    px4_mode_from_name,
)


def test_arduplane_modes_are_pymavlinks():
    theirs = {v: k for k, v in mavutil.mode_mapping_apm.items()}
    for name, num in ARDUPLANE_MODES.items():
        # pymavlink spells one name without underscores (LOITERALTQLAND)
        assert theirs.get(name, theirs.get(name.replace("_", ""))) == num, name
    assert set(ARDUPLANE_MODES.values()) == set(mavutil.mode_mapping_apm)


def test_px4_modes_are_pymavlinks():
    for name, (_base, main, sub) in mavutil.px4_map.items():
        known = name in PX4_MAIN_MODES or name in PX4_AUTO_SUB_MODES
        if known:
            assert px4_mode_from_name(name) == (main, sub), name
    # pymavlink's symbolic constants: every main mode and AUTO sub mode we name
    for name, num in PX4_MAIN_MODES.items():
        const = getattr(mavutil, f"PX4_CUSTOM_MAIN_MODE_{name.replace('_LEGACY', '')}", None)
        assert const is None or const == num, name
    for name, num in PX4_AUTO_SUB_MODES.items():
        const = getattr(mavutil, f"PX4_CUSTOM_SUB_MODE_AUTO_{name}", None)
        assert const is None or const == num, name


def test_px4_custom_mode_round_trip():
    for main in PX4_MAIN_MODES.values():
        for sub in (0, *PX4_AUTO_SUB_MODES.values()):
            assert px4_decode_custom_mode(px4_custom_mode(main, sub)) == (main, sub)
    assert modes.PX4_LOITER_CUSTOM_MODE == (4 << 16) | (3 << 24)


def test_command_and_flag_numbers_are_the_dialects():
    d = mavutil.mavlink
    names = [
        n for n in dir(modes) if n.startswith(("MAV_CMD_", "MAV_MODE_FLAG_", "MAV_AUTOPILOT_"))
    ]
    assert len(names) >= 15
    for n in names:
        assert getattr(modes, n) == getattr(d, n), n
