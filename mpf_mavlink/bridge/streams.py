"""The bridge's telemetry negotiation before engaging (:class:`StreamNegotiator`): message
intervals (or ArduPilot's REQUEST_DATA_STREAM fallback), measured rates, the home position."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from mpf_mavlink.bridge.base import BridgeResult
from mpf_mavlink.bridge.commands import is_final
from mpf_mavlink.bridge.link_io import VehicleLink
from mpf_mavlink.mavlink import (
    Flavour,
    dialect,
    encode_get_home_position,
    encode_request_data_stream,
    encode_request_message,
    encode_set_message_interval,
)
from mpf_mavlink.mavlink.wire_limits import MAV_CMD_SET_MESSAGE_INTERVAL

#: The window (s) over which a stream's rate is measured.
RATE_WINDOW_S = 1.0
#: How long interval requests get before ArduPilot is also sent REQUEST_DATA_STREAM (s).
INTERVAL_GRACE_S = 1.5

#: (message, id, requested Hz, minimum Hz) of one stream the loop needs.
Plan = list[tuple[str, int, float, float]]


class StreamNegotiator:
    """Asks for the streams the loop needs and measures what arrives (on ``vl.arrivals``)."""

    def __init__(self, vl: VehicleLink, log: Callable[[str], None]) -> None:
        self.vl, self.m, self.log = vl, vl.m, log

    def plan(self) -> Plan:
        """(message, id, requested Hz, minimum Hz) of what the loop needs."""
        m, d = self.m, dialect
        wind = ("WIND", d.MAVLINK_MSG_ID_WIND) if self.vl.flavour is Flavour.ARDUPILOT else (
            "WIND_COV", d.MAVLINK_MSG_ID_WIND_COV)  # fmt: skip
        local = d.MAVLINK_MSG_ID_LOCAL_POSITION_NED
        plan = [
            ("ATTITUDE", d.MAVLINK_MSG_ID_ATTITUDE, m.attitude_rate_hz, m.attitude_min_hz),
            ("LOCAL_POSITION_NED", local, m.position_rate_hz, m.position_min_hz),
            # the geodetic anchor (and the position when LOCAL_POSITION_NED is not streamed)
            ("GLOBAL_POSITION_INT", d.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
             min(m.position_rate_hz, 10.0), 0.0),
            ("VFR_HUD", d.MAVLINK_MSG_ID_VFR_HUD, m.airspeed_rate_hz, m.airspeed_min_hz),
        ]  # fmt: skip
        if m.wind_rate_hz > 0:
            plan.append((wind[0], wind[1], m.wind_rate_hz, 0.0))
        return plan

    def measured(self, name: str, now: float, window: float = RATE_WINDOW_S) -> float:
        """Messages per second of type ``name`` over the last ``window`` s."""
        q = (self.vl.arrivals or {}).get(name)
        if not q:
            return 0.0
        return sum(1 for t in q if t > now - window) / window

    def short(self, plan: Plan, now: float) -> list[str]:
        """The streams below their minimum now, one clause each."""
        out = []
        for name, _mid, hz, lo in plan:
            if lo <= 0:
                continue
            got = self.measured(name, now)
            if name == "LOCAL_POSITION_NED":
                # a vehicle without a local frame: the global position is the position
                got = max(got, self.measured("GLOBAL_POSITION_INT", now))
            if got < lo:
                out.append(f"{name} at {got:.1f} Hz (asked {hz:g}, needs >= {lo:g})")
        return out

    def negotiate(self, res: BridgeResult) -> str | None:
        """Ask for the stream rates the loop needs and verify them; None when reached, else why
        not (one clause). ArduPlane streams 1 Hz per group on a stock link (SRn defaults), PX4's
        onboard link streams fast already; both honour ArduPilot
        also REQUEST_DATA_STREAM (sent when an interval request is not accepted or not reached
        within INTERVAL_GRACE_S)."""
        vl, m = self.vl, self.m
        plan = self.plan()
        if m.lockstep:  # the rates are measured on the vehicle's clock: have it first
            vl.spin(m.heartbeat_timeout_s, lambda: vl.vehicle_t is not None)
        vl.arrivals = {}
        interval = MAV_CMD_SET_MESSAGE_INTERVAL
        # one request per message, their ACKs taken as they come (the rates decide)
        vl.commands.send_all(
            [encode_set_message_interval(vl.link.mav, vl.sysid, vl.compid, mid, hz)
             for _name, mid, hz, _ in plan],
            interval,
        )  # fmt: skip
        method = "MAV_CMD_SET_MESSAGE_INTERVAL"
        t_req = t0 = vl.clock()
        wall0 = time.monotonic()  # lockstep: a vehicle that sends nothing shows no time at all
        refused: list[str] = []
        fallback_sent = False
        try:
            while True:
                vl.spin(0.1)
                now = vl.clock()
                refused += [a.result_name for a in vl.commands.take(interval)
                            if is_final(a) and not a.accepted]  # fmt: skip
                if (
                    vl.flavour is Flavour.ARDUPILOT
                    and not fallback_sent
                    and (refused or (now - t0 >= INTERVAL_GRACE_S and self.short(plan, now)))
                ):
                    self._request_data_streams()
                    method += " + REQUEST_DATA_STREAM"
                    fallback_sent, t_req = True, now
                if now - t_req >= RATE_WINDOW_S + 0.2 and not self.short(plan, now):
                    break
                if now - t0 >= m.stream_timeout_s or (
                    m.lockstep and time.monotonic() - wall0 >= m.lockstep_wall_timeout_s
                ):
                    lacking = self.short(plan, now)
                    if lacking:
                        extra = f"; refused: {', '.join(sorted(set(refused)))}" if refused else ""
                        return (
                            f"stream rates not reached within {m.stream_timeout_s:g} s: "
                            f"{'; '.join(lacking)}{extra}"
                        )
                    break
            self._report(res, plan, method)
            return None
        finally:
            vl.arrivals = None

    def _request_data_streams(self) -> None:
        """ArduPilot's REQUEST_DATA_STREAM for the groups (MAV_DATA_STREAM_*) holding the
        messages we need (libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp, STREAM_*_msgs)."""
        vl, m, d = self.vl, self.m, dialect
        by_group = {d.MAV_DATA_STREAM_EXTRA1: m.attitude_rate_hz,
                    d.MAV_DATA_STREAM_POSITION: m.position_rate_hz,
                    d.MAV_DATA_STREAM_EXTRA2: m.airspeed_rate_hz}  # fmt: skip
        if m.wind_rate_hz > 0:
            by_group[d.MAV_DATA_STREAM_EXTRA3] = m.wind_rate_hz
        for sid, hz in by_group.items():
            vl.send(
                encode_request_data_stream(vl.link.mav, vl.sysid, vl.compid, sid, math.ceil(hz))
            )

    def _report(self, res: BridgeResult, plan: Plan, method: str) -> None:
        now = self.vl.clock()
        msgs = {
            name: {"requested_hz": hz, "min_hz": lo,
                   "measured_hz": round(self.measured(name, now), 2)}
            for name, _mid, hz, lo in plan
        }  # fmt: skip
        res.streams = {"method": method, "messages": msgs}
        self.log(f"stream rates asked ({method}): " + ", ".join(
            f"{k} {v['requested_hz']:g} Hz (measured {v['measured_hz']:.1f})"
            for k, v in msgs.items()))  # fmt: skip

    def await_home(self, has_home: Callable[[], bool], describe: Callable[[], str]) -> bool:
        """Ask for HOME_POSITION (MAV_CMD_REQUEST_MESSAGE, then MAV_CMD_GET_HOME_POSITION for
        older autopilots) until ``has_home()``; ArduPlane never streams it on its own."""
        vl = self.vl
        mav, sysid, comp = vl.link.mav, vl.sysid, vl.compid
        t_end = time.monotonic() + self.m.home_timeout_s
        k = 0
        while time.monotonic() < t_end:
            if k % 2 == 0:
                home_id = dialect.MAVLINK_MSG_ID_HOME_POSITION
                vl.send(encode_request_message(mav, sysid, comp, home_id))
            else:
                vl.send(encode_get_home_position(mav, sysid, comp))
            k += 1
            if vl.spin(min(1.0, max(0.0, t_end - time.monotonic())), has_home):
                self.log(f"home: {describe()}")
                return True
        self.log(f"no HOME_POSITION within {self.m.home_timeout_s:g} s")
        return False
