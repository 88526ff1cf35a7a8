"""The emulated autopilot's flight mode: which modes each flavour accepts, what each one flies
(a behaviour), the HEARTBEAT's base and custom mode, and what entering a mode sets (the hold's
centre, altitude and radius, the course to keep). Mode numbers are the firmware's
(:mod:`mpf_mavlink.mavlink.modes`)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pymavlink.dialects.v20 import ardupilotmega as M

from mpf_mavlink.mavlink.modes import (
    ARDUPLANE_MODES,
    PX4_AUTO_SUB_MODES,
    PX4_MAIN_MODES,
    px4_custom_mode,
)

# behaviours: what the emulation flies in a mode
LOITER, CRUISE, LEVEL, OFFBOARD, GUIDED = "loiter", "cruise", "level", "offboard", "guided"

# the modes the emulation accepts, by the firmware's number (others are refused as unknown)
PX4_BEHAVIOUR = {
    PX4_MAIN_MODES[name]: beh
    for name, beh in (
        ("MANUAL", LEVEL),
        ("ALTCTL", CRUISE),
        ("POSCTL", CRUISE),
        ("AUTO", LOITER),
        ("ACRO", LEVEL),
        ("OFFBOARD", OFFBOARD),
        ("STABILIZED", LEVEL),
    )
}
PX4_SUBS = {
    PX4_AUTO_SUB_MODES[n]: n for n in ("READY", "TAKEOFF", "LOITER", "MISSION", "RTL", "LAND")
}
PX4_NAMES = {num: name for name, num in PX4_MAIN_MODES.items() if num in PX4_BEHAVIOUR}
AP_BEHAVIOUR = {
    ARDUPLANE_MODES[name]: beh
    for name, beh in (
        ("MANUAL", LEVEL),
        ("CIRCLE", LOITER),
        ("STABILIZE", LEVEL),
        ("TRAINING", LEVEL),
        ("ACRO", LEVEL),
        ("FBWA", LEVEL),
        ("FBWB", CRUISE),
        ("CRUISE", CRUISE),
        ("AUTOTUNE", LEVEL),
        ("AUTO", LOITER),
        ("RTL", LOITER),
        ("LOITER", LOITER),
        ("TAKEOFF", LOITER),
        ("GUIDED", GUIDED),
    )
}
AP_NAMES = {num: name for name, num in ARDUPLANE_MODES.items() if num in AP_BEHAVIOUR}
PX4_AUTO, PX4_LOITER = PX4_MAIN_MODES["AUTO"], PX4_AUTO_SUB_MODES["LOITER"]
PX4_HOLD = px4_custom_mode(PX4_AUTO, PX4_LOITER)


class Time(Protocol):
    """The vehicle's clock as the emulation reads it (:class:`sim.vehicle.clock.StepClock`)."""

    @property
    def boot_s(self) -> float: ...

    @property
    def t(self) -> float: ...


@dataclass
class Tunables:
    """What a ground station may change in flight (parameters, :mod:`sim.vehicle.gcs_services`):
    the loss timeouts, the loiter radius and direction, the cruise airspeed and its limits."""

    com_of_loss_t: float = 1.0
    guided_timeout: float = 3.0
    loiter_radius: float = 80.0
    loiter_direction: int = 1
    cruise_airspeed: float = 16.0
    airspeed_trim: float = 16.0
    airspeed_min: float = 10.0
    airspeed_max: float = 20.0
    obl_rc_act: int = 0  # PX4 COM_OBL_RC_ACT: 0 = position (Hold), what the SIL flies
    # PX4's RC-loss parameters, at PX4 v1.16 SITL's values: stored and served, nothing else (the
    # SIL has no RC to lose)
    rcl_except: int = 0  # COM_RCL_EXCEPT
    nav_rcl_act: int = 2  # NAV_RCL_ACT: Return
    rc_in_mode: int = 1  # COM_RC_IN_MODE: SITL's rcS sets 1 (joystick only)
    px4_require_thrust: bool = False


