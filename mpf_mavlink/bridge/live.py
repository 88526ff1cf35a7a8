"""The MAVLink bridge: telemetry -> VehicleState -> MPF law -> adapter -> SET_ATTITUDE_TARGET,
wrapped in the offboard life cycle.

States (``BridgeResult.state_reached`` is the furthest one):
  CONNECTING -> WAIT_HEARTBEAT -> CHECKS -> INIT -> PRESTREAM -> ENGAGE -> TRACKING -> HANDBACK -> DONE

- CHECKS runs :func:`mpf_mavlink.bridge.preflight.run_checks` from the vehicle's first estimate; a
  failure refuses to engage (no mode request is ever sent) and exits 3.
- PRESTREAM streams setpoints (one per ATTITUDE sample, re-sent when telemetry is slower than
  ``mavlink.min_setpoint_rate_hz``) for ``mavlink.prestream_s`` at that rate before asking for
  OFFBOARD (PX4 main 6) / GUIDED (ArduPlane 15).
- ENGAGE is confirmed only by an accepted COMMAND_ACK AND a HEARTBEAT in that mode.
- TRACKING: one law evaluation and one setpoint per ATTITUDE sample; s integrates sdot over
  the autopilot's time stamps (never the wall clock).
- Exits: mission duration, Ctrl-C / SIGTERM / exception (hand back to the hold mode while
  streaming wings-level setpoints, confirm with ACK + HEARTBEAT); telemetry or live target
  stale (stop commanding at once, then request the hold mode); someone else changed the mode
  (stop commanding, no mode request: never fight the pilot).
- Re-engagement (``mavlink.reengage_max`` > 0, off by default): after a telemetry or target
  loss and its hand-back, wait up to ``reengage_wait_s`` for the stream to be back for
  ``reengage_settle_s`` with the vehicle in the hold mode (or PX4's failsafe Hold), then
  INIT -> PRESTREAM -> ENGAGE -> TRACKING again until the mission's original end. A vehicle
  in any other mode has a pilot: the run ends, saying so.

The per-sample computation (estimator, target, s, law, adapter, safe setpoints) lives in
:class:`mpf_mavlink.bridge.controller.Controller`, which replay drives the same way. The wall clock
(time.monotonic) is used only for link timeouts (against a lockstep simulation,
``mavlink.lockstep``, the telemetry and mode timeouts count the vehicle's time instead, bounded
by ``lockstep_wall_timeout_s`` of wall time), rates and the resend timer; the receive time
the estimator and a live target see is the message's tlog record time (microseconds), and the
decisions taken from the wall clock are written to the tlog as STATUSTEXT: ``MPF t0=``,
``MPF s0=`` after INIT and ``MPF stream`` when setpoints start (see controller.py), so a replay
of the tlog reproduces every setpoint.
Records: ``mavlink.tlog`` (both directions), ``timeseries.csv`` (TRACKING rows, what the law
saw), ``setpoints.csv``, ``metrics.json`` (figures, counters, exit) and the plots.
"""

from __future__ import annotations

import gc
import math
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mpf_mavlink.bridge.base import (
    EXIT_CHECK,
    EXIT_OK,
    EXIT_SAFETY,
    EXIT_SIGINT,
    EXIT_SIGTERM,
    BridgeOptions,
    BridgeResult,
    State,
    _Stop,
    _Terminated,
)
from mpf_mavlink.bridge.controller import HALT_TEXT, STREAM_TEXT, LiveTarget, ScriptedTarget
from mpf_mavlink.bridge.recording import Recording
from mpf_mavlink.config import bridge as bridge_config  # noqa: F401  (registers the mavlink/adapter sections)
from mpf_mavlink.config.bridge import hold_mode_error
from mpf_mavlink.config.schema import Config
from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink import (
    Flavour,
    enable_signing,
    encode_arm,
    flavour_from_heartbeat,
    is_offboard,
    load_signing_key,
    open_link,
    wait_heartbeat,
)
from mpf_mavlink.runs.rundir import COLUMNS, prepare_out_dir


