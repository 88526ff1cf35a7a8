"""Truth metrics of a SIL run (see :mod:`sim.sil`): the bridge's mission clock matched to the
vehicle's boot clock by the positions the bridge logged, then the run table of the MPF error
``pt = p - p_f(s)`` from the plant's TRUE position and the TRUE target at the ``s`` the bridge
flew."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mpf_mavlink.bridge.estimator import wind_frame_rows
from mpf_mavlink.config.scenario import build_extensions, build_gains, build_path, build_target
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.guidance.dispatch import guidance_law
from mpf_mavlink.core.guidance.law import vehicle_state_of_floats
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import state_floats
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
    cfg: Config,
    truth: dict[str, np.ndarray],
    bc: dict[str, np.ndarray],
    path: TabulatedPath | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The run table from the plant's truth (see module docstring); ``t`` = s since engagement
    (``path``: the config's, already built)."""
    path = build_path(cfg.path) if path is None else path
    target = build_target(cfg.target)
    gains, ext = build_gains(cfg), build_extensions(cfg)
    t0, resid = _align(truth, bc)
    bt, bs = bc["t"], bc["s"]
    tb = truth["time_boot_s"]
    tm = tb - t0  # bridge mission time of each truth frame
    sel = np.nonzero((tm >= bt[0] - 1e-6) & (tm <= bt[-1] + 1e-6))[0]
    s_at = np.interp(tm[sel], bt, bs)
    # Python floats row by row (the law's own scalar path): numpy's per-call cost on 3-vectors
    # would be most of the work over a 30,000-row flight
    P, V, W = (truth[k].tolist() for k in ("position_ned", "velocity_ned", "wind_ned"))
    tt = truth.get("target_t", truth["t"]).tolist()  # the target's clock (SimVehicle target_epoch)
    tml, s_atl = tm.tolist(), s_at.tolist()
    law = cfg.guidance.law
    table = RunTable()
    w1_prev: tuple[float, float, float] | None = None
    t_prev = 0.0
    t_engage = float(bt[0])
    for j, k in enumerate(sel.tolist()):
        p, w = tuple(P[k]), tuple(W[k])
        v = V[k]
        va0, va1, va2 = v[0] - w[0], v[1] - w[1], v[2] - w[2]
        (a, e, b), (c, f, g), (h, i, q) = wind_frame_rows(va0, va1, va2)
        t = tml[k] - t_engage
        veh = vehicle_state_of_floats(
            t, (a, e, b, c, f, g, h, i, q, *p, *w), math.sqrt(va0 * va0 + va1 * va1 + va2 * va2)
        )
        tgt = target.state(tt[k])
        cmd, diag = guidance_law(law, s_atl[j], veh, tgt, path, gains, ext)
        w1 = (a, c, h)  # the columns of R_W^I: w1, w2 = (e, f, i), w3 = (b, g, q)
        w_act = (0.0, 0.0)
        if w1_prev is not None and t > t_prev:
            dt = t - t_prev
            d0, d1, d2 = ((w1[0] - w1_prev[0]) / dt, (w1[1] - w1_prev[1]) / dt,
                          (w1[2] - w1_prev[2]) / dt)  # fmt: skip
            w_act = (-(d0 * b + d1 * g + d2 * q), d0 * e + d1 * f + d2 * i)
        w1_prev, t_prev = w1, t
        tf = state_floats(tgt)
        tR = (tf[0:3], tf[3:6], tf[6:9])
        table.append(row_from(diag, p, (cmd.w2, cmd.w3), w_act, cmd.sdot, tf[9:12], tR, w))
    cols = table.arrays()
    if "saturated" in bc and len(bt):
        # what flew: the bridge's step in force at each frame clipped a command (its envelope
        # monitor's word), not the law re-evaluated on the truth
        idx = np.clip(np.searchsorted(bt, tm[sel], side="right") - 1, 0, len(bt) - 1)
        cols["saturated"] = np.asarray(bc["saturated"], float)[idx]
    rel_all = np.column_stack([cols["rel_x"], cols["rel_y"], cols["rel_z"]])
    cross = distance_to_polyline(path.positions(), rel_all, bool(getattr(path, "closed", False)))
    info = {
        "alignment_t0_s": t0,
        "alignment_residual_m": resid,
        "cross_track_m": cross,
        "t_vehicle": truth["t"][sel],
        "rows": sel,
    }
    return cols, info
