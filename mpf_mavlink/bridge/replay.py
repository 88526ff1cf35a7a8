"""Open-loop replay of a tlog: what the law saw and would have commanded, and a check that a
tlog recorded by ``mpf-mavlink run`` (or the SIL) reproduces every setpoint it sent.

The replay drives :class:`mpf_mavlink.bridge.controller.Controller` exactly as the bridge does (see
that module): messages in file order, receive times = the tlog record times, filtered as the
bridge's link filters them (:class:`_LinkFilter`: the ``mavlink`` section's ids - vehicle
``vehicle_sysid``, live target ``target_sysid``, our own packets ``source_system``/
``source_component`` -, the identity pinned by the vehicle's first autopilot HEARTBEAT, the
boot-clock gate), nothing before that HEARTBEAT. Message counts, modes and gaps in the summary
are over the whole file; the tracking figures over the window.

Origin and start of control
---------------------------
- A tlog of this project's bridge carries STATUSTEXT markers from our ids: ``MPF t0=``,
  ``MPF s0=`` (CHECKS/INIT) and ``MPF stream`` (setpoints start). The replay sets the mission
  origin and s at those records and steps from the ``MPF stream`` record on, like the bridge;
  ``MPF halt`` (a loss with re-engagement configured) stops the steps until the next
  ``MPF s0=`` and ``MPF stream`` of the re-engagement.
- Any other tlog (MAVProxy, QGroundControl, an autopilot's SITL): the origin is taken the way
  the bridge takes it at CHECKS, at the first complete state at or after ``--from``: t0 = that
  ATTITUDE's time, s0 = ``guidance.initial_s_m`` or the closest point of the moving path; the
  control steps start with the next ATTITUDE. Low telemetry rates (a few Hz) go through the same
  estimator, with the staleness limits of the config.

Determinism check
-----------------
Every SET_ATTITUDE_TARGET from our ids is classified in file order: the command of the latest
control step (same time_boot_ms; every field compared, floats after float32 rounding like the
wire, tolerance 1e-6), a re-send of the previous setpoint (identical), or a wings-level safe
setpoint of the hand-back (the adapter's ``safe_setpoint`` for the roll of an ATTITUDE received
since the last command, or 0). A re-send is also recognised when it equals what the replay
computed for the last command (so one altered record is reported once, not with its copies).
Anything else, a field that differs, or a control step the bridge
did not send between two that it did, is a difference; the first one is reported with its
index, time, field and both values.

``--from`` / ``--to`` (s since the first record of the tlog) choose what is recorded in the run
directory and summarised; the state is always rebuilt from the start of the log.
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.bridge.controller import (
    Controller,
    ControlSetup,
    Step,
    parse_marker,
    write_setpoints,
)
from mpf_mavlink.bridge.envelope import demand_of_step, envelope_monitor
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.adapter import Setpoint, safe_setpoint
from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink import (
    Flavour,
    decode,
    dialect,
    encode_set_attitude_target_quat,
    encode_set_attitude_target_rates,
    flavour_from_heartbeat,
    iter_tlog,
    mode_name,
)
from mpf_mavlink.mavlink.boot_clock import BootClockGate
from mpf_mavlink.mavlink.link import AUTOPILOTS, MAV_COMP_ID_AUTOPILOT1
from mpf_mavlink.mavlink.tlog_read import TlogStats
from mpf_mavlink.runs.replay_result import (
    _INT_FIELDS,
    _SAT,
    TOLERANCE,
    CommandCheck,
    ReplayResult,
    _f32,
    _largest_diff,
    _sat_fields,
)
from mpf_mavlink.runs.rundir import COLUMNS, RunTable, compute_metrics, prepare_out_dir
from mpf_mavlink.runs.verdict import assess
from mpf_mavlink.runs.write import limits_row, write_limits, write_run

_SATURATED = COLUMNS.index("saturated")


class _LinkFilter:
    """What the bridge's link lets through, message by message (mavlink/link.py: Link._read_one
    and the pinning in wait_heartbeat): the vehicle's system (after its first autopilot
    HEARTBEAT only the autopilot's component, and HEARTBEATs only with that MAV_AUTOPILOT), the
    live target's system, and the vehicle's ``time_boot_ms`` through the same
    :class:`BootClockGate` fed with the same receive times (the tlog's record times)."""

    def __init__(self, m: Any, live: bool) -> None:
        self.vehicle = m.vehicle_sysid
        self.allowed = {m.target_sysid} if live and m.target_sysid is not None else set()
        self.compid: int | None = None
        self.autopilot: int | None = None
        self.gate = BootClockGate()
        self.rejected: Counter[str] = Counter()

    def accept(self, sysid: int, compid: int, mtype: str, msg: Any, t: float) -> bool:
        if sysid == self.vehicle:
            if self.compid is not None and compid != self.compid:
                self.rejected["other component"] += 1
                return False
        elif sysid not in self.allowed:
            self.rejected["other system"] += 1
            return False
        if mtype == "HEARTBEAT" and sysid == self.vehicle and self.autopilot is not None:
            if getattr(msg, "autopilot", None) != self.autopilot:
                self.rejected["identity"] += 1
                return False
        if sysid == self.vehicle:
            tb = getattr(msg, "time_boot_ms", None)
            if isinstance(tb, int):
                why = self.gate.check(mtype, tb * 1e-3, t)
                if why is not None:
                    self.rejected[why] += 1
                    return False
        return True

    def pin(self, sysid: int, compid: int, mtype: str, msg: Any) -> bool:
        """True for the HEARTBEAT that wait_heartbeat takes (and pins the identity to)."""
        if (
            mtype == "HEARTBEAT"
            and sysid == self.vehicle
            and compid == MAV_COMP_ID_AUTOPILOT1
            and msg.autopilot in AUTOPILOTS
        ):
            self.compid, self.autopilot = compid, int(msg.autopilot)
            return True
        return False


class _Replayer:
    """One pass over the tlog (see the module docstring for the rules)."""

    def __init__(
        self, cfg: Config, t_from: float, t_to: float, t_first: float, markers: bool
    ) -> None:
        self.cfg = cfg
        self.m = m = cfg.section("mavlink")
        self.ctl = Controller(ControlSetup.of(cfg))
        self.env_lim = envelope_monitor(cfg, self.ctl.ad_params).lim
        self.link = _LinkFilter(m, self.ctl.live)
        self.own = (m.source_system, m.source_component)
        self.t_first = t_first
        self.win = (t_first + t_from, t_first + t_to)
        self.markers = markers
        self.phase = "wait_heartbeat"  # -> before_origin -> origin -> streaming (<-> halted)
        self.flavour = Flavour.UNKNOWN
        self.vehicle_compid = 1
        self.origin = "never"
        self.s0: float | None = None
        self.table = RunTable()
        self.sp_rows: list[tuple[float, ...]] = []
        self.lim_rows: list[tuple[float, ...]] = []  # limits.csv: the recorded telemetry
        self.steps = 0
        self.check = CommandCheck(markers=markers)
        self.notes: list[str] = []
        # determinism bookkeeping
        self._mav = dialect.MAVLink(
            None, srcSystem=m.source_system, srcComponent=m.source_component
        )
        self._pending: Step | None = None
        self._pending_roll = 0.0  # the roll of the latest ATTITUDE at that step (ctl.roll())
        self._pending_since_match = 0
        self._last_sent: dict[str, float] | None = None
        self._last_expected: dict[str, float] | None = None  # what the replay computed for it
        self._last_safe = False
        self._rolls: list[float] = [0.0]
        self._n_sat = 0
        # summary bookkeeping
        self.modes: list[tuple[float, float, str]] = []
        self.att_times: list[tuple[float, float]] = []  # (record time, boot time) s
        self.skip_reasons: Counter[str] = Counter()

    # -- helpers ------------------------------------------------------------------------------
    def _expected(self, sp: Setpoint, tb_ms: int) -> dict[str, float]:
        """The SET_ATTITUDE_TARGET the bridge sends for ``sp`` (the same encoders)."""
        try:
            msg = self._encode(sp, tb_ms)
        except ValueError:  # the bridge then sends the plain wings-level setpoint
            msg = self._encode(safe_setpoint(self.ctl.ad_params), tb_ms)
        return _f32(_sat_fields(msg))

    def _encode(self, sp: Setpoint, tb_ms: int) -> Any:
        sysid, compid = self.m.vehicle_sysid, self.vehicle_compid
        if self.flavour is Flavour.PX4:
            return encode_set_attitude_target_rates(
                self._mav, tb_ms, sysid, compid, *sp.body_rates_frd, sp.thrust
            )
        return encode_set_attitude_target_quat(
            self._mav, tb_ms, sysid, compid, sp.q_wxyz, sp.thrust, sp.body_rates_frd
        )

    def _t_rel(self, t: float) -> float:
        return t - self.t_first

    def _difference(self, text: str) -> None:
        if self.check.first_difference is None:
            self.check.first_difference = text

    # -- the pass -----------------------------------------------------------------------------
    def feed(self, i: int, t: float, msg: Any) -> None:
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        mtype = msg.get_type()
        if (sysid, compid) == self.own:
            self._outgoing(i, t, msg, mtype)
            return
        if not self.link.accept(sysid, compid, mtype, msg, t):
            return
        if self.phase == "wait_heartbeat":
            # the bridge waits for the vehicle's first autopilot HEARTBEAT and drops the rest
            if self.link.pin(sysid, compid, mtype, msg):
                self.vehicle_compid = compid
                seen = flavour_from_heartbeat(msg)
                fl = self.m.flavour
                self.flavour = Flavour(fl) if fl != "auto" else seen
                self.phase = "before_origin"
                self._heartbeat(t, msg)
                self._after_message(t)
            return
        sample = decode(msg)
        if sample is not None:
            name = type(sample).__name__
            if sysid == self.m.vehicle_sysid:
                if name == "HeartbeatSample":
                    if sample.autopilot != dialect.MAV_AUTOPILOT_INVALID:
                        self._heartbeat(t, sample)
                elif name != "CommandAckSample" and self.ctl.feed_vehicle(sample, t):
                    if name == "AttitudeSample":  # not a position instant (multi-rate loop)
                        self.att_times.append((t, sample.t_boot_s))
                        R = sample.R_B_N
                        self._rolls.append(math.atan2(R[2][1], R[2][2]))
                    if self.phase == "streaming":
                        self._step(t)
            else:
                self.ctl.feed_target(sample, t)
        self._after_message(t)

    def _after_message(self, t: float) -> None:
        if self.phase != "before_origin":
            return
        ok = self.ctl.ready()  # the bridge's wait for a complete state, message by message
        if ok and not self.markers and t >= self.win[0]:
            t0 = self.ctl.set_origin()
            self.s0 = self.ctl.init_s()
            self.origin = "first complete state in the window (no MPF markers)"
            self.notes.append(
                f"origin taken at {self._t_rel(t):.2f} s: t0 = {t0:.3f} s boot time, s0 = "
                f"{self.s0:.2f} m"
            )
            self.phase = "streaming"

    def _heartbeat(self, t: float, hb: Any) -> None:
        """Mode segments (start, end, name); a segment ends where the next one starts."""
        name = mode_name(self.flavour, hb)
        tr = self._t_rel(t)
        if self.modes:
            a, _, last = self.modes[-1]
            self.modes[-1] = (a, tr, last)
            if last == name:
                return
        self.modes.append((tr, tr, name))

    def _step(self, t: float) -> None:
        st = self.ctl.step()
        if st is None:
            # the reason without its figures, so that the summary can count them
            self.skip_reasons[
                self.ctl.why_not.split(" (")[0] or "duplicate or out-of-order ATTITUDE"
            ] += 1
            return
        self.steps += 1
        if self._pending is not None:
            self._pending_since_match += 1  # the previous step was never sent
        self._pending = st
        self._pending_roll = self.ctl.roll()
        if self.win[0] <= t <= self.win[1]:
            row = st.row()
            # a command clipped at a limit is ``saturated``, as the bridge recorded it
            if demand_of_step(st, self.ctl, self.env_lim).clipped:
                row[_SATURATED] = 1.0
            self.table.append(row)
            self.sp_rows.append(tuple(st.setpoint_row()))
            self.lim_rows.append(limits_row(st.t, st.estimate, st.setpoint.thrust))

    def _outgoing(self, i: int, t: float, msg: Any, mtype: str) -> None:
        if mtype == "STATUSTEXT":
            mk = parse_marker(str(msg.text))
            if mk is None or not self.markers:
                return
            key, value = mk
            if key == "t0":
                assert value is not None
                est, why = self.ctl.est.estimate()
                if est is None or est.t_boot_s != value:
                    seen = "no state" if est is None else repr(est.t_boot_s)
                    self.notes.append(
                        f"the bridge took t0 = {value!r} s, this replay's state gives {seen}: the "
                        "tlog and the code/config disagree"
                    )
                self.ctl.set_origin(value)
                self.origin = "MPF markers of the bridge"
                self.phase = "origin"
            elif key == "s0":
                assert value is not None
                try:
                    mine = self.ctl.init_s()
                except MpfError as e:
                    mine = None
                    self.notes.append(f"at the s0 marker: {e}")
                if mine is not None and mine != value:
                    self.notes.append(
                        f"the bridge took s0 = {value!r} m, this config gives {mine!r} m: the "
                        "tlog and the code/config disagree"
                    )
                self.s0 = self.ctl.init_s(value)
            elif key == "stream":
                self.phase = "streaming"
            elif key == "halt":
                # the bridge stopped stepping (a loss with re-engagement configured): so does
                # the replay, and what it computed since the last command was never to be sent
                self.phase = "halted"
                self._pending, self._pending_since_match = None, 0
            return
        if mtype != _SAT:
            return
        self._n_sat += 1
        self.check.sent += 1
        if not self.markers:
            return
        c = self.check
        rec = _sat_fields(msg)
        where = (
            f"SET_ATTITUDE_TARGET #{self._n_sat} (tlog record {i}, t = {self._t_rel(t):.3f} s, "
            f"time_boot_ms {int(rec['time_boot_ms'])})"
        )
        st = self._pending
        if st is not None and rec["time_boot_ms"] == st.time_boot_ms:
            self.ctl.delay.note_sent(t)  # the step's first send measures the loop delay (TIMESYNC)
            self._compare(where, rec, self._expected(st.setpoint, st.time_boot_ms))
            return
        if rec == self._last_sent or rec == self._last_expected:
            if self._last_safe:
                c.safe += 1  # the hand-back streams its wings-level setpoint until confirmed
            else:
                c.resent += 1
            return
        for roll in reversed(self._rolls):
            sp = safe_setpoint(self.ctl.ad_params, roll)
            if _largest_diff(rec, self._expected(sp, int(rec["time_boot_ms"])))[0] <= TOLERANCE:
                c.safe += 1
                self._last_sent, self._last_expected, self._last_safe = rec, None, True
                return
        if st is not None:  # the bridge commanded another instant than the replay
            self._compare(where, rec, self._expected(st.setpoint, st.time_boot_ms))
            return
        c.unexplained += 1
        self._last_sent, self._last_expected, self._last_safe = rec, None, False
        self._difference(
            f"{where}: no control step of the replay produced it (nor a re-send or a safe setpoint)"
        )

    def _compare(self, where: str, rec: dict[str, float], exp: dict[str, float]) -> None:
        c = self.check
        c.compared += 1
        if self._pending_since_match and c.compared > 1:
            unsent = self._pending_since_match
            c.unsent_steps += unsent
            self._difference(f"before {where}: {unsent} replayed control step(s) were never sent")
        self._pending_since_match = 0
        st = self._pending
        if st is not None:
            # hand-back setpoints level the wings from the roll of an ATTITUDE from here on
            # (the step's own ATTITUDE: at a position instant its attitude is a propagated one)
            self._rolls = [0.0, self._pending_roll]
        self._pending = None
        self._last_sent, self._last_expected, self._last_safe = rec, exp, False
        text = _judge(c, rec, exp)
        if text is not None:
            self._difference(f"{where}: {text}")


def _judge(c: CommandCheck, rec: dict[str, float], exp: dict[str, float]) -> str | None:
    """Count a recorded setpoint ``rec`` against the replayed ``exp`` in ``c``: what differs
    beyond TOLERANCE, or None."""
    d, name = _largest_diff(rec, exp)
    if math.isfinite(d) and name not in _INT_FIELDS:
        c.max_diff = max(c.max_diff, d)
    if d <= TOLERANCE:
        return None
    c.differing += 1
    c.max_diff = max(c.max_diff, d) if math.isfinite(d) else math.inf
    return f"{name} recorded {rec[name]!r}, replayed {exp[name]!r} (|diff| {d:.3g})"


def _has_markers(messages: list[tuple[int, float, Any]], own: tuple[int, int]) -> bool:
    """Whether the tlog carries the bridge's ``MPF t0=`` marker from our ids."""
    for _, _, msg in messages:
        if msg.get_type() == "STATUSTEXT" and (msg.get_srcSystem(), msg.get_srcComponent()) == own:
            mk = parse_marker(str(msg.text))
            if mk is not None and mk[0] == "t0":
                return True
    return False


def _gaps(
    times: list[tuple[float, float]], t_first: float, timeout_s: float
) -> tuple[list[tuple[float, float]], float]:
    """Gaps of the ATTITUDE stream in the autopilot's own time (boot time): receive times of a
    log can come in bursts (a slow SITL, a buffering logger) that are not gaps of the vehicle.
    Threshold: the bridge's telemetry timeout, or 4 nominal periods at low rates.
    Returns (start in s since the first record, length s) and the threshold."""
    if len(times) < 2:
        return [], timeout_s
    rec = np.array([a for a, _ in times])
    boot = np.array([b for _, b in times])
    dt = np.diff(boot)
    thr = max(timeout_s, 4.0 * float(np.median(dt)))
    idx = np.nonzero(dt > thr)[0]
    return [(float(rec[k] - t_first), float(dt[k])) for k in idx], thr


def _read_window(
    path: str, t_from: float | None, t_to: float | None
) -> tuple[list[tuple[int, float, Any]], TlogStats, float, float, float]:
    """(messages, stats, duration, from, to) of the tlog at ``path``: every decoded message as
    (index of the record among the good ones, time, message), the window in s since the first
    record. Raises MpfError (one line) for a missing file, no MAVLink record, or a bad window."""
    if not os.path.isfile(path):
        raise MpfError(f"{path}: no such tlog file")
    stats = TlogStats()
    # iter_tlog counts a record before it yields it. Every type is decoded: the link's clock
    # gate sees every message of the vehicle that carries a time_boot_ms, so the replay's must
    # too.
    messages = [(stats.records - 1, t, msg) for t, msg in iter_tlog(path, stats=stats)]
    if stats.records == 0 or stats.t_first_s is None or stats.t_last_s is None:
        raise MpfError(
            f"{path}: not a tlog (no MAVLink record with a valid CRC in {os.path.getsize(path)} "
            "bytes)"
        )
    duration = stats.t_last_s - stats.t_first_s
    a = 0.0 if t_from is None else float(t_from)
    b = duration if t_to is None else float(t_to)
    if not (math.isfinite(a) and math.isfinite(b)) or a < 0.0 or b <= a or a > duration:
        raise MpfError(
            f"bad window --from {a:g} --to {b:g}: need 0 <= from < to and from <= {duration:.2f} "
            "s (the log's length)"
        )
    return messages, stats, duration, a, b


def _replay_metrics(cols: dict[str, Any], cfg: Config) -> dict[str, Any]:
    """The run's metrics (as the bridge's), with the median and final |pt| and the fraction of
    steps that broke Assumption 1 when anything was replayed."""
    mc = cfg.metrics
    metrics = compute_metrics(cols, mc.steady_after_s, mc.converge_threshold_m)
    if len(cols["t"]):
        metrics["median_pt_m"] = float(np.median(cols["pt_norm"]))
        metrics["final_pt_m"] = float(cols["pt_norm"][-1])
        metrics["assumption1_violated_fraction"] = float(np.mean(cols["margin"] <= 0.0))
    return metrics


def _replay_figures(
    rp: _Replayer,
    path: str,
    cfg: Config,
    stats: TlogStats,
    window: tuple[float, float],
    gaps: list[Any],
) -> dict[str, Any]:
    """metrics.json's ``replay`` entry: the log, the window, what was replayed and how the
    commands compared."""
    c = rp.check
    return {
        "tlog": path, "config": cfg.source, "window_s": list(window), "records": stats.records,
        "skipped_regions": stats.skipped_regions, "skipped_bytes": stats.skipped_bytes,
        "truncated_tail_bytes": stats.truncated_tail_bytes,
        "zero_tail_bytes": stats.zero_tail_bytes, "counts": dict(stats.counts),
        "modes": [list(x) for x in rp.modes], "attitude_gaps": [list(g) for g in gaps],
        "origin": rp.origin, "t0_boot_s": rp.ctl.t0, "s0_m": rp.s0, "steps": rp.steps,
        "skipped_steps": dict(rp.skip_reasons), "link_rejected": dict(rp.link.rejected),
        "commands": {
            "markers": c.markers, "sent": c.sent, "compared": c.compared, "resent": c.resent,
            "safe": c.safe, "differing": c.differing, "unexplained": c.unexplained,
            "unsent_steps": c.unsent_steps, "max_diff": c.max_diff, "identical": c.identical,
            "first_difference": c.first_difference,
        },
    }  # fmt: skip


def _write_replay(
    out: Path,
    rp: _Replayer,
    cfg: Config,
    cols: dict[str, Any],
    metrics: dict[str, Any],
    plots: bool,
) -> None:
    """The run directory: setpoints.csv, the recorded flight against the limits (limits.csv,
    the verdict's figures), then timeseries.csv, metrics.json and the figures."""
    # setpoints first: the plots draw them too
    write_setpoints(out, rp.sp_rows)
    if rp.lim_rows:
        L = np.array(rp.lim_rows, float)
        L[:, 0] -= L[0, 0]  # s since the first replayed step, as the steady window counts
        # the recorded flight against the limits (the verdict's figures; replay keeps its
        # own exit codes)
        vd = assess(cfg, L[:, 0], cols["pt_norm"], L[:, 4], L[:, 3], L[:, 1], L[:, 2],
                    L[:, 5], source="telemetry")  # fmt: skip
        vd.record(metrics)
        write_limits(out, L)
    write_run(out, cols, metrics, rp.ctl.path.positions(), plots=plots and len(cols["t"]) >= 2)


def _note_why_nothing_was_replayed(rp: _Replayer, vehicle_sysid: int) -> None:
    """A note in the summary when the replay never reached a control step's state."""
    if rp.phase in ("wait_heartbeat",):
        rp.notes.append(
            f"no autopilot HEARTBEAT from system {vehicle_sysid}: nothing was replayed "
            "(mavlink.vehicle_sysid?)"
        )
    elif rp.ctl.t0 is None:
        rp.notes.append(f"never a complete state: {rp.ctl.why_not}")


def replay(
    tlog: str | os.PathLike[str],
    cfg: Config,
    out_dir: str | os.PathLike[str] | None = None,
    t_from: float | None = None,
    t_to: float | None = None,
    plots: bool = True,
    log: Callable[[str], None] = lambda s: None,
) -> ReplayResult:
    """Replay ``tlog`` with the law and adapter of ``cfg``; write a run directory to ``out_dir``
    (None: no files). ``t_from``/``t_to``: window in s since the first record.

    Raises MpfError (one line) when the file cannot be read, holds no MAVLink record, or the
    window is empty."""
    wall0 = time.perf_counter()
    path = os.fspath(tlog)
    m = cfg.section("mavlink")
    messages, stats, duration, a, b = _read_window(path, t_from, t_to)
    assert stats.t_first_s is not None  # _read_window checked it
    # only now: a wrong file or window must not leave an empty run directory behind
    out = prepare_out_dir(Path(out_dir)) if out_dir is not None else None
    own = (m.source_system, m.source_component)
    markers = _has_markers(messages, own)
    rp = _Replayer(cfg, a, b, stats.t_first_s, markers)
    log(
        f"replaying {len(messages)} messages of {path} ({'with' if markers else 'without'} the "
        "bridge's markers)"
    )
    for i, t, msg in messages:
        rp.feed(i, t, msg)
    if rp.modes:
        s0, _, n = rp.modes[-1]
        rp.modes[-1] = (s0, duration, n)
    cols = rp.table.arrays()
    metrics = _replay_metrics(cols, cfg)
    gaps, thr = _gaps(rp.att_times, stats.t_first_s, m.telemetry_timeout_s)
    _note_why_nothing_was_replayed(rp, m.vehicle_sysid)
    res = ReplayResult(
        path=path,
        config=cfg.source,
        flavour=rp.flavour.value,
        records=stats.records,
        skipped_regions=stats.skipped_regions,
        skipped_bytes=stats.skipped_bytes,
        truncated_tail_bytes=stats.truncated_tail_bytes,
        zero_tail_bytes=stats.zero_tail_bytes,
        unknown_msgids=stats.unknown_msgids,
        t_first_s=stats.t_first_s,
        duration_s=duration,
        window=(a, b),
        counts=dict(stats.counts),
        modes=rp.modes,
        gaps=gaps,
        gap_threshold_s=thr,
        attitude_samples=len(rp.att_times),
        steps=rp.steps,
        skipped_steps=dict(rp.skip_reasons),
        link_rejected=dict(rp.link.rejected),
        recorded=len(cols["t"]),
        origin=rp.origin,
        t0_boot_s=rp.ctl.t0,
        s0_m=rp.s0,
        check=rp.check,
        metrics=metrics,
        notes=rp.notes,
        out_dir=out,
    )
    metrics["replay"] = _replay_figures(rp, path, cfg, stats, (a, b), gaps)
    kf = getattr(rp.ctl.target, "kf", None)  # the live target's estimator: what became of reports
    if kf is not None:
        metrics["replay"]["target_estimator"] = dict(kf.counts)
    if out is not None:
        _write_replay(out, rp, cfg, cols, metrics, plots)
    res.elapsed_s = time.perf_counter() - wall0
    return res


__all__ = ["CommandCheck", "ReplayResult", "TOLERANCE", "replay"]
