"""The bridge's session (:class:`Session`): mode requests confirmed by ACK + HEARTBEAT, the
pilot watch, pre-flight checks, the path origin, hand-back and re-engagement."""

from __future__ import annotations

import dataclasses
import signal
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mpf_mavlink.bridge.base import EXIT_OK, EXIT_SAFETY, BridgeResult, Phase, State, _Stop
from mpf_mavlink.bridge.control_step import ControlLoop
from mpf_mavlink.bridge.controller import Controller, measured_inputs, origin_texts
from mpf_mavlink.bridge.operator import OperatorDisplay
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.frames import matrix_to_euler
from mpf_mavlink.mavlink import (
    Flavour,
    encode_set_mode,
    is_offboard,
    mode_name,
)
from mpf_mavlink.mavlink.modes import (
    arduplane_mode_from_name,
    px4_decode_custom_mode,
    px4_mode_from_name,
)
from mpf_mavlink.mavlink.wire_limits import MAV_CMD_DO_SET_MODE

if TYPE_CHECKING:
    from mpf_mavlink.bridge.preflight import SimulatedPlant

#: Extra mode requests a session may send for ACKs lost while the HEARTBEAT shows the mode.
MODE_REASKS = 8
#: How long after a mode request a re-ask for a lost ACK may go out (s).
MODE_REASK_AFTER_S = 0.3


def _measured_record(m: Any) -> dict[str, Any]:
    """The measured inputs of the pre-engage checks as metrics.json keeps them."""
    if m is None:
        return {}
    t = m.target
    return {
        "wind_ned_m_s": list(m.wind_ned_m_s),
        "wind_source": m.wind_source,
        "wind_var_m2_s2": m.wind_var_m2_s2,
        "wind_margin_m_s": m.wind_margin_m_s()[0],
        "airspeed_m_s": m.airspeed_m_s,
        "target": None if t is None else {
            "position_ned_m": list(t.position_ned_m), "speed_m_s": t.speed_m_s,
            "heading_rad": t.heading_rad, "turn_rate_rad_s": t.turn_rate_rad_s,
            "climb_rate_m_s": t.climb_rate_m_s,
        },
    }  # fmt: skip


def preflight_checks(
    ctl: Controller,
    cfg: Config,
    duration_s: float,
    res: BridgeResult,
    log: Callable[[str], None],
    plant: SimulatedPlant | None = None,
) -> list[Any]:
    """The pre-flight checks of a ``duration_s`` (s) mission from the vehicle's state now, with
    what it measures (wind, airspeed, a live target's motion); those failed (CheckResult). The
    checks' text goes to ``res.checks`` and ``log``. ``plant``: the simulated vehicle behind the
    link when there is one (:attr:`BridgeOptions.plant`)."""
    from mpf_mavlink.bridge.preflight import format_checks, run_checks

    ctl.set_origin()  # mission time 0: the checks' and the scripted target's origin
    est, _ = ctl.est.estimate()
    assert est is not None
    pos, R_W_I = est.vehicle.position, est.vehicle.R_W_I
    p0 = (float(pos[0]), float(pos[1]), float(pos[2]))
    cfg = dataclasses.replace(
        cfg,
        sim=dataclasses.replace(cfg.sim, duration_s=duration_s),
        kinematic=dataclasses.replace(
            cfg.kinematic,
            initial_position_ned_m=p0,
            initial_attitude_rpy_rad=matrix_to_euler(R_W_I),
        ),
    )
    if plant is not None:  # the SIL's own start gives way to where the aircraft is
        plant = dataclasses.replace(plant, initial_position_ned_m=p0)
    # what the autopilot reports now (wind, airspeed, the live target's motion), not what
    # the configuration assumes: a mission the measured wind makes infeasible is refused
    measured = measured_inputs(ctl)
    res.measured = _measured_record(measured)
    results = run_checks(cfg, not ctl.live, measured, plant, ctl.path)
    text = format_checks(results)
    res.checks = text.splitlines()
    log(text)
    return [r for r in results if not r.ok]


