"""Incoming messages, once due, to the piece of the vehicle that answers each: setpoints to the
autopilot emulation, flying commands to its command handler, stream requests to the telemetry,
parameters / missions / FTP to the ground-station services, TIMESYNC answered here."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as M

from sim.vehicle.telemetry import STREAM_COMMANDS

if TYPE_CHECKING:
    from sim.vehicle.vehicle import SimVehicle


def dispatch(v: SimVehicle, msg: Any) -> None:
    """One incoming message, due now, to the piece that answers it."""
    mt, me = msg.get_type(), (0, v.sysid)
    if mt == "SET_ATTITUDE_TARGET":
        if msg.target_system not in me:
            v.autopilot.setpoints.dropped["wrong_target"] += 1
        else:
            v.autopilot.set_attitude_target(msg, v.time.ms())
    elif mt in ("COMMAND_LONG", "COMMAND_INT") and msg.target_system in me:
        try:
            if msg.command in STREAM_COMMANDS:
                v.telemetry.command(msg)
            else:
                v.autopilot.commands.command(msg)
        except (ValueError, OverflowError):  # a NaN / huge where an integer belongs
            v.link.ack(msg.command, M.MAV_RESULT_DENIED, msg)
    elif mt == "SET_MODE" and msg.target_system in me:
        v.autopilot.commands.set_mode(msg)
    elif mt == "REQUEST_DATA_STREAM" and msg.target_system in me:
        v.telemetry.request_data_stream(msg)
    elif mt in v.gcs.HANDLES:
        try:
            v.gcs.handle(msg)
        except (ValueError, OverflowError, TypeError):  # malformed: no answer, no crash
            dropped = v.autopilot.setpoints.dropped
            dropped["malformed"] = dropped.get("malformed", 0) + 1
    elif mt == "TIMESYNC" and msg.tc1 == 0:
        mav = v.link.mav
        mav.send(mav.timesync_encode(int(v.time.boot_s * 1e9), msg.ts1))
