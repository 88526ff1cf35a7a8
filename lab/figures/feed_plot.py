"""Truth, raw reports and the estimate of a target feed: ``python -m lab.figures.feed_plot``.

The demo's boat (configs/default.yaml) reports itself through the SIL's feed
(:mod:`sim.target.feed`: 1 Hz, 2 m and 0.3 m/s noise, 0.3 s latency, 10 % drop-outs, its clock
100 s off ours, seed 7 unless told otherwise); the frames go through the bridge's decoders into
its live target (the estimator, ``mode: filter``, told the feed's latency as the acceptance
(``scripts/bench --only target_feed``) tells it; ``--set`` overrides it) and, for comparison, the
extrapolation of the last report (``mode: last_sample``), both queried every 20 ms as the
control loop does. Writes a PNG with the north-east track over a window, and the position and
{T}-yaw errors over time
(a yaw error of d rad moves a path point r metres from the target by r d: the demo's
lemniscate reaches 150 m), and prints the RMS figures after ``--steady`` seconds.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: E402

from mpf_mavlink.bridge.estimator import Estimator, EstimatorParams  # noqa: E402
from mpf_mavlink.bridge.target_sources import ExtrapolatedTarget, LiveTarget  # noqa: E402
from mpf_mavlink.config.scenario import build_target  # noqa: E402
from mpf_mavlink.config.schema import load_config  # noqa: E402
from mpf_mavlink.mavlink.codec import decode  # noqa: E402
from sim.plant.jsbsim_plant import LocalNED  # noqa: E402
from sim.plant.kinematic_plant import ned_to_geodetic_fast  # noqa: E402
from sim.target.feed import TargetFeed  # noqa: E402

FRAME = 0.02


def simulate(cfg: Any, duration_s: float, feed_kw: dict[str, Any]) -> dict[str, Any]:
    """Fly the feed for ``duration_s``: truth, reports and both estimates every frame."""
    sil = cfg.section("sil")
    origin = LocalNED(sil.home_lat_deg, sil.home_lon_deg, sil.home_alt_m)
    motion = build_target(cfg.target)
    mav = M.MAVLink(None, srcSystem=2, srcComponent=1)
    feed = TargetFeed(motion, mav, ned_to_geodetic_fast, origin, **feed_kw)
    est = Estimator(EstimatorParams(origin=(origin.lat0_deg, origin.lon0_deg, origin.alt0_m)))
    kf = LiveTarget(est, cfg.section("target_estimator").params())
    last = ExtrapolatedTarget(est, 5.0)
    rx = M.MAVLink(None)
    rows = []
    for k in range(int(duration_s / FRAME)):
        t = k * FRAME
        for buf in feed.poll(t, t):
            s = decode(rx.decode(bytearray(buf)))
            if s is not None:
                kf.update(s, t)
                last.update(s, t)
        tr = motion.state(t)
        row = [t, *tr.position, math.atan2(tr.R_T_I[1, 0], tr.R_T_I[0, 0])]
        for tg in (kf, last):
            st = tg.state(t)
            row += (
                [math.nan] * 4
                if isinstance(st, str)
                else [*st.position, math.atan2(st.R_T_I[1, 0], st.R_T_I[0, 0])]
            )
        rows.append(row)
    A = np.array(rows)
    reps = np.array([(r.t_target, *r.position) for r in feed.sent])
    return {"rows": A, "reports": reps}


def figures(res: dict[str, Any], steady_s: float) -> dict[str, float]:
    A = res["rows"]
    A = A[A[:, 0] >= steady_s]
    out = {}
    for name, c in (("estimate", 5), ("last_sample", 9)):
        dp = np.linalg.norm(A[:, c : c + 3] - A[:, 1:4], axis=1)
        dy = np.angle(np.exp(1j * (A[:, c + 3] - A[:, 4])))
        ok = np.isfinite(dp)
        out[f"{name}_position_rms_m"] = float(np.sqrt(np.mean(dp[ok] ** 2)))
        out[f"{name}_yaw_rms_rad"] = float(np.sqrt(np.mean(dy[ok] ** 2)))
        out[f"{name}_usable_fraction"] = float(np.mean(ok))
    return out


def plot(res: dict[str, Any], path: str, window: tuple[float, float]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    A, R = res["rows"], res["reports"]
    w = (A[:, 0] >= window[0]) & (A[:, 0] <= window[1])
    wr = (R[:, 0] >= window[0]) & (R[:, 0] <= window[1])
    fig, ax = plt.subplots(1, 3, figsize=(16, 5))
    a = ax[0]
    a.plot(A[w, 2], A[w, 1], "k-", lw=2, label="truth")
    a.plot(R[wr, 2], R[wr, 1], "o", ms=4, color="tab:orange", label="reports (1 Hz, 2 m)")
    a.plot(A[w, 10], A[w, 9], "-", color="tab:red", lw=0.8, label="last report, extrapolated")
    a.plot(A[w, 6], A[w, 5], "-", color="tab:blue", lw=1.5, label="estimate")
    a.set_xlabel("east (m)")
    a.set_ylabel("north (m)")
    a.set_aspect("equal", adjustable="datalim")
    a.set_title(f"track, t = {window[0]:.0f}-{window[1]:.0f} s")
    a.legend(fontsize=8)
    t = A[:, 0]
    a = ax[1]
    a.plot(
        R[:, 0],
        np.linalg.norm(
            R[:, 1:4] - np.array([A[np.searchsorted(t, x), 1:4] for x in R[:, 0]]), axis=1
        ),
        ".",
        ms=3,
        color="tab:orange",
        label="reports",
    )
    a.plot(
        t,
        np.linalg.norm(A[:, 9:12] - A[:, 1:4], axis=1),
        color="tab:red",
        lw=0.6,
        label="last report, extrapolated",
    )
    a.plot(t, np.linalg.norm(A[:, 5:8] - A[:, 1:4], axis=1), color="tab:blue", label="estimate")
    a.set_xlabel("t (s)")
    a.set_ylabel("position error (m)")
    a.set_ylim(0, 8)
    a.legend(fontsize=8)
    a = ax[2]
    for c, col, lab in ((12, "tab:red", "last report, extrapolated"), (8, "tab:blue", "estimate")):
        a.plot(t, 150.0 * np.angle(np.exp(1j * (A[:, c] - A[:, 4]))), color=col, lw=0.8, label=lab)
    a.set_xlabel("t (s)")
    a.set_ylabel("{T} yaw error x 150 m (m)")
    a.set_ylim(-15, 15)
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lab.figures.feed_plot", description=__doc__)
    p.add_argument("--config", default="configs/default.yaml")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--steady", type=float, default=120.0)
    p.add_argument("--out", default="target_estimate.png")
    p.add_argument("--seed", type=int, default=7)
    a = p.parse_args(argv)
    kw = dict(
        rate_hz=1.0,
        position_noise_m=2.0,
        velocity_noise_m_s=0.3,
        latency_s=0.3,
        dropout=0.1,
        clock_offset_s=100.0,
        seed=a.seed,
    )
    # the estimator knows the feed's latency (sim/ never imports the benchmarks: they do not ship)
    cfg = load_config(a.config, [f"target_estimator.latency_s={kw['latency_s']}", *a.set])
    res = simulate(cfg, a.duration, kw)
    figs = figures(res, a.steady)
    for k, v in figs.items():
        print(f"{k:34s} {v:.4f}")
    plot(res, a.out, (a.steady, a.steady + 40.0))
    print(f"plot: {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
