"""The flight verdict (mpf_mavlink/runs/verdict.py) and the pre-flight gate of ``sim``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mpf_mavlink.cli.main import main
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.runs.verdict import EXIT_VERDICT, judge, verdict_line

DEMO = str(Path(__file__).resolve().parents[1] / "configs" / "default.yaml")
CFG = load_config(DEMO)  # steady after 120 s, X8 limits 14-18 m/s, 45 deg bank


def _flight(n: int = 3001, dt: float = 0.1) -> dict[str, np.ndarray]:
    t = np.arange(n) * dt  # 300 s
    return {
        "t": t, "pt": np.full(n, 0.3), "alt": np.full(n, 100.0), "v": np.full(n, 16.0),
        "roll": np.full(n, 0.5), "pitch": np.full(n, 0.05),
    }  # fmt: skip


def _judge(f: dict[str, np.ndarray]) -> list[str]:
    return judge(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"])


def test_a_good_flight_passes():
    assert _judge(_flight()) == []
    assert verdict_line([]) == "verdict: PASS"


def test_each_bound_fails_with_its_own_clause():
    f = _flight()
    f["pt"][2000] = 10.5  # after the 120 s of capture: above metrics.fail_pt_m = 10 m
    f["pt"][100] = 80.0  # during the capture: not judged
    (c,) = _judge(f)
    assert c.startswith("|pt| 10.5 m at t = 200.0 s")
    f = _flight()
    f["alt"][500] = 9.0  # metrics.altitude_floor_m = 10 m
    assert _judge(f)[0].startswith("altitude 9.0 m at t = 50.0 s")
    # airspeed: 14 (1 - 0.15) = 11.9 m/s; 1.0 s under it is a turbulence dip, 1.2 s a failure
    f = _flight()
    f["v"][1000:1010] = 11.0
    assert _judge(f) == []
    f["v"][1000:1012] = 11.0
    assert _judge(f)[0].startswith("airspeed outside [11.9, 20.7] m/s for 1.2 s from t = 100.0 s")
    # bank: 45 + 15 = 60 deg held for 2 s
    f = _flight()
    f["roll"][1000:1020] = math.radians(62.0)
    assert _judge(f)[0].startswith("bank beyond 60 deg for 2.0 s")
    f = _flight()
    f["roll"][1500] = math.radians(120.0)  # an instant upside down is a loss of control
    assert _judge(f)[0] == "loss of control at t = 150.0 s (bank 120 deg, pitch 3 deg)"
    f["pt"][:] = np.nan  # a NaN error is no pass
    assert any(c.startswith("|pt| nan") for c in _judge(f))
    assert verdict_line(["a", "b"]) == "verdict: FAIL: a; b"


def test_sim_refuses_what_check_refuses_unless_forced(tmp_path, capsys):
    # wind 10 m/s: Assumption 1 fails (the path points move at 16.5 m/s in the air, > 14)
    rc = main(["sim", DEMO, "--set", "sil.wind_ned_m_s=[0,10,0]", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc == 3
    assert "refused to fly: check failed: assumption_1" in err and "--force" in err
    assert err.count("\n") == 1  # one line
    # 20 m/s needs 44.6 deg of bank of the 45: inside the 5 deg margin, refused
    rc = main(["sim", DEMO, "--set", "vehicle.airspeed_m_s=20", "--set", "vehicle.airspeed_max_m_s=22",
               "--out", str(tmp_path / "r2")])  # fmt: skip
    assert rc == 3 and "feasibility" in capsys.readouterr().err


def test_sil_flight_that_fails_its_bound_exits_nonzero_with_a_verdict(tmp_path, capsys):
    # The kinematic plant, 20 s, |pt| judged from 10 s against 1 mm: no flight holds that
    # (the demo's steady error is ~0.2 m), so the verdict fails, the run exits 5 and says why
    # in its last line.
    rc = main(
        [
            "sim", DEMO, "--set", "sil.plant=kinematic", "--set", "sil.turbulence=none",
            "--set", "sim.duration_s=20", "--set", "metrics.steady_after_s=10",
            "--set", "metrics.fail_pt_m=0.001", "--out", str(tmp_path / "r"), "-q", "--no-plots",
        ]
    )  # fmt: skip
    out = capsys.readouterr().out.strip().splitlines()
    assert rc == EXIT_VERDICT
    assert out[-1].startswith("verdict: FAIL: |pt| ") and "(bound 0.001 m from t = 10 s)" in out[-1]
