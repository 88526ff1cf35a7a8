"""Figures of a rig flight from the bridge's run directory (and its tlog when it was killed).

Cross-track is the horizontal distance from the aircraft to the nearest point of the path (in
the target's frame, where the path is fixed), signed + to the left of the path's direction of
travel: valid for any shape (on a clockwise circle, + is outward). ``|pt|`` (the bridge's
steady RMS) is the distance to the virtual point and includes the along-track lag.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.mavlink.tlog_read import iter_tlog


def read_json(p: Path) -> dict[str, Any]:
    try:
        out = json.loads(p.read_text())
    except (OSError, ValueError):
        return {}
    return out if isinstance(out, dict) else {}


def cross_track(run: Path, steady_after_s: float) -> dict[str, Any]:
    """Steady RMS / max / mean of the signed horizontal cross-track (m); {} without a record."""
    ts, pt = run / "timeseries.csv", run / "path_T.csv"
    if not (ts.is_file() and pt.is_file()):
        return {}
    d = np.genfromtxt(ts, delimiter=",", names=True)
    P = np.genfromtxt(pt, delimiter=",", skip_header=1).reshape(-1, 3)
    if d.size < 2 or len(P) < 2:
        return {}
    m = d["t"] >= steady_after_s
    if not m.any():
        return {}
    out = signed_cross_track(np.column_stack([d["rel_x"][m], d["rel_y"][m]]), P)
    return {
        "cross_track_rms_m": float(np.sqrt(np.mean(out**2))),
        "cross_track_max_m": float(np.max(np.abs(out))),
        "cross_track_mean_m": float(np.mean(out)),
    }


def signed_cross_track(q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The signed horizontal distance (m, + left of travel) of each point q (n, 2; target
    frame) from the path through the nodes P (m, 3)."""
    a, b = P[:-1, :2], P[1:, :2]
    closed = np.hypot(*(P[0, :2] - P[-1, :2])) < 1e-6 * max(1.0, float(np.ptp(P[:, :2])))
    if not closed and _is_loop(P):
        a, b = np.vstack([a, P[-1:, :2]]), np.vstack([b, P[:1, :2]])
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-12)
    out = np.empty(len(q))
    for i0 in range(0, len(q), 2000):  # chunks keep the (samples x segments) arrays small
        qq = q[i0 : i0 + 2000, None, :]
        u = np.clip(np.sum((qq - a) * ab, axis=2) / L2, 0.0, 1.0)
        foot = a + u[..., None] * ab
        dv = qq - foot
        dist = np.hypot(dv[..., 0], dv[..., 1])
        k = np.argmin(dist, axis=1)
        r = np.arange(len(k))
        t = ab[k]
        cross = t[:, 0] * dv[r, k, 1] - t[:, 1] * dv[r, k, 0]  # NED: < 0 is left of travel
        out[i0 : i0 + len(k)] = np.where(cross > 0, -1.0, 1.0) * dist[r, k]
    return out


def moving_path_figures(
    t: np.ndarray,
    rel: np.ndarray,
    nodes: np.ndarray,
    closed: bool,
    steady_after_s: float,
    threshold_m: float,
    circle: bool,
) -> dict[str, Any]:
    """The head-to-head's figures of one flight, the same for MPF and the firmware's own
    guidance: e = the 3D distance (m) of the aircraft from the moving path, i.e. of its position
    in the target's frame ``rel`` (n, 3; NED axes of {T}) from the path's nodes (m, 3) by
    :func:`mpf_mavlink.runs.compare.distance_to_polyline`, sampled at times ``t`` (s).

    e_rms_m / e_max_m over t >= steady_after_s; e_first_within_s / e_stays_within_s against
    ``threshold_m``; e_mean_vertical_m: mean height (m, up +) of the aircraft above the path's
    nearest node; e_mean_radial_m (a circle): mean distance (m, out +) from the nodes' centroid
    less the circle's radius; cross_track_*: the signed horizontal distance (left +)."""
    from scipy.spatial import cKDTree

    from mpf_mavlink.runs.compare import distance_to_polyline
    from mpf_mavlink.runs.rundir import convergence_time_s

    t, rel, nodes = np.asarray(t, float), np.asarray(rel, float), np.asarray(nodes, float)
    out: dict[str, Any] = {"e_samples": int(len(t))}
    if len(t) < 2 or len(nodes) < 2:
        return out
    e = distance_to_polyline(nodes, rel, closed)
    inside = np.nonzero(e < threshold_m)[0]
    out["e_first_within_s"] = float(t[inside[0]]) if len(inside) else None
    out["e_stays_within_s"] = convergence_time_s(t, e, threshold_m)
    m = t >= steady_after_s
    if not m.any():
        return out
    _, k = cKDTree(nodes).query(rel[m])
    xt = signed_cross_track(rel[m, :2], nodes)
    out.update(
        e_steady_samples=int(np.count_nonzero(m)),
        e_rms_m=float(np.sqrt(np.mean(e[m] ** 2))),
        e_max_m=float(np.max(e[m])),
        e_mean_vertical_m=float(np.mean(nodes[k, 2] - rel[m, 2])),
        cross_track_rms_m=float(np.sqrt(np.mean(xt**2))),
        cross_track_max_m=float(np.max(np.abs(xt))),
        cross_track_mean_m=float(np.mean(xt)),
    )
    if circle:
        c = nodes[:, :2].mean(axis=0)
        r = float(np.mean(np.hypot(*(nodes[:, :2] - c).T)))
        out["e_mean_radial_m"] = float(np.mean(np.hypot(*(rel[m, :2] - c).T) - r))
    return out


