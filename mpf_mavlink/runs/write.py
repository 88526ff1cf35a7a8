"""Writing a run directory: the tables of :mod:`.rundir` and the figures of :mod:`.plots`
(its own module so that plots can read run directories without rundir importing plots)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.runs.rundir import COLUMNS, _clean

#: the header of ``limits.csv``: what the verdict judged against the limits (t s since engagement;
#: roll, pitch rad; airspeed m/s; altitude m above home; thrust 0..1)
LIMITS_COLUMNS = "t,roll,pitch,airspeed,altitude,thrust"


def limits_row(t: float, estimate: Any, thrust: float) -> tuple[float, ...]:
    """One row of ``limits.csv`` from the bridge's estimate (``R_B_N``, ``vehicle.position``
    NED, ``vehicle.airspeed``) and the thrust sent: t, roll, pitch, airspeed, altitude, thrust."""
    R = estimate.R_B_N
    r20, r21, r22 = R[2].tolist() if type(R) is np.ndarray else (float(x) for x in R[2])
    roll = math.atan2(r21, r22)
    pitch = math.asin(max(-1.0, min(1.0, -r20)))
    v = estimate.vehicle
    f = getattr(v, "floats", None)  # VehicleState.floats: p_d is its 12th
    return (t, roll, pitch, float(v.airspeed), -float(v.position[2] if f is None else f[11]),
            float(thrust))  # fmt: skip


def write_limits(out: Path, rows: NDArray[np.float64]) -> Path:
    """``limits.csv``: the series the verdict judged (the plant's truth in ``sim``, telemetry
    and the thrust sent in ``run``), drawn by ``limits.png``. Written before the figures."""
    out.mkdir(parents=True, exist_ok=True)
    p = out / "limits.csv"
    A = np.asarray(rows, float).reshape(-1, 6)
    np.savetxt(p, A, delimiter=",", header=LIMITS_COLUMNS, comments="", fmt="%.7g")
    return p


def write_run(
    out: Path,
    cols: dict[str, NDArray[np.float64]],
    metrics: dict[str, Any],
    path_T: NDArray[np.float64] | None,
    plots: bool = True,
) -> list[Path]:
    """Write timeseries.csv, path_T.csv, metrics.json and (optionally) the plots."""
    out.mkdir(parents=True, exist_ok=True)
    A = (
        np.column_stack([cols[c] for c in COLUMNS])
        if len(cols["t"])
        else np.zeros((0, len(COLUMNS)))
    )
    np.savetxt(
        out / "timeseries.csv", A, delimiter=",", header=",".join(COLUMNS), comments="", fmt="%.9g"
    )
    if path_T is not None:
        np.savetxt(
            out / "path_T.csv", path_T, delimiter=",", header="x,y,z", comments="", fmt="%.6f"
        )
    (out / "metrics.json").write_text(json.dumps(_clean(metrics), indent=2) + "\n")
    written = [out / "timeseries.csv", out / "metrics.json"]
    if plots:
        # matplotlib and the figures load only when a run is drawn, at its end
        from mpf_mavlink.runs.plots import plot_run

        written += plot_run(out)
    return written
