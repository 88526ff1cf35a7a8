"""Bench group ``guidance_compare``: MPF / best baseline per scenario of the comparison set.

Full SIL (JSBSim X8 + the bridge over MAVLink, seeds of the configs), each law flown
``BENCH_COMPARE_S`` seconds with the steady window from ``BENCH_STEADY_S``: shorter than the
configs' 600 s so the group stays within minutes per scenario on 2 cores (README table: the
same flights). Ratio < 1: MPF's steady RMS distance from the moving path is smaller.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

BENCH_COMPARE_S = 240.0
BENCH_STEADY_S = 120.0
CIRCLE_LAWS = ["mpf", "npfg", "npfg_static", "l1_loiter", "pursuit"]
PATH_LAWS = ["mpf", "npfg", "npfg_static", "pursuit"]
SCENARIOS: dict[str, tuple[str, list[str]]] = {
    "demo_figure_eight": ("configs/default.yaml", PATH_LAWS),
    "circle_turning_target": ("configs/compare/circle_turning_target.yaml", CIRCLE_LAWS),
    "helix_climbing_target": ("configs/compare/helix_climbing_target.yaml", CIRCLE_LAWS),
    "static_circle": ("configs/compare/static_circle.yaml", CIRCLE_LAWS),
    "strong_wind": ("configs/compare/strong_wind.yaml", CIRCLE_LAWS),
    "turning_target_latency": ("configs/compare/turning_target_latency.yaml", CIRCLE_LAWS),
    # 3D missions (issue 25): no loiter circle to compare with
    "spline3d_turning_target": ("configs/spline3d_turning_target.yaml", PATH_LAWS),
    "helix": ("configs/helix.yaml", PATH_LAWS),
}


def guidance_compare() -> dict[str, Any]:
    from mpf_mavlink.cli.compare import run_compare
    from mpf_mavlink.config.schema import load_config
    from mpf_mavlink.runs.compare import best_baseline, ratio_mpf_best

    out: dict[str, Any] = {}
    for name, (path, laws) in SCENARIOS.items():
        cfg = load_config(path, [f"metrics.steady_after_s={BENCH_STEADY_S}"])
        with tempfile.TemporaryDirectory() as d:
            rows, _ = run_compare(
                cfg, laws, "sil", Path(d), BENCH_COMPARE_S, progress=False, plots=False,
                log=lambda s: None,
            )  # fmt: skip
        out[name] = {
            "ratio_mpf_best": ratio_mpf_best(rows),
            "best_baseline": best_baseline(rows)[0],
            "steady_rms_xt_m": {r.law: r.figures["steady_rms_xt_m"] for r in rows},
        }
    return out
