"""Run a configured simulation in-process and produce the run table and metrics."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from mpf_mavlink.config.scenario import build_extensions, build_gains, build_path, build_target
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.frames import euler_to_matrix
from mpf_mavlink.runs.rundir import RunTable, compute_metrics, row_from
from sim.plant.kinematic import ClosedLoop, initial_state, record, region_wind


@dataclass
class SimResult:
    cols: dict[str, np.ndarray]
    metrics: dict[str, Any]
    path_T: np.ndarray


def record_sample(table: RunTable, smp: Any) -> None:
    """Append one recorded closed-loop step (:class:`sim.plant.kinematic.Sample`) to a run table."""
    table.append(
        row_from(smp.diag, smp.p, smp.w_cmd, smp.w, smp.sdot, smp.target_p, smp.target_R, smp.wind)
    )


def kinematic_loop(cfg: Config) -> tuple[ClosedLoop, Any]:
    """The closed loop and its initial state for a config's kinematic plant."""
    k = cfg.kinematic
    path = build_path(cfg.path)
    target = build_target(cfg.target)
    gusts = [
        (np.asarray(g.center_ned_m, float), g.radius_m, np.asarray(g.velocity_ned_m_s, float))
        for g in k.wind.gusts
    ]
    loop = ClosedLoop(
        path,
        target,
        build_gains(cfg),
        build_extensions(cfg),
        cfg.vehicle.airspeed_m_s,
        k.autopilot_bandwidth_rad_s,
        region_wind(k.wind.steady_ned_m_s, gusts),
        cfg.guidance.law,
    )
    R0 = euler_to_matrix(*k.initial_attitude_rpy_rad)
    x0 = initial_state(
        path, target, np.asarray(k.initial_position_ned_m, float), R0, cfg.guidance.initial_s_m
    )
    return loop, x0


def run_kinematic(cfg: Config, progress: bool = True) -> SimResult:
    """Integrate the paper's closed loop for cfg.sim.duration_s and compute the metrics."""
    from tqdm import tqdm

    loop, x = kinematic_loop(cfg)
    dt = cfg.kinematic.dt_s
    n = int(round(cfg.sim.duration_s / dt))
    table = RunTable()
    every = cfg.sim.record_every
    wall0 = time.perf_counter()
    bar = tqdm(
        total=n, desc="sim", unit="step", disable=not progress, delay=2.0, file=sys.stderr,
        mininterval=0.5, leave=False,
    )  # fmt: skip

    def rec(smp: Any) -> None:
        record_sample(table, smp)

    for i in range(n):
        x = loop.step(x, dt)
        if i % every == 0:
            rec(loop.last)  # the first RK4 stage of this step: the state before it
        if i % 500 == 499:
            bar.update(500)
    rec(record(loop, x))
    bar.close()
    wall = time.perf_counter() - wall0
    cols = table.arrays()
    m = compute_metrics(cols, cfg.metrics.steady_after_s, cfg.metrics.converge_threshold_m)
    m.update({"sim_time_s": float(cols["t"][-1]), "wall_time_s": wall, "plant": "kinematic"})
    return SimResult(cols, m, loop.path.positions())
