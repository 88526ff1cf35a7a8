"""What a replay reports: the determinism check of the replayed commands against the recorded
SET_ATTITUDE_TARGET records (:class:`CommandCheck`, floats compared after float32 rounding like
the wire, tolerance :data:`TOLERANCE`) and the summary of a replay (:class:`ReplayResult`).

The replay itself (the link filter, the control steps, the comparison in file order) is in
:mod:`mpf_mavlink.bridge.replay` (it drives the bridge's controller; runs/ never imports the
bridge), which re-exports these names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

TOLERANCE = 1e-6  # largest accepted difference of a replayed setpoint field
_SAT = "SET_ATTITUDE_TARGET"
_FLOAT_FIELDS = (
    "q_w",
    "q_x",
    "q_y",
    "q_z",
    "body_roll_rate",
    "body_pitch_rate",
    "body_yaw_rate",
    "thrust",
)
_INT_FIELDS = ("time_boot_ms", "target_system", "target_component", "type_mask")


def _sat_fields(msg: Any) -> dict[str, float]:
    """The comparable fields of a SET_ATTITUDE_TARGET (floats as the wire carries them)."""
    q = msg.q
    return {
        "time_boot_ms": float(msg.time_boot_ms),
        "target_system": float(msg.target_system),
        "target_component": float(msg.target_component),
        "type_mask": float(msg.type_mask),
        "q_w": float(q[0]), "q_x": float(q[1]), "q_y": float(q[2]), "q_z": float(q[3]),
        "body_roll_rate": float(msg.body_roll_rate),
        "body_pitch_rate": float(msg.body_pitch_rate),
        "body_yaw_rate": float(msg.body_yaw_rate),
        "thrust": float(msg.thrust),
    }  # fmt: skip


def _f32(d: dict[str, float]) -> dict[str, float]:
    return {k: (float(np.float32(v)) if k in _FLOAT_FIELDS else v) for k, v in d.items()}


def _largest_diff(rec: dict[str, float], exp: dict[str, float]) -> tuple[float, str]:
    worst, name = -1.0, ""
    for k in (*_INT_FIELDS, *_FLOAT_FIELDS):
        d = abs(rec[k] - exp[k])
        if not d <= worst:  # NaN counts as the largest
            worst, name = (math.inf if math.isnan(d) else d), k
    return worst, name


@dataclass
class CommandCheck:
    """Replayed commands against the SET_ATTITUDE_TARGET records of our ids."""

    markers: bool = False  # the tlog carries the bridge's MPF markers
    sent: int = 0  # SET_ATTITUDE_TARGET records from our ids
    compared: int = 0  # matched to a control step and compared field by field
    resent: int = 0  # re-sends of the previous (control) setpoint
    safe: int = 0  # wings-level hand-back setpoints (each send)
    differing: int = 0  # compared with a field beyond the tolerance
    unexplained: int = 0  # neither a command, a re-send nor a safe setpoint
    unsent_steps: int = 0  # control steps the bridge did not send (between two it did)
    max_diff: float = 0.0  # largest field difference over the compared commands
    first_difference: str | None = None

    @property
    def identical(self) -> bool:
        return (
            self.markers
            and self.compared > 0
            and not (self.differing or self.unexplained or self.unsent_steps)
        )

    def verdict(self) -> str:
        if self.sent == 0:
            return "no SET_ATTITUDE_TARGET from our ids in this tlog: nothing to compare"
        if not self.markers:
            return (
                f"{self.sent} SET_ATTITUDE_TARGET from our ids but no MPF markers (not recorded "
                "by this bridge): not compared"
            )
        head = (
            f"{self.compared} commands compared (max |diff| {self.max_diff:.3g}), "
            f"{self.resent} re-sends, {self.safe} safe setpoints"
        )
        if self.identical:
            return f"identical: {head}"
        extra = []
        if self.differing:
            extra.append(f"{self.differing} differ")
        if self.unexplained:
            extra.append(f"{self.unexplained} unexplained")
        if self.unsent_steps:
            extra.append(f"{self.unsent_steps} replayed steps were never sent")
        return f"DIFFERENT: {head}; {', '.join(extra)}; first: {self.first_difference}"


@dataclass
class ReplayResult:
    path: str
    config: str
    flavour: str
    records: int
    skipped_regions: int
    skipped_bytes: int
    truncated_tail_bytes: int
    zero_tail_bytes: int  # zeros after the last record: its writer died (a mapped tlog)
    unknown_msgids: int
    t_first_s: float | None  # s since the epoch
    duration_s: float
    window: tuple[float, float]  # s since the first record
    counts: dict[str, int]  # message type -> good records (whole file)
    modes: list[tuple[float, float, str]]  # (start, end, name), s since the first record
    gaps: list[tuple[float, float]]  # (start, length) of ATTITUDE gaps, s
    gap_threshold_s: float
    attitude_samples: int
    steps: int  # control steps (law evaluations)
    skipped_steps: dict[str, int]  # ATTITUDE samples without a step, by reason
    link_rejected: dict[str, int]  # messages the bridge's link would have dropped, by reason
    recorded: int  # steps inside the window (rows of timeseries.csv)
    origin: str  # where t0/s0 came from
    t0_boot_s: float | None
    s0_m: float | None
    check: CommandCheck
    metrics: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    out_dir: Path | None = None
    elapsed_s: float = 0.0

    def summary(self) -> str:
        lines = ["", f"tlog              {self.path}"]
        skip = f"{self.skipped_regions} corrupt stretches skipped ({self.skipped_bytes} bytes"
        skip += (
            f", {self.truncated_tail_bytes} of them a cut-off tail)"
            if self.truncated_tail_bytes
            else ")"
        )
        lines.append(
            f"records           {self.records} good; {skip}; {self.unknown_msgids} unknown ids"
        )
        if self.zero_tail_bytes:
            lines.append(
                f"                  then {self.zero_tail_bytes} zero bytes: the writer was killed "
                "before it closed the file (every record it wrote is above)"
            )
        lines.append(
            f"duration          {self.duration_s:.2f} s; window {self.window[0]:.2f} .. "
            f"{self.window[1]:.2f} s"
        )
        top = sorted(self.counts.items(), key=lambda kv: (-kv[1], kv[0]))
        shown = ", ".join(f"{k} {v}" for k, v in top[:12])
        more = f", ... ({len(top) - 12} more types)" if len(top) > 12 else ""
        lines.append(f"messages          {shown}{more}")
        if self.modes:
            flown = "; ".join(f"{name} {a:.1f}-{b:.1f} s" for a, b, name in self.modes)
            lines.append(f"modes ({self.flavour:<9}) {flown}")
        else:
            lines.append("modes             no autopilot HEARTBEAT from the vehicle")
        if self.gaps:
            worst = sorted(self.gaps, key=lambda g: -g[1])[:5]
            txt = ", ".join(f"{b:.2f} s at {a:.1f} s" for a, b in worst)
            lines.append(
                f"telemetry gaps    {len(self.gaps)} ATTITUDE gaps > {self.gap_threshold_s:.2f} s "
                f"of autopilot time (longest: {txt})"
            )
        else:
            lines.append(
                f"telemetry gaps    none > {self.gap_threshold_s:.2f} s in "
                f"{self.attitude_samples} ATTITUDE samples"
            )
        if self.link_rejected:
            why = ", ".join(
                f"{n} {k}" for k, n in sorted(self.link_rejected.items(), key=lambda kv: -kv[1])
            )
            lines.append(f"link filter       dropped as the bridge's link would: {why}")
        o = (
            f"t0 = {self.t0_boot_s!r} s boot time, s0 = {self.s0_m!r} m"
            if self.t0_boot_s is not None
            else "never (no complete state)"
        )
        lines.append(f"origin            {o} ({self.origin})")
        lines.append(f"control steps     {self.steps} ({self.recorded} in the window)")
        if self.skipped_steps:
            why = "; ".join(
                f"{n} {k}" for k, n in sorted(self.skipped_steps.items(), key=lambda kv: -kv[1])
            )
            lines.append(f"ATTITUDE skipped  {sum(self.skipped_steps.values())}: {why}")
        m = self.metrics
        for k, label, unit in (
            ("convergence_time_s", "convergence time", "s"),
            ("steady_rms_m", "steady RMS |pt|", "m"),
            ("steady_max_m", "steady max |pt|", "m"),
            ("median_pt_m", "median |pt|", "m"),
            ("max_rate_cmd_rad_s", "peak rate command", "rad/s"),
            ("assumption1_violated_fraction", "Assumption 1 off", "(fraction of steps)"),
        ):
            v = m.get(k)
            lines.append(f"{label:<17} {'n/a' if v is None else f'{v:.4g}'} {unit}")
        lines.append(f"commands          {self.check.verdict()}")
        for n in self.notes:
            lines.append(f"note              {n}")
        if self.out_dir is not None:
            lines.append(
                f"run directory     {self.out_dir}  (timeseries.csv, setpoints.csv, metrics.json, "
                "*.png)"
            )
        lines.append(f"replay took       {self.elapsed_s:.2f} s")
        return "\n".join(lines)
