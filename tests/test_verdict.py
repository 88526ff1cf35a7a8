"""The flight verdict (mpf_mavlink/runs/verdict.py) and the pre-flight gate of ``sim``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mpf_mavlink.cli.main import main
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.runs.verdict import EXIT_VERDICT, assess, verdict_line

DEMO = str(Path(__file__).resolve().parents[1] / "configs" / "default.yaml")
CFG = load_config(DEMO)  # steady after 120 s, X8 limits 14-18 m/s, 45 deg bank


def _flight(n: int = 3001, dt: float = 0.1) -> dict[str, np.ndarray]:
    t = np.arange(n) * dt  # 300 s
    return {
        "t": t, "pt": np.full(n, 0.3), "alt": np.full(n, 100.0), "v": np.full(n, 16.0),
        "roll": np.full(n, 0.5), "pitch": np.full(n, 0.05),
    }  # fmt: skip


def _judge(f: dict[str, np.ndarray]) -> list[str]:
    return assess(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"]).clauses


def test_a_good_flight_passes():
    assert _judge(_flight()) == []
    assert verdict_line([]) == "verdict: PASS"


def test_each_bound_fails_with_its_own_clause():
    f = _flight()
    f["pt"][2000] = 10.5  # after the 120 s of capture: above metrics.fail_pt_m = 10 m
    f["pt"][100] = 80.0  # during the capture: not judged
    (c,) = _judge(f)
    assert c.startswith("tracking: |pt| 10.5 m at t = 200.0 s")
    f = _flight()
    f["alt"][500] = 9.0  # metrics.altitude_floor_m = 10 m
    assert _judge(f)[0].startswith("safety: altitude 9.0 m at t = 50.0 s")
    # airspeed: 14 (1 - 0.15) = 11.9 m/s; 1.0 s under it is a turbulence dip, 1.2 s a failure
    f = _flight()
    f["v"][1000:1010] = 11.0
    assert _judge(f) == []
    f["v"][1000:1012] = 11.0
    assert _judge(f)[0].startswith(
        "energy: airspeed outside [11.9, 20.7] m/s for 1.2 s from t = 100.0 s (limit 1 s)"
    )
    f = _flight()
    f["roll"][1500] = math.radians(120.0)  # an instant upside down is a loss of control
    assert _judge(f)[0] == "safety: loss of control at t = 150.0 s (bank 120 deg, pitch 3 deg)"
    f["pt"][:] = np.nan  # a NaN error is no pass
    assert any(c.startswith("tracking: |pt| nan") for c in _judge(f))
    assert verdict_line(["a", "b"]) == "verdict: FAIL: a; b"


# One test per verdict class of issue 26 (not judged, bank, thrust ceiling, airspeed). Each
# fails on main ea270a0's verdict, which passed all four flights.


def test_bank_beyond_the_vehicle_limit_held_fails():
    # 52 deg against the demo's 45 deg limit (vehicle.max_bank_rad) + 5 deg
    # (metrics.bank_tolerance_rad, the checks' margin mirrored): a gust's second is within
    # metrics.limit_hold_s = 1 s (about 3 roll time constants), 3 s is demanded. The old verdict
    # allowed 15 deg (60 deg) and passed it.
    f = _flight()
    f["roll"][2000:2010] = math.radians(52.0)
    assert _judge(f) == []
    f["roll"][2000:2030] = math.radians(52.0)
    (c,) = _judge(f)
    assert (
        c == "attitude: bank beyond 50.0 deg for 3.0 s from t = 200.0 s (max 52.0 deg; limit 1 s)"
    )
    # held within checks.bank_margin_rad (5 deg) of the limit for 30 % of the 180 s steady
    # window (limit_fraction 20 %): the turn is saturated, as the 86 m ArduPlane circle was
    f = _flight()
    f["roll"][1200:1740] = math.radians(43.0)
    (c,) = _judge(f)
    assert c.startswith("attitude: bank at its limit (>= 40.0 of 45.0 deg) for 30 % of the steady")
    assert "(54 of 180 s, first at t = 120.0 s; limit 20 %)" in c


def test_thrust_pinned_at_its_ceiling_fails_as_an_energy_problem():
    from mpf_mavlink.runs.verdict import assess

    f = _flight()
    thr = np.full(len(f["t"]), 0.3)
    thr[1300:] = 1.0  # 170 of the 180 s steady window at adapter.thrust_max = 1 (94 %)
    (c,) = assess(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"], thr).clauses
    assert c.startswith("energy: thrust at its ceiling 1 for 94 % of the steady window")
    v = assess(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"], thr)
    assert v.status == "FAIL" and v.classes == ["energy"] and v.exit_code(0) == EXIT_VERDICT
    assert v.line().startswith("verdict: FAIL (energy): energy: thrust at its ceiling")
    thr[1300:1320] = 0.5  # 20 s short of the ceiling: 83 %, still a failure; 15 % passes
    assert assess(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"], thr).clauses
    thr[:] = 0.3
    thr[2700:] = 1.0  # 30 s of 180 = 17 % (a climb, a gust): within 20 %
    assert assess(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"], thr).clauses == []


def test_an_airspeed_the_aircraft_cannot_hold_fails():
    # 12.5 m/s for the whole steady window, never below the 11.9 m/s floor: the old verdict
    # passed it; the law assumes 16 m/s (vehicle.airspeed_m_s), +-15 % = +-2.4 m/s
    f = _flight()
    f["v"][1200:] = 12.5
    (c,) = _judge(f)
    assert c.startswith("energy: airspeed not held: mean 12.5 m/s from t = 120 s for 180 s")
    assert "against the 16 m/s the law assumes (limit +-2.4 m/s)" in c
    f["v"][1200:] = 14.0  # 2.0 m/s slow: within
    assert _judge(f) == []


def test_a_flight_too_short_to_judge_is_not_judged(tmp_path, capsys):
    from mpf_mavlink.runs.verdict import EXIT_NOT_JUDGED, assess

    f = _flight(n=601)  # 60 s: the steady window starts at 120 s
    v = assess(CFG, f["t"], f["pt"], f["alt"], f["v"], f["roll"], f["pitch"])
    assert v.status == "NOT JUDGED" and v.exit_code(0) == EXIT_NOT_JUDGED == 6
    assert v.line().startswith("verdict: NOT JUDGED: tracked 60.0 s, steady window 0.0 s")
    f["alt"][300] = 5.0  # a limit broken in a short flight still fails it
    assert assess(CFG, f["t"], f["pt"], f["alt"]).status == "FAIL"
    # end to end: 20 s of the kinematic SIL plant with the steady window from 10 s (10 s <
    # metrics.min_steady_s = 20 s): exit 6 and the last line says why
    rc = main(
        [
            "sim", DEMO, "--set", "sil.plant=kinematic", "--set", "sil.turbulence=none",
            "--set", "sim.duration_s=20", "--set", "metrics.steady_after_s=10",
            "--out", str(tmp_path / "r"), "-q", "--no-plots",
        ]
    )  # fmt: skip
    out = capsys.readouterr().out.strip().splitlines()
    assert rc == 6, out[-1]
    assert out[-1].startswith("verdict: NOT JUDGED: tracked 2")
    assert "metrics.min_steady_s = 20 s" in out[-1]


def test_sim_refuses_what_check_refuses_unless_forced(tmp_path, capsys):
    # wind 10 m/s: Assumption 1 fails (the path points move at 16.5 m/s in the air, > 14)
    rc = main(["sim", DEMO, "--set", "sil.wind_ned_m_s=[0,10,0]", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc == 3
    assert "refused to fly: check failed: assumption_1" in err and "--force" in err
    assert err.count("\n") == 1  # one line
    # 20 m/s needs 44.6 deg of bank of the 45: inside the 5 deg margin, refused
    rc = main(["sim", DEMO, "--set", "vehicle.airspeed_m_s=20",
               "--set", "vehicle.airspeed_max_m_s=22", "--out", str(tmp_path / "r2")])  # fmt: skip
    assert rc == 3 and "feasibility" in capsys.readouterr().err


def test_sil_flight_that_fails_its_bound_exits_nonzero_with_a_verdict(tmp_path, capsys):
    # The kinematic plant, 40 s, |pt| judged from 10 s against 1 mm: no flight holds that
    # (the demo's steady error is ~0.2 m), so the verdict fails, the run exits 5 and says why
    # in its last line.
    rc = main(
        [
            "sim", DEMO, "--set", "sil.plant=kinematic", "--set", "sil.turbulence=none",
            "--set", "sim.duration_s=40", "--set", "metrics.steady_after_s=10",
            "--set", "metrics.fail_pt_m=0.001", "--out", str(tmp_path / "r"), "-q", "--no-plots",
        ]
    )  # fmt: skip
    out = capsys.readouterr().out.strip().splitlines()
    assert rc == EXIT_VERDICT
    assert (
        out[-1].startswith("verdict: FAIL (")
        and "tracking: |pt| " in out[-1]
        and "(bound 0.001 m from t = 10 s)" in out[-1]
    )
