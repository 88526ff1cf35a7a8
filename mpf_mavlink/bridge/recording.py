"""The bridge's run record: metrics, verdict, run directory (tables, plots) at the end of a run."""

from __future__ import annotations

import gc
from pathlib import Path

import numpy as np

from mpf_mavlink.bridge.base import EXIT_OK, BridgeResult
from mpf_mavlink.bridge.controller import SETPOINT_COLUMNS
from mpf_mavlink.bridge.session import Session
from mpf_mavlink.runs.rundir import compute_metrics
from mpf_mavlink.runs.verdict import assess
from mpf_mavlink.runs.write import write_limits, write_run


class Recording(Session):
    """Metrics, verdict and the run directory when the run ends."""

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
        if self.link is not None:  # a run that ends without a hand-back says why, too
            self.display.stopped(self.link, res.exit_reason, res.exit_code == 0)
        self._close()
        cols = self.table.arrays()
        limits_rows: np.ndarray | None = None
        metrics = compute_metrics(
            cols, self.cfg.metrics.steady_after_s, self.cfg.metrics.converge_threshold_m
        )
        if len(cols["t"]):
            metrics["final_pt_m"] = float(cols["pt_norm"][-1])
            # the verdict on what the bridge saw (its estimates: the truth is not known here)
            # (telemetry; the thrust is the one sent, the autopilot applies it in offboard)
            J = np.array(self.judge_rows, float).reshape(-1, 4)
            thr_sent = np.array([r[8] for r in self.sp_rows], float)
            t_rel = cols["t"] - cols["t"][0]
            vd = assess(
                self.cfg, t_rel, cols["pt_norm"], J[:, 0], J[:, 1], J[:, 2], J[:, 3],
                thr_sent if len(thr_sent) == len(t_rel) else None, source="telemetry",
            )  # fmt: skip
            res.verdict = vd.line()
            vd.record(metrics)
            if res.exit_code == EXIT_OK:
                res.exit_code = vd.exit_code(EXIT_OK)
            limits_rows = np.column_stack(
                [t_rel, J[:, 2], J[:, 3], J[:, 1], J[:, 0],
                 thr_sent if len(thr_sent) == len(t_rel) else np.full(len(t_rel), np.nan)]
            )  # fmt: skip
        if self.sp_rows:
            # thrust pinned at its ceiling: the airspeed the law assumes is not being held
            thr = np.array([r[8] for r in self.sp_rows], float)
            metrics["thrust_saturated_fraction"] = float(
                np.mean(thr >= self.ad_params.thrust_max - 0.005)
            )
        st = self.ctl.ad_state
        metrics["adapter_learned"] = {
            "trim_pitch_rad": st.trim_hat,
            "turn_gain": st.turn_gain,
            "pitch_rate_bias_rad_s": st.q_bias,
        }
        # what the delay compensation used at the end (guidance/predict.py): the loop delay
        # measured from the autopilot's ATTITUDE_TARGET echoes or TIMESYNC (controller.py, the
        # loop delay), or mavlink.known_delay_s, the
        # ATTITUDE period, the control-step period (shorter with position instants: the
        # multi-rate loop), the prediction horizon and the look-ahead they gave
        ctl = self.ctl
        metrics["delay_compensation"] = {
            "enabled": bool(self.m.delay_compensation),
            "loop_delay_s": ctl.delay_s,
            "loop_delay_source": ctl.delay_source(),  # echo, timesync or mavlink.known_delay_s
            "echoes_in_median": len(ctl.delays),  # the last 9 at most
            "echoes_frozen": ctl.echoes_frozen,  # ATTITUDE_TARGET stamps that had not moved
            "timesync_delays_in_median": len(ctl.ts_delays),
            "timesync_rtt_min_s": min(r for _, r, _ in ctl.timesync) if ctl.timesync else None,
            "attitude_period_s": ctl.att_period_s,
            "attitude_source": ctl.est.att_source,  # chosen once per flight (estimator.py)
            "attitude_samples_ignored": ctl.est.att_ignored,  # of the other source
            "step_period_s": ctl.period_s,
            "position_instants": bool(ctl.position_instants),
            "position_steps": ctl.position_steps,
            "horizon_s": ctl.tau_s,
            "look_ahead_m": ctl.alpha_m,
            "look_ahead_configured_m": ctl.gains.alpha,
        }
        metrics.update(
            streams=res.streams, fallback=res.fallback, fallback_detail=res.fallback_detail,
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
            if limits_rows is not None:
                write_limits(out, limits_rows)
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