class Session:
    """Modes, the pilot watch, checks, hand-back and re-engagement of one run."""

    def __init__(
        self,
        cfg: Config,
        loop: ControlLoop,
        phase: Phase,
        display: OperatorDisplay,
        log: Callable[[str], None],
    ) -> None:
        self.cfg, self.loop, self.phase, self.display, self.log = cfg, loop, phase, display, log
        self.vl, self.ctl, self.m = loop.vl, loop.ctl, loop.m
        self.engaged = False
        self.n = {"mode_requests": 0, "reengagements": 0}

    # -- modes -------------------------------------------------------------------------------
    def on_heartbeat(self, hb: Any, rx: float | None) -> None:
        """The autopilot's HEARTBEAT: a mode change while engaged is someone else's."""
        vl = self.vl
        if not self.engaged or is_offboard(vl.flavour, hb):
            return
        mode = mode_name(vl.flavour, hb)
        if rx is not None and vl.link.clock_gate.restarting(rx):
            # a vehicle that reboots faster than the telemetry timeout comes back in its
            # start-up mode: that is no pilot, and the log should say so
            raise _Stop(
                f"the vehicle rebooted (its boot clock restarted) and came back in {mode}: "
                "stopped commanding",
                "pilot",
            )
        raise _Stop(
            f"mode changed to {mode} by someone else: stopped commanding, not fighting it",
            "pilot",
        )

    def mode_is(self, name: str) -> bool:
        hb = self.vl.hb
        if hb is None or not (hb.base_mode & 1):
            return False
        if self.vl.flavour is Flavour.PX4:
            main, sub = px4_mode_from_name(name)
            got = px4_decode_custom_mode(hb.custom_mode)
            return got[0] == main and (main != 4 or got[1] == sub)
        return bool(hb.custom_mode == arduplane_mode_from_name(name))

    def request_mode(self, name: str, confirm: Callable[[], bool]) -> tuple[bool, str]:
        """DO_SET_MODE with retries; confirmed by an accepted ACK and ``confirm()`` (heartbeat)."""
        vl, m = self.vl, self.m
        last = "no COMMAND_ACK"
        # ACKs of earlier attempts still count: on a lossy link an attempt's ACK and the 1 Hz
        # HEARTBEAT in the new mode often do not both arrive within one mode_timeout_s
        acked: list[bool] = []
        asks_left = MODE_REASKS

        def done() -> bool:
            nonlocal last
            for a in vl.commands.take(MAV_CMD_DO_SET_MODE):
                acked.append(a.accepted)
                last = a.result_name
            return any(acked) and confirm()

        def send() -> tuple[float, float | None]:
            # the ACKs of this mode's earlier attempts are taken first (done), not forgotten
            done()
            msg = encode_set_mode(vl.link.mav, vl.sysid, vl.compid, vl.flavour, name)
            vl.commands.send(msg, MAV_CMD_DO_SET_MODE)
            self.n["mode_requests"] += 1
            return time.monotonic(), vl.vehicle_t

        # lockstep: each attempt counts vehicle time; all of them together at most
        # lockstep_wall_timeout_s of wall time (a dead vehicle shows no time at all)
        wall_s = max(m.mode_timeout_s, m.lockstep_wall_timeout_s / m.mode_retries)
        vl.commands.take(MAV_CMD_DO_SET_MODE)  # answers to an earlier request
        for attempt in range(m.mode_retries):
            t_sent = send()
            t0, vt0 = t_sent  # the attempt's start (lockstep: vehicle time)
            while (left := vl.left(t0, vt0, m.mode_timeout_s, wall_s)) > 0.0:
                if vl.spin(min(left, 0.1), done):
                    return True, "confirmed"
                lost_ack = confirm() and not any(acked)
                if lost_ack and asks_left and vl.elapsed(*t_sent) >= MODE_REASK_AFTER_S:
                    # the HEARTBEAT already reports the mode but the ACK was lost (a lossy
                    # radio): asking again is harmless (the autopilot ACKs the mode it is in)
                    # and brings the confirmation the life cycle requires
                    asks_left -= 1
                    t_sent = send()
            if any(acked) and not confirm():
                last = f"accepted but the HEARTBEAT still reports {self.mode_str()}"
            self.log(f"mode {name}: attempt {attempt + 1} not confirmed ({last})")
        return False, last

    def mode_str(self) -> str:
        hb = self.vl.hb
        return mode_name(self.vl.flavour, hb) if hb is not None else "no heartbeat"

    def hold_mode(self) -> str:
        if self.m.hold_mode:
            return str(self.m.hold_mode)
        return "AUTO.LOITER" if self.vl.flavour is Flavour.PX4 else "LOITER"

    def offboard_mode(self) -> str:
        return "OFFBOARD" if self.vl.flavour is Flavour.PX4 else "GUIDED"

    def in_offboard(self) -> bool:
        return self.vl.hb is not None and is_offboard(self.vl.flavour, self.vl.hb)

    # -- the virtual point -----------------------------------------------------------------------
    def init_s(self) -> None:
        s0 = self.ctl.init_s()
        assert self.ctl.t0 is not None
        # no message is processed between CHECKS and here: the records mark that instant
        texts = origin_texts(self.ctl.t0, s0)
        # a re-engagement keeps the mission-time origin: only the new s0 is recorded
        for text in texts if self.loop.t_engage is None else texts[1:]:
            self.vl.send_text(text)
        self.log(f"virtual point initialised at s = {s0:.2f} m")

    # -- re-engagement -------------------------------------------------------------------------
    def may_reengage(self, stop: _Stop) -> bool:
        """Whether a stop may be followed by a re-engagement (configured, loss of telemetry or
        of the live target, after the mission was engaged once, attempts left)."""
        return (
            stop.kind in ("telemetry", "target")
            and self.loop.t_engage is not None
            and self.n["reengagements"] < self.m.reengage_max
        )

    def await_reengage(self, res: BridgeResult, stop: _Stop) -> str | None:
        """After the hand-back that followed a loss: wait for telemetry (and the live target)
        to be back for ``reengage_settle_s`` with the vehicle in the hold mode. None when the
        mission may be flown again, else why not (one clause)."""
        m = self.m
        hold = self.hold_mode()
        # PX4's own offboard-loss failsafe is Hold (AUTO.LOITER): that is no pilot either
        ours = {hold, "AUTO.LOITER"} if self.vl.flavour is Flavour.PX4 else {hold}
        k = self.n["reengagements"] + 1
        self.log(
            f"{stop.reason}; re-engagement {k} of {m.reengage_max}: waiting up to "
            f"{m.reengage_wait_s:g} s for it to come back"
        )
        t_lost = time.monotonic()
        t_end = t_lost + m.reengage_wait_s
        back_since: float | None = None
        asked_hold = res.handback_confirmed
        while True:
            now = time.monotonic()
            if now >= t_end:
                what = self.ctl.why_not or f"no ATTITUDE for {now - self.loop.last_att_mono:.1f} s"
                return (
                    f"not back for {m.reengage_settle_s:g} s within {m.reengage_wait_s:g} s "
                    f"({what})"
                )
            self.vl.spin(min(0.05, t_end - now))
            now = time.monotonic()
            if not self._back():
                back_since = None
                continue
            if back_since is None:
                back_since = now
            if now - back_since < m.reengage_settle_s:
                continue
            if self._mission_over():
                return f"the mission's {m.mission_duration_s:g} s ran out meanwhile"
            if any(self.mode_is(name) for name in ours):
                self.n["reengagements"] = k
                self.log(f"back after {now - t_lost:.2f} s in {self.mode_str()}: re-engaging")
                res.handback_requested = res.handback_confirmed = False
                return None
            if self.in_offboard() and not asked_hold:
                # the hand-back could not get through the outage: ask again now the link is back
                asked_hold = True
                ok, why = self.request_mode(hold, lambda: self.mode_is(hold))
                res.handback_requested, res.handback_confirmed = True, ok
                if not ok:
                    return f"hand-back to {hold} not confirmed ({why})"
                continue
            return f"the vehicle is in {self.mode_str()}, not {hold}: someone else has it"

    def _back(self) -> bool:
        """Telemetry (and the live target) usable again."""
        loop = self.loop
        timeout = self.m.telemetry_timeout_s
        fresh = self.vl.left(loop.last_att_mono, loop.last_att_vt, timeout) >= 0.0
        return fresh and self.ctl.ready()

    def _mission_over(self) -> bool:
        est, _ = self.ctl.est.estimate()
        t_engage = self.loop.t_engage
        return (
            est is not None
            and t_engage is not None
            and est.vehicle.t - t_engage >= self.m.mission_duration_s
        )

    # -- hand-back -----------------------------------------------------------------------------
    def handback(self, res: BridgeResult, kind: str) -> None:
        """Stop or hand back according to why we stop; never raises."""
        loop, vl = self.loop, self.vl
        loop.streaming = False
        if vl.link is None:
            return
        self.display.stopped(vl.link, res.exit_reason, res.exit_code == EXIT_OK)
        if self.phase.state < State.PRESTREAM:
            return
        main = threading.current_thread() is threading.main_thread()
        prev = signal.getsignal(signal.SIGTERM) if main else None
        try:
            if prev is not None:
                signal.signal(signal.SIGTERM, signal.SIG_IGN)  # finish the hand-back first
            if kind == "pilot" or (not self.engaged and not self.in_offboard()):
                self.phase.set(State.DONE)
                return
            self._hand_back(res, kind)
        except Exception as e:  # noqa: BLE001 - the summary must still be written
            self.log(f"hand-back failed: {type(e).__name__}: {e}")
        finally:
            loop.streaming = False
            if prev is not None:
                signal.signal(signal.SIGTERM, prev)

    def _hand_back(self, res: BridgeResult, kind: str) -> None:
        self.phase.set(State.HANDBACK)
        self.engaged = False
        hold = self.hold_mode()
        res.handback_requested = True
        if kind not in ("telemetry", "target"):
            # keep a wings-level setpoint flowing until the mode change is confirmed, so the
            # autopilot's offboard-loss failsafe does not fire in between
            self.loop.hold_wings_level()
        try:
            ok, why = self.request_mode(hold, lambda: self.mode_is(hold))
        except _Stop:
            ok, why = False, "interrupted"
        self.loop.streaming = False
        res.handback_confirmed = ok
        self.log(f"hand-back to {hold}: {'confirmed' if ok else 'NOT confirmed (' + why + ')'}")
        if not ok and res.exit_code == EXIT_OK:
            res.exit_code = EXIT_SAFETY
            res.exit_reason += f"; hand-back to {hold} not confirmed"
        self.phase.set(State.DONE)
