"""Campaign throughput and acceptance figures (issue 16): ``scripts/bench --only campaign_*``.

- ``campaign_throughput``: the first 64 flights of configs/campaign_roa.yaml (kinematic plant)
  on 1 and then 2 local workers: flights/min and the ratio (bar: >= 1.8 on 2 cores);
- ``campaign_roa``: the whole ROA campaign (1,024 kinematic flights; bar: <= 10 min on 2
  cores) with its convergence figures;
- ``campaign_demo_robustness``: configs/campaign_demo_robustness.yaml, 40 SIL flights of 600 s
  on 2 workers (bar: <= 12 min);
- ``campaign_sil_flight``: one SIL flight of the demo (600 s) as a campaign's worker flies it
  (``mpf-mavlink sim -q --no-plots`` in a subprocess: start-up, the pre-flight gate, the
  real-time-paced hand-over and hand-back, the tracking, the truth's metrics and the records),
  three times: its wall and CPU seconds, what a campaign pays per flight beyond the tracking's
  real-time factor (``rtf_flight``: simulated seconds per wall second of the whole flight).

The machine's load average is printed with each: on a shared machine the figures are pessimistic.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path
from typing import Any

ROA = "configs/campaign_roa.yaml"
DEMO = "configs/campaign_demo_robustness.yaml"


def _fly(path: str, workers: int, samples: int | None = None) -> dict[str, Any]:
    from mpf_mavlink.campaign.design import load_campaign
    from mpf_mavlink.campaign.report import summarise
    from mpf_mavlink.campaign.run import run_campaign

    spec = load_campaign(path)
    if samples is not None:
        spec = dataclasses.replace(spec, samples=samples)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="mpf-bench-campaign-") as d:
        # a copy of the campaign file with the sample count used (the fingerprint reads it)
        res = run_campaign(spec, Path(d), workers=workers, progress=False, log=lambda _s: None)
    s = summarise(spec, res.rows)
    wall = [float(r.get("wall_s") or 0.0) for r in res.rows]
    cpu = [float(r.get("cpu_s") or 0.0) for r in res.rows]
    return {
        "flights": res.flown, "workers": workers, "wall_s": res.wall_s,
        "flights_per_min": 60.0 * res.flown / res.wall_s if res.wall_s else None,
        "flight_wall_s_mean": sum(wall) / max(1, len(wall)),
        # CPU seconds per flight (worker + the flight's subprocesses): the figure a loaded,
        # shared machine does not inflate; flights/min on an idle N-core machine is about
        # 60 N / cpu_s_per_flight
        "cpu_s_per_flight": sum(cpu) / max(1, len(cpu)),
        "cpu_s_total": sum(cpu),
        "success_rate": s["success_rate"], "converged_rate": s["converged_rate"],
        "status": s["status"], "percentiles": s["percentiles"],
        "load_avg_1min_before": load0, "load_avg_1min_after": os.getloadavg()[0],
    }  # fmt: skip


def campaign_throughput(n: int = 64) -> dict[str, Any]:
    one = _fly(ROA, 1, n)
    two = _fly(ROA, 2, n)
    return {"one_worker": one, "two_workers": two,
            "speedup": two["flights_per_min"] / one["flights_per_min"]}  # fmt: skip


def campaign_roa() -> dict[str, Any]:
    return _fly(ROA, 2)


def campaign_demo_robustness() -> dict[str, Any]:
    return _fly(DEMO, 2)


def campaign_sil_flight(runs: int = 3) -> dict[str, Any]:
    import statistics

    from mpf_mavlink.campaign.flight import fly

    rows: list[dict[str, Any]] = []
    for _ in range(runs):
        r = fly("configs/default.yaml", [], "jsbsim", ["real_time_factor_tracking"], 600.0)
        rows.append({k: r.get(k) for k in ("status", "error", "wall_s", "cpu_s", "sim_time_s",
                                           "real_time_factor_tracking")})  # fmt: skip
    ok = [r for r in rows if r["status"] == "ok" and r["wall_s"]]
    wall = statistics.median(float(r["wall_s"]) for r in ok) if ok else None
    sim = statistics.median(float(r["sim_time_s"] or 0.0) for r in ok) if ok else None
    return {
        "wall_s": wall,
        "cpu_s": statistics.median(float(r["cpu_s"]) for r in ok) if ok else None,
        "rtf_flight": sim / wall if wall and sim else None,
        "runs": rows,
    }
