"""The MAVLink bridge: telemetry -> VehicleState -> MPF law -> adapter -> SET_ATTITUDE_TARGET,
wrapped in the offboard life cycle.

States (``BridgeResult.state_reached`` is the furthest one):
  CONNECTING -> WAIT_HEARTBEAT -> CHECKS -> INIT -> PRESTREAM -> ENGAGE -> TRACKING -> HANDBACK
  -> DONE

- CHECKS runs :func:`mpf_mavlink.bridge.preflight.run_checks` from the vehicle's first estimate
  with what it measures (its wind, airspeed, a live target's motion: ``MeasuredInputs``, after
  waiting up to ``mavlink.wind_stale_s`` for its first WIND / WIND_COV); a failure refuses to
  engage (no mode request is ever sent) and exits 3, unless ``--force``.
- PRESTREAM streams setpoints (one per ATTITUDE sample, re-sent when telemetry is slower than
  ``mavlink.min_setpoint_rate_hz``) for ``mavlink.prestream_s`` at that rate before asking for
  OFFBOARD (PX4 main 6) / GUIDED (ArduPlane 15).
- ENGAGE is confirmed only by an accepted COMMAND_ACK AND a HEARTBEAT in that mode.
- TRACKING: one law evaluation and one setpoint per ATTITUDE sample; s integrates sdot over
  the autopilot's time stamps (never the wall clock).
- TRACKING feeds each step to the envelope monitor (:mod:`mpf_mavlink.bridge.envelope`):
  episodes beyond the aircraft's limits go to the ground station (STATUSTEXT, WARNING) and
  metrics.json; its ``hold`` policy ends the run like a safety exit (hand-back, exit 4).
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
``mavlink.lockstep``, every wait of the life cycle, the prestream, re-sends and stream rates
count the vehicle's time instead, bounded by ``lockstep_wall_timeout_s`` of wall time, and each
ATTITUDE no setpoint answers gets a SYSTEM_TIME clock answer), rates and the resend timer; the
receive time the estimator and a live target see is the message's tlog record time
(microseconds), and the decisions taken from the wall clock are written to the tlog as
STATUSTEXT: ``MPF t0=``, ``MPF s0=`` after INIT and ``MPF stream`` when setpoints start (see
controller.py), so a replay of the tlog reproduces every setpoint.
Records: ``mavlink.tlog`` (both directions), ``timeseries.csv`` (TRACKING rows, what the law
saw), ``setpoints.csv``, ``metrics.json`` (figures, counters, exit) and the plots.
"""

from __future__ import annotations

import dataclasses
import functools
import gc
import math
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mpf_mavlink import mavlink as mav
from mpf_mavlink.bridge import fleet_hooks as fleet_link
from mpf_mavlink.bridge.base import (
    EXIT_CHECK,
    EXIT_OK,
    EXIT_SAFETY,
    EXIT_SIGINT,
    EXIT_SIGTERM,
    BridgeOptions,
    BridgeResult,
    Phase,
    State,
    _Stop,
    _Terminated,
    resolve_mavlink,
)
from mpf_mavlink.bridge.control_step import ControlLoop
from mpf_mavlink.bridge.controller import (
    HALT_TEXT,
    STREAM_TEXT,
    Controller,
    ControlSetup,
    Step,
)
from mpf_mavlink.bridge.envelope import demand_of_step, envelope_monitor, wind_limit_m_s
from mpf_mavlink.bridge.fallback import FallbackSetup
from mpf_mavlink.bridge.link_io import LinkHandlers, VehicleLink
from mpf_mavlink.bridge.operator import OperatorDisplay
from mpf_mavlink.bridge.recording import Recorder, is_lean
from mpf_mavlink.bridge.session import Session, preflight_checks
from mpf_mavlink.bridge.streams import StreamNegotiator
from mpf_mavlink.config import bridge as bridge_config  # noqa: F401  (registers the sections)
from mpf_mavlink.config.bridge import hold_mode_error
from mpf_mavlink.config.schema import Config
from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink import (
    Flavour,
    dialect,
    encode_arm,
    flavour_from_heartbeat,
    open_link,
    wait_heartbeat,
)
from mpf_mavlink.mavlink.wire_limits import MAV_CMD_COMPONENT_ARM_DISARM
from mpf_mavlink.runs.rundir import prepare_out_dir


