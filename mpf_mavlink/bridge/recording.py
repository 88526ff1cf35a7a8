"""The bridge's run record (:class:`Recorder`): the rows of the tracking phase, then metrics,
verdict and the run directory (tables, plots) when the run ends.

``mavlink.recording: lean`` (campaigns) keeps every :data:`LEAN_ROW_EVERY`-th tracking row,
draws no plots and writes no tlog; the flight itself is the same (the receive times the loop
sees are the link's, with or without a tlog)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.bridge.base import EXIT_OK, BridgeResult
from mpf_mavlink.bridge.controller import Controller, Step, write_setpoints
from mpf_mavlink.bridge.envelope import verdict_words
from mpf_mavlink.config.schema import Config
from mpf_mavlink.runs.rundir import COLUMNS, RunTable, compute_metrics
from mpf_mavlink.runs.write import limits_row, write_limits, write_run

#: Lean recording keeps one tracking row in this many (50 Hz ATTITUDE: 10 Hz rows).
LEAN_ROW_EVERY = 5
_SATURATED = COLUMNS.index("saturated")


def is_lean(m: Any) -> bool:
    """``mavlink.recording: lean`` (campaigns)."""
    return bool(m.recording == "lean")


class Recorder:
    """Rows of the tracking phase (time series, setpoints, the verdict's series) and the run
    directory they end in."""

    def __init__(self, cfg: Config, m: Any, url: str, out_dir: Path) -> None:
        self.cfg, self.m, self.url, self.out = cfg, m, url, Path(out_dir)
        self.every = LEAN_ROW_EVERY if is_lean(m) else 1
        self.plots = bool(m.plots) and not is_lean(m)
        self._skip = 0
        self.table = RunTable()
        self.sp_rows: list[tuple[float, ...]] = []
        # the verdict's series, limits_row's: t, roll, pitch, airspeed, altitude, thrust
        self.judge_rows: list[tuple[float, ...]] = []

    def record(self, st: Step, clipped: bool = False) -> None:
        """One tracking step's rows (every ``every``-th step). ``clipped``: a command of this
        step was cut at a limit (the envelope monitor's word): the row's ``saturated`` says so
        as well as the law's own rate limit."""
        if self._skip:
            self._skip -= 1
            return
        self._skip = self.every - 1
        row = st.row()
        if clipped:
            row[_SATURATED] = 1.0
        self.table.append(row)
        self.sp_rows.append(tuple(st.setpoint_row()))
        self.judge_rows.append(limits_row(st.t, st.estimate, st.setpoint.thrust))

    # -- the end of the run ------------------------------------------------------------------------
    def finish(
        self,
        res: BridgeResult,
        ctl: Controller,
        counters: dict[str, Any],
        envelope: dict[str, Any] | None = None,
    ) -> None:
        """Metrics, the verdict (which may set the exit code) and the run directory; a failure
        to write is recorded in ``res.records_error``, never raised. ``envelope``: the envelope
        monitor's summary (metrics.json ``envelope``; the verdict names its episodes)."""
        cols = self.table.arrays()
        metrics = compute_metrics(
            cols, self.cfg.metrics.steady_after_s, self.cfg.metrics.converge_threshold_m
        )
        if envelope is not None:
            metrics["envelope"] = envelope
        limits_rows = self._verdict(res, cols, metrics)
        if self.sp_rows:
            # thrust pinned at its ceiling: the airspeed the law assumes is not being held
            thr = np.array([r[8] for r in self.sp_rows], float)
            metrics["thrust_saturated_fraction"] = float(
                np.mean(thr >= ctl.ad_params.thrust_max - 0.005)
            )
        st = ctl.ad_state
        metrics["adapter_learned"] = {
            "trim_pitch_rad": st.trim_hat,
            "turn_gain": st.turn_gain,
            "pitch_rate_bias_rad_s": st.q_bias,
            "trim_schedule_rad": st.sched.k,
        }
        metrics["delay_compensation"] = delay_metrics(ctl, bool(self.m.delay_compensation))
        metrics.update(
            streams=res.streams, fallback=res.fallback, fallback_detail=res.fallback_detail,
            state_reached=res.state_reached, exit_reason=res.exit_reason, exit_code=res.exit_code,
            flavour=res.flavour, tracked_s=res.tracked_s, handback_requested=res.handback_requested,
            handback_confirmed=res.handback_confirmed, checks=res.checks, counters=counters,
            checks_measured=res.measured, forced=res.forced,
            url=self.url, recording="lean" if self.every > 1 else "full",
        )  # fmt: skip
        res.metrics = metrics
        try:
            self._write(cols, metrics, limits_rows, ctl)
        except Exception as e:  # noqa: BLE001 - records must not hide the flight's outcome
            res.records_error = f"run directory not written: {e}"

    def _verdict(
        self, res: BridgeResult, cols: dict[str, np.ndarray], metrics: dict[str, Any]
    ) -> np.ndarray | None:
        """The verdict on what the bridge saw (its estimates: the truth is not known here; the
        thrust is the one sent, which the autopilot applies in offboard); the limits' rows."""
        if not len(cols["t"]):
            return None
        metrics["final_pt_m"] = float(cols["pt_norm"][-1])
        J = np.array(self.judge_rows, float).reshape(-1, 6)
        thr_sent = np.array([r[8] for r in self.sp_rows], float)
        t_rel = cols["t"] - cols["t"][0]
        thr = thr_sent if len(thr_sent) == len(t_rel) else None
        # the verdict's module loads once the run has ended, not before the flight
        from mpf_mavlink.runs.verdict import assess

        vd = assess(
            self.cfg, t_rel, cols["pt_norm"], J[:, 4], J[:, 3], J[:, 1], J[:, 2], thr,
            source="telemetry",
        )  # fmt: skip
        env = metrics.get("envelope")
        words = verdict_words(env) if isinstance(env, dict) else ""
        if words:
            vd.notes.append(f"envelope: {words}")
        res.verdict = vd.line()
        vd.record(metrics)
        if res.exit_code == EXIT_OK:
            res.exit_code = vd.exit_code(EXIT_OK)
        thr_col = thr if thr is not None else np.full(len(t_rel), np.nan)
        return np.column_stack([t_rel, J[:, 1], J[:, 2], J[:, 3], J[:, 4], thr_col])

    def _write(
        self,
        cols: dict[str, np.ndarray],
        metrics: dict[str, Any],
        limits_rows: np.ndarray | None,
        ctl: Controller,
    ) -> None:
        out = self.out
        # setpoints first: the plots draw them too
        write_setpoints(out, self.sp_rows)
        if limits_rows is not None:
            write_limits(out, limits_rows)
        plots = self.plots and len(cols["t"]) >= 2
        write_run(out, cols, metrics, ctl.path.positions(), plots=plots)


def delay_metrics(ctl: Controller, enabled: bool) -> dict[str, Any]:
    """What the delay compensation used at the end (guidance/predict.py): the loop delay
    measured from the autopilot's ATTITUDE_TARGET echoes or TIMESYNC (controller.py), or
    mavlink.known_delay_s; the ATTITUDE period, the control-step period (shorter with position
    instants: the multi-rate loop), the prediction horizon and the look-ahead they gave."""
    d = ctl.delay
    return {
        "enabled": enabled,
        "loop_delay_s": d.delay_s,
        "loop_delay_source": d.delay_source(),  # echo, timesync or mavlink.known_delay_s
        "echoes_in_median": len(d.delays),  # the last 9 at most
        "echoes_frozen": d.echoes_frozen,  # ATTITUDE_TARGET stamps that had not moved
        "timesync_delays_in_median": len(d.ts_delays),
        "timesync_rtt_min_s": min(r for _, r, _ in d.timesync) if d.timesync else None,
        "attitude_period_s": ctl.instants.att_period_s,
        "attitude_source": ctl.est.att_source,  # chosen once per flight (estimator.py)
        "attitude_samples_ignored": ctl.est.att_ignored,  # of the other source
        "step_period_s": ctl.period_s,
        "position_instants": bool(ctl.instants.position_instants),
        "position_steps": ctl.instants.position_steps,
        "horizon_s": ctl.tau_s,
        "look_ahead_m": ctl.alpha_m,
        "look_ahead_configured_m": ctl.gains.alpha,
    }
