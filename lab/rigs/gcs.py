"""The rig's ground-station link to the firmware: modes, arming, parameters, what it sees.

It does what a pilot's ground station does and nothing more; the bridge has its own link.
Time is the autopilot's (``time_boot_ms`` of what it sends), so that a flight at a speed-up
is timed in the firmware's seconds.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mpf_mavlink.mavlink.modes import (  # noqa: E402
    Flavour,
    arduplane_mode_from_name,
    mode_name,
    px4_mode_from_name,
)

MAV_CMD_DO_SET_MODE, MAV_CMD_COMPONENT_ARM_DISARM = 176, 400


def recv_from(
    c: Any, sysid: int, secs: float, poll_s: float, tick: Callable[[], None] = lambda: None
) -> Iterator[Any]:
    """The messages of system ``sysid`` that connection ``c`` receives in ``secs`` of wall
    time, waiting at most ``poll_s`` at a time; ``tick()`` runs before every wait."""
    t_end = time.monotonic() + secs
    while True:
        tick()
        left = t_end - time.monotonic()
        if left <= 0:
            return
        m = c.recv_match(blocking=True, timeout=min(left, poll_s))
        if m is not None and m.get_srcSystem() == sysid:
            yield m


class Gcs:
    """One MAVLink connection as a ground station (system 255, component 190)."""

    def __init__(self, url: str, flavour: Flavour, timeout_s: float = 60.0) -> None:
        self.flavour = flavour
        t_end = time.monotonic() + timeout_s
        last: Exception | None = None
        while True:
            try:
                self.c = mavutil.mavlink_connection(url, source_system=255, source_component=190)
                break
            except OSError as e:  # the firmware is not listening yet
                last = e
                if time.monotonic() > t_end:
                    raise RuntimeError(f"no SITL on {url}: {last}") from None
                time.sleep(0.5)
        self.last: dict[str, Any] = {}
        self.t_boot_s = 0.0  # the autopilot's clock, from the last time_boot_ms seen
        self._hb_sent = -math.inf
        hb = None
        while hb is None and time.monotonic() < t_end:
            self._heartbeat()
            hb = self.c.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
            if hb is not None and hb.get_srcComponent() != 1:
                hb = None  # only the autopilot's own (component 1)
        if hb is None:
            raise RuntimeError(f"no HEARTBEAT on {url} within {timeout_s:g} s")
        self.sys, self.comp = hb.get_srcSystem(), hb.get_srcComponent()
        self.last["HEARTBEAT"] = hb
        if flavour == Flavour.ARDUPILOT:  # stock ArduPilot streams 1 Hz until asked
            for sid, hz in ((6, 5), (10, 10), (11, 5), (2, 1), (3, 2)):
                self.c.mav.request_data_stream_send(self.sys, self.comp, sid, hz, 1)

    def _heartbeat(self) -> None:
        now = time.monotonic()
        if now - self._hb_sent >= 1.0:  # PX4 counts a GCS as connected while it hears one
            self.c.mav.heartbeat_send(6, 8, 0, 0, 0)  # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID
            self._hb_sent = now

    def pump(self, secs: float, echo: bool = True) -> None:
        """Read for ``secs`` of wall time, keeping the latest message of each type."""
        for m in recv_from(self.c, self.sys, secs, 0.1, self._heartbeat):
            if m.get_type() == "HEARTBEAT" and m.get_srcComponent() != self.comp:
                continue  # the bridge's own HEARTBEAT, routed by the autopilot
            self.last[m.get_type()] = m
            tb = getattr(m, "time_boot_ms", None)
            if tb is not None and m.get_type() in ("ATTITUDE", "GLOBAL_POSITION_INT"):
                self.t_boot_s = tb / 1000.0
            if echo and m.get_type() == "STATUSTEXT":
                print(f"  [sitl] {m.text}", flush=True)

    def wait_boot(self, secs: float) -> None:
        """Pump until the autopilot's clock has advanced by ``secs``."""
        t0 = self.t_boot_s
        while self.t_boot_s - t0 < secs:
            self.pump(0.2)

    def mode(self) -> str:
        hb = self.last.get("HEARTBEAT")
        return "?" if hb is None else mode_name(self.flavour, hb)

    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return bool(hb and hb.base_mode & 128)

    def note_hold(
        self, modes: list[str], trace: list[tuple[float, float, float, float, float]], t: float
    ) -> None:
        """Append the mode when it changed, and (t s, roll rad, N, E, D m) when t moved on."""
        if not modes or modes[-1] != self.mode():
            modes.append(self.mode())
        att, lp = self.last.get("ATTITUDE"), self.last.get("LOCAL_POSITION_NED")
        if att is not None and lp is not None and (not trace or trace[-1][0] != t):
            trace.append((t, att.roll, lp.x, lp.y, lp.z))

    def arm_retrying(self, t_end: float, attempt: Callable[[], None], late: str) -> None:
        """Runs ``attempt()`` (a take-off request and an arm) every 3 s until the vehicle is
        armed; RuntimeError(``late``) past ``t_end`` (monotonic s)."""
        last_try = -math.inf
        while not self.armed():
            if time.monotonic() > t_end:
                raise RuntimeError(late)
            if time.monotonic() - last_try > 3.0:
                attempt()
                last_try = time.monotonic()
            self.pump(0.5)

    def climb_until(
        self, t_end: float, reached: Callable[[Any], bool], late: Callable[[], str]
    ) -> None:
        """Pumps until ``reached(GLOBAL_POSITION_INT)`` (called with the latest, which is
        never None); RuntimeError(``late()``) past ``t_end`` (monotonic s)."""
        while True:
            if time.monotonic() > t_end:
                raise RuntimeError(late())
            self.pump(0.5)
            gp = self.last.get("GLOBAL_POSITION_INT")
            if gp is not None and reached(gp):
                return

    def settle(self, secs: float) -> None:
        """Waits ``secs`` of the autopilot's time for the loiter to settle and says where."""
        self.wait_boot(secs)
        gp = self.last["GLOBAL_POSITION_INT"]
        print(f"loitering at {gp.relative_alt / 1000.0:.1f} m ({self.mode()})", flush=True)

    def command(self, cmd: int, *params: float) -> None:
        p = [*params, *([0.0] * (7 - len(params)))]
        self.c.mav.command_long_send(self.sys, self.comp, cmd, 0, *p)

    def set_mode(self, name: str) -> None:
        if self.flavour == Flavour.PX4:
            main, sub = px4_mode_from_name(name)
            self.command(MAV_CMD_DO_SET_MODE, 1, main, sub)
        else:
            self.command(MAV_CMD_DO_SET_MODE, 1, arduplane_mode_from_name(name))

    def arm(self) -> None:
        self.command(MAV_CMD_COMPONENT_ARM_DISARM, 1)

    def set_param(self, name: str, value: float, timeout_s: float = 5.0) -> None:
        """Set a parameter and wait for the autopilot to echo the new value."""
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            self.c.mav.param_set_send(self.sys, self.comp, name.encode(), float(value), 9)
            got = self._param_value(name, 1.0)
            if got is not None and abs(got - value) <= 1e-4 * max(1.0, abs(value)):
                return
        raise RuntimeError(f"the autopilot did not take {name}={value:g}")

    def get_param(self, name: str, timeout_s: float = 5.0) -> float | None:
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            self.c.mav.param_request_read_send(self.sys, self.comp, name.encode(), -1)
            v = self._param_value(name, 1.0)
            if v is not None:
                return v
        return None

    def _param_value(self, name: str, timeout_s: float) -> float | None:
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            self._heartbeat()
            m = self.c.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
            if m is not None and m.param_id.rstrip("\x00") == name:
                return float(m.param_value)
        return None

    def close(self) -> None:
        self.c.close()
