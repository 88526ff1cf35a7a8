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
(time.monotonic) is used only for link timeouts, rates and the resend timer; the receive time
the estimator and a live target see is the message's tlog record time (microseconds), and the
decisions taken from the wall clock are written to the tlog as STATUSTEXT: ``MPF t0=``,
``MPF s0=`` after INIT and ``MPF stream`` when setpoints start (see controller.py), so a replay
of the tlog reproduces every setpoint.
Records: ``mavlink.tlog`` (both directions), ``timeseries.csv`` (TRACKING rows, what the law
saw), ``setpoints.csv``, ``metrics.json`` (figures, counters, exit) and the plots.
"""

from __future__ import annotations

import dataclasses
import enum
import gc
import math
import signal
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.bridge.controller import (
    HALT_TEXT,
    SETPOINT_COLUMNS,
    STREAM_TEXT,
    Controller,
    LiveTarget,
    ScriptedTarget,
    Step,
    origin_texts,
)
from mpf_mavlink.config import bridge as bridge_config  # noqa: F401  (registers the mavlink/adapter sections)
from mpf_mavlink.config.bridge import hold_mode_error
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.adapter import Setpoint, safe_setpoint
from mpf_mavlink.core.frames import matrix_to_euler
from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink import (
    Flavour,
    decode,
    dialect,
    enable_signing,
    encode_arm,
    encode_do_reposition,
    encode_get_home_position,
    encode_request_data_stream,
    encode_request_message,
    encode_set_attitude_target_quat,
    encode_set_attitude_target_rates,
    encode_set_message_interval,
    encode_set_mode,
    flavour_from_heartbeat,
    is_offboard,
    load_signing_key,
    mode_name,
    open_link,
    wait_heartbeat,
)
from mpf_mavlink.mavlink.modes import (
    arduplane_mode_from_name,
    px4_decode_custom_mode,
    px4_mode_from_name,
)
from mpf_mavlink.runs.rundir import COLUMNS, RunTable, compute_metrics, prepare_out_dir
from mpf_mavlink.runs.verdict import EXIT_VERDICT, judge, verdict_line
from mpf_mavlink.runs.write import write_run

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_DO_REPOSITION = 192
# ArduPilot's REQUEST_DATA_STREAM groups (MAV_DATA_STREAM_*) holding the messages we need
# (libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp, STREAM_*_msgs)
_AP_STREAM_POSITION, _AP_STREAM_EXTRA1, _AP_STREAM_EXTRA2, _AP_STREAM_EXTRA3 = 6, 10, 11, 12
# PX4 parameters that say what happens when our setpoints stop (read and printed before engaging)
_PX4_FALLBACK_PARAMS = ("COM_OF_LOSS_T", "COM_OBL_RC_ACT")
_PX4_OBL_ACTIONS = {
    0: "Position (loiter at the current position)", 1: "Altitude", 2: "Stabilized",
    3: "Return", 4: "Land", 5: "Hold (loiter)", 6: "Terminate", 7: "Disarm",
}  # fmt: skip


class State(enum.IntEnum):
    CONNECTING = 0
    WAIT_HEARTBEAT = 1
    CHECKS = 2
    INIT = 3
    PRESTREAM = 4
    ENGAGE = 5
    TRACKING = 6
    HANDBACK = 7
    DONE = 8


# Exit codes (the CLI returns them): 0 mission flown and handed back; 3 a check failed;
# 4 a safety exit (telemetry/target lost, pilot took over, engage refused, hand-back not
# confirmed); 130 Ctrl-C; 143 SIGTERM; 1 an unexpected exception (re-raised after hand-back).
EXIT_OK, EXIT_CHECK, EXIT_SAFETY, EXIT_SIGINT, EXIT_SIGTERM = 0, 3, 4, 130, 143


class _Stop(Exception):
    """A planned exit of the streaming phases."""

    def __init__(self, reason: str, kind: str) -> None:
        super().__init__(reason)
        self.reason, self.kind = reason, kind  # kind: duration|telemetry|target|pilot|engage


class _Terminated(BaseException):
    """SIGTERM, delivered like KeyboardInterrupt."""


@dataclass(frozen=True)
class BridgeOptions:
    """What the command line adds to the config."""

    url: str
    out_dir: Path
    flavour: str | None = None  # None: mavlink.flavour
    duration_s: float | None = None  # None: mavlink.mission_duration_s
    heartbeat_timeout_s: float | None = None
    arm: bool | None = None
    plots: bool | None = None
    reengage: int | None = None  # None: mavlink.reengage_max
    force: bool = False  # engage even when a pre-flight check fails


@dataclass
class BridgeResult:
    state_reached: str  # furthest life-cycle state (CONNECTING .. TRACKING)
    exit_reason: str
    exit_code: int
    flavour: str = "unknown"
    tracked_s: float = 0.0
    engaged: bool = False
    handback_requested: bool = False
    handback_confirmed: bool = False
    checks: list[str] = field(default_factory=list)
    counters: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    out_dir: Path | None = None
    final_state: str = "CONNECTING"  # DONE after a stop or hand-back
    streams: dict[str, Any] = field(default_factory=dict)  # requested / measured rates (Hz)
    fallback: str = ""  # what the autopilot does if our setpoints stop
    records_error: str | None = None  # why the run directory could not be written
    verdict: str = ""  # the flight's one-line verdict (mpf_mavlink/runs/verdict.py); "" = not flown

    def summary(self) -> str:
        c = self.counters
        lines = [
            "",
            f"state reached     {self.state_reached} (final: {self.final_state})",
            f"exit              {self.exit_reason} (code {self.exit_code})",
            f"autopilot         {self.flavour}",
            f"tracked           {self.tracked_s:.2f} s",
            f"hand-back         {'confirmed' if self.handback_confirmed else ('requested, not confirmed' if self.handback_requested else 'not requested')}",
            f"setpoints sent    {c.get('setpoints_sent', 0)} (re-sent {c.get('setpoints_resent', 0)}, safe {c.get('safe_setpoints', 0)})",
            f"law evaluations   {c.get('law_evals', 0)}",
            f"re-engagements    {c.get('reengagements', 0)}",
            f"stream rates      {self._streams_line()}",
            f"fallback          {self.fallback or 'not set'}",
            f"rx/tx packets     {c.get('rx_packets', 0)}/{c.get('tx_packets', 0)}; rejected: "
            f"{c.get('rejected_sysid', 0)} foreign ids, {c.get('rejected_unsigned', 0)} unsigned, "
            f"{c.get('rejected_bad_signature', 0)} bad signatures, {c.get('bad_data', 0)} bad frames",
        ]
        m = self.metrics
        for k, label, unit in (
            ("first_within_s", "first within", "s"),
            ("convergence_time_s", "stays within", "s"),
            ("steady_mean_vertical_m", "mean vertical", "m"),
            ("steady_mean_radial_m", "mean radial", "m"),
            ("thrust_saturated_fraction", "thrust at ceiling", "(fraction)"),
            ("steady_rms_m", "steady RMS |pt|", "m"),
            ("max_rate_cmd_rad_s", "peak rate command", "rad/s"),
            ("final_pt_m", "final |pt|", "m"),
        ):
            v = m.get(k)
            lines.append(f"{label:<17} {'n/a' if v is None else f'{v:.4g}'} {unit}")
        if self.out_dir is not None:
            lines.append(
                f"run directory     {self.out_dir}  (mavlink.tlog, timeseries.csv, metrics.json)"
            )
        lost = c.get("tlog_write_errors", 0)
        if lost or self.records_error:  # a full disk must not end a flight, nor pass unnoticed
            what = self.records_error or "run directory written"
            lines.append(f"RECORDS LOST      {lost} tlog records not written; {what}")
        return "\n".join(lines)

    def _streams_line(self) -> str:
        st = self.streams
        if not st:
            return "not requested"
        parts = [
            f"{k} {v['requested_hz']:g}->{v['measured_hz']:.1f}"
            for k, v in st.get("messages", {}).items()
        ]
        return f"asked ({st.get('method', '?')}): " + ", ".join(parts) + " Hz"


# ----------------------------------------------------------------------------- the bridge
class Bridge:
    """One run against one vehicle. Use :func:`run_bridge`."""

    def __init__(
        self, cfg: Config, opts: BridgeOptions, log: Callable[[str], None] = print
    ) -> None:
        self.cfg = cfg
        self.opts = opts
        self.log = log
        m = cfg.section("mavlink")
        if opts.flavour is not None:
            m = dataclasses.replace(m, flavour=opts.flavour)
        if opts.duration_s is not None:
            m = dataclasses.replace(m, mission_duration_s=float(opts.duration_s))
        if opts.heartbeat_timeout_s is not None:
            m = dataclasses.replace(m, heartbeat_timeout_s=float(opts.heartbeat_timeout_s))
        if opts.arm is not None:
            m = dataclasses.replace(m, arm=bool(opts.arm))
        if opts.plots is not None:
            m = dataclasses.replace(m, plots=bool(opts.plots))
        if opts.reengage is not None:
            m = dataclasses.replace(m, reengage_max=int(opts.reengage))
        self.m = m
        self.ctl = Controller(cfg, m)
        self.ad_params = self.ctl.ad_params
        self.est = self.ctl.est
        self.live = self.ctl.live
        self.target: Any = self.ctl.target
        self.path = self.ctl.path

        self.link: Any = None
        self.state = State.CONNECTING
        self.furthest = State.CONNECTING  # furthest life-cycle state before HANDBACK/DONE
        self.flavour = Flavour.UNKNOWN
        self.vehicle_compid = 1
        self.hb: Any = None  # latest autopilot HeartbeatSample
        self.acks: list[Any] = []
        self.streaming = False
        self.engaged = False
        self.last_sp: Setpoint | None = None
        self.last_time_boot_ms = 0
        self.last_att_mono = -math.inf
        self.last_good_mono = -math.inf
        self.last_send_mono = -math.inf
        self.last_hb_tx_mono = -math.inf
        self.first_send_mono: float | None = None
        self.prestream_sends = 0
        self.t_engage: float | None = None
        self.t_last: float | None = None
        self.table = RunTable()
        self.sp_rows: list[tuple[float, ...]] = []
        # arrival times (monotonic s) per message type while the stream rates are measured
        self._arrivals: dict[str, deque[float]] | None = None
        self.params: dict[str, float] = {}  # PARAM_VALUE answers (name -> value)
        self.judge_rows: list[tuple[float, float, float, float]] = []  # alt, airspeed, roll, pitch
        self.n = {
            "setpoints_sent": 0,
            "setpoints_resent": 0,
            "safe_setpoints": 0,
            "law_evals": 0,
            "mode_requests": 0,
            "reengagements": 0,
        }

    @property
    def why_not(self) -> str:
        """Why the last control step (or the wait for a state) did not produce a setpoint."""
        return self.ctl.why_not

    # -- I/O helpers -------------------------------------------------------------------------
    def _rx_time(self, msg: Any) -> float | None:
        """The receive time (s since the epoch) as the tlog recorded it: the link logs each
        message just before handing it over, so the last record is this one. The same float
        as a tlog reader computes (us * 1e-6), so replay sees exactly what we saw."""
        tl = self.link.tlog if self.link is not None else None
        if tl is not None and tl.last_packet is msg.get_msgbuf() and tl.last_us is not None:
            return tl.last_us * 1e-6
        t = getattr(msg, "_timestamp", None)  # no tlog record for it: quantise alike
        return None if t is None else round(t * 1e6) * 1e-6

    def _dispatch(self, msg: Any) -> None:
        src = msg.get_srcSystem()
        if src == self.m.vehicle_sysid:
            if self._arrivals is not None:
                self._arrivals.setdefault(msg.get_type(), deque(maxlen=400)).append(
                    time.monotonic()
                )
            if msg.get_type() == "PARAM_VALUE":
                name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else ""
                if math.isfinite(msg.param_value):
                    self.params[name] = float(msg.param_value)
                return
        rx = self._rx_time(msg)
        msg._timestamp = rx  # decoders copy it into the samples (VFR_HUD, WIND, HEARTBEAT)
        sample = decode(msg)
        if sample is None:
            return
        name = type(sample).__name__
        if src == self.m.vehicle_sysid:
            if name == "HeartbeatSample":
                if sample.autopilot == dialect.MAV_AUTOPILOT_INVALID:
                    return  # a GCS or companion on the same system id
                self.hb = sample
                if self.engaged and not is_offboard(self.flavour, sample):
                    mode = mode_name(self.flavour, sample)
                    if rx is not None and self.link.clock_gate.restarting(rx):
                        # a vehicle that reboots faster than the telemetry timeout comes back
                        # in its start-up mode: that is no pilot, and the log should say so
                        raise _Stop(
                            f"the vehicle rebooted (its boot clock restarted) and came back in {mode}: stopped commanding",
                            "pilot",
                        )
                    raise _Stop(
                        f"mode changed to {mode} by someone else: stopped commanding, not fighting it",
                        "pilot",
                    )
                return
            if name == "CommandAckSample":
                self.acks.append(sample)
                return
            if self.ctl.feed_vehicle(sample, rx):
                self.last_att_mono = time.monotonic()
                if self.streaming and self.state < State.HANDBACK:
                    self._control_step()
        elif self.live and src == self.m.target_sysid:
            self.ctl.feed_target(sample, rx)

    def _send_text(self, text: str) -> None:
        """A STATUSTEXT (severity INFO) from us: the tlog's record of a decision."""
        self._send(self.link.mav.statustext_encode(dialect.MAV_SEVERITY_INFO, text.encode("ascii")))

    def _send(self, msg: Any) -> None:
        self.link.send(msg)

    def _periodic(self) -> None:
        now = time.monotonic()
        if now - self.last_hb_tx_mono >= 1.0:
            self.last_hb_tx_mono = now
            self.link.send_heartbeat()
        if not self.streaming:
            return
        period = 1.0 / self.m.min_setpoint_rate_hz
        # re-send only while the last ATTITUDE is young enough that the last re-send still
        # falls within telemetry_timeout_s of it: commands never outlive the telemetry by more
        fresh = now - self.last_att_mono + period <= self.m.telemetry_timeout_s
        if self.state == State.HANDBACK:  # wings-level setpoints until the hold mode is confirmed
            if fresh and self.last_sp is not None and now - self.last_send_mono >= period:
                self._send_setpoint(self.last_sp, self.last_time_boot_ms)
                self.n["setpoints_resent"] += 1
            return
        if now - self.last_att_mono > self.m.telemetry_timeout_s:
            raise _Stop(
                f"telemetry lost: no ATTITUDE for {now - self.last_att_mono:.2f} s; stopped commanding",
                "telemetry",
            )
        if now - self.last_good_mono > self.m.telemetry_timeout_s:
            kind = "target" if "target" in self.why_not else "telemetry"
            raise _Stop(f"{self.why_not}; stopped commanding", kind)
        if fresh and self.last_sp is not None and now - self.last_send_mono >= period:
            self._send_setpoint(self.last_sp, self.last_time_boot_ms)
            self.n["setpoints_resent"] += 1

    def _spin(self, timeout_s: float, until: Callable[[], bool] | None = None) -> bool:
        """Pump messages (streaming setpoints when on) until ``until()`` or the timeout."""
        t_end = time.monotonic() + timeout_s
        while True:
            if until is not None and until():
                return True
            now = time.monotonic()
            if now >= t_end:
                return False
            wait = min(t_end - now, 0.01)
            if self.streaming:
                wait = min(
                    wait, max(0.0, self.last_send_mono + 1.0 / self.m.min_setpoint_rate_hz - now)
                )
            msg = self.link.recv(wait)
            if msg is not None:
                self._dispatch(msg)
            self._periodic()

    # -- control -----------------------------------------------------------------------------
    def _control_step(self) -> None:
        st = self.ctl.step()
        if st is None:
            return
        self.n["law_evals"] += 1
        self.t_last = st.t
        self._send_setpoint(st.setpoint, st.time_boot_ms)
        self.last_sp, self.last_time_boot_ms = st.setpoint, st.time_boot_ms
        self.last_good_mono = time.monotonic()
        if self.state == State.TRACKING:
            self._record(st)
            if self.t_engage is not None and st.t - self.t_engage >= self.m.mission_duration_s:
                raise _Stop(f"mission duration {self.m.mission_duration_s:g} s reached", "duration")

    def _record(self, st: Step) -> None:
        self.table.append(st.row())
        self.sp_rows.append(tuple(st.setpoint_row()))
        e = st.estimate
        R2 = e.R_B_N[2]
        self.judge_rows.append(
            (
                -float(e.vehicle.position[2]),
                float(e.vehicle.airspeed),
                math.atan2(float(R2[1]), float(R2[2])),
                math.asin(max(-1.0, min(1.0, -float(R2[0])))),
            )
        )

    def _send_setpoint(self, sp: Setpoint, time_boot_ms: int) -> None:
        if sp.safe:
            self.n["safe_setpoints"] += 1
        try:
            if self.flavour is Flavour.PX4:
                msg = encode_set_attitude_target_rates(
                    self.link.mav,
                    time_boot_ms,
                    self.m.vehicle_sysid,
                    self.vehicle_compid,
                    *sp.body_rates_frd,
                    sp.thrust,
                )
            else:
                msg = encode_set_attitude_target_quat(
                    self.link.mav,
                    time_boot_ms,
                    self.m.vehicle_sysid,
                    self.vehicle_compid,
                    sp.q_wxyz,
                    sp.thrust,
                    sp.body_rates_frd,
                )
        except ValueError:  # the adapter already guarantees finite values; belt and braces
            sp = safe_setpoint(self.ad_params)
            self.n["safe_setpoints"] += 1
            return self._send_setpoint(sp, time_boot_ms)
        self._send(msg)
        now = time.monotonic()
        self.last_send_mono = now
        self.n["setpoints_sent"] += 1
        if self.state == State.PRESTREAM:
            if self.first_send_mono is None:
                self.first_send_mono = now
            self.prestream_sends += 1

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

        for attempt in range(self.m.mode_retries):
            self.acks.clear()
            t_sent = send()
            t_end = t_sent + self.m.mode_timeout_s
            while True:
                left = t_end - time.monotonic()
                if self._spin(max(0.0, min(left, 0.1)), done):
                    return True, "confirmed"
                if left <= 0.1:
                    break
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
                res.fallback = self._px4_fallback()
                self.log(f"fallback if the bridge dies: {res.fallback}")
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

    def _px4_fallback(self) -> str:
        """Read PX4's offboard-loss timeout and action (PARAM_REQUEST_READ) and say what they do."""
        mav, sysid, comp = self.link.mav, self.m.vehicle_sysid, self.vehicle_compid
        for name in _PX4_FALLBACK_PARAMS:
            self._send(mav.param_request_read_encode(sysid, comp, name.encode("ascii"), -1))
        self._spin(2.0, lambda: all(n in self.params for n in _PX4_FALLBACK_PARAMS))
        t, act = self.params.get("COM_OF_LOSS_T"), self.params.get("COM_OBL_RC_ACT")
        if t is None or act is None:
            return (
                "PX4 offboard-loss failsafe: COM_OF_LOSS_T / COM_OBL_RC_ACT not answered (unknown)"
            )
        what = _PX4_OBL_ACTIONS.get(int(act), f"action {int(act)}")
        return f"PX4 offboard-loss failsafe after COM_OF_LOSS_T = {t:g} s: COM_OBL_RC_ACT = {int(act)}, {what}"

    def _set_set_fallback(self, res: BridgeResult) -> None:
        """ArduPlane in GUIDED: make its guided target a loiter about the path's centre at the
        path's altitude (radius and direction of the path when it is a circle), so that the
        aircraft circles where the mission was when our setpoints stop (GUIDED_TIMEOUT)."""
        from mpf_mavlink.core.frames import ned_to_geodetic

        o = self.est.geodetic_origin()
        est, _ = self.est.estimate()
        if o is None or est is None:
            res.fallback = "ArduPlane's own GUIDED loiter (no HOME_POSITION: none set by us)"
            self.log(f"fallback if the bridge dies: {res.fallback}")
            return
        tgt = self.target.state(est.vehicle.t)
        if isinstance(tgt, str):
            res.fallback = f"ArduPlane's own GUIDED loiter ({tgt})"
            return
        pts = self.path.positions()  # in the target frame
        centre_T = np.asarray(pts, float).mean(axis=0)
        centre = tgt.position + tgt.R_T_I @ centre_T
        radius = float(np.max(np.linalg.norm((np.asarray(pts, float) - centre_T)[:, :2], axis=1)))
        radius = min(max(radius, 50.0), 1000.0)
        p = self.cfg.path
        ccw = p.type in ("circle", "helix") and not p.clockwise
        lat0, lon0, alt0, off = o
        rel = centre - np.asarray(off, float)
        lat, lon, alt = ned_to_geodetic(rel, lat0, lon0, alt0)
        self.acks.clear()
        try:
            self._send(encode_do_reposition(
                self.link.mav, self.m.vehicle_sysid, self.vehicle_compid, lat, lon, alt, radius, ccw))  # fmt: skip
        except ValueError as e:
            res.fallback = f"ArduPlane's own GUIDED loiter (reposition not sent: {e})"
            self.log(f"fallback if the bridge dies: {res.fallback}")
            return
        acks: list[Any] = []

        def acked() -> bool:
            acks.extend(a for a in self.acks if a.command == MAV_CMD_DO_REPOSITION)
            self.acks.clear()
            return bool(acks)

        self._spin(1.5, acked)
        what = (
            f"ArduPlane GUIDED loiter r = {radius:.0f} m {'CCW' if ccw else 'CW'} about "
            f"{lat:.7f}, {lon:.7f} at {alt:.1f} m AMSL (the path's centre)"
        )
        if acks and acks[0].accepted:
            res.fallback = what
        else:
            why = acks[0].result_name if acks else "no COMMAND_ACK"
            res.fallback = f"NOT set ({why}): ArduPlane's own GUIDED loiter; asked for {what}"
        self.log(f"fallback if the bridge dies: {res.fallback}")

    def _set_state(self, s: State) -> None:
        self.state = s
        if s <= State.TRACKING:
            self.furthest = max(self.furthest, s)
        self.log(f"[{s.name}]")

    def _ready(self) -> bool:
        return self.ctl.ready()

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
            if now - self.last_att_mono > m.telemetry_timeout_s or not self.ctl.ready():
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

    def _close(self) -> None:
        if self.link is not None:
            self.link.close()

    def _finish(self, res: BridgeResult) -> BridgeResult:
        gc.unfreeze()  # run_bridge may be called again in this process (tests, SIL)
        res.state_reached = self.furthest.name
        res.final_state = self.state.name
        if self.t_engage is not None and self.t_last is not None:
            res.tracked_s = max(0.0, self.t_last - self.t_engage)
        counters = dict(self.n)
        if self.link is not None:
            counters.update({k: v for k, v in self.link.counters.as_dict().items()})
        res.counters = counters
        self._close()
        cols = self.table.arrays()
        metrics = compute_metrics(
            cols, self.cfg.metrics.steady_after_s, self.cfg.metrics.converge_threshold_m
        )
        if len(cols["t"]):
            metrics["final_pt_m"] = float(cols["pt_norm"][-1])
            # the verdict on what the bridge saw (its estimates: the truth is not known here)
            J = np.array(self.judge_rows, float).reshape(-1, 4)
            fails = judge(
                self.cfg,
                cols["t"] - cols["t"][0],
                cols["pt_norm"],
                J[:, 0],
                J[:, 1],
                J[:, 2],
                J[:, 3],
            )
            res.verdict = verdict_line(fails)
            metrics["verdict"], metrics["verdict_failures"] = res.verdict, fails
            if fails and res.exit_code == EXIT_OK:
                res.exit_code = EXIT_VERDICT
        if self.sp_rows:
            # thrust pinned at its ceiling: the airspeed the law assumes is not being held
            thr = np.array([r[8] for r in self.sp_rows], float)
            metrics["thrust_saturated_fraction"] = float(
                np.mean(thr >= self.ad_params.thrust_max - 0.005)
            )
        st = self.ctl.ad_state
        metrics["adapter_learned"] = {"trim_pitch_rad": st.trim_hat, "turn_gain": st.turn_gain}
        metrics.update(
            streams=res.streams, fallback=res.fallback,
            state_reached=res.state_reached, exit_reason=res.exit_reason, exit_code=res.exit_code,
            flavour=res.flavour, tracked_s=res.tracked_s, handback_requested=res.handback_requested,
            handback_confirmed=res.handback_confirmed, checks=res.checks, counters=counters,
            url=self.opts.url,
        )  # fmt: skip
        res.metrics = metrics
        out = Path(self.opts.out_dir)
        try:
            # setpoints first: the plots draw them too
            np.savetxt(
                out / "setpoints.csv",
                np.array(self.sp_rows, float).reshape(-1, 13),
                delimiter=",",
                header=SETPOINT_COLUMNS,
                comments="",
                fmt="%.9g",
            )
            write_run(
                out,
                cols,
                metrics,
                self.path.positions(),
                plots=self.m.plots and len(cols["t"]) >= 2,
            )
        except Exception as e:  # noqa: BLE001 - records must not hide the flight's outcome
            res.records_error = f"run directory not written: {e}"
            self.log(f"could not write the run directory: {e}")
        return res


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
