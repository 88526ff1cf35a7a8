"""What the autopilot does when the bridge's setpoints stop (:class:`FallbackSetup`): PX4's
offboard-loss action made Hold (parameters, before engaging) and its loiter point; ArduPlane's
GUIDED loiter about the path's centre (after engaging)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mpf_mavlink.bridge.base import BridgeResult
from mpf_mavlink.bridge.controller import Controller
from mpf_mavlink.bridge.link_io import VehicleLink, param_set_value
from mpf_mavlink.bridge.px4_fallback import PX4_FALLBACK_PARAMS, PX4_OBL_HOLD, describe, detail
from mpf_mavlink.core.frames import ned_to_geodetic
from mpf_mavlink.mavlink import dialect, encode_do_reposition
from mpf_mavlink.mavlink.wire_limits import MAV_CMD_DO_REPOSITION

#: PARAM_REQUEST_READ / PARAM_SET attempts (0.6 s each) for PX4's fallback: with 20 % loss
#: each way one round trip fails 36 % of the time, six in a row 0.2 %
FALLBACK_ATTEMPTS = 6
PARAM_WAIT_S = 0.6
#: How long a DO_REPOSITION's COMMAND_ACK is waited for (s).
REPOSITION_ACK_S = 1.5
#: How far (m) the path's centre moves before the fallback point follows it.
FOLLOW_MOVED_M = 5.0
#: Mean Earth radius (m), for the small distances :meth:`FallbackSetup.follow` compares.
EARTH_RADIUS_M = 6_371_000.0
#: The loiter radius about the path's centre is the path's extent, within these bounds (m).
LOITER_RADIUS_M = (50.0, 1000.0)


class FallbackSetup:
    """The autopilot's own fallback, read and set over ``vl``; the path's centre from ``ctl``."""

    def __init__(
        self, vl: VehicleLink, ctl: Controller, path_cfg: Any, log: Callable[[str], None]
    ) -> None:
        self.vl, self.ctl, self.path_cfg, self.log = vl, ctl, path_cfg, log
        self.set_from: float | None = None  # the COM_OBL_RC_ACT we replaced
        self.follow_s = float(vl.m.fallback_follow_s)
        self._placed: tuple[float, float, bool] | None = None  # lat, lon (deg), PX4's form
        self._placed_t = 0.0  # mission time (s) of the last placement
        self.replaced = 0  # placements after the first (a moving target's)
        self._refused: str | None = None

    def px4_params(self, res: BridgeResult) -> str | None:
        """PX4, before engaging: read what an offboard loss does (px4_fallback.py), make it Hold
        (COM_OBL_RC_ACT = 5 by PARAM_SET, confirmed by the PARAM_VALUE that answers it) and
        say so in ``res.fallback``. Returns why the bridge must not engage (the Hold could not
        be confirmed), else None."""
        vl = self.vl
        p = vl.params
        self._read_params()
        act = p.get("COM_OBL_RC_ACT")
        if act is not None and int(act) != PX4_OBL_HOLD:
            self.set_from = act
            ptype = vl.param_types.get("COM_OBL_RC_ACT", dialect.MAV_PARAM_TYPE_INT32)
            p.pop("COM_OBL_RC_ACT", None)
            value = param_set_value(PX4_OBL_HOLD, ptype, True)
            for _ in range(FALLBACK_ATTEMPTS):  # answered by PARAM_VALUE; a lost one re-sent
                vl.send(vl.link.mav.param_set_encode(
                    vl.sysid, vl.compid, b"COM_OBL_RC_ACT", value, ptype))  # fmt: skip
                if vl.spin(PARAM_WAIT_S, lambda: "COM_OBL_RC_ACT" in p):
                    break
        res.fallback = describe(p, self.set_from)
        res.fallback_detail = detail(p, self.set_from, None)
        act = p.get("COM_OBL_RC_ACT")
        if act is None or int(act) != PX4_OBL_HOLD:
            got = "no answer" if act is None else f"it is {int(act)}"
            return (
                f"PX4's offboard-loss action could not be made Hold (COM_OBL_RC_ACT = 5: {got}); "
                "mavlink.set_fallback: false flies without"
            )
        return None

    def _read_params(self) -> None:
        # a request or its answer lost on a lossy link is asked again (an autopilot without a
        # parameter stays silent: only the first two are required)
        vl, p = self.vl, self.vl.params
        core = PX4_FALLBACK_PARAMS[:2]
        for attempt in range(FALLBACK_ATTEMPTS):
            for name in PX4_FALLBACK_PARAMS:
                if name not in p:
                    req = vl.link.mav.param_request_read_encode
                    vl.send(req(vl.sysid, vl.compid, name.encode("ascii"), -1))
            if vl.spin(PARAM_WAIT_S, lambda: all(n in p for n in PX4_FALLBACK_PARAMS)):
                break
            if attempt >= 1 and all(n in p for n in core):
                break

    def px4_prepare(self, res: BridgeResult) -> str | None:
        """PX4, before engaging: with ``mavlink.set_fallback`` :meth:`px4_params` (and why not
        to engage, or None); without, what decides instead (into ``res.fallback``)."""
        if not self.vl.m.set_fallback:
            res.fallback = (
                "not read or set (mavlink.set_fallback: false): PX4's COM_OBL_RC_ACT decides "
                "(stock 0: Position mode, which on a fixed-wing flies straight on, not a hold)"
            )
            return None
        why = self.px4_params(res)
        self.log(f"fallback if the bridge dies: {res.fallback}")
        return why

    def px4_reposition(self, res: BridgeResult) -> None:
        """PX4 in OFFBOARD: MAV_CMD_DO_REPOSITION to the path's centre at the path's altitude,
        without a mode change (param2 = 0): the navigator keeps it as the loiter point of the
        next Hold (the offboard-loss failsafe set above, or our hand-back), instead of where the
        aircraft happens to be then."""
        vl = self.vl
        got = self.path_centre()
        if isinstance(got, str):
            res.fallback = describe(vl.params, self.set_from)
            self.log(f"fallback if the bridge dies: {res.fallback} ({got})")
            return
        lat, lon, alt, _r, _ccw = got
        try:
            msg = encode_do_reposition(
                vl.link.mav, vl.sysid, vl.compid, lat, lon, alt, 100.0, False, px4=True
            )
        except ValueError as e:
            self.log(f"fallback: no reposition point ({e})")
            return
        ack = vl.commands.command(msg, MAV_CMD_DO_REPOSITION, REPOSITION_ACK_S)
        where = f"the path's centre {lat:.7f}, {lon:.7f} at {alt:.1f} m AMSL"
        centre = None
        if ack is not None and ack.accepted:
            centre = where
            self._placed = (lat, lon, True)
        else:
            why = ack.result_name if ack is not None else "no COMMAND_ACK"
            self.log(f"fallback: DO_REPOSITION to {where} not accepted ({why})")
        point = None if centre is None else {"lat": lat, "lon": lon, "alt_amsl_m": alt}
        res.fallback = describe(vl.params, self.set_from, centre)
        res.fallback_detail = detail(vl.params, self.set_from, point)
        self.log(f"fallback if the bridge dies: {res.fallback}")

    def ardupilot_loiter(self, res: BridgeResult) -> None:
        """ArduPlane in GUIDED: make its guided target a loiter about the path's centre at the
        path's altitude (radius and direction of the path when it is a circle), so that the
        aircraft circles where the mission was when our setpoints stop (GUIDED_TIMEOUT)."""
        vl = self.vl
        got = self.path_centre()
        if isinstance(got, str):
            if got == "no HOME_POSITION":
                res.fallback = "ArduPlane's own GUIDED loiter (no HOME_POSITION: none set by us)"
                self.log(f"fallback if the bridge dies: {res.fallback}")
            else:
                res.fallback = f"ArduPlane's own GUIDED loiter ({got})"
            return
        lat, lon, alt, radius, ccw = got
        try:
            msg = encode_do_reposition(
                vl.link.mav, vl.sysid, vl.compid, lat, lon, alt, radius, ccw)  # fmt: skip
        except ValueError as e:
            res.fallback = f"ArduPlane's own GUIDED loiter (reposition not sent: {e})"
            self.log(f"fallback if the bridge dies: {res.fallback}")
            return
        ack = vl.commands.command(msg, MAV_CMD_DO_REPOSITION, REPOSITION_ACK_S)
        what = (
            f"ArduPlane GUIDED loiter r = {radius:.0f} m {'CCW' if ccw else 'CW'} about "
            f"{lat:.7f}, {lon:.7f} at {alt:.1f} m AMSL (the path's centre)"
        )
        if ack is not None and ack.accepted:
            res.fallback = what
            self._placed = (lat, lon, False)
        else:
            why = ack.result_name if ack is not None else "no COMMAND_ACK"
            res.fallback = f"NOT set ({why}): ArduPlane's own GUIDED loiter; asked for {what}"
        self.log(f"fallback if the bridge dies: {res.fallback}")

    def follow(self, t: float) -> None:
        """While tracking, at mission time ``t`` (s): every ``mavlink.fallback_follow_s`` of it,
        re-place the fallback point at the path's centre once the centre has moved more than
        :data:`FOLLOW_MOVED_M` from it, so that an aircraft whose bridge dies loiters where the
        target is, not where it was at engagement. The DO_REPOSITION is not waited for (the
        control loop must not stall); a refusal is read at the next placement and logged once."""
        if self._placed is None or self.follow_s <= 0.0 or t - self._placed_t < self.follow_s:
            return
        self._placed_t = t
        for ack in self.vl.commands.take(MAV_CMD_DO_REPOSITION):
            if not ack.accepted and self._refused is None:
                self._refused = ack.result_name
                self.log(f"fallback: re-placing the loiter point refused ({ack.result_name})")
        got = self.path_centre()
        if isinstance(got, str):
            return
        lat, lon, alt, radius, ccw = got
        lat0, lon0, px4 = self._placed
        dn = math.radians(lat - lat0) * EARTH_RADIUS_M
        de = math.radians(lon - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
        if math.hypot(dn, de) < FOLLOW_MOVED_M:
            return
        vl = self.vl
        try:
            msg = encode_do_reposition(
                vl.link.mav, vl.sysid, vl.compid, lat, lon, alt,
                100.0 if px4 else radius, False if px4 else ccw, px4=px4,
            )  # fmt: skip
        except ValueError:
            return
        vl.commands.send(msg, MAV_CMD_DO_REPOSITION)
        self._placed = (lat, lon, px4)
        self.replaced += 1

    def path_centre(self) -> tuple[float, float, float, float, bool] | str:
        """(lat, lon, alt AMSL, radius m, counter-clockwise) of the path's centre now, or why
        not."""
        ctl = self.ctl
        o = ctl.est.origin.geodetic()
        est, _ = ctl.est.estimate()
        if o is None or est is None:
            return "no HOME_POSITION"
        tgt = ctl.target.state(est.vehicle.t)
        if isinstance(tgt, str):
            return tgt
        pts = np.asarray(ctl.path.positions(), float)  # in the target frame
        centre_T = pts.mean(axis=0)
        centre = tgt.position + tgt.R_T_I @ centre_T
        radius = float(np.max(np.linalg.norm((pts - centre_T)[:, :2], axis=1)))
        radius = min(max(radius, LOITER_RADIUS_M[0]), LOITER_RADIUS_M[1])
        p = self.path_cfg
        ccw = p.type in ("circle", "helix") and not p.clockwise
        lat0, lon0, alt0, off = o
        lat, lon, alt = ned_to_geodetic(centre - np.asarray(off, float), lat0, lon0, alt0)
        return float(lat), float(lon), float(alt), radius, bool(ccw)