def run_record_figures(run: Path, cfg: Any) -> dict[str, Any]:
    """:func:`moving_path_figures` of a bridge's run directory (timeseries.csv: t and the
    aircraft in the target's frame rel_x..z; path_T.csv: the path's nodes); {} without one."""
    ts, pt = run / "timeseries.csv", run / "path_T.csv"
    if not (ts.is_file() and pt.is_file()):
        return {}
    d = np.genfromtxt(ts, delimiter=",", names=True)
    if d.size < 2:
        return {}
    P = np.genfromtxt(pt, delimiter=",", skip_header=1).reshape(-1, 3)
    rel = np.column_stack([d["rel_x"], d["rel_y"], d["rel_z"]])
    from mpf_mavlink.config.scenario import build_path

    closed = bool(build_path(cfg.path).closed)
    return moving_path_figures(
        d["t"], rel, P, closed, cfg.metrics.steady_after_s, cfg.metrics.converge_threshold_m,
        circle=cfg.path.type == "circle",
    )  # fmt: skip


def _is_loop(P: np.ndarray) -> bool:
    """A path whose last node is one node spacing from its first (a sampled closed curve)."""
    step = np.median(np.hypot(*np.diff(P[:, :2], axis=0).T))
    return bool(np.hypot(*(P[0, :2] - P[-1, :2])) <= 2.0 * step)


def tlog_counts(tlog: Path, component: int = 191) -> dict[str, Any]:
    """What a killed bridge sent and received, from its tlog (it writes as it goes)."""
    if not tlog.is_file():
        return {}
    sent: dict[str, int] = {}
    first = last = None
    for t, m in iter_tlog(tlog):
        if m.get_srcComponent() == component:  # the bridge's own packets
            typ = m.get_type()
            sent[typ] = sent.get(typ, 0) + 1
            if typ == "SET_ATTITUDE_TARGET":
                first = t if first is None else first
                last = t
    span = (last - first) if (first is not None and last is not None) else None
    return {"sent": sent, "setpoint_span_s": span}


def tlog_stream_hz(tlog: Path, msg: str = "ATTITUDE", component: int = 191) -> float | None:
    """The rate (Hz, log time) at which the bridge received ``msg`` while it tracked: the
    autopilot's messages of that type logged between the bridge's first and last
    SET_ATTITUDE_TARGET, over that span; None without a tlog or a tracking span."""
    if not tlog.is_file():
        return None
    first = last = None
    times: list[float] = []
    for t, m in iter_tlog(tlog, types=(msg, "SET_ATTITUDE_TARGET")):
        typ = m.get_type()
        if typ == "SET_ATTITUDE_TARGET" and m.get_srcComponent() == component:
            first = t if first is None else first
            last = t
        elif typ == msg and m.get_srcComponent() != component:
            times.append(t)
    if first is None or last is None or last - first <= 1.0:
        return None
    n = sum(1 for t in times if first <= t <= last)
    return n / (last - first)


# |bank| (deg) a hold is judged with when the autopilot's own roll limit is not known
HOLD_BANK_DEG = 35.0


def hold_figures(
    trace: list[tuple[float, float, float, float, float]],
    centre: tuple[float, float],
    alt_m: float,
    radius_m: float,
    bank_limit_deg: float = HOLD_BANK_DEG,
) -> dict[str, Any]:
    """After a SIGKILL: rows (t, roll rad, north, east, down) over the watch window -> the
    largest distance from the path's centre, |bank| and altitude error, and the hold verdict
    (within 2x the path radius, |bank| within ``bank_limit_deg``, the autopilot's own roll limit
    where it was read, altitude within 10 m)."""
    if not trace:
        return {"hold_verdict": "FAIL: nothing seen after the kill"}
    A = np.array(trace, float)
    dist = np.hypot(A[:, 2] - centre[0], A[:, 3] - centre[1])
    bank = np.degrees(np.abs(A[:, 1]))
    dalt = np.abs(-A[:, 4] - alt_m)
    fails = []
    if dist.max() > 2.0 * radius_m:
        fails.append(f"{dist.max():.0f} m from the centre (> 2 x {radius_m:g} m)")
    if bank.max() > bank_limit_deg:
        fails.append(f"|bank| {bank.max():.1f} deg (> {bank_limit_deg:g}, the hold's limit)")
    if dalt.max() > 10.0:
        fails.append(f"altitude off by {dalt.max():.1f} m (> 10)")
    tail = A[:, 0] >= A[-1, 0] - 15.0
    return {
        "watched_s": float(A[-1, 0] - A[0, 0]),
        "max_dist_from_centre_m": float(dist.max()),
        "last15_mean_dist_m": float(np.mean(dist[tail])),
        "max_bank_deg": float(bank.max()),
        "bank_limit_deg": bank_limit_deg,
        "max_alt_error_m": float(dalt.max()),
        "hold_verdict": "PASS" if not fails else "FAIL: " + "; ".join(fails),
    }


def fmt(v: Any, f: str = ".3g") -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float) and not math.isfinite(v):
        return "n/a"
    return f"{v:{f}}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)
