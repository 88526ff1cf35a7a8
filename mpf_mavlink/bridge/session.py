"""The bridge's session state machine: mode requests confirmed by ACK + HEARTBEAT, pre-flight
checks, the path origin, hand-back and re-engagement."""

from __future__ import annotations

import dataclasses
import signal
import threading
import time
from collections.abc import Callable

from mpf_mavlink.bridge.base import (
    EXIT_OK,
    EXIT_SAFETY,
    MAV_CMD_DO_SET_MODE,
    BridgeResult,
    State,
    _Stop,
)
from mpf_mavlink.bridge.controller import origin_texts
from mpf_mavlink.bridge.streams import Streams
from mpf_mavlink.core.adapter import safe_setpoint
from mpf_mavlink.core.frames import matrix_to_euler
from mpf_mavlink.mavlink import Flavour, encode_set_mode, is_offboard, mode_name
from mpf_mavlink.mavlink.modes import (
    arduplane_mode_from_name,
    px4_decode_custom_mode,
    px4_mode_from_name,
)


class Session(Streams):
    """Modes, checks, hand-back and re-engagement."""

    # -- modes -------------------------------------------------------------------------------
    def _mode_is(self, name: str) -> bool:
        hb = self.hb
        if hb is None or not (hb.base_mode & 1):
            return False
        if self.flavour is Flavour.PX4:
            main, sub = px4_mode_from_name(name)
            got = px4_decode_custom_mode(hb.custom_mode)
            return got[0] == main and (main != 4 or got[1] == sub)
        return hb.custom_mode == arduplane_mode_from_name(name)

    def _request_mode(self, name: str, confirm: Callable[[], bool]) -> tuple[bool, str]:
        """DO_SET_MODE with retries; confirmed by an accepted ACK and ``confirm()`` (heartbeat)."""
        last = "no COMMAND_ACK"
        # ACKs of earlier attempts still count: on a lossy link an attempt's ACK and the 1 Hz
        # HEARTBEAT in the new mode often do not both arrive within one mode_timeout_s
        acked: list[bool] = []
        asks_left = 8  # extra requests for an ACK that was lost (see below)

        def done() -> bool:
            nonlocal last
            for a in self.acks:
                if a.command == MAV_CMD_DO_SET_MODE:
                    acked.append(a.accepted)
                    last = a.result_name
            self.acks.clear()
            return any(acked) and confirm()

        def send() -> float:
            self._send(
                encode_set_mode(
                    self.link.mav, self.m.vehicle_sysid, self.vehicle_compid, self.flavour, name
                )
            )
            self.n["mode_requests"] += 1
            return time.monotonic()

        # lockstep: each attempt counts vehicle time; all of them together at most
        # lockstep_wall_timeout_s of wall time (a dead vehicle shows no time at all)
        m = self.m
        wall_s = max(m.mode_timeout_s, m.lockstep_wall_timeout_s / m.mode_retries)
        for attempt in range(m.mode_retries):
            self.acks.clear()
            t_sent = send()
            t0, vt0 = t_sent, self.vehicle_t  # the attempt's start (lockstep: vehicle time)
            while True:
                left = self._left(t0, vt0, m.mode_timeout_s, wall_s)
                if left <= 0.0:
                    break
                if self._spin(min(left, 0.1), done):
                    return True, "confirmed"
                if confirm() and not any(acked) and asks_left and time.monotonic() - t_sent >= 0.3:
                    # the HEARTBEAT already reports the mode but the ACK was lost (a lossy
                    # radio): asking again is harmless (the autopilot ACKs the mode it is in)
                    # and brings the confirmation the life cycle requires
                    asks_left -= 1
                    t_sent = send()
            if any(acked) and not confirm():
                last = f"accepted but the HEARTBEAT still reports {self._mode_str()}"
            self.log(f"mode {name}: attempt {attempt + 1} not confirmed ({last})")
        return False, last

    def _mode_str(self) -> str:
        return mode_name(self.flavour, self.hb) if self.hb is not None else "no heartbeat"

    def _hold_mode(self) -> str:
        if self.m.hold_mode:
            return self.m.hold_mode
        return "AUTO.LOITER" if self.flavour is Flavour.PX4 else "LOITER"

    def _offboard_mode(self) -> str:
        return "OFFBOARD" if self.flavour is Flavour.PX4 else "GUIDED"

    def _checks(self, res: BridgeResult) -> list[str]:
        from mpf_mavlink.bridge.preflight import format_checks, run_checks

        self.ctl.set_origin()  # mission time 0: the checks' and the scripted target's origin
        init = self.ctl.initial_state()
        assert init is not None
        pos, R_W_I = init
        cfg = self.cfg
        cfg = dataclasses.replace(
            cfg,
            sim=dataclasses.replace(cfg.sim, duration_s=self.m.mission_duration_s),
            kinematic=dataclasses.replace(
                cfg.kinematic,
                initial_position_ned_m=(float(pos[0]), float(pos[1]), float(pos[2])),
                initial_attitude_rpy_rad=matrix_to_euler(R_W_I),
            ),
        )
        results = run_checks(cfg, scripted_target=not self.live)
        text = format_checks(results)
        res.checks = text.splitlines()
        self.log(text)
        return [r.name for r in results if not r.ok]

    def _init_s(self) -> None:
        s0 = self.ctl.init_s()
        assert self.ctl.t0 is not None
        # no message is processed between CHECKS and here: the records mark that instant
        texts = origin_texts(self.ctl.t0, s0)
        # a re-engagement keeps the mission-time origin: only the new s0 is recorded
        for text in texts if self.t_engage is None else texts[1:]:
            self._send_text(text)
        self.log(f"virtual point initialised at s = {s0:.2f} m")

    def _may_reengage(self, stop: _Stop) -> bool:
        """Whether a stop may be followed by a re-engagement (configured, loss of telemetry or
        of the live target, after the mission was engaged once, attempts left)."""
        return (
            stop.kind in ("telemetry", "target")
            and self.t_engage is not None
            and self.n["reengagements"] < self.m.reengage_max
        )

    def _await_reengage(self, res: BridgeResult, stop: _Stop) -> str | None:
        """After the hand-back that followed a loss: wait for telemetry (and the live target)
        to be back for ``reengage_settle_s`` with the vehicle in the hold mode. None when the
        mission may be flown again, else why not (one clause)."""
        m = self.m
        hold = self._hold_mode()
        # PX4's own offboard-loss failsafe is Hold (AUTO.LOITER): that is no pilot either
        ours = {hold, "AUTO.LOITER"} if self.flavour is Flavour.PX4 else {hold}
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
                what = self.why_not or f"no ATTITUDE for {now - self.last_att_mono:.1f} s"
                return f"not back for {m.reengage_settle_s:g} s within {m.reengage_wait_s:g} s ({what})"
            self._spin(min(0.05, t_end - now))
            now = time.monotonic()
            if (
                self._left(self.last_att_mono, self.last_att_vt, m.telemetry_timeout_s) < 0.0
                or not self.ctl.ready()
            ):
                back_since = None
                continue
            if back_since is None:
                back_since = now
            if now - back_since < m.reengage_settle_s:
                continue
            est, _ = self.ctl.est.estimate()
            if (
                est is not None
                and self.t_engage is not None
                and est.vehicle.t - self.t_engage >= m.mission_duration_s
            ):
                return f"the mission's {m.mission_duration_s:g} s ran out meanwhile"
            if any(self._mode_is(name) for name in ours):
                self.n["reengagements"] = k
                self.log(f"back after {now - t_lost:.2f} s in {self._mode_str()}: re-engaging")
                res.handback_requested = res.handback_confirmed = False
                return None
            if self.hb is not None and is_offboard(self.flavour, self.hb) and not asked_hold:
                # the hand-back could not get through the outage: ask again now the link is back
                asked_hold = True
                ok, why = self._request_mode(hold, lambda: self._mode_is(hold))
                res.handback_requested, res.handback_confirmed = True, ok
                if not ok:
                    return f"hand-back to {hold} not confirmed ({why})"
                continue
            return f"the vehicle is in {self._mode_str()}, not {hold}: someone else has it"

    def _handback(self, res: BridgeResult, kind: str) -> None:
        """Stop or hand back according to why we stop; never raises."""
        self.streaming = False
        if self.link is None:
            return
        self.display.stopped(self.link, res.exit_reason, res.exit_code == EXIT_OK)
        if self.state < State.PRESTREAM:
            return
        prev = (
            signal.getsignal(signal.SIGTERM)
            if threading.current_thread() is threading.main_thread()
            else None
        )
        try:
            if prev is not None:
                signal.signal(signal.SIGTERM, signal.SIG_IGN)  # finish the hand-back first
            in_offboard = self.hb is not None and is_offboard(self.flavour, self.hb)
            if kind == "pilot" or (not self.engaged and not in_offboard):
                self._set_state(State.DONE)
                return
            self._set_state(State.HANDBACK)
            self.engaged = False
            hold = self._hold_mode()
            res.handback_requested = True
            if kind not in ("telemetry", "target") and self.last_sp is not None:
                # keep a wings-level setpoint flowing until the mode change is confirmed, so the
                # autopilot's offboard-loss failsafe does not fire in between
                self.last_sp = safe_setpoint(self.ad_params, self.ctl.roll())
                self.streaming = True
            try:
                ok, why = self._request_mode(hold, lambda: self._mode_is(hold))
            except _Stop:
                ok, why = False, "interrupted"
            self.streaming = False
            res.handback_confirmed = ok
            self.log(f"hand-back to {hold}: {'confirmed' if ok else 'NOT confirmed (' + why + ')'}")
            if not ok and res.exit_code == EXIT_OK:
                res.exit_code = EXIT_SAFETY
                res.exit_reason += f"; hand-back to {hold} not confirmed"
            self._set_state(State.DONE)
        except Exception as e:  # noqa: BLE001 - the summary must still be written
            self.log(f"hand-back failed: {type(e).__name__}: {e}")
        finally:
            self.streaming = False
            if prev is not None:
                signal.signal(signal.SIGTERM, prev)