class Modes:
    """The current mode, its behaviour and what its entry set; the log of changes."""

    def __init__(
        self,
        px4: bool,
        tunables: Tunables,
        clock: Time,
        state: Callable[[], Any],
        announce: Callable[[str], None],
    ) -> None:
        self.px4 = px4
        self.tun = tunables
        self.clock = clock
        self._state = state  # the plant's state now
        self._announce = announce  # "Mode X" to the ground
        self.on_guided: Callable[[], None] = lambda: None  # a GUIDED entry resets its setpoints
        self.armed = True
        self.behaviour = LEVEL
        self.name = ""
        self.custom_mode = 0
        self.center = (0.0, 0.0)  # hold centre (north, east m)
        self.hold_radius = tunables.loiter_radius
        self.alt_sp = 0.0  # altitude set-point (m above home)
        self.course = 0.0  # the course a cruise holds (rad)
        self.entered_s = 0.0  # boot time of the last entry
        self.changes: list[tuple[float, str]] = []  # (t, name)
        self.log: list[tuple[float, float, str]] = []  # (t, wall perf_counter s, name)

    def enter(self, behaviour: str, name: str, custom_mode: int, announce: bool) -> None:
        st = self._state()  # now, not the frame's start (a mode change can come mid-frame)
        self.behaviour, self.name, self.custom_mode = behaviour, name, custom_mode
        self.center = (float(st.position_ned[0]), float(st.position_ned[1]))
        self.hold_radius = self.tun.loiter_radius
        self.alt_sp = -float(st.position_ned[2])
        self.course = math.atan2(float(st.velocity_ned[1]), float(st.velocity_ned[0]))
        self.entered_s = self.clock.boot_s
        t = self.clock.t
        self.changes.append((t, name))
        self.log.append((t, time.perf_counter(), name))
        if behaviour == GUIDED:
            self.on_guided()
        if announce:
            self._announce(f"Mode {name}")

    def set_px4(self, main: int, sub: int = 0, announce: bool = True) -> None:
        if main == PX4_AUTO and sub == 0:
            sub = PX4_AUTO_SUB_MODES["MISSION"]  # PX4: AUTO without a sub mode is MISSION
        name = PX4_NAMES[main] + (f".{PX4_SUBS.get(sub, sub)}" if main == PX4_AUTO else "")
        if main != PX4_AUTO:
            sub = 0
        self.enter(PX4_BEHAVIOUR[main], name, px4_custom_mode(main, sub), announce)

    def set_ardupilot(self, number: int, announce: bool = True) -> None:
        self.enter(AP_BEHAVIOUR[number], AP_NAMES[number], int(number), announce)

    def hold(self, announce: bool = True) -> None:
        """The flavour's hold: PX4 AUTO.LOITER ("Hold"), ArduPlane LOITER."""
        if self.px4:
            self.set_px4(PX4_AUTO, PX4_LOITER, announce)
        else:
            self.set_ardupilot(ARDUPLANE_MODES["LOITER"], announce)

    def cruise(self, announce: bool = True) -> None:
        """Course and altitude hold: PX4 POSCTL, ArduPlane CRUISE."""
        if self.px4:
            self.set_px4(PX4_MAIN_MODES["POSCTL"], announce=announce)
        else:
            self.set_ardupilot(ARDUPLANE_MODES["CRUISE"], announce)

    def base_mode(self) -> int:
        """HEARTBEAT.base_mode: custom mode, armed, and the flags of the mode's kind."""
        b = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            b |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if self.behaviour != LEVEL or self.name not in ("MANUAL", "ACRO"):
            b |= M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self.behaviour in (OFFBOARD, GUIDED, LOITER):
            b |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.behaviour == LOITER:
            b |= M.MAV_MODE_FLAG_AUTO_ENABLED
        return int(b)

    def request(
        self, p1: float, p2: float, p3: float, offboard_ready: Callable[[], bool]
    ) -> tuple[int, str | None]:
        """MAV_CMD_DO_SET_MODE (param1..3): the result and, when refused, why."""
        px4 = self.px4
        if not (int(p1) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
            why = "Mode change refused: custom mode flag (param1 = 1) not set"
            return (M.MAV_RESULT_DENIED if px4 else M.MAV_RESULT_UNSUPPORTED), why
        if not px4:
            number = int(round(p2))
            if number not in AP_BEHAVIOUR:
                return M.MAV_RESULT_FAILED, f"Mode change refused: unknown ArduPlane mode {number}"
            if number != self.custom_mode:
                self.set_ardupilot(number)
            return M.MAV_RESULT_ACCEPTED, None
        main, sub = int(round(p2)), int(round(p3))
        if main not in PX4_BEHAVIOUR or (main == PX4_AUTO and sub not in PX4_SUBS and sub != 0):
            why = f"Mode change refused: unknown PX4 mode {main}/{sub}"
            return M.MAV_RESULT_TEMPORARILY_REJECTED, why
        offboard = PX4_MAIN_MODES["OFFBOARD"]
        if main == offboard and self.behaviour != OFFBOARD and not offboard_ready():
            why = "Mode change refused: offboard setpoints not streaming (> 2 Hz for 1 s)"
            return M.MAV_RESULT_TEMPORARILY_REJECTED, why
        if main == PX4_AUTO and sub == 0:
            sub = PX4_AUTO_SUB_MODES["MISSION"]  # PX4: AUTO without a sub mode is MISSION
        if px4_custom_mode(main, sub if main == PX4_AUTO else 0) != self.custom_mode:
            self.set_px4(main, sub)  # re-selecting the current mode changes nothing
        return M.MAV_RESULT_ACCEPTED, None
