"""The emulated autopilot's answers to COMMAND_LONG / COMMAND_INT and SET_MODE about flying:
mode changes, arming, DO_REPOSITION, NAV_TAKEOFF, each acknowledged as the flavour's firmware
does. Stream and version requests are the endpoint's (:mod:`sim.vehicle.telemetry`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

from pymavlink.dialects.v20 import ardupilotmega as M

from mpf_mavlink.core.frames import geodetic_to_ned
from mpf_mavlink.mavlink.modes import ARDUPLANE_MODES, px4_decode_custom_mode
from sim.autopilot.modes import GUIDED, PX4_AUTO, PX4_HOLD, PX4_LOITER, Modes, Tunables
from sim.autopilot.setpoints import Setpoints, finite

ARDUPILOT_FORCE_DISARM = 21196.0  # param2 magic of MAV_CMD_COMPONENT_ARM_DISARM
_GLOBAL = (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT)
_RELATIVE = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


class Outbox(Protocol):
    """Where the emulation's answers go (:class:`sim.vehicle.link.Link`)."""

    def ack(self, command: int, result: int, msg: Any, reason: str | None = None) -> None: ...

    def statustext(self, severity: int, text: str) -> None: ...


class Commands:
    """COMMAND_* and SET_MODE of the flying kind, answered for the emulation's ``modes`` and
    ``setpoints``; ``state`` returns the plant's state now."""

    HANDLED = frozenset(
        (
            M.MAV_CMD_DO_SET_MODE,
            M.MAV_CMD_COMPONENT_ARM_DISARM,
            M.MAV_CMD_DO_REPOSITION,
            M.MAV_CMD_NAV_TAKEOFF,
        )
    )

    def __init__(self, px4: bool, modes: Modes, setpoints: Setpoints, tunables: Tunables,
                 home_lla: tuple[float, float, float], state: Callable[[], Any],
                 out: Outbox) -> None:  # fmt: skip
        self.px4 = px4
        self.modes = modes
        self.setpoints = setpoints
        self.tun = tunables
        self.home_lla = home_lla
        self.state = state
        self.out = out

    def _offboard_ready(self) -> bool:
        return self.setpoints.offboard_available(self.modes.clock.boot_s)

    def set_mode(self, msg: Any) -> None:
        """SET_MODE: PX4 acks it as DO_SET_MODE, ArduPilot with command 11 (the message id)."""
        ready = self._offboard_ready
        if self.px4:
            main, sub = px4_decode_custom_mode(msg.custom_mode)
            res, _ = self.modes.request(float(msg.base_mode), float(main), float(sub), ready)
            self.out.ack(M.MAV_CMD_DO_SET_MODE, res, msg)
        else:
            res, _ = self.modes.request(float(msg.base_mode), float(msg.custom_mode), 0.0, ready)
            self.out.ack(M.MAVLINK_MSG_ID_SET_MODE, res, msg)

    def command(self, msg: Any) -> None:
        """One command of :attr:`HANDLED`, acknowledged."""
        cmd, ack, px4 = msg.command, self.out.ack, self.px4
        p1, p2 = msg.param1, msg.param2
        if cmd == M.MAV_CMD_DO_SET_MODE:
            res, why = self.modes.request(p1, p2, msg.param3, self._offboard_ready)
            ack(cmd, res, msg, why)
        elif cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p1 >= 0.5 or abs(p2 - ARDUPILOT_FORCE_DISARM) < 0.5:
                self.modes.armed = p1 >= 0.5
                ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            else:  # in the air: both autopilots refuse a disarm unless forced
                res = M.MAV_RESULT_TEMPORARILY_REJECTED if px4 else M.MAV_RESULT_FAILED
                ack(cmd, res, msg, "Disarm refused: vehicle is flying (use force 21196)")
        elif cmd == M.MAV_CMD_DO_REPOSITION and px4:
            ack(cmd, self._px4_reposition(msg), msg)
        elif cmd == M.MAV_CMD_DO_REPOSITION:
            # ArduPlane takes it as COMMAND_INT only; a COMMAND_LONG is UNSUPPORTED (4.7 SITL)
            is_int = msg.get_type() == "COMMAND_INT"
            ack(cmd, self._ap_reposition(msg) if is_int else M.MAV_RESULT_UNSUPPORTED, msg)
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            ack(cmd, self._takeoff(msg), msg)
        else:
            ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)

    def _ap_reposition(self, msg: Any) -> int:
        """ArduPlane's MAV_CMD_DO_REPOSITION (COMMAND_INT): in GUIDED (or with the change-mode
        flag) the guided target becomes a loiter of radius param3 (> 0; else the loiter radius)
        about (x, y, z), counter-clockwise when param4 is non-zero; the forced attitude stays."""
        lat, lon = msg.x * 1e-7, msg.y * 1e-7
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0) or (msg.x == 0 and msg.y == 0):
            return int(M.MAV_RESULT_DENIED)
        alt = float(msg.z)
        if msg.frame in _RELATIVE:
            alt += self.home_lla[2]
        elif msg.frame not in _GLOBAL:
            return int(M.MAV_RESULT_DENIED)
        modes = self.modes
        if not (int(msg.param2) & 1) and modes.behaviour != GUIDED:
            return int(M.MAV_RESULT_FAILED)
        if modes.behaviour != GUIDED:
            modes.set_ardupilot(ARDUPLANE_MODES["GUIDED"])
        n, e, d = (float(v) for v in geodetic_to_ned(lat, lon, alt, *self.home_lla))
        ok = math.isfinite(msg.param3) and msg.param3 > 0
        r = float(msg.param3) if ok else self.tun.loiter_radius
        ccw = math.isfinite(msg.param4) and msg.param4 != 0.0
        self.setpoints.guided_loiter = ((n, e), -d, r, -1 if ccw else 1)
        return int(M.MAV_RESULT_ACCEPTED)

    def _position(self, msg: Any) -> tuple[float, float, float] | None:
        """(lat deg, lon deg, altitude AMSL m) of a COMMAND_INT (x, y 1e7, z; a global frame)
        or COMMAND_LONG (param5..7); None when not finite or out of range. A NaN altitude is
        the current one (the MAVLink rule for "keep")."""
        if msg.get_type() == "COMMAND_INT":
            if msg.frame not in _GLOBAL + _RELATIVE:
                return None
            lat, lon, alt = msg.x * 1e-7, msg.y * 1e-7, float(msg.z)
            rel = msg.frame in _RELATIVE
        else:
            lat, lon, alt, rel = float(msg.param5), float(msg.param6), float(msg.param7), False
        if not (finite(lat, lon) and abs(lat) <= 90.0 and abs(lon) <= 180.0):
            return None
        if lat == 0 and lon == 0:
            return None
        if not math.isfinite(alt):
            alt = float(self.state().alt_m)
        elif rel:
            alt += self.home_lla[2]
        return lat, lon, alt

    def _px4_reposition(self, msg: Any) -> int:
        """PX4's MAV_CMD_DO_REPOSITION: with the change-mode flag (param2 bit 0), or already in
        Hold, the vehicle loiters about the point (radius param3 when > 0, as PX4's fixed-wing
        navigator) at its altitude; without either it is accepted and changes nothing."""
        pos = self._position(msg)
        if pos is None:
            return int(M.MAV_RESULT_DENIED)
        modes = self.modes
        if not (int(msg.param2) & 1) and modes.custom_mode != PX4_HOLD:
            return int(M.MAV_RESULT_ACCEPTED)
        if modes.custom_mode != PX4_HOLD:
            modes.set_px4(PX4_AUTO, PX4_LOITER)
        n, e, d = (float(x) for x in geodetic_to_ned(*pos, *self.home_lla))
        modes.center, modes.alt_sp = (n, e), -d
        if math.isfinite(msg.param3) and msg.param3 > 0:
            modes.hold_radius = float(msg.param3)
        return int(M.MAV_RESULT_ACCEPTED)

    def _takeoff(self, msg: Any) -> int:
        """MAV_CMD_NAV_TAKEOFF in the air. PX4 accepts it and enters AUTO.TAKEOFF (here: a loiter
        climbing to param7, AMSL, where it is). ArduPlane answers FAILED (4.7 SITL does so from
        the ground; its TAKEOFF is a mode, not this command)."""
        if not self.px4:
            return int(M.MAV_RESULT_FAILED)
        alt = float(msg.param7) if msg.get_type() == "COMMAND_LONG" else float(msg.z)
        self.modes.set_px4(PX4_AUTO, 2)  # AUTO.TAKEOFF
        if math.isfinite(alt):
            self.modes.alt_sp = alt - self.home_lla[2]
        return int(M.MAV_RESULT_ACCEPTED)
