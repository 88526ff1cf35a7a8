"""The bridge's run state: options, results, life-cycle states, exits, and the attributes
every concern of :class:`mpf_mavlink.bridge.live.Bridge` reads (:class:`BridgeBase`)."""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from mpf_mavlink.bridge.controller import Controller
from mpf_mavlink.bridge.operator import OperatorDisplay
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.adapter import Setpoint
from mpf_mavlink.mavlink import Flavour
from mpf_mavlink.runs.rundir import RunTable

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_DO_REPOSITION = 192
# ArduPilot's REQUEST_DATA_STREAM groups (MAV_DATA_STREAM_*) holding the messages we need
# (libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp, STREAM_*_msgs)
_AP_STREAM_POSITION, _AP_STREAM_EXTRA1, _AP_STREAM_EXTRA2, _AP_STREAM_EXTRA3 = 6, 10, 11, 12
# PX4 parameters that say what happens when our setpoints stop (read and printed before engaging)


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
    flavour: Literal["auto", "px4", "ardupilot"] | None = None  # None: mavlink.flavour
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
    fallback_detail: dict[str, Any] = field(default_factory=dict)  # PX4: params, hold, centre
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
        dc = m.get("delay_compensation")
        if isinstance(dc, dict) and dc.get("loop_delay_s") is not None:
            lines.append(
                f"loop delay        {1e3 * float(dc['loop_delay_s']):.1f} ms ({dc.get('loop_delay_source')}"
                f"{', off' if not dc.get('enabled') else ''})"
            )
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


class BridgeBase:
    """Attributes shared by the bridge's concerns (link, control step, streams, session, recording)."""

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
        # the vehicle's clock (s since its boot): the newest time stamp it sent, and its value
        # at the last ATTITUDE and the last good control step (the lockstep timeouts)
        self.vehicle_t: float | None = None
        self.last_att_vt: float | None = None
        self.last_good_vt: float | None = None
        self.last_send_mono = -math.inf
        self.last_hb_tx_mono = -math.inf
        self.last_ts_tx_mono = -math.inf  # the latest TIMESYNC request (PX4's loop delay)
        self.first_send_mono: float | None = None
        self.prestream_sends = 0
        self.t_engage: float | None = None
        self.t_last: float | None = None
        self.table = RunTable()
        self.sp_rows: list[tuple[float, ...]] = []
        # arrival times (monotonic s) per message type while the stream rates are measured
        self._arrivals: dict[str, deque[float]] | None = None
        self.params: dict[str, float] = {}  # PARAM_VALUE answers (name -> value)
        self.param_types: dict[str, int] = {}  # name -> MAV_PARAM_TYPE
        self.judge_rows: list[tuple[float, float, float, float]] = []  # alt, airspeed, roll, pitch
        # guidance values and state texts for a ground station (after each setpoint, rate-limited)
        self.display = OperatorDisplay(m.operator_display, m.operator_display_hz)
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

    def _set_state(self, s: State) -> None:
        self.state = s
        if s <= State.TRACKING:
            self.furthest = max(self.furthest, s)
        self.log(f"[{s.name}]")
        if self.link is not None:
            self.display.text(self.link, s.name)

    def _ready(self) -> bool:
        return self.ctl.ready()

    def _close(self) -> None:
        if self.link is not None:
            self.link.close()
