"""The stored real calibration flights (lab/calibration/flights/) and what flies their SIL legs
on a bare clone: the bench group ``calibration`` and the robustness bench's ``--profile``. No
flight here (the bench groups fly; these check what they are given and refuse)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from lab.calibration.calibrate import (
    ARDUPLANE_MATRIX,
    BAND,
    PX4_MATRIX,
    compare_row,
    load_flights,
    sil_command,
)
from mpf_mavlink.config.autopilot_profile import load_profile
from mpf_mavlink.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def _sets(cmd: list[str]) -> dict[str, str]:
    return dict(cmd[i + 1].split("=", 1) for i, c in enumerate(cmd) if c == "--set")


@pytest.mark.parametrize(
    ("autopilot", "matrix"), [("arduplane", ARDUPLANE_MATRIX), ("px4", PX4_MATRIX)]
)
def test_stored_flights_cover_the_matrix_with_their_real_figures(autopilot, matrix):
    recs = load_flights(autopilot)
    assert [r["mission"]["name"] for r in recs] == [m.name for m in matrix]
    for r in recs:
        real = r["real"]
        # a steady window of real tracking: an RMS, its means, the tracked time it was over
        assert real["steady_rms_m"] > 0.0 and real["tracked_s"] >= 120.0
        assert abs(real["steady_mean_radial_m"]) < real["steady_rms_m"] + 1e-9
        assert len(r["start_ned_m"]) == 3 and r["start_ned_m"][2] < 0.0  # above the origin


def test_sil_leg_flies_the_real_flights_start_state_mission_and_wind(tmp_path):
    rec = next(r for r in load_flights("arduplane") if r["mission"]["name"] == "wind6")
    prof = ROOT / "configs" / "autopilots" / "arduplane-4.7.yaml"
    cmd = sil_command(rec, "arduplane", prof, tmp_path / "leg", seed=2)
    s = _sets(cmd)
    p0 = rec["start_ned_m"]
    assert s["sil.initial_position_ned_m"] == f"[{p0[0]:.2f},{p0[1]:.2f},{p0[2]:.2f}]"
    assert s["sim.duration_s"] == f"{rec['real']['tracked_s']:g}"
    assert s["sil.flavour"] == "ardupilot" and s["sil.seed"] == "2"
    assert s["sil.autopilot_profile"] == str(prof)
    # SIM_WIND_DIR 180 is wind FROM the south: the air moves north at 6 m/s
    wn, we, wd = (float(x) for x in s["sil.wind_ned_m_s"].strip("[]").split(","))
    assert (wn, we, wd) == pytest.approx((6.0, 0.0, 0.0), abs=1e-3)
    for o in rec["overrides"]:  # the rig's own overrides as the real flight flew them
        k, v = o.split("=", 1)
        assert s[k] == v
    # as long as the real flight tracked: no hand-back by the envelope monitor's hold policy
    assert s["envelope.policy"] == "warn"


def test_compare_row_judges_the_band_and_the_means():
    real = {"steady_rms_m": 0.2, "steady_mean_radial_m": -0.1, "steady_mean_vertical_m": 0.0}

    def sil(rms: float, radial: float) -> dict:
        b = {"steady_rms_m": rms, "steady_mean_radial_m": radial, "steady_mean_vertical_m": 0.0}
        return {"bridge": b, "truth": {}}

    lo, hi = 0.2 / BAND[1], 0.2 / BAND[0]  # the SIL RMS at the band's edges
    assert compare_row("a", real, sil(lo * 1.01, -0.1))["within"]
    assert not compare_row("a", real, sil(lo * 0.99, -0.1))["within"]
    assert not compare_row("a", real, sil(hi * 1.01, -0.1))["within"]
    assert not compare_row("a", real, sil(0.2, 0.21))["within"]  # 0.31 m apart
    assert math.isclose(compare_row("a", real, sil(0.25, 0.0))["ratio"], 0.8)
    # a SIL leg handed back before the real flight's tracked time is not compared
    leg = sil(0.2, -0.1)
    leg["bridge"]["tracked_s"] = 77.3
    row = compare_row("a", {**real, "tracked_s": 240.0}, leg)
    assert not row["within"] and row["sil_short"]
    leg["bridge"]["tracked_s"] = 240.0
    assert compare_row("a", {**real, "tracked_s": 240.0}, leg)["within"]


def test_calibration_and_profiled_robustness_are_bench_groups():
    from bench import main as bench

    bench._optional_groups()
    for g in ("calibration", "sil_robustness_px4", "sil_robustness_arduplane"):
        assert g in bench.GROUPS


def test_robustness_profile_flies_the_profile_without_sihs_thrust(tmp_path):
    from bench.robustness import profile_rows, profile_sets

    sets = dict(s.split("=", 1) for s in profile_sets("px4", tmp_path))
    assert sets["sil.flavour"] == "px4"
    used = load_profile(sets["sil.autopilot_profile"])
    shipped = load_profile(ROOT / "configs" / "autopilots" / "px4-1.16-sih.yaml")
    assert shipped.thrust.full_thrust_airspeed_m_s is not None
    assert used.thrust.full_thrust_airspeed_m_s is None  # SIH's airframe, not the X8's
    assert used.estimator == shipped.estimator and used.turn == shipped.turn
    kept = dict(s.split("=", 1) for s in profile_sets("px4", tmp_path, thrust=True))
    assert Path(kept["sil.autopilot_profile"]).resolve() == (
        ROOT / "configs" / "autopilots" / "px4-1.16-sih.yaml"
    )
    ap = dict(s.split("=", 1) for s in profile_sets("arduplane", tmp_path))
    assert ap["sil.flavour"] == "ardupilot"
    # each profile flies the rows whose config is its autopilot's flavour
    assert "demo" in profile_rows("px4") and "demo" not in profile_rows("arduplane")
    assert "c172x" in profile_rows("arduplane") and "c172x" not in profile_rows("px4")
    with pytest.raises(ConfigError, match="no such autopilot profile"):
        profile_sets(str(tmp_path / "none.yaml"), tmp_path)


@pytest.mark.parametrize(
    ("args", "msg"),
    [
        (["--profile", "nope"], "robustness: --profile: nope: no such autopilot profile"),
        (["--rows", "calm,nope"], "robustness: unknown row 'nope'"),
    ],
)
def test_robustness_refuses_bad_input_in_one_line_before_flying(args, msg):
    r = subprocess.run(
        [sys.executable, "-m", "bench.robustness", *args],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode == 2
    assert r.stderr.strip() == msg
    assert r.stdout == ""


def test_calibrate_store_writes_what_load_flights_reads(tmp_path):
    # a real run directory as the rig leaves it (only the files `store` reads)
    run = tmp_path / "runs" / "stationary"
    (run / "bridge").mkdir(parents=True)
    (tmp_path / "runs" / "stationary.mission.json").write_text(
        json.dumps({"name": "stationary", "radius_m": 150.0, "alt_m": 100.0})
    )
    (run / "summary.json").write_text(json.dumps({"mission": {"overrides": ["path.radius_m=150"]}}))
    (run / "bridge" / "metrics.json").write_text(
        json.dumps({"steady_rms_m": 0.17, "tracked_s": 240.0, "steady_mean_radial_m": -0.1})
    )
    cols = "t,p_n,p_e,p_d,tgt_yaw,pt_n,pt_e,pt_d,rel_x,rel_y"
    rows = [f"{0.5 * i:g},{11.0 * i:g},0,-100,0,0,0,0.1,{150 * math.cos(i / 20):.3f},"
            f"{150 * math.sin(i / 20):.3f}" for i in range(400)]  # fmt: skip
    (run / "bridge" / "timeseries.csv").write_text("\n".join([cols, *rows]) + "\n")
    to = tmp_path / "flights.json"
    r = subprocess.run(
        [sys.executable, "-m", "lab.calibration.calibrate", "store", "arduplane",
         "--out", str(tmp_path / "runs"), "--firmware", "test", "--to", str(to)],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    (rec,) = load_flights("arduplane", to)
    assert rec["real"]["steady_rms_m"] == 0.17 and rec["start_ned_m"] == [0.0, 0.0, -100.0]
    assert rec["start_heading_rad"] == pytest.approx(0.0)  # flying north
    assert rec["real"]["steady_mean_radial_se_m"] == pytest.approx(0.0, abs=1e-6)  # on the circle
    r = subprocess.run(
        [sys.executable, "-m", "lab.calibration.calibrate", "store", "arduplane",
         "--out", str(tmp_path / "none"), "--firmware", "x", "--to", str(tmp_path / "f2.json")],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode == 2 and "no real runs" in r.stderr
    assert not (tmp_path / "f2.json").exists()


def test_mean_standard_error_counts_the_independent_samples_of_a_correlated_series():
    import numpy as np

    from lab.calibration.calibrate import mean_standard_error

    rng = np.random.default_rng(5)
    dt, n = 0.02, 60000  # 1200 s at 50 Hz
    t = np.arange(n) * dt
    white = rng.standard_normal(n)
    # white noise: every sample independent, s.e. = sd / sqrt(N) (to the sum's noise, ~10 %)
    assert mean_standard_error(t, white) == pytest.approx(1.0 / math.sqrt(n), rel=0.15)
    # a first-order Gauss-Markov series of correlation time tau: integrated time 2 tau, so
    # s.e. = sd sqrt(2 tau / T) (the sum truncated at the first negative lag: within ~25 %)
    tau = 6.0
    phi = math.exp(-dt / tau)
    x = np.empty(n)
    x[0] = 0.0
    q = math.sqrt(1 - phi * phi)
    for i in range(1, n):
        x[i] = phi * x[i - 1] + q * white[i]
    want = float(np.std(x)) * math.sqrt(2 * tau / (t[-1] - t[0]))
    assert mean_standard_error(t, x) == pytest.approx(want, rel=0.35)
    assert mean_standard_error(t[:5], x[:5]) is None  # too short to say
