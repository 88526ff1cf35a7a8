"""``scripts/bench --only certify``: what a certificate costs (issue 41's bar: 200 flights of a
300 s mission in <= 15 min on 2 cores, 13.3 flights/min). Flies ``MPF_BENCH_CERTIFY_FLIGHTS``
(default 20) flights of configs/certify/px4_turning_target.yaml lengthened to 300 s on
``MPF_BENCH_CERTIFY_WORKERS`` (default 2) local workers and prints flights/min, CPU-s per
flight and the minutes 200 flights would take at that rate, with the machine's load average
(a shared machine's figures are pessimistic)."""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CONDITIONS = ROOT / "configs" / "certify" / "px4_turning_target.yaml"
CONFIG = ROOT / "configs" / "bridge_px4.yaml"


def certify(flights: int | None = None, workers: int | None = None) -> dict[str, Any]:
    from mpf_mavlink.certify.conditions import parse_conditions
    from mpf_mavlink.certify.run import fly_all, mission

    n = flights or int(os.environ.get("MPF_BENCH_CERTIFY_FLIGHTS", "20"))
    # more workers than cores overlap one flight's real-time-paced hand-over with another's work
    workers = workers or int(os.environ.get("MPF_BENCH_CERTIFY_WORKERS", "2"))
    cond = dataclasses.replace(parse_conditions(CONDITIONS), duration_s=300.0)
    m = mission(CONFIG, [], "px4", cond)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="mpf-bench-certify-") as d:
        res = fly_all(m, cond, n, Path(d) / "cert", workers=workers, progress=False,
                      log=lambda s: None)  # fmt: skip
    cpu = [float(r["cpu_s"]) for r in res.rows if r.get("cpu_s") not in ("", None)]
    fpm = 60.0 * res.flown / res.wall_s if res.wall_s > 0 else None
    return {
        "flights": res.flown,
        "mission_s": 300.0,
        "workers": res.workers,
        "wall_s": res.wall_s,
        "flights_per_min": fpm,
        "cpu_s_per_flight": sum(cpu) / len(cpu) if cpu else None,
        "minutes_for_200": (200.0 / fpm) if fpm else None,
        "bar_minutes_for_200": 15.0,
        "status": {
            s: sum(1 for r in res.rows if r["status"] == s) for s in {r["status"] for r in res.rows}
        },  # fmt: skip
        "load_average": [load0, os.getloadavg()[0]],
        "profile": m.profile,
    }
