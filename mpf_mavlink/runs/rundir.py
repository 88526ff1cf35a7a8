"""Run directories: the time series (CSV), metrics.json and the plots, for sim, run and replay.

Layout of a run directory:
  timeseries.csv  one row per recorded step (columns below, SI units, NED, radians)
  path_T.csv      the path's node positions in the target frame (m), for the plots
  metrics.json    tracking figures (see :func:`compute_metrics`) plus run facts
  *.png           the paper's figures (see :mod:`mpf_mavlink.runs.plots`)
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.errors import MpfError

COLUMNS = [
    "t", "s", "sdot",
    "p_n", "p_e", "p_d", "pf_n", "pf_e", "pf_d", "tgt_n", "tgt_e", "tgt_d",
    "rel_x", "rel_y", "rel_z",
    "pt_n", "pt_e", "pt_d", "pt_norm", "psi", "e2", "e3", "y_w", "z_w",
    "w2_cmd", "w3_cmd", "w2", "w3", "margin", "saturated", "psi_turn",
    "wind_n", "wind_e", "wind_d",
    "tgt_roll", "tgt_pitch", "tgt_yaw",
]  # fmt: skip
# Units: t (s), s (m), sdot (m/s); positions, errors (m, NED); psi, e (-); rates (rad/s);
# margin (m/s, Assumption 1); saturated, psi_turn (0/1); wind (m/s, NED); tgt_roll/pitch/yaw:
# ZYX Euler angles of R_T^I (rad), so that the path can be drawn where the target carried it.


@dataclass
class RunTable:
    """Columns of a run, appended row by row (floats only)."""

    rows: list[tuple[float, ...]] = field(default_factory=list)
    extra: dict[str, list[float]] = field(default_factory=dict)

    def append(self, row: list[float] | tuple[float, ...]) -> None:
        # Stored as tuples: a tuple of floats drops out of the cyclic garbage collector, a list
        # never does, and a long flight's rows would make every full collection (tens of ms,
        # inside a control loop) longer and longer.
        self.rows.append(tuple(row))

    def arrays(self) -> dict[str, NDArray[np.float64]]:
        A = np.array(self.rows, dtype=float).reshape(-1, len(COLUMNS))
        return {c: A[:, i] for i, c in enumerate(COLUMNS)}


def _floats(x: Any) -> Any:
    """x (an array, nested or not) as Python floats in lists; a tuple (of floats, or of tuples
    of floats) as it is."""
    if type(x) is tuple:
        return x
    return (
        x.tolist()
        if type(x) is np.ndarray and x.dtype == np.float64
        else np.asarray(x, float).tolist()
    )


def row_from(
    diag: Any,
    p: Any,
    w_cmd: tuple[float, float],
    w_act: tuple[float, float],
    sdot: float,
    target_p: Any,
    target_R: Any,
    wind: Any,
) -> list[float]:
    """One CSV row from the law's diagnostics and the vehicle/target state (NED)."""
    # scalar arithmetic: called at every control step, where numpy's per-call cost dominates
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = _floats(target_R)
    p0, p1, p2 = _floats(p)
    q0, q1, q2 = _floats(target_p)
    e0, e1, e2 = _floats(wind)
    d0, d1, d2 = p0 - q0, p1 - q1, p2 - q2
    rel = (r00 * d0 + r10 * d1 + r20 * d2, r01 * d0 + r11 * d1 + r21 * d2,
           r02 * d0 + r12 * d1 + r22 * d2)  # fmt: skip
    t_roll = math.atan2(r21, r22)
    t_pitch = -math.asin(max(-1.0, min(1.0, r20)))
    t_yaw = math.atan2(r10, r00)
    return [
        diag.t, diag.s, sdot,
        p0, p1, p2, *diag.p_f,
        q0, q1, q2,
        rel[0], rel[1], rel[2],
        *diag.pt, diag.pt_norm, diag.psi, diag.e[0], diag.e[1], diag.y_w, diag.z_w,
        w_cmd[0], w_cmd[1], float(w_act[0]), float(w_act[1]), diag.path_speed_margin,
        1.0 if "sat" in diag.mode else 0.0, 1.0 if "psi_turn" in diag.mode else 0.0,
        e0, e1, e2,
        t_roll, t_pitch, t_yaw,
    ]  # fmt: skip


def convergence_time_s(
    t: NDArray[np.float64], err: NDArray[np.float64], threshold: float
) -> float | None:
    """The time (s) from which ``err`` stays below ``threshold`` to the end of the run.

    ``t[0]`` if it never reaches the threshold; None if it is still at or above it at the last
    sample (the run never converged). ``t`` must not be empty.
    """
    above = np.nonzero(err >= threshold)[0]
    if len(above) == 0:
        return float(t[0])
    if above[-1] == len(t) - 1:
        return None
    return float(t[above[-1] + 1])


