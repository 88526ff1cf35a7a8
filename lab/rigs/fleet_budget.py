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
contributes c_X,i = g_i X_i - mean_j g_j X_j to d(e_i)/dt. Per member: those contributions'
RMS, the along-path speed error (nu_air - nu_sp, u - nu_air and their sum: what moves the
aircraft against what the coordination asked), how the two correlate, the sum's variance by
period and its share that repeats with the lap (binned on s).

And the lap clock (:func:`clock_artifact`): every bridge computes e through a lap clock in its
own wind estimate; e is recomputed from the members' s through each one's logged estimate (it
must match the logged e) and through one common clock (the members' mean estimate): their
difference is what the bridges' own clocks add to e.
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
        nref[i] = along_path_speed(u_ref, f1t, vpt, wet)
        nsp[i] = along_path_speed(float(vsp[i]), f1t, vpt, wet)
        nair[i] = along_path_speed(float(V[i]), f1t, vpt, wet)
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
    es = []
    lap_T = L / np.nanmean(np.concatenate([m["nref"] for m in ms]))
    for m in ms:
        f = {k: np.interp(grid, m["t_unix"], m[k]) for k in m if k != "t_unix"}
        # g = dshat/ds: the lap clock's (L/T)/nu_ref
        g = (L / lap_T) / f["nref"]
        X["coord"].append(g * (f["nsp"] - f["nref"]))
        X["airspeed"].append(g * (f["nair"] - f["nsp"]))
        X["wind"].append(g * (f["u"] - f["nair"]))
        X["residual"].append(g * (f["sdot"] - f["u"]))
        es.append(f["e"])
    res: dict[str, Any] = {"window_s": float(t1 - t0), "members": []}
    bands = ((0.0, 1 / 100), (1 / 100, 1 / 40), (1 / 40, 1 / 15), (1 / 15, 1 / 5), (1 / 5, 5.0))
    for i in range(n):
        c = {k: X[k][i] - np.mean([X[k][j] for j in range(n) if j != i], axis=0) for k in terms}
        e = es[i]
        row: dict[str, Any] = {"e_rms_m": float(np.sqrt(np.mean(e**2)))}
        for k in terms:
            row[f"c_{k}_rms_m_s"] = float(np.sqrt(np.mean(c[k] ** 2)))
        m = ms[i]
        sel = m["t_unix"] >= t0
        air = (m["nair"] - m["nsp"])[sel]
        wind = (m["u"] - m["nair"])[sel]
        tot = air + wind
        row["airspeed_err_rms_m_s"] = float(np.sqrt(np.nanmean((m["V"] - m["vsp"])[sel] ** 2)))
        row["airspeed_err_mean_m_s"] = float(np.nanmean((m["V"] - m["vsp"])[sel]))
        row["airspeed_range_m_s"] = [float(np.min(m["V"][sel])), float(np.max(m["V"][sel]))]
        row["du_rms_m_s"] = float(np.sqrt(np.mean(m["du"][sel] ** 2)))
        row["along_from_airspeed_rms_m_s"] = float(np.nanstd(air))
        row["along_from_wind_rms_m_s"] = float(np.nanstd(wind))
        row["along_total_rms_m_s"] = float(np.nanstd(tot))
        row["corr_airspeed_wind"] = float(np.corrcoef(air, wind)[0, 1])
        x = tot - np.nanmean(tot)
        P = np.abs(np.fft.rfft(np.nan_to_num(x))) ** 2
        fr = np.fft.rfftfreq(len(x), 0.02)
        row["total_variance_by_period"] = {
            f"{1 / hi if hi < 5 else 0.2:g}-{1 / lo if lo > 0 else math.inf:g} s":
            float(P[(fr >= lo) & (fr < hi)].sum() / P.sum()) for lo, hi in bands
        }  # fmt: skip
        ph = np.floor((m["s"][sel] % L) / L * 24).astype(int)
        prof = np.array([np.nanmean(tot[ph == b]) if np.any(ph == b) else 0.0 for b in range(24)])
        row["total_lap_periodic_share"] = float(np.nanvar(prof[ph]) / np.nanvar(tot))
        res["members"].append(row)
    res["clock"] = clock_artifact(out, path, u_ref, tg.turn_rate_rad_s, tg.speed_m_s, n, after_s)
    return res


def clock_artifact(
    out: Path, path: Any, u_ref: float, turn_rate: float, v_t: float, n: int, after_s: float
) -> dict[str, Any]:
    """Each bridge's e against the same error in one common lap clock: e recomputed from the
    members' s (fleet.csv) through a lap clock in each bridge's own logged wind estimate (a
    check of the recomputation: it must match the logged e) and through one clock in the
    members' mean estimate over the window (the error the fleet would agree on)."""
    from mpf_mavlink.core.guidance import coordination as co

    L = float(path.length)
    F = [_csv(out / f"member{k}" / "bridge" / "fleet.csv") for k in range(n)]
    B = [_csv(out / f"member{k}" / "bridge" / "timeseries.csv") for k in range(n)]
    t0 = max(f["t_unix_s"][0] for f in F) + after_s
    t1 = min(f["t_unix_s"][-1] for f in F)
    g = np.arange(t0, t1, 0.5)

    def on(k: int, name: str) -> np.ndarray:
        tb = np.interp(B[k]["t"], F[k]["t_s"], F[k]["t_unix_s"])
        return np.asarray(np.interp(g, tb, B[k][name]), float)

    W = [np.column_stack([on(k, "wind_n"), on(k, "wind_e"), on(k, "wind_d")]) for k in range(n)]
    Y = [on(k, "tgt_yaw") for k in range(n)]
    S = [np.interp(g, f["t_unix_s"], f["s_m"]) for f in F]
    E = [np.interp(g, f["t_unix_s"], f["e_m"]) for f in F]
    wm = np.mean([w.mean(axis=0) for w in W], axis=0)
    lap = co.LapClock(path, 256)

    def e_in(wind: Any) -> np.ndarray:
        res = np.zeros((n, len(g)))
        for i in range(len(g)):
            for k in range(n):
                c, s_ = math.cos(Y[k][i]), math.sin(Y[k][i])
                R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
                lap.update(R, (v_t * c, v_t * s_, 0.0), (0.0, 0.0, turn_rate), wind(k, i), u_ref)
                xi = [lap.shat(S[j][i]) - j / n * L for j in range(n)]
                res[k, i] = np.mean([co.wrap_m(xi[k] - xi[j], L) for j in range(n) if j != k])
        return res

    own = e_in(lambda k, i: tuple(W[k][i]))
    com = e_in(lambda k, i: tuple(wm))

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x**2)))

    return {
        "wind_estimate_mean_m_s": [w.mean(axis=0).round(2).tolist() for w in W],
        "wind_estimate_std_m_s": [w.std(axis=0).round(2).tolist() for w in W],
        "e_logged_rms_m": [rms(E[k]) for k in range(n)],
        "recomputed_vs_logged_rms_m": [rms(own[k] - E[k]) for k in range(n)],
        "e_common_clock_rms_m": [rms(com[k]) for k in range(n)],
        "logged_vs_common_clock_rms_m": [rms(E[k] - com[k]) for k in range(n)],
    }


def main(argv: list[str] | None = None) -> int:
    a = sys.argv[1:] if argv is None else argv
    out = Path(a[0])
    root = Path(__file__).resolve().parents[2]
    config = Path(a[1]) if len(a) > 1 else root / "configs" / "fleet_demo.yaml"
    print(json.dumps(budget(out, config), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
