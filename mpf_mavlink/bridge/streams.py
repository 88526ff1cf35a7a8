"""The bridge's telemetry negotiation before engaging: message intervals (or ArduPilot's
REQUEST_DATA_STREAM fallback), measured rates, the home position, the autopilot's fallback settings."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from mpf_mavlink.bridge.base import (
    _AP_STREAM_EXTRA1,
    _AP_STREAM_EXTRA2,
    _AP_STREAM_EXTRA3,
    _AP_STREAM_POSITION,
    MAV_CMD_DO_REPOSITION,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    BridgeResult,
)
from mpf_mavlink.bridge.link_io import LinkIO, param_set_value
from mpf_mavlink.bridge.px4_fallback import PX4_FALLBACK_PARAMS, PX4_OBL_HOLD, describe, detail
from mpf_mavlink.mavlink import (
    Flavour,
    dialect,
    encode_do_reposition,
    encode_get_home_position,
    encode_request_data_stream,
    encode_request_message,
    encode_set_message_interval,
)

#: PARAM_REQUEST_READ / PARAM_SET attempts (0.6 s each) for PX4's fallback: with 20 % loss
#: each way one round trip fails 36 % of the time, six in a row 0.2 %
FALLBACK_ATTEMPTS = 6


class Streams(LinkIO):
    """Stream rates, home position and the autopilot's own fallback, before engaging."""

    # -- streams, home, fallback ----------------------------------------------------------------
    def _stream_plan(self) -> list[tuple[str, int, float, float]]:
        """(message, id, requested Hz, minimum Hz) of what the loop needs."""
        m = self.m
        d = dialect
        wind = ("WIND", d.MAVLINK_MSG_ID_WIND) if self.flavour is Flavour.ARDUPILOT else (
            "WIND_COV", d.MAVLINK_MSG_ID_WIND_COV)  # fmt: skip
        plan = [
            ("ATTITUDE", d.MAVLINK_MSG_ID_ATTITUDE, m.attitude_rate_hz, m.attitude_min_hz),
            ("LOCAL_POSITION_NED", d.MAVLINK_MSG_ID_LOCAL_POSITION_NED, m.position_rate_hz, m.position_min_hz),
            # the geodetic anchor (and the position when LOCAL_POSITION_NED is not streamed)
            ("GLOBAL_POSITION_INT", d.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, min(m.position_rate_hz, 10.0), 0.0),
            ("VFR_HUD", d.MAVLINK_MSG_ID_VFR_HUD, m.airspeed_rate_hz, m.airspeed_min_hz),
        ]  # fmt: skip
        if m.wind_rate_hz > 0:
            plan.append((wind[0], wind[1], m.wind_rate_hz, 0.0))
        return plan

    def _measured(self, name: str, window: float, now: float) -> float:
        q = (self._arrivals or {}).get(name)
        if not q:
            return 0.0
        return sum(1 for t in q if t > now - window) / window

    def _negotiate_streams(self, res: BridgeResult) -> str | None:
        """Ask for the stream rates the loop needs and verify them; None when reached, else why
        not (one clause). ArduPlane streams 1 Hz per group on a stock link (SRn defaults), PX4's
        onboard link streams fast already; both honour MAV_CMD_SET_MESSAGE_INTERVAL, ArduPilot
        also REQUEST_DATA_STREAM (sent when an interval request is not accepted or not reached
        within 1.5 s)."""
        m, mav, sysid, comp = self.m, self.link.mav, self.m.vehicle_sysid, self.vehicle_compid
        plan = self._stream_plan()
        self._arrivals = {}
        self.acks.clear()
        for _name, mid, hz, _ in plan:
            self._send(encode_set_message_interval(mav, sysid, comp, mid, hz))
        method = "MAV_CMD_SET_MESSAGE_INTERVAL"
        t_req = t0 = time.monotonic()
        window = 1.0
        fallback_sent = False
        refused: list[str] = []

        def short(now: float) -> list[str]:
            out = []
            for name, _mid, hz, lo in plan:
                if lo <= 0:
                    continue
                got = self._measured(name, window, now)
                if name == "LOCAL_POSITION_NED":
                    # a vehicle without a local frame: the global position is the position
                    got = max(got, self._measured("GLOBAL_POSITION_INT", window, now))
                if got < lo:
                    out.append(f"{name} at {got:.1f} Hz (asked {hz:g}, needs >= {lo:g})")
            return out

        try:
            while True:
                self._spin(0.1)
                now = time.monotonic()
                for a in self.acks:
                    if a.command == MAV_CMD_SET_MESSAGE_INTERVAL and not a.accepted:
                        refused.append(a.result_name)
                self.acks.clear()
                if (
                    self.flavour is Flavour.ARDUPILOT
                    and not fallback_sent
                    and (refused or (now - t0 >= 1.5 and short(now)))
                ):
                    by_group = {_AP_STREAM_EXTRA1: m.attitude_rate_hz,
                                _AP_STREAM_POSITION: m.position_rate_hz,
                                _AP_STREAM_EXTRA2: m.airspeed_rate_hz}  # fmt: skip
                    if m.wind_rate_hz > 0:
                        by_group[_AP_STREAM_EXTRA3] = m.wind_rate_hz
                    for sid, hz in by_group.items():
                        self._send(
                            encode_request_data_stream(mav, sysid, comp, sid, int(math.ceil(hz)))
                        )
                    method += " + REQUEST_DATA_STREAM"
                    fallback_sent = True
                    t_req = now
                if now - t_req >= window + 0.2 and not short(now):
                    break
                if now - t0 >= m.stream_timeout_s:
                    lacking = short(now)
                    if lacking:
                        extra = f"; refused: {', '.join(sorted(set(refused)))}" if refused else ""
                        return (
                            f"stream rates not reached within {m.stream_timeout_s:g} s: "
                            f"{'; '.join(lacking)}{extra}"
                        )
                    break
            now = time.monotonic()
            res.streams = {
                "method": method,
                "messages": {
                    name: {
                        "requested_hz": hz,
                        "min_hz": lo,
                        "measured_hz": round(self._measured(name, window, now), 2),
                    }
                    for name, _mid, hz, lo in plan
                },  # fmt: skip
            }
            self.log(f"stream rates asked ({method}): " + ", ".join(
                f"{k} {v['requested_hz']:g} Hz (measured {v['measured_hz']:.1f})"
                for k, v in res.streams["messages"].items()))  # fmt: skip
            return None
        finally:
            self._arrivals = None

    def _await_home(self) -> bool:
        """Ask for HOME_POSITION (MAV_CMD_REQUEST_MESSAGE, then MAV_CMD_GET_HOME_POSITION for
        older autopilots) and wait for it; ArduPlane never streams it on its own."""
        mav, sysid, comp = self.link.mav, self.m.vehicle_sysid, self.vehicle_compid
        t_end = time.monotonic() + self.m.home_timeout_s
        k = 0
        while time.monotonic() < t_end:
            if k % 2 == 0:
                self._send(
                    encode_request_message(mav, sysid, comp, dialect.MAVLINK_MSG_ID_HOME_POSITION)
                )
            else:
                self._send(encode_get_home_position(mav, sysid, comp))
            k += 1
            if self._spin(min(1.0, max(0.0, t_end - time.monotonic())),
                          lambda: self.est.home is not None):  # fmt: skip
                h = self.est.home
                self.log(f"home: {h.lat_deg:.7f}, {h.lon_deg:.7f}, {h.alt_amsl_m:.2f} m AMSL")
                return True
        self.log(f"no HOME_POSITION within {self.m.home_timeout_s:g} s")
        return False

    def _px4_fallback(self, res: BridgeResult) -> str | None:
        """PX4, before engaging: read what an offboard loss does (px4_fallback.py), make it Hold
        (COM_OBL_RC_ACT = 5 by PARAM_SET, confirmed by the PARAM_VALUE that answers it) and
        say so in ``res.fallback``. Returns why the bridge must not engage (the Hold could not
        be confirmed), else None."""
        mav, sysid, comp = self.link.mav, self.m.vehicle_sysid, self.vehicle_compid
        p = self.params
        core = PX4_FALLBACK_PARAMS[:2]
        # a request or its answer lost on a lossy link is asked again (an autopilot without a
        # parameter stays silent: only the first two are required)
        for attempt in range(FALLBACK_ATTEMPTS):
            for name in PX4_FALLBACK_PARAMS:
                if name not in p:
                    self._send(mav.param_request_read_encode(sysid, comp, name.encode("ascii"), -1))
            if self._spin(0.6, lambda: all(n in p for n in PX4_FALLBACK_PARAMS)):
                break
            if attempt >= 1 and all(n in p for n in core):
                break
        act = p.get("COM_OBL_RC_ACT")
        set_from: float | None = None
        if act is not None and int(act) != PX4_OBL_HOLD:
            set_from = act
            ptype = self.param_types.get("COM_OBL_RC_ACT", dialect.MAV_PARAM_TYPE_INT32)
            p.pop("COM_OBL_RC_ACT", None)
            for _ in range(FALLBACK_ATTEMPTS):  # answered by PARAM_VALUE; a lost one re-sent
                self._send(mav.param_set_encode(
                    sysid, comp, b"COM_OBL_RC_ACT",
                    param_set_value(PX4_OBL_HOLD, ptype, True), ptype))  # fmt: skip
                if self._spin(0.6, lambda: "COM_OBL_RC_ACT" in p):
                    break
        self._px4_fallback_state = (set_from, None)
        res.fallback = describe(p, set_from)
        res.fallback_detail = detail(p, set_from, None)
        act = p.get("COM_OBL_RC_ACT")
        if act is None or int(act) != PX4_OBL_HOLD:
            got = "no answer" if act is None else f"it is {int(act)}"
            return f"PX4's offboard-loss action could not be made Hold (COM_OBL_RC_ACT = 5: {got}); mavlink.set_fallback: false flies without"
        return None

    def _px4_reposition(self, res: BridgeResult) -> None:
        """PX4 in OFFBOARD: MAV_CMD_DO_REPOSITION to the path's centre at the path's altitude,
        without a mode change (param2 = 0): the navigator keeps it as the loiter point of the
        next Hold (the offboard-loss failsafe set above, or our hand-back), instead of where the
        aircraft happens to be then."""
        set_from = getattr(self, "_px4_fallback_state", (None, None))[0]
        got = self._path_centre()
        if isinstance(got, str):
            res.fallback = describe(self.params, set_from)
            self.log(f"fallback if the bridge dies: {res.fallback} ({got})")
            return
        lat, lon, alt, _r, _ccw = got
        self.acks.clear()
        try:
            self._send(encode_do_reposition(
                self.link.mav, self.m.vehicle_sysid, self.vehicle_compid, lat, lon, alt, 100.0,
                False, px4=True))  # fmt: skip
        except ValueError as e:
            self.log(f"fallback: no reposition point ({e})")
            return
        ack = self._reposition_ack()
        where = f"the path's centre {lat:.7f}, {lon:.7f} at {alt:.1f} m AMSL"
        centre = None
        if ack is not None and ack.accepted:
            centre = where
        else:
            why = ack.result_name if ack is not None else "no COMMAND_ACK"
            self.log(f"fallback: DO_REPOSITION to {where} not accepted ({why})")
        res.fallback = describe(self.params, set_from, centre)
        res.fallback_detail = detail(
            self.params,
            set_from,
            None if centre is None else {"lat": lat, "lon": lon, "alt_amsl_m": alt},
        )
        self.log(f"fallback if the bridge dies: {res.fallback}")

    def _reposition_ack(self) -> Any | None:
        """The autopilot's COMMAND_ACK to the DO_REPOSITION just sent, within 1.5 s, or None."""
        acks: list[Any] = []

        def acked() -> bool:
            acks.extend(a for a in self.acks if a.command == MAV_CMD_DO_REPOSITION)
            self.acks.clear()
            return bool(acks)

        self._spin(1.5, acked)
        return acks[0] if acks else None

    def _path_centre(self) -> tuple[float, float, float, float, bool] | str:
        """(lat, lon, alt AMSL, radius m, counter-clockwise) of the path's centre now, or why
        not."""
        from mpf_mavlink.core.frames import ned_to_geodetic

        o = self.est.geodetic_origin()
        est, _ = self.est.estimate()
        if o is None or est is None:
            return "no HOME_POSITION"
        tgt = self.target.state(est.vehicle.t)
        if isinstance(tgt, str):
            return tgt
        pts = self.path.positions()  # in the target frame
        centre_T = np.asarray(pts, float).mean(axis=0)
        centre = tgt.position + tgt.R_T_I @ centre_T
        radius = float(np.max(np.linalg.norm((np.asarray(pts, float) - centre_T)[:, :2], axis=1)))
        radius = min(max(radius, 50.0), 1000.0)
        p = self.cfg.path
        ccw = p.type in ("circle", "helix") and not p.clockwise
        lat0, lon0, alt0, off = o
        lat, lon, alt = ned_to_geodetic(centre - np.asarray(off, float), lat0, lon0, alt0)
        return float(lat), float(lon), float(alt), radius, bool(ccw)

    def _set_set_fallback(self, res: BridgeResult) -> None:
        """ArduPlane in GUIDED: make its guided target a loiter about the path's centre at the
        path's altitude (radius and direction of the path when it is a circle), so that the
        aircraft circles where the mission was when our setpoints stop (GUIDED_TIMEOUT)."""
        got = self._path_centre()
        if isinstance(got, str):
            if got == "no HOME_POSITION":
                res.fallback = "ArduPlane's own GUIDED loiter (no HOME_POSITION: none set by us)"
                self.log(f"fallback if the bridge dies: {res.fallback}")
            else:
                res.fallback = f"ArduPlane's own GUIDED loiter ({got})"
            return
        lat, lon, alt, radius, ccw = got
        self.acks.clear()
        try:
            self._send(encode_do_reposition(
                self.link.mav, self.m.vehicle_sysid, self.vehicle_compid, lat, lon, alt, radius, ccw))  # fmt: skip
        except ValueError as e:
            res.fallback = f"ArduPlane's own GUIDED loiter (reposition not sent: {e})"
            self.log(f"fallback if the bridge dies: {res.fallback}")
            return
        ack = self._reposition_ack()
        what = (
            f"ArduPlane GUIDED loiter r = {radius:.0f} m {'CCW' if ccw else 'CW'} about "
            f"{lat:.7f}, {lon:.7f} at {alt:.1f} m AMSL (the path's centre)"
        )
        if ack is not None and ack.accepted:
            res.fallback = what
        else:
            why = ack.result_name if ack is not None else "no COMMAND_ACK"
            res.fallback = f"NOT set ({why}): ArduPlane's own GUIDED loiter; asked for {what}"
        self.log(f"fallback if the bridge dies: {res.fallback}")