def compute_metrics(
    cols: dict[str, NDArray[np.float64]], steady_after_s: float, threshold_m: float = 1.0
) -> dict[str, Any]:
    """Tracking figures.

    first_within_s: first time |pt| is below threshold; convergence_time_s ("stays within"):
    first time after which |pt| stays below threshold (None if it never does; one late
    excursion moves it, first_within_s says when the capture was done);
    steady_*: over t >= steady_after_s (None when the run is shorter); steady_mean_vertical_m:
    mean height of the vehicle above the desired point (-pt_d, m); steady_mean_radial_m: mean
    horizontal distance from the path's centre (the centroid of the desired points in the
    target frame) of the vehicle minus that of the desired point (m, > 0: a wider circle);
    max_rate_cmd_rad_s: peak |[w2, w3]_cmd| over the whole run.
    """
    t = cols["t"]
    e = cols["pt_norm"]
    if len(t) == 0:
        return {"convergence_time_s": None, "steady_rms_m": None, "steady_max_m": None,
                "steady_psi_max": None, "max_rate_cmd_rad_s": None}  # fmt: skip
    conv = convergence_time_s(t, e, threshold_m)
    inside = np.nonzero(e < threshold_m)[0]
    first = float(t[inside[0]]) if len(inside) else None
    m = t >= steady_after_s
    rate = np.hypot(cols["w2_cmd"], cols["w3_cmd"])
    vert = rad = None
    if m.any():
        vert = float(np.mean(-cols["pt_d"][m]))
        # horizontal, in the target's heading frame: the vehicle (rel) and the desired point
        yaw = cols["tgt_yaw"]
        c, sn = np.cos(yaw), np.sin(yaw)
        pn, pe = cols["pt_n"], cols["pt_e"]
        ptx, pty = c * pn + sn * pe, -sn * pn + c * pe
        vx, vy = cols["rel_x"], cols["rel_y"]
        dx, dy = vx - ptx, vy - pty
        cx, cy = float(np.mean(dx)), float(np.mean(dy))
        rad = float(np.mean((np.hypot(vx - cx, vy - cy) - np.hypot(dx - cx, dy - cy))[m]))
    out: dict[str, Any] = {
        "first_within_s": first,
        "convergence_time_s": conv,
        "steady_mean_vertical_m": vert,
        "steady_mean_radial_m": rad,
        "steady_rms_m": float(np.sqrt(np.mean(e[m] ** 2))) if m.any() else None,
        "steady_max_m": float(np.max(e[m])) if m.any() else None,
        "steady_psi_max": float(np.max(cols["psi"][m])) if m.any() else None,
        "max_rate_cmd_rad_s": float(np.max(rate)),
        "initial_pt_m": float(e[0]),
        "saturated_fraction": float(np.mean(cols["saturated"])),
    }
    return out


#: directories prepare_out_dir created in this process (outermost first): a command that fails
#: removes those still empty (:func:`remove_empty_created`), so a failed run leaves nothing
_CREATED: list[Path] = []


def remove_empty_created() -> list[Path]:
    """Remove the directories :func:`prepare_out_dir` created that are still empty (innermost
    first); returns those removed. Called by the CLI when a command fails."""
    gone = []
    for d in reversed(_CREATED):
        try:
            # a run that failed before it flew (no vehicle, wrong flavour) wrote only the tlog
            # of its own few heartbeats: no record of a flight
            items = list(d.iterdir())
            if [p.name for p in items] == ["mavlink.tlog"] and items[0].stat().st_size < 65536:
                items[0].unlink()
        except OSError:
            pass
        try:
            d.rmdir()  # only an empty directory
            gone.append(d)
        except OSError:
            pass
    _CREATED.clear()
    return gone


def prepare_out_dir(out: str | Path) -> Path:
    """Create the run directory and prove it is writable now, before anything flies."""
    d = Path(out)
    new = [a for a in (d, *d.parents) if not a.exists()]
    _CREATED.extend(reversed(new))
    try:
        d.mkdir(parents=True, exist_ok=True)
        # a name of its own: another process probing the same directory must not unlink ours
        fd, probe = tempfile.mkstemp(prefix=".write-test-", dir=d)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(b"0" * 4096)
                f.flush()
                os.fsync(f.fileno())
        finally:
            os.unlink(probe)
    except OSError as e:
        raise MpfError(f"{d}: output directory is not writable ({e.strerror})") from None
    return d


def _clean(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    if isinstance(v, np.floating | np.integer | np.bool_):
        return _clean(v.item())
    return v


def read_run(
    d: str | Path,
) -> tuple[dict[str, NDArray[np.float64]], NDArray[np.float64] | None, dict[str, Any]]:
    """Read a run directory back (for ``mpf-mavlink plot``)."""
    d = Path(d)
    f = d / "timeseries.csv"
    if not f.is_file():
        raise MpfError(f"{d}: not a run directory (no timeseries.csv)")
    try:
        A = np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
        header = f.open().readline().strip().split(",")
    except (OSError, ValueError) as e:
        raise MpfError(f"{f}: unreadable time series ({e})") from None
    cols = {c: (A[:, i] if A.size else np.zeros(0)) for i, c in enumerate(header)}
    path_T = None
    if (d / "path_T.csv").is_file():
        path_T = np.loadtxt(d / "path_T.csv", delimiter=",", skiprows=1, ndmin=2)
    metrics = json.loads((d / "metrics.json").read_text()) if (d / "metrics.json").is_file() else {}
    return cols, path_T, metrics