# ----------------------------------------------------------------------------- the bridge
class Bridge(Recording):
    """One run against one vehicle. Use :func:`run_bridge`.

    The concerns are layered classes, each using only those below it: :class:`BridgeBase`
    (state), :class:`~.control_step.ControlStep`, :class:`~.link_io.LinkIO`,
    :class:`~.streams.Streams`, :class:`~.session.Session`, :class:`~.recording.Recording`;
    this class is the life cycle that strings them together (:meth:`run`)."""

    # -- life cycle --------------------------------------------------------------------------
    def run(self) -> BridgeResult:
        out = Path(self.opts.out_dir)
        res = BridgeResult("CONNECTING", "", EXIT_SAFETY, out_dir=out)
        pending: BaseException | None = None
        m = self.m
        try:
            prepare_out_dir(out)
            signing_key = load_signing_key(m.signing_key_file) if m.signing_key_file else None
            allowed = [m.target_sysid] if (self.live and m.target_sysid is not None) else []
            self.link = open_link(
                self.opts.url, source_system=m.source_system, source_component=m.source_component,
                vehicle_sysid=m.vehicle_sysid, allowed_sysids=allowed, tlog_path=out / "mavlink.tlog",
                tlog_fsync_every_s=m.tlog_fsync_every_s, timeout_s=m.heartbeat_timeout_s,
                vehicle_time=m.lockstep,  # lockstep: the tlog carries the simulation's time
            )  # fmt: skip
            if signing_key is not None:
                enable_signing(self.link, signing_key, m.signing_link_id)
            self._set_state(State.WAIT_HEARTBEAT)
            hb = wait_heartbeat(self.link, m.heartbeat_timeout_s)
            self.vehicle_compid = hb.get_srcComponent()
            self._dispatch(hb)
            seen = flavour_from_heartbeat(hb)
            want = Flavour(m.flavour) if m.flavour != "auto" else seen
            if want is Flavour.UNKNOWN:
                raise MpfError(
                    f"unknown autopilot (HEARTBEAT.autopilot = {hb.autopilot}); use --flavour px4|ardupilot"
                )
            if m.flavour != "auto" and seen is not Flavour.UNKNOWN and seen is not want:
                raise MpfError(
                    f"--flavour {m.flavour} but the vehicle's HEARTBEAT says {seen.value}"
                )
            if m.hold_mode and (
                why := hold_mode_error(m.hold_mode, want.value)
            ):  # before anything is sent
                raise MpfError(f"{self.cfg.source}: mavlink.hold_mode: {why}")
            self.flavour = want
            res.flavour = want.value
            self.log(
                f"heartbeat from system {m.vehicle_sysid}: {want.value}, mode {self._mode_str()}"
            )
            if m.request_streams:
                why = self._negotiate_streams(res)
                if why is not None:
                    res.exit_reason = f"refused to engage: {why}"
                    res.exit_code = EXIT_CHECK
                    self.log(res.exit_reason)
                    return self._finish(res)
            need_home = self.live or (self.flavour is Flavour.ARDUPILOT and m.set_fallback)
            if need_home and self.est.geodetic_origin() is None:
                if not self._await_home() and self.live:
                    res.exit_reason = (
                        f"refused to engage: no HOME_POSITION within {m.home_timeout_s:g} s "
                        "(the live target is placed about it; or set mavlink.origin_*)"
                    )
                    res.exit_code = EXIT_CHECK
                    self.log(res.exit_reason)
                    return self._finish(res)
            if self.flavour is Flavour.PX4 and m.set_fallback:
                why = self._px4_fallback(res)
                self.log(f"fallback if the bridge dies: {res.fallback}")
                if why is not None:
                    res.exit_reason = f"refused to engage: {why}"
                    res.exit_code = EXIT_CHECK
                    self.log(res.exit_reason)
                    return self._finish(res)
            elif self.flavour is Flavour.PX4:
                res.fallback = (
                    "not read or set (mavlink.set_fallback: false): PX4's COM_OBL_RC_ACT decides "
                    "(stock 0: Position mode, which on a fixed-wing flies straight on, not a hold)"
                )
            # wait for a complete state (and the live target) before checking anything
            ok = self._spin(m.heartbeat_timeout_s, self._ready)
            if not ok:
                raise MpfError(
                    f"no usable telemetry within {m.heartbeat_timeout_s:g} s: {self.why_not or 'no attitude'}"
                )
            self._set_state(State.CHECKS)
            failed = self._checks(res)
            if failed and self.opts.force:
                self.log(f"[FORCED] engaging despite the failed check: {', '.join(failed)}")
                failed = []
            if failed:
                res.exit_reason = f"refused to engage: check failed: {', '.join(failed)}"
                res.exit_code = EXIT_CHECK
                return self._finish(res)
            while True:
                try:
                    self._fly(res)
                except _Stop as e:
                    if not self._may_reengage(e):
                        raise
                    self._send_text(HALT_TEXT)  # for replay: control steps stop here
                    self._handback(res, e.kind)
                    why_not = self._await_reengage(res, e)
                    if why_not is not None:
                        raise _Stop(f"{e.reason}; not re-engaged: {why_not}", e.kind) from None
        except _Stop as e:
            res.exit_reason = e.reason
            res.exit_code = EXIT_OK if e.kind == "duration" else EXIT_SAFETY
            self._handback(res, e.kind)
        except MpfError:
            self._close()
            raise
        except KeyboardInterrupt:
            res.exit_reason, res.exit_code = "interrupted (Ctrl-C)", EXIT_SIGINT
            self._handback(res, "interrupt")
        except _Terminated:
            res.exit_reason, res.exit_code = "terminated (SIGTERM)", EXIT_SIGTERM
            self._handback(res, "interrupt")
        except Exception as e:  # noqa: BLE001 - hand back first, then let the bug be seen
            res.exit_reason, res.exit_code = f"error: {type(e).__name__}: {e}", 1
            pending = e
            self._handback(res, "interrupt")
        out_res = self._finish(res)
        if pending is not None:
            raise pending
        return out_res

    def _fly(self, res: BridgeResult) -> None:
        """INIT -> PRESTREAM -> ENGAGE -> TRACKING; ends only by raising (_Stop and others).
        Called again for a re-engagement: s starts afresh at the closest point, the mission
        time origin t0 and the mission's end (``t_engage`` + duration) stay."""
        m = self.m
        self.first_send_mono, self.prestream_sends = None, 0
        self._set_state(State.INIT)
        self._init_s()
        self._set_state(State.PRESTREAM)
        # Everything allocated so far (modules, the dialect, the path tables) goes to the
        # collector's permanent generation: a full collection of it takes ~25 ms, which
        # would otherwise land inside a control step now and then.
        gc.collect()
        gc.freeze()
        # the checks (and that collection) take a while without pumping: take the backlog in
        # (state only, no setpoints for old samples), then start the staleness clocks afresh
        while (msg := self.link.recv(0.0)) is not None:
            self._dispatch(msg)
        self._send_text(STREAM_TEXT)  # for replay: control steps start after this record
        self.streaming = True
        self.last_good_mono = self.last_att_mono = time.monotonic()
        self.last_good_vt = self.last_att_vt = self.vehicle_t
        rate = m.min_setpoint_rate_hz

        def prestreamed() -> bool:
            if self.first_send_mono is None:
                return False
            span = self.last_send_mono - self.first_send_mono  # first to last setpoint sent
            return span >= m.prestream_s and (self.prestream_sends - 1) / span >= rate

        if not self._spin(m.prestream_s + 3.0, prestreamed):
            raise _Stop(
                f"could not stream setpoints at {rate:g} Hz for {m.prestream_s:g} s", "engage"
            )
        self.log(
            f"pre-streamed {self.prestream_sends} setpoints in {self.last_send_mono - (self.first_send_mono or self.last_send_mono):.2f} s"
        )
        if m.arm and not (self.hb is not None and self.hb.armed):
            self.acks.clear()
            self._send(encode_arm(self.link.mav, m.vehicle_sysid, self.vehicle_compid, True))
            refused: list[str] = []

            def armed_or_refused() -> bool:
                # a rejected ARM (pre-arm checks failed) ends the wait at once, with its reason
                for a in self.acks:
                    if (
                        a.command == 400 and not a.accepted and a.result != 5
                    ):  # 5: MAV_RESULT_IN_PROGRESS
                        refused.append(a.result_name)
                self.acks.clear()
                return bool(refused) or (self.hb is not None and self.hb.armed)

            if not self._spin(m.mode_timeout_s * m.mode_retries, armed_or_refused) or refused:
                why = f"ARM refused ({refused[0]})" if refused else "no armed HEARTBEAT"
                raise _Stop(f"vehicle did not arm: {why}", "engage")
        self._set_state(State.ENGAGE)
        mode = self._offboard_mode()
        ok, why = self._request_mode(
            mode, lambda: self.hb is not None and is_offboard(self.flavour, self.hb)
        )
        if not ok:
            raise _Stop(f"vehicle did not enter {mode}: {why}", "engage")
        self.engaged = True
        res.engaged = True
        if self.flavour is Flavour.ARDUPILOT and m.set_fallback and not self.n["reengagements"]:
            self._set_set_fallback(res)
        if self.flavour is Flavour.PX4 and m.set_fallback and not self.n["reengagements"]:
            self._px4_reposition(res)
        if self.t_engage is None:  # a re-engagement keeps the mission's end
            self.t_engage = self.t_last if self.t_last is not None else 0.0
        self._set_state(State.TRACKING)
        if self.n["reengagements"]:
            self.log(f"{mode} confirmed: tracking again until the mission's end")
        else:
            self.log(f"{mode} confirmed: tracking for {m.mission_duration_s:g} s")
        # what exists now (modules, config, path tables) lives for the whole flight: keep
        # it out of the cyclic collector, whose full passes would otherwise walk it inside
        # the control loop
        gc.collect()
        gc.freeze()
        self._spin(math.inf)


def run_bridge(
    cfg: Config, opts: BridgeOptions, log: Callable[[str], None] = print
) -> BridgeResult:
    """Fly one run. SIGTERM is turned into a hand-back (when called from the main thread).

    Raises MpfError (one line) for a bad URL, no vehicle, a bad key file, an unknown autopilot.
    """
    bridge = Bridge(cfg, opts, log)
    main = threading.current_thread() is threading.main_thread()
    prev = None
    if main:

        def on_term(signum: int, frame: Any) -> None:
            raise _Terminated()

        prev = signal.signal(signal.SIGTERM, on_term)
    try:
        return bridge.run()
    finally:
        if main and prev is not None:
            signal.signal(signal.SIGTERM, prev)


__all__ = [
    "Bridge",
    "BridgeOptions",
    "BridgeResult",
    "LiveTarget",
    "ScriptedTarget",
    "State",
    "run_bridge",
    "COLUMNS",
]
