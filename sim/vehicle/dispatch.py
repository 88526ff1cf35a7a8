"""Incoming messages, once due, to the piece of the vehicle that answers each: setpoints to the
autopilot emulation, flying commands to its command handler, stream requests to the telemetry,
parameters / missions / FTP to the ground-station services, TIMESYNC answered here."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from sim.autopilot.emulation import AutopilotEmulation
from sim.vehicle.clock import StepClock
from sim.vehicle.gcs_services import GcsServices
from sim.vehicle.link import Link
from sim.vehicle.telemetry import STREAM_COMMANDS, Telemetry


class Dispatcher:
    """Routes due messages for one vehicle (system ``sysid``)."""

    def __init__(self, sysid: int, autopilot: AutopilotEmulation, telemetry: Telemetry,
                 gcs: GcsServices, link: Link, clock: StepClock) -> None:  # fmt: skip
        self.sysid = sysid
        self.autopilot, self.telemetry, self.gcs = autopilot, telemetry, gcs
        self.link, self.clock = link, clock

    def __call__(self, msg: Any) -> None:
        """One incoming message, due now, to the piece that answers it."""
        mt, me = msg.get_type(), (0, self.sysid)
        if mt == "SET_ATTITUDE_TARGET":
            if msg.target_system not in me:
                self.autopilot.setpoints.dropped["wrong_target"] += 1
            else:
                self.autopilot.set_attitude_target(msg, self.clock.ms())
        elif mt in ("COMMAND_LONG", "COMMAND_INT") and msg.target_system in me:
            if msg.command == M.MAV_CMD_DO_SET_MODE:
                self.link.lockstep.mode_request_applied()  # the lockstep waits again
            try:
                if msg.command in STREAM_COMMANDS:
                    self.telemetry.command(msg)
                else:
                    self.autopilot.commands.command(msg)
            except (ValueError, OverflowError):  # a NaN / huge where an integer belongs
                self.link.ack(msg.command, M.MAV_RESULT_DENIED, msg)
        elif mt == "SET_MODE" and msg.target_system in me:
            self.link.lockstep.mode_request_applied()
            self.autopilot.commands.set_mode(msg)
        elif mt == "REQUEST_DATA_STREAM" and msg.target_system in me:
            self.telemetry.request_data_stream(msg)
        elif mt in self.gcs.HANDLES:
            try:
                self.gcs.handle(msg)
            except (ValueError, OverflowError, TypeError):  # malformed: no answer, no crash
                dropped = self.autopilot.setpoints.dropped
                dropped["malformed"] = dropped.get("malformed", 0) + 1
        elif mt == "TIMESYNC" and msg.tc1 == 0:
            mav = self.link.mav
            mav.send(mav.timesync_encode(int(self.clock.boot_s * 1e9), msg.ts1))