class _Refused(Exception):
    """The bridge refuses to engage (exit 3) for this reason; ``log``: say it (the checks
    have printed theirs)."""

    def __init__(self, reason: str, log: bool = True) -> None:
        super().__init__(reason)
        self.log = log


# The cyclic collector's young generations are collected right after a setpoint goes out
# (:meth:`Bridge._tick`), a little before the allocation count would start a collection
# itself: that one (0.1-0.4 ms, more on a busy machine) would otherwise land wherever the count
# runs over, as often as not between a telemetry datagram and the setpoint that answers it.
_GC_THRESHOLD0, _GC_THRESHOLD1, _ = gc.get_threshold()
_GC_EARLY = 0.7  # of threshold0: a frame's allocations cannot take the count over it


def _collect_young() -> None:
    """Collect generation 0 (and 1 when it is due, as the collector would) once the count
    of new objects is near the collector's own threshold."""
    c0, c1, _ = gc.get_count()
    if c0 >= _GC_EARLY * _GC_THRESHOLD0:
        gc.collect(1 if c1 >= _GC_THRESHOLD1 else 0)


class Bridge:
    """One run against one vehicle (use :func:`run_bridge`): the pieces, each owning its state
    (VehicleLink: the link and what the vehicle says; Controller: the per-sample computation;
    ControlLoop: steps, setpoints, watchdog; StreamNegotiator; FallbackSetup; Session: modes,
    hand-back, re-engagement; Recorder), strung together by :meth:`run`'s life cycle."""

    def __init__(
        self, cfg: Config, opts: BridgeOptions, log: Callable[[str], None] = print
    ) -> None:
        self.cfg, self.opts, self.log = cfg, opts, log
        self.m = m = resolve_mavlink(cfg, opts)
        self.ctl = Controller(ControlSetup.of(cfg, m))
        self.display = OperatorDisplay(m.operator_display, m.operator_display_hz)
        self.vl = VehicleLink(m, live_target=self.ctl.live)
        self.phase = Phase(self._on_state)
        self.rec = Recorder(cfg, m, opts.url, Path(opts.out_dir))
        self.envelope = envelope_monitor(cfg, self.ctl.ad_params)
        self.loop = ControlLoop(
            self.ctl,
            self.vl,
            self.phase,
            self.rec.record,
            self._show,
            functools.partial(report_envelope, self.envelope, self.ctl, self.vl, log),
        )
        self.session = Session(cfg, self.loop, self.phase, self.display, log)
        self.streams = StreamNegotiator(self.vl, log)
        self.fallback = FallbackSetup(self.vl, self.ctl, cfg.path, log)
        self.vl.subscribe(
            LinkHandlers(
                heartbeat=self.session.on_heartbeat,
                vehicle=self.loop.on_vehicle,
                target=self.ctl.feed_target,
                tick=self._tick,
                due=self.loop.due,
            )
        )
        self._sent_at_tick = 0
        self.fleet = fleet_link.attach(self)  # fleet: None unless fleet.enabled

    def _tick(self) -> None:
        now = time.monotonic()
        self.vl.duties(now)
        self.loop.tick(now)
        if self.phase.state is State.TRACKING and self.loop.t_last is not None:
            self.fallback.follow(self.loop.t_last)
        sent = self.loop.n["setpoints_sent"]
        if sent != self._sent_at_tick:  # a setpoint went out in this wake-up
            self._sent_at_tick = sent
            _collect_young()

    def _on_state(self, s: State) -> None:
        self.log(f"[{s.name}]")
        if self.vl.link is not None:
            self.display.text(self.vl.link, s.name)

    def _show(self, st: Step) -> None:
        self.display.values(self.vl.link, st, int(self.phase.state))

    # -- life cycle --------------------------------------------------------------------------
    def run(self) -> BridgeResult:
        out = Path(self.opts.out_dir)
        res = BridgeResult("CONNECTING", "", EXIT_SAFETY, out_dir=out)
        pending: BaseException | None = None
        try:
            prepare_out_dir(out)
            self._connect(res)
            self._prepare(res)
            self._fly_until_stopped(res)
        except _Refused as e:
            res.exit_reason, res.exit_code = f"refused to engage: {e}", EXIT_CHECK
            if e.log:
                self.log(res.exit_reason)
        except _Stop as e:
            res.exit_reason = e.reason
            res.exit_code = EXIT_OK if e.kind == "duration" else EXIT_SAFETY
            self.session.handback(res, e.kind)
        except MpfError:
            self.vl.close()
            raise
        except KeyboardInterrupt:
            res.exit_reason, res.exit_code = "interrupted (Ctrl-C)", EXIT_SIGINT
            self.session.handback(res, "interrupt")
        except _Terminated:
            res.exit_reason, res.exit_code = "terminated (SIGTERM)", EXIT_SIGTERM
            self.session.handback(res, "interrupt")
        except Exception as e:  # noqa: BLE001 - hand back first, then let the bug be seen
            res.exit_reason, res.exit_code = f"error: {type(e).__name__}: {e}", 1
            pending = e
            self.session.handback(res, "interrupt")
        out_res = self._finish(res)
        if pending is not None:
            raise pending
        return out_res

    def _connect(self, res: BridgeResult) -> None:
        """Open the link, wait for the autopilot's HEARTBEAT and settle its flavour."""
        m, vl = self.m, self.vl
        # (mav.*signing*: the package loads its signing module for a signed flight only)
        key = mav.load_signing_key(m.signing_key_file) if m.signing_key_file else None
        allowed = [m.target_sysid] if (self.ctl.live and m.target_sysid is not None) else []
        tlog = None if is_lean(m) else Path(self.opts.out_dir) / "mavlink.tlog"
        vl.link = open_link(
            self.opts.url, source_system=m.source_system, source_component=m.source_component,
            vehicle_sysid=m.vehicle_sysid, allowed_sysids=allowed, tlog_path=tlog,
            tlog_fsync_every_s=m.tlog_fsync_every_s, timeout_s=m.heartbeat_timeout_s,
            vehicle_time=m.lockstep,  # lockstep: the tlog carries the simulation's time
        )  # fmt: skip
        if key is not None:
            mav.enable_signing(vl.link, key, m.signing_link_id)
        fleet_link.open_(self.fleet, m)  # fleet: the coordination link
        self.phase.set(State.WAIT_HEARTBEAT)
        hb = wait_heartbeat(vl.link, m.heartbeat_timeout_s, on_other=vl.before_heartbeat)
        vl.compid = hb.get_srcComponent()
        vl.dispatch(hb)
        want = settle_flavour(m, hb, self.cfg.source)
        vl.flavour = want
        res.flavour = want.value
        self.log(
            f"heartbeat from system {m.vehicle_sysid}: {want.value}, mode {self.session.mode_str()}"
        )

    def _prepare(self, res: BridgeResult) -> None:
        """Streams, home, the autopilot's fallback, a complete state, the checks; raises
        :class:`_Refused` when the bridge must not engage."""
        m, vl, est = self.m, self.vl, self.ctl.est
        if m.request_streams and (why := self.streams.negotiate(res)) is not None:
            raise _Refused(why)
        need_home = self.ctl.live or (vl.flavour is Flavour.ARDUPILOT and m.set_fallback)
        if need_home and est.origin.geodetic() is None:
            await_home(m, est, self.streams, self.ctl.live)
        if vl.flavour is Flavour.PX4 and (why := self.fallback.px4_prepare(res)) is not None:
            raise _Refused(why)
        # wait for a complete state (and the live target) before checking anything
        if not vl.spin(m.heartbeat_timeout_s, self.ctl.ready):
            raise MpfError(
                f"no usable telemetry within {m.heartbeat_timeout_s:g} s: "
                f"{self.ctl.why_not or 'no attitude'}"
            )
        # the checks judge the autopilot's wind: wait for its first WIND / WIND_COV (slower
        # than the rest, 1-4 Hz), else they would run on our own estimate of it or on none
        if not vl.spin(m.wind_stale_s, lambda: est.wind is not None):
            self.log(
                f"no WIND / WIND_COV within {m.wind_stale_s:g} s: the checks use the wind "
                "estimated from ground velocity and airspeed"
            )
        self.phase.set(State.CHECKS)
        plant, duration = self.opts.plant, self.m.mission_duration_s
        failed = preflight_checks(self.ctl, self.cfg, duration, res, self.log, plant)
        if failed and self.opts.force:
            failed = force_through(failed, res, vl, self.log)
        # the wind the monitor holds the flight to: what the checks accepted plus its margin
        wind = wind_limit_m_s(self.cfg, res.measured, plant)
        self.envelope.lim = dataclasses.replace(self.envelope.lim, wind_max_m_s=wind)
        if failed:
            # the wording of `check` and `sim`'s gate: each failed check with its figures
            raise _Refused(
                "check failed: "
                + "; ".join(f"{r.name} ({r.summary})" for r in failed)
                + " (--force flies it anyway)"
            )

    def _fly_until_stopped(self, res: BridgeResult) -> None:
        """Fly; after a loss hand back and, when configured, re-engage. Ends by raising."""
        session = self.session
        while True:
            try:
                self._fly(res)
            except _Stop as e:
                if not session.may_reengage(e):
                    raise
                self.vl.send_text(HALT_TEXT)  # for replay: control steps stop here
                session.handback(res, e.kind)
                why_not = session.await_reengage(res, e)
                if why_not is not None:
                    raise _Stop(f"{e.reason}; not re-engaged: {why_not}", e.kind) from None

    def _fly(self, res: BridgeResult) -> None:
        """INIT -> PRESTREAM -> ENGAGE -> TRACKING; ends only by raising (_Stop and others).
        Called again for a re-engagement: s starts afresh at the closest point, the mission
        time origin t0 and the mission's end (``t_engage`` + duration) stay."""
        m, vl, loop, session = self.m, self.vl, self.loop, self.session
        self.phase.set(State.INIT)
        session.init_s()
        self.phase.set(State.PRESTREAM)
        # Everything allocated so far (modules, the dialect, the path tables) goes to the
        # collector's permanent generation: a full collection of it takes ~25 ms, which
        # would otherwise land inside a control step now and then.
        gc.collect()
        gc.freeze()
        # the checks (and that collection) take a while without pumping: take the backlog in
        # (state only, no setpoints for old samples), then start the staleness clocks afresh
        if not m.lockstep:  # lockstep: the vehicle waited for us, there is no backlog
            vl.drain()
        vl.send_text(STREAM_TEXT)  # for replay: control steps start after this record
        loop.start()
        rate = loop.prestream_rate_hz()
        if not vl.spin(m.prestream_s + 3.0, loop.prestreamed):
            raise _Stop(
                f"could not stream setpoints at {rate:g} Hz for {m.prestream_s:g} s", "engage"
            )
        span = loop.prestream_span_s()
        self.log(f"pre-streamed {loop.prestream_sends} setpoints in {span:.2f} s")
        if m.arm and not (vl.hb is not None and vl.hb.armed):
            arm(vl, m)
        self.phase.set(State.ENGAGE)
        mode = session.offboard_mode()
        ok, why = session.request_mode(mode, session.in_offboard)
        if not ok:
            raise _Stop(f"vehicle did not enter {mode}: {why}", "engage")
        session.engaged = res.engaged = True
        first = not session.n["reengagements"]
        if vl.flavour is Flavour.ARDUPILOT and m.set_fallback and first:
            self.fallback.ardupilot_loiter(res)
        if vl.flavour is Flavour.PX4 and m.set_fallback and first:
            self.fallback.px4_reposition(res)
        if loop.t_engage is None:  # a re-engagement keeps the mission's end
            loop.t_engage = loop.t_last if loop.t_last is not None else 0.0
        self.phase.set(State.TRACKING)
        until = "the mission's end" if not first else f"{m.mission_duration_s:g} s"
        self.log(f"{mode} confirmed: tracking {'again until' if not first else 'for'} {until}")
        # what exists now (modules, config, path tables) lives for the whole flight: keep
        # it out of the cyclic collector, whose full passes would otherwise walk it inside
        # the control loop
        gc.collect()
        gc.freeze()
        vl.spin(math.inf)

    def _finish(self, res: BridgeResult) -> BridgeResult:
        gc.unfreeze()  # run_bridge may be called again in this process (tests, SIL)
        res.state_reached = self.phase.furthest.name
        res.final_state = self.phase.state.name
        loop, vl = self.loop, self.vl
        if loop.t_engage is not None and loop.t_last is not None:
            res.tracked_s = max(0.0, loop.t_last - loop.t_engage)
        counters: dict[str, Any] = {**loop.n, **self.session.n}
        if vl.link is not None:
            counters.update(vl.link.counters.as_dict())
            # a run that ends without a hand-back says why, too
            self.display.stopped(vl.link, res.exit_reason, res.exit_code == 0)
        res.counters = counters
        vl.close()
        env = None
        if self.envelope.steps:
            env = self.envelope.summary(self.cfg.metrics.steady_after_s, loop.t_last)
        self.rec.finish(res, self.ctl, counters, env)
        fleet_link.finish(self.fleet, Path(self.opts.out_dir))  # fleet: fleet.csv, metrics
        if res.records_error:
            self.log(f"could not write the run directory: {res.records_error}")
        return res


