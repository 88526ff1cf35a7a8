"""Truth metrics of a SIL run (see :mod:`sim.sil`): the bridge's mission clock matched to the
vehicle's boot clock by the positions the bridge logged, then the run table of the MPF error
``pt = p - p_f(s)`` from the plant's TRUE position and the TRUE target at the ``s`` the bridge
flew."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mpf_mavlink.bridge.estimator import wind_frame
from mpf_mavlink.config.scenario import build_extensions, build_gains, build_path, build_target
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.guidance.baselines import guidance_law
from mpf_mavlink.core.guidance.law import VehicleState
from mpf_mavlink.runs.compare import distance_to_polyline
from mpf_mavlink.runs.rundir import RunTable, row_from


def _align(truth: dict[str, np.ndarray], bc: dict[str, np.ndarray]) -> tuple[float, float]:
    """Offset ``t0`` (s) with vehicle boot time = bridge mission time + t0, and the RMS position
    mismatch (m) at that offset. The bridge logs the vehicle's LOCAL_POSITION_NED of the
    ATTITUDE instant it acted on, so the right offset matches to float32 rounding."""
    tb, P = truth["time_boot_s"], truth["position_ned"]
    bt = bc["t"]
    bp = np.column_stack([bc["p_n"], bc["p_e"], bc["p_d"]])
    n = min(len(bt), 300)
    d0 = np.linalg.norm(P - bp[0], axis=1)
    best = (math.inf, 0.0)
    for k in np.argsort(d0)[:5]:
        t0 = round(float(tb[k] - bt[0]), 3)  # the boot clock is in ms
        ts = bt[:n] + t0
        Pi = np.column_stack([np.interp(ts, tb, P[:, i]) for i in range(3)])
        rms = float(np.sqrt(np.mean(np.sum((Pi - bp[:n]) ** 2, axis=1))))
        best = min(best, (rms, t0))
    return best[1], best[0]


def truth_table(
    cfg: Config, truth: dict[str, np.ndarray], bc: dict[str, np.ndarray]
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The run table from the plant's truth (see module docstring); ``t`` = s since engagement."""
    path, target = build_path(cfg.path), build_target(cfg.target)
    gains, ext = build_gains(cfg), build_extensions(cfg)
    t0, resid = _align(truth, bc)
    bt, bs = bc["t"], bc["s"]
    tb = truth["time_boot_s"]
    tm = tb - t0  # bridge mission time of each truth frame
    sel = np.nonzero((tm >= bt[0] - 1e-6) & (tm <= bt[-1] + 1e-6))[0]
    s_at = np.interp(tm[sel], bt, bs)
    P, V, W = truth["position_ned"], truth["velocity_ned"], truth["wind_ned"]
    tv = truth["t"]
    tt = truth.get("target_t", tv)  # the target's clock (see SimVehicle target_epoch)
    table = RunTable()
    w1_prev: np.ndarray | None = None
    t_prev = 0.0
    t_engage = float(bt[0])
    rel_all = np.empty((len(sel), 3))
    for j, k in enumerate(sel):
        va = V[k] - W[k]
        R_W = wind_frame(float(va[0]), float(va[1]), float(va[2]))
        t = float(tm[k]) - t_engage
        veh = VehicleState(t, P[k], R_W, float(np.linalg.norm(va)), W[k])
        tgt = target.state(float(tt[k]))
        cmd, diag = guidance_law(cfg.guidance.law, float(s_at[j]), veh, tgt, path, gains, ext)
        w1 = R_W[:, 0]
        w_act = (0.0, 0.0)
        if w1_prev is not None and t > t_prev:
            w1d = (w1 - w1_prev) / (t - t_prev)
            w_act = (-float(w1d @ R_W[:, 2]), float(w1d @ R_W[:, 1]))
        w1_prev, t_prev = w1, t
        table.append(
            row_from(diag, P[k], (cmd.w2, cmd.w3), w_act, cmd.sdot, tgt.position, tgt.R_T_I, W[k])
        )
        rel_all[j] = tgt.R_T_I.T @ (P[k] - tgt.position)
    cols = table.arrays()
    cross = distance_to_polyline(path.positions(), rel_all, bool(getattr(path, "closed", False)))
    info = {
        "alignment_t0_s": t0,
        "alignment_residual_m": resid,
        "cross_track_m": cross,
        "t_vehicle": tv[sel],
        "rows": sel,
    }
    return cols, info
