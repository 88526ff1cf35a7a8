"""The bridge's vocabulary: options, results, life-cycle states (:class:`Phase`) and exits."""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from mpf_mavlink.config.schema import Config

if TYPE_CHECKING:
    from mpf_mavlink.bridge.preflight import SimulatedPlant


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
# confirmed, the envelope monitor's hold policy handed back); 130 Ctrl-C; 143 SIGTERM; 1 an
# unexpected exception (re-raised after hand-back).
EXIT_OK, EXIT_CHECK, EXIT_SAFETY, EXIT_SIGINT, EXIT_SIGTERM = 0, 3, 4, 130, 143


class _Stop(Exception):
    """A planned exit of the streaming phases."""

    def __init__(self, reason: str, kind: str) -> None:
        super().__init__(reason)
        self.reason, self.kind = (
            reason,
            kind,
        )  # kind: duration|telemetry|target|pilot|engage|envelope


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
    #: the simulated vehicle behind the link, for the checks (the SIL gives it); None: the
    #: vehicle is what the link says (its measured wind, airspeed and state), as on a real one
    plant: SimulatedPlant | None = None


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
    # what the pre-engage checks were given by the autopilot (wind, airspeed, live target)
    measured: dict[str, Any] = field(default_factory=dict)
    # --force engaged despite these failed checks (their names); [] when none failed
    forced: list[str] = field(default_factory=list)
    verdict: str = ""  # the flight's one-line verdict (mpf_mavlink/runs/verdict.py); "" = not flown

    def summary(self) -> str:
        c = self.counters
        lines = [
            "",
            f"state reached     {self.state_reached} (final: {self.final_state})",
            f"exit              {self.exit_reason} (code {self.exit_code})",
            f"autopilot         {self.flavour}",
            f"tracked           {self.tracked_s:.2f} s",
            f"hand-back         {self._handback_word()}",
            f"setpoints sent    {c.get('setpoints_sent', 0)} (re-sent "
            f"{c.get('setpoints_resent', 0)}, safe {c.get('safe_setpoints', 0)})",
            f"law evaluations   {c.get('law_evals', 0)}",
            f"re-engagements    {c.get('reengagements', 0)}",
            f"stream rates      {self._streams_line()}",
            f"fallback          {self.fallback or 'not set'}",
            f"rx/tx packets     {c.get('rx_packets', 0)}/{c.get('tx_packets', 0)}; rejected: "
            f"{c.get('rejected_sysid', 0)} foreign ids, {c.get('rejected_unsigned', 0)} unsigned, "
            f"{c.get('rejected_bad_signature', 0)} bad signatures, "
            f"{c.get('bad_data', 0)} bad frames",
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
                f"loop delay        {1e3 * float(dc['loop_delay_s']):.1f} ms "
                f"({dc.get('loop_delay_source')}"
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

    def _handback_word(self) -> str:
        if self.handback_confirmed:
            return "confirmed"
        return "requested, not confirmed" if self.handback_requested else "not requested"

    def _streams_line(self) -> str:
        st = self.streams
        if not st:
            return "not requested"
        parts = [
            f"{k} {v['requested_hz']:g}->{v['measured_hz']:.1f}"
            for k, v in st.get("messages", {}).items()
        ]
        return f"asked ({st.get('method', '?')}): " + ", ".join(parts) + " Hz"


def resolve_mavlink(cfg: Config, opts: BridgeOptions) -> Any:
    """The config's ``mavlink`` section with the command line's overrides applied."""
    m = cfg.section("mavlink")
    overrides = {
        "flavour": opts.flavour,
        "mission_duration_s": None if opts.duration_s is None else float(opts.duration_s),
        "heartbeat_timeout_s": (
            None if opts.heartbeat_timeout_s is None else float(opts.heartbeat_timeout_s)
        ),
        "arm": None if opts.arm is None else bool(opts.arm),
        "plots": None if opts.plots is None else bool(opts.plots),
        "reengage_max": None if opts.reengage is None else int(opts.reengage),
    }
    given: dict[str, Any] = {k: v for k, v in overrides.items() if v is not None}
    return dataclasses.replace(m, **given) if given else m


class Phase:
    """The life-cycle state, the furthest one reached before HANDBACK/DONE, and who is told
    of a change (the log and the operator's ground station)."""

    def __init__(self, on_change: Callable[[State], None]) -> None:
        self.state = State.CONNECTING
        self.furthest = State.CONNECTING
        self._on_change = on_change

    def set(self, s: State) -> None:
        self.state = s
        if s <= State.TRACKING:
            self.furthest = max(self.furthest, s)
        self._on_change(s)