def settle_flavour(m: Any, hb: Any, source: str) -> Flavour:
    """The autopilot flavour to fly: ``mavlink.flavour``, or the HEARTBEAT's with ``auto``;
    raises MpfError (before anything is sent) when unknown, contradicted by the HEARTBEAT, or
    when ``mavlink.hold_mode`` is not one of that flavour's modes (``source``: the config)."""
    seen = flavour_from_heartbeat(hb)
    want = Flavour(m.flavour) if m.flavour != "auto" else seen
    if want is Flavour.UNKNOWN:
        raise MpfError(
            f"unknown autopilot (HEARTBEAT.autopilot = {hb.autopilot}); use --flavour px4|ardupilot"
        )
    if m.flavour != "auto" and seen is not Flavour.UNKNOWN and seen is not want:
        raise MpfError(f"--flavour {m.flavour} but the vehicle's HEARTBEAT says {seen.value}")
    if m.hold_mode and (why := hold_mode_error(m.hold_mode, want.value)):
        raise MpfError(f"{source}: mavlink.hold_mode: {why}")  # before any send
    return want


def await_home(m: Any, est: Any, streams: StreamNegotiator, live: bool) -> None:
    """Wait for HOME_POSITION (the geodetic origin); raises :class:`_Refused` without it when
    a ``live`` target is placed about it."""

    def home() -> str:
        h = est.origin.home
        return f"{h.lat_deg:.7f}, {h.lon_deg:.7f}, {h.alt_amsl_m:.2f} m AMSL"

    if not streams.await_home(lambda: est.origin.home is not None, home) and live:
        raise _Refused(
            f"no HOME_POSITION within {m.home_timeout_s:g} s "
            "(the live target is placed about it; or set mavlink.origin_*)"
        )


