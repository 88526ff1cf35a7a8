"""What drives a fleet's coordination error: the budget of d(e)/dt from the flight records.

``python -m lab.rigs.fleet_budget DIR [CONFIG]`` (DIR a ``scripts/sil_fleet`` flight: member<k>/
with truth.csv, bridge/timeseries.csv and bridge/fleet.csv). Per member, on the bridge's clock:

- nu_ref: the along-path speed the lap clock assumes (u_ref of airspeed in the estimated wind),
- nu_sp: the same at the airspeed set-point the coordination asked (u_ref + du),
- nu_air: at the airspeed the plant flew (truth), in the estimated wind,
- u: the along-path ground speed relative to the moving path the plant flew (truth velocity
  less the path point's, along f1).

so that u - nu_ref = (nu_sp - nu_ref) [coordination] + (nu_air - nu_sp) [airspeed tracking]
+ (u - nu_air) [the wind the aircraft rides less the estimate, and its crab]. shat advances at
g(s) u with g = dshat/ds = (L/T) / nu_ref; e_i = mean_j (xi_i - xi_j), so each term X
contributes c_X,i = g_i X_i - mean_j g_j X_j to d(e_i)/dt. Each contribution is then passed
through the loop the coordination closes (de/dt = c - k e, k fitted: the coordination term's
own slope against e), which gives the part of e each one is responsible for.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.core.guidance.coordination import along_path_speed


def _csv(p: Path) -> np.ndarray:
    return np.genfromtxt(p, delimiter=",", names=True)


def member_terms(d: Path, path: Any, u_ref: float, turn_rate: float, v_t: float) -> dict[str, Any]:
    """The along-path speed terms of one member directory (arrays on the bridge's rows)."""
    T = _csv(d / "truth.csv")
    B = _csv(d / "bridge" / "timeseries.csv")
    F = _csv(d / "bridge" / "fleet.csv")
    S = _csv(d / "timeseries.csv")
    lim = np.genfromtxt(d / "limits.csv", delimiter=",", skip_header=1)
    # truth t - t0 = top-level t = bridge t - (bridge t0)
    t0_truth = T["t"][0] - lim[0, 0]
    tb0 = B["t"][0] - S["t"][0]
    tb = B["t"]
    tt = T["t"] - t0_truth + tb0  # truth on the bridge's mission clock
    n = len(tb)
    V = np.interp(tb, tt, T["airspeed"])
    vg = np.column_stack([np.interp(tb, tt, T[k]) for k in ("v_n", "v_e", "v_d")])
    wt = np.column_stack([np.interp(tb, tt, T[k]) for k in ("wind_n", "wind_e", "wind_d")])
    we = np.column_stack([B["wind_n"], B["wind_e"], B["wind_d"]])
    vsp = np.interp(tb, F["t_s"], F["airspeed_sp_m_s"])
    du = np.interp(tb, F["t_s"], F["du_m_s"])
    e = np.interp(tb, F["t_s"], F["e_m"])
    shat = np.interp(tb, F["t_s"], F["shat_m"])
    t_unix = np.interp(tb, F["t_s"], F["t_unix_s"])
    nref, nsp, nair, u, uw = (np.full(n, np.nan) for _ in range(5))
    for i in range(n):
        yaw = B["tgt_yaw"][i]
        c, s_ = math.cos(yaw), math.sin(yaw)
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        pt = path.eval(float(B["s"][i]))
        p_T, f1 = np.asarray(pt[0]), R @ np.asarray(pt[1])
        w = np.array([0.0, 0.0, turn_rate])
        vp = np.array([v_t * c, v_t * s_, 0.0]) + R @ np.cross(w, p_T)
        f1t, vpt, wet = tuple(f1), tuple(vp), tuple(we[i])
        nref[i] = along_path_speed(u_ref, f1t, vpt, wet)  # type: ignore[arg-type]
        nsp[i] = along_path_speed(float(vsp[i]), f1t, vpt, wet)  # type: ignore[arg-type]
        nair[i] = along_path_speed(float(V[i]), f1t, vpt, wet)  # type: ignore[arg-type]
        u[i] = float((vg[i] - vp) @ f1)
        uw[i] = float((wt[i] - we[i]) @ f1)
    return {"t_unix": t_unix, "t": tb, "s": B["s"], "sdot": B["sdot"], "shat": shat, "e": e,
            "du": du, "vsp": vsp, "V": V, "nref": nref, "nsp": nsp, "nair": nair, "u": u,
            "wind_err_along": uw}  # fmt: skip


def budget(out: Path, config: Path, n: int = 3, after_s: float = 150.0) -> dict[str, Any]:
    from mpf_mavlink.config.scenario import build_path
    from mpf_mavlink.config.schema import load_config

    cfg = load_config(config)
    path = build_path(cfg.path)
    L = float(path.length)
    u_ref = float(cfg.section("fleet").u_ref_m_s or cfg.vehicle.airspeed_m_s)
    tg = cfg.target
    ms = [member_terms(out / f"member{k}", path, u_ref, tg.turn_rate_rad_s, tg.speed_m_s)
          for k in range(n)]  # fmt: skip
    t0 = max(m["t_unix"][0] for m in ms) + after_s
    t1 = min(m["t_unix"][-1] for m in ms)
    grid = np.arange(t0, t1, 0.1)
    terms = ("coord", "airspeed", "wind", "residual")
    X: dict[str, list[np.ndarray]] = {k: [] for k in terms}
    es, gs = [], []
    lap_T = L / np.nanmean(np.concatenate([m["nref"] for m in ms]))
    for m in ms:
        f = {k: np.interp(grid, m["t_unix"], m[k]) for k in m if k != "t_unix"}
        # g = dshat/ds: the lap clock's (L/T)/nu_ref
        g = (L / lap_T) / f["nref"]
        gs.append(g)
        X["coord"].append(g * (f["nsp"] - f["nref"]))
        X["airspeed"].append(g * (f["nair"] - f["nsp"]))
        X["wind"].append(g * (f["u"] - f["nair"]))
        X["residual"].append(g * (f["sdot"] - f["u"]))
        es.append(f["e"])
    res: dict[str, Any] = {"window_s": float(t1 - t0), "members": []}
    dt = 0.1
    for i in range(n):
        c = {k: X[k][i] - np.mean([X[k][j] for j in range(n) if j != i], axis=0) for k in terms}
        e = es[i]
        de = np.gradient(e, dt)
        # the loop's own slope: coordination contribution against e (least squares)
        k_loop = float(-np.sum(c["coord"] * e) / np.sum(e * e))
        row: dict[str, Any] = {"e_rms_m": float(np.sqrt(np.mean(e**2))),
                               "de_dt_rms_m_s": float(np.sqrt(np.mean(de**2))),
                               "k_loop_1_s": k_loop}  # fmt: skip
        for k in terms:
            row[f"c_{k}_rms_m_s"] = float(np.sqrt(np.mean(c[k] ** 2)))
        # the part of e each disturbance makes through the closed loop de/dt = c - k e
        a = math.exp(-k_loop * dt)
        for k in ("airspeed", "wind", "residual"):
            y = np.zeros_like(e)
            for j in range(1, len(e)):
                y[j] = a * y[j - 1] + (1.0 - a) / k_loop * c[k][j]
            row[f"e_from_{k}_rms_m"] = float(np.sqrt(np.mean((y - y.mean()) ** 2)))
        # how well the sum of contributions explains de/dt
        tot = sum(c[k] for k in terms)
        row["de_dt_vs_sum_corr"] = float(np.corrcoef(de, tot)[0, 1])
        m = ms[i]
        sel = m["t_unix"] >= t0
        row["airspeed_err_rms_m_s"] = float(np.sqrt(np.nanmean((m["V"] - m["vsp"])[sel] ** 2)))
        row["airspeed_range_m_s"] = [float(np.min(m["V"][sel])), float(np.max(m["V"][sel]))]
        row["du_rms_m_s"] = float(np.sqrt(np.mean(m["du"][sel] ** 2)))
        row["wind_err_along_rms_m_s"] = float(np.sqrt(np.nanmean(m["wind_err_along"][sel] ** 2)))
        row["u_minus_nair_rms_m_s"] = float(np.sqrt(np.nanmean((m["u"] - m["nair"])[sel] ** 2)))
        row["nair_minus_nsp_rms_m_s"] = float(
            np.sqrt(np.nanmean((m["nair"] - m["nsp"])[sel] ** 2))
        )
        res["members"].append(row)
    return res


def main(argv: list[str] | None = None) -> int:
    a = sys.argv[1:] if argv is None else argv
    out = Path(a[0])
    config = Path(a[1]) if len(a) > 1 else Path(__file__).resolve().parents[2] / "configs" / "fleet_demo.yaml"
    print(json.dumps(budget(out, config), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
