"""Benchmarks: ``scripts/bench`` prints one JSON object of figures.

controller_step_us: median and p99 of one MPF law evaluation on the paper scenario, over states
along a real closed-loop trajectory, with the diagnostics record (the bridge's Controller.step
asks for it: it records it and reads its mode and p_f); median_target_arrays: the same with the
target state read from its arrays, as for a producer that does not keep its floats
(TargetState.floats; the paper profile and extrapolate keep them). controller_path: the
bridge's whole control path per step (bench.control_path). paper_wall_time_s: the 300 s
Section V scenario, kinematic plant, lambda_w = 10. Further figures (bridge, SIL, replay)
appear as those parts exist; ``--only NAME`` runs one group.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np


def controller_step_us(n: int = 3000, passes: int = 7) -> dict[str, Any]:
    import dataclasses

    from mpf_mavlink.config.schema import load_config
    from mpf_mavlink.core.guidance.law import VehicleState, mpf_law
    from mpf_mavlink.core.guidance.law_unrolled import mpf_law_unrolled
    from sim.runner import kinematic_loop

    cfg = load_config("configs/paper_lemniscate.yaml", ["sim.duration_s=30"])
    loop, x = kinematic_loop(cfg)
    states = []
    for i in range(n):
        x = loop.step(x, 0.02) if i % 3 == 0 else x
        states.append((x.s, VehicleState(x.t, x.p, x.R, loop.v_w), loop.target_state(x.t)))
    path, gains, ext = loop.path, loop.gains, loop.ext  # the harness's lookups, not the law's
    plain = [(s, veh, dataclasses.replace(tgt)) for s, veh, tgt in states]  # without its floats
    clock = time.perf_counter
    # The n calls take ~30 ms: one pass is at the mercy of a shared host's clock speed in that
    # instant (single-pass medians of the same code can differ ~2x), so the calls are timed in
    # several passes spread over ~0.5 s and the figure is the median of all.
    times = np.empty((passes, n))
    arrays = np.empty((passes, n))
    unrolled = np.empty((passes, n))
    for k in range(passes):
        for i, (s, veh, tgt) in enumerate(states):
            t0 = clock()
            mpf_law(s, veh, tgt, path, gains, ext)
            times[k, i] = clock() - t0
        for i, (s, veh, tgt) in enumerate(plain):
            t0 = clock()
            mpf_law(s, veh, tgt, path, gains, ext)
            arrays[k, i] = clock() - t0
        # the kinematic simulator's form of the same law (law_unrolled), timed in the same pass
        for i, (s, veh, tgt) in enumerate(states):
            t0 = clock()
            mpf_law_unrolled(s, veh, tgt, path, gains, ext)
            unrolled[k, i] = clock() - t0
    return {
        "median": float(np.median(times) * 1e6),
        "p99": float(np.percentile(times, 99) * 1e6),
        "median_target_arrays": float(np.median(arrays) * 1e6),
        "median_unrolled": float(np.median(unrolled) * 1e6),
        "pass_medians": [round(float(np.median(p)) * 1e6, 2) for p in times],
    }


def paper_wall_time_s() -> dict[str, Any]:
    from mpf_mavlink.config.schema import load_config
    from sim.runner import run_kinematic

    cfg = load_config("configs/paper_lemniscate.yaml")
    t0 = time.perf_counter()
    m = run_kinematic(cfg, progress=False).metrics
    return {
        "wall_s": time.perf_counter() - t0,
        "sim_s": m["sim_time_s"],
        "convergence_time_s": m["convergence_time_s"],
        "steady_rms_m": m["steady_rms_m"],
    }


def fdm_steps_per_s() -> dict[str, Any]:
    """JSBSim X8 steps per second of wall time with the state read at 50 Hz (the SIL's core;
    was a timed test, which a loaded machine made flaky)."""
    from sim.plant.jsbsim_plant import benchmark

    return {"steps_per_s": benchmark(seconds=300.0)}


def controller_path_us() -> dict[str, Any]:
    """The bridge's control path (estimator, target, prediction, law, adapter) per step, over
    the calls of a replay of a 120 s SIL demo tlog: bench.control_path."""
    from bench.control_path import controller_path_us as run

    return run()


GROUPS = {
    "controller_step_us": controller_step_us,
    "controller_path": controller_path_us,
    "paper_scenario": paper_wall_time_s,
    "fdm_steps_per_s": fdm_steps_per_s,
}


def _optional_groups() -> None:
    try:
        from bench.bridge import (
            bridge_latency_ms,
            bridge_link_us,
            estimator_us,
            replay_s,
        )

        GROUPS["bridge_latency_ms"] = bridge_latency_ms
        GROUPS["bridge_link_us"] = bridge_link_us
        GROUPS["estimator_us"] = estimator_us
        GROUPS["replay_s"] = replay_s
    except ImportError:
        pass
    from bench.sil import sil_real_time_factor, sil_tracking

    GROUPS["sil_real_time_factor"] = sil_real_time_factor
    GROUPS["sil_tracking"] = sil_tracking
    from bench.sil import sil_vehicle_frame_us

    GROUPS["sil_vehicle_frame_us"] = sil_vehicle_frame_us
    from bench.robustness import (
        sil_airframes,
        sil_robustness,
        sil_robustness_arduplane,
        sil_robustness_px4,
    )

    GROUPS["sil_robustness"] = sil_robustness
    GROUPS["sil_airframes"] = sil_airframes
    GROUPS["sil_robustness_px4"] = sil_robustness_px4
    GROUPS["sil_robustness_arduplane"] = sil_robustness_arduplane
    from bench.calibration import calibration

    GROUPS["calibration"] = calibration
    from bench.target import target_feed, target_filter_us

    GROUPS["target_feed"] = target_feed
    GROUPS["target_filter_us"] = target_filter_us
    from bench.campaign import (
        campaign_demo_robustness,
        campaign_roa,
        campaign_sil_flight,
        campaign_throughput,
    )
    from bench.framing import mavlink_framing_us

    GROUPS["mavlink_framing_us"] = mavlink_framing_us
    GROUPS["campaign_throughput"] = campaign_throughput
    GROUPS["campaign_roa"] = campaign_roa
    GROUPS["campaign_demo_robustness"] = campaign_demo_robustness
    GROUPS["campaign_sil_flight"] = campaign_sil_flight
    from bench.certify import certify

    GROUPS["certify"] = certify


def main(argv: list[str] | None = None) -> int:
    _optional_groups()
    from bench.compare import guidance_compare

    GROUPS["guidance_compare"] = guidance_compare
    p = argparse.ArgumentParser(
        prog="scripts/bench", description="Print benchmark figures as JSON."
    )
    p.add_argument("--only", choices=sorted(GROUPS), action="append", help="run only these groups")
    args = p.parse_args(argv)
    out: dict[str, Any] = {}
    for name, fn in GROUPS.items():
        if args.only and name not in args.only:
            continue
        print(f"[bench] {name} ...", file=sys.stderr)
        out[name] = fn()
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