def force_through(
    failed: list[Any], res: BridgeResult, vl: VehicleLink, log: Callable[[str], None]
) -> list[Any]:
    """``--force``: engage despite the ``failed`` checks, said loudly (log, metrics.json's
    ``forced``, a STATUSTEXT to the ground station); nothing is left failed."""
    names = ", ".join(r.name for r in failed)
    res.forced = [r.name for r in failed]
    log(f"[FORCED] --force: ENGAGING DESPITE THE FAILED CHECK: {names} (metrics.json: forced)")
    # the ground station hears it too (STATUSTEXT, WARNING, <= 50 characters)
    vl.send_text(f"MPF FORCED despite failed {names}"[:50], dialect.MAV_SEVERITY_WARNING)
    return []


def arm(vl: VehicleLink, m: Any) -> None:
    """ARM, confirmed by an armed HEARTBEAT; a rejected ARM ends the wait at once."""
    timeout = m.mode_timeout_s * m.mode_retries
    t_end = time.monotonic() + timeout

    def armed() -> bool:
        return vl.hb is not None and vl.hb.armed

    msg = encode_arm(vl.link.mav, vl.sysid, vl.compid, True)
    ack = vl.commands.command(msg, MAV_CMD_COMPONENT_ARM_DISARM, timeout, armed)
    refused = ack is not None and not ack.accepted
    if refused or not vl.spin(max(0.0, t_end - time.monotonic()), armed):
        why = f"ARM refused ({ack.result_name})" if refused and ack else "no armed HEARTBEAT"
        raise _Stop(f"vehicle did not arm: {why}", "engage")


def report_envelope(
    mon: Any, ctl: Controller, vl: VehicleLink, log: Callable[[str], None], st: Step
) -> tuple[bool, str | None]:
    """The envelope monitor on one tracking step: its STATUSTEXTs go to the ground station
    (severity WARNING, once per episode) and the log; (clipped, hand-back reason)."""
    d = demand_of_step(st, ctl, mon.lim)
    acts = mon.update(d)
    for text in acts.texts:
        log(f"[ENVELOPE] t = {st.t:.1f} s: {text}")
        vl.send_text(text, dialect.MAV_SEVERITY_WARNING)
    return d.clipped, acts.hand_back


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
