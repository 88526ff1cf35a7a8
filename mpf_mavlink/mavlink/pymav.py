"""The one place pymavlink is loaded: MAVLink 2 selected before the first import of mavutil,
the ``ardupilotmega`` dialect loaded explicitly (see the package docstring)."""

from __future__ import annotations

import os
from typing import Any

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil as mavutil  # noqa: E402  (the environment must be set first)

DIALECT_NAME = "ardupilotmega"


def _load_dialect() -> Any:
    mavutil.set_dialect(DIALECT_NAME)
    mod = mavutil.mavlink
    if mod is None or mod.WIRE_PROTOCOL_VERSION != "2.0":  # pragma: no cover - env sabotage
        raise ImportError(f"pymavlink did not load the MAVLink 2 {DIALECT_NAME} dialect")
    return mod


#: the generated pymavlink dialect module (message classes, enums, ``MAVLink`` parser class)
dialect: Any = _load_dialect()
