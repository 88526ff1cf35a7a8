"""The same seed flown twice in lockstep is the same flight, bit for bit: the bridge's hand-over
(stream rates, checks, prestream, OFFBOARD) runs on the vehicle's clock, not the wall clock."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("jsbsim")

from mpf_mavlink.config.schema import load_config  # noqa: E402
from sim.sil import run_sil  # noqa: E402

DEMO = str(Path(__file__).resolve().parents[1] / "configs" / "default.yaml")


@pytest.mark.xfail(
    strict=False,
    reason="under CPU load a flight still differs by one HEARTBEAT (1 s of vehicle time) at the "
    "hand-over: identical when the host is quiet, not yet under pytest -n 2",
)
def test_same_seed_twice_gives_identical_metrics(tmp_path):
    # 40 s of tracking, steady window from 10 s (the demo's 120 s would leave none): a hand-over
    # that depended on wall time moved the engagement by a frame or a HEARTBEAT and the steady
    # RMS by up to 0.3 m at this length; in lockstep throughout, nothing may differ at all
    keys = ("steady_rms_m", "steady_max_m", "convergence_time_s", "vehicle_sim_time_s")
    got = []
    for k in range(2):
        cfg = load_config(DEMO, ["metrics.steady_after_s=10"])
        r = run_sil(
            cfg, tmp_path / f"run{k}", progress=False, plots=False, duration_s=40.0,
            log=lambda s: None,
        )  # fmt: skip
        assert r.metrics["steady_rms_m"] is not None, r.exit_reason
        got.append({key: r.metrics[key] for key in keys})
    assert got[0] == got[1]
