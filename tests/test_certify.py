"""The calibrated SIL's profile choice (sil.autopilot_profile auto | none | FILE), the check
that refuses what a profile cannot fly, and `certify`: conditions, statistics, resume, the
certificate, and the validation table of real flights."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from scipy import stats

from mpf_mavlink.certify.conditions import draw, flight_sets, parse_conditions
from mpf_mavlink.certify.report import certificate
from mpf_mavlink.certify.stats import (
    clopper_pearson,
    flights_needed,
    quantile_interval,
    upper_bound_rank,
)
from mpf_mavlink.config import load_config
from mpf_mavlink.config.autopilot_profile import SHIPPED, calibrated_sets, load_profile
from mpf_mavlink.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "default.yaml"


# --------------------------------------------------------------------------- profile choice
@pytest.mark.parametrize(
    ("flavour", "stem"), [("px4", "px4-1.16-sih"), ("ardupilot", "arduplane-4.7")]
)
def test_auto_is_the_identified_profile_of_the_flavour(flavour, stem):
    cfg = load_config(DEMO, [f"sil.flavour={flavour}", "sil.autopilot_profile=auto"])
    res = cfg.section("sil").profile(cfg.source)
    assert res is not None and res.split and res.path.stem == stem
    assert res.profile.autopilot == ("px4" if flavour == "px4" else "arduplane")
    # the autopilot's part is carried whole: PX4's identified roll wander of 0.0168 rad
    full = load_profile(SHIPPED[res.profile.autopilot])
    assert res.profile.estimator == full.estimator and res.profile.turn == full.turn


def test_auto_drops_the_airframes_thrust_and_a_file_keeps_it():
    # PX4 SIH's full thrust flies 14 m/s level: that is SIH's airframe, not the X8's
    assert load_profile(SHIPPED["px4"]).thrust.full_thrust_airspeed_m_s == 14.0
    auto = load_config(DEMO, ["sil.autopilot_profile=auto"]).section("sil").profile("")
    assert auto is not None and auto.profile.thrust.full_thrust_airspeed_m_s is None
    f = load_config(DEMO, [f"sil.autopilot_profile={SHIPPED['px4']}"]).section("sil").profile("")
    assert f is not None and not f.split and f.profile.thrust.full_thrust_airspeed_m_s == 14.0


@pytest.mark.parametrize("value", [None, "none"])
def test_none_and_left_out_are_the_plain_emulation(value):
    sets = [] if value is None else [f"sil.autopilot_profile={value}"]
    cfg = load_config(DEMO, sets)
    assert cfg.section("sil").profile(cfg.source) is None


def test_a_bad_profile_file_is_one_line_naming_the_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("autopilot: px4\nturn: {turn_gain: 9}\n")
    with pytest.raises(ConfigError) as e:
        load_config(DEMO, [f"sil.autopilot_profile={bad}"])
    msg = str(e.value)
    assert "\n" not in msg and "sil.autopilot_profile" in msg and "turn.turn_gain" in msg
    with pytest.raises(ConfigError, match="no such autopilot profile"):
        load_config(DEMO, ["sil.autopilot_profile=nope.yaml"])


def test_flows_fill_in_auto_only_when_the_config_names_nothing():
    sets, label = calibrated_sets(load_config(DEMO))
    assert sets == ["sil.autopilot_profile=auto"] and label.startswith("auto: px4-1.16-sih")
    sets, label = calibrated_sets(load_config(DEMO, ["sil.autopilot_profile=none"]))
    assert sets == [] and label.startswith("none")


# --------------------------------------------------------------------------- the check
def _check(sets):
    from mpf_mavlink.bridge.preflight import run_checks

    return {r.name: r for r in run_checks(load_config(DEMO, sets))}


def test_the_check_refuses_the_px4_profile_file_for_its_thrust():
    r = _check([f"sil.autopilot_profile={SHIPPED['px4']}"])["autopilot_profile"]
    # the law flies 16 m/s; SIH's full thrust holds 14 m/s level
    assert r.status == "fail" and "airspeed 16 m/s needs more thrust" in r.summary
    assert "14 m/s" in r.summary


def test_the_check_refuses_the_arduplane_turn_gain_beyond_the_bank_limit():
    r = _check(["sil.flavour=ardupilot", "sil.autopilot_profile=auto"])["autopilot_profile"]
    # the demo's 33.4 deg peak bank at turn gain 0.744: atan(tan(33.4 deg) / 0.744) ~ 41.5 deg,
    # beyond the 45 deg limit less its 5 deg margin
    want = math.degrees(math.atan(math.tan(math.radians(33.4)) / 0.744))
    assert r.status == "fail" and "beyond the limit 45.0 deg" in r.summary
    assert abs(math.degrees(r.figures["peak_bank_rad"]) - want) < 0.3


def test_the_check_passes_px4_auto_on_the_demo_and_is_absent_without_a_profile():
    checks = _check(["sil.autopilot_profile=auto"])
    assert checks["autopilot_profile"].status == "pass"
    assert "autopilot_profile" not in _check([])


# --------------------------------------------------------------------------- conditions
def _write(tmp_path, text):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("name: x\nwind: {speed_m_s: [5, 2]}\n", "wind.speed_m_s: low 5 exceeds high 2"),
        ("name: x\nwind: {speed_m_s: [-1, 2]}\n", "wind.speed_m_s: must be >= 0"),
        ("name: x\nwind: {gusts: [0, 1]}\n", "wind.gusts: unknown key"),
        ("name: x\nlink: {target_rate_hz: [0, 1]}\n", "link.target_rate_hz: must be > 0"),
        ("name: x\nturbulence: {dryden: [stormy]}\n", "turbulence.dryden"),
        ("name: x\nquantile: 1.5\n", "quantile"),
        ("wind: {}\n", "name"),
        ("name: x\nduration_s: 100\nsteady_after_s: 120\n", "steady_after_s: must be <"),
    ],
)
def test_bad_conditions_are_one_line_naming_the_key(tmp_path, text, words):
    with pytest.raises(ConfigError) as e:
        parse_conditions(_write(tmp_path, text))
    assert "\n" not in str(e.value) and words in str(e.value)


def test_draws_are_per_flight_and_inside_their_ranges(tmp_path):
    c = parse_conditions(_write(tmp_path, "name: x\nwind: {speed_m_s: [2, 5]}\nseed: 3\n"))
    d = [draw(c, i) for i in range(50)]
    assert all(2.0 <= x["wind.speed_m_s"] <= 5.0 for x in d)
    assert draw(c, 7) == d[7]  # flight 7 is the same flight whatever the number flown
    cfg = load_config(DEMO)
    sets = flight_sets(cfg, {**d[0], "wind.speed_m_s": 4.0, "wind.from_rad": math.pi / 2})
    # 4 m/s from the east blows toward the west: -4 m/s east
    assert "sil.wind_ned_m_s=[-0.0000,-4.0000,0.0]" in sets


# --------------------------------------------------------------------------- statistics
def test_the_order_statistic_needs_59_flights_for_95_at_95():
    # 1 - 0.95^58 = 0.9490 < 0.95 <= 1 - 0.95^59 = 0.9515
    assert flights_needed(0.95, 0.95) == 59
    assert flights_needed(0.9, 0.95) == 29  # 1 - 0.9^29 = 0.953, 0.9^28 leaves 0.948
    assert flights_needed(0.95, 0.99) == 90
    assert upper_bound_rank(59) == 59 and upper_bound_rank(58) is None
    # with 200 flights the bound is an inner order statistic, P(B < r) >= 0.95
    r = upper_bound_rank(200)
    assert r is not None and stats.binom.cdf(r - 1, 200, 0.95) >= 0.95
    assert stats.binom.cdf(r - 2, 200, 0.95) < 0.95


@pytest.mark.parametrize(("k", "n"), [(0, 59), (3, 59), (10, 200), (59, 59)])
def test_clopper_pearson_is_the_beta_quantiles(k, n):
    lo, hi = clopper_pearson(k, n, 0.95)
    want_lo = 0.0 if k == 0 else stats.beta.ppf(0.025, k, n - k + 1)
    want_hi = 1.0 if k == n else stats.beta.ppf(0.975, k + 1, n - k)
    assert lo == pytest.approx(want_lo, abs=1e-12) and hi == pytest.approx(want_hi, abs=1e-12)
    if k == 0:  # zero failures in 59: the rule of three's ~3/n, exactly 1 - 0.025^(1/59)
        assert hi == pytest.approx(1.0 - 0.025 ** (1.0 / 59), rel=1e-9)


def test_the_quantile_interval_brackets_its_order_statistics():
    xs = list(range(1, 101))  # x_(i) = i
    q = quantile_interval(xs, 0.5, 0.95)
    # the median's 95 % ranks of n = 100: 40 and 61 (binomial(100, 0.5) quantiles)
    assert q["low"] == 40 and q["high"] == 61 and q["estimate"] == 50.5


# --------------------------------------------------------------------------- certificate
def _rows(values, fail_at=()):
    return [
        {"flight": i, "steady_rms_m": v, "steady_max_m": 2 * v, "altitude_margin_m": 80 - i,
         "max_bank_rad": 0.3 + 0.001 * i, "bank_limit_rad": 0.61,
         "verdict_status": "FAIL" if i in fail_at else "PASS",
         "status": "failed" if i in fail_at else "ok", "error": "", "cpu_s": 6.0,
         "conditions": json.dumps({"wind.speed_m_s": 1.0 + i})}
        for i, v in enumerate(values)
    ]  # fmt: skip


def test_the_certificate_of_59_flights(tmp_path):
    c = parse_conditions(_write(tmp_path, "name: x\n"))
    cert = certificate(_rows([0.1 * (i + 1) for i in range(59)], fail_at=(58,)), c,
                       {"name": "x"})  # fmt: skip
    # 59 flights: the one-sided 95 % bound is the largest, 5.9 m; the median the 30th, 3.0 m
    assert cert["steady_rms_m"]["upper_bound"] == pytest.approx(5.9)
    assert cert["steady_rms_m"]["median"] == pytest.approx(3.0)
    assert cert["p_fail"]["failed"] == 1 and cert["p_fail"]["of"] == 59
    assert cert["p_fail"]["interval"][1] == pytest.approx(stats.beta.ppf(0.975, 2, 58))
    assert cert["worst_altitude_margin_m"] == {"value": 22, "flight": 58}
    assert cert["failing"][0]["flight"] == 58


# --------------------------------------------------------------------------- validation table
def test_the_validation_table_says_inside_or_outside(tmp_path):
    from lab.rigs.validate import table, verdict_row

    cert = {"quantile": 0.95, "flights": {"judged": 59},
            "mission": {"name": "m", "autopilot": "px4", "profile": "auto", "duration_s": 180,
                        "steady_after_s": 60},
            "steady_rms_m": {"upper_bound": 1.0, "median": 0.8},
            "steady_max_m": {"upper_bound": 2.0, "median": 1.5}}  # fmt: skip
    ok = "PASS"
    rows = [
        verdict_row(cert, 0, {"wind.speed_m_s": 3.0},
                    {"steady_rms_m": 0.9, "steady_max_m": 1.9, "verdict": ok}),
        verdict_row(cert, 1, {"wind.speed_m_s": 4.0},
                    {"steady_rms_m": 1.2, "steady_max_m": 1.5, "verdict": "FAIL: limits"}),
        verdict_row(cert, 2, {}, {"steady_rms_m": 0.7, "steady_max_m": 1.4, "verdict": ok}),
        # a flight cut short (a lost link): its figures are of no steady window, and a small
        # error there must neither count as inside nor move the median
        verdict_row(cert, 3, {}, {"steady_rms_m": 0.1, "steady_max_m": 0.2,
                                  "verdict": "NOT JUDGED: tracked 20.4 s"}),
    ]  # fmt: skip
    assert [r["steady_rms_m_inside"] for r in rows] == [True, False, True, None]
    assert [r["judged"] for r in rows] == [True, True, True, False]
    text = table(cert, rows, "scripts/sitl px4 --certificate c.json --flights 4")
    assert "`scripts/sitl px4 --certificate c.json --flights 4`" in text
    assert "| 1 | wind 4.0 m/s from 0 deg | 1.200 | 1.000 | OUTSIDE |" in text
    assert "Outside the bound: 1 of 3 judged flights (1 of 4 NOT JUDGED" in text
    # the real median 0.9 (of the three judged) over the predicted 0.8
    assert "real / predicted 1.12 (within [0.67, 1.5])" in text


# --------------------------------------------------------------------------- end to end
@pytest.mark.slow
def test_a_tiny_certify_flies_3_flights_and_a_rerun_only_the_missing(tmp_path):
    cond = _write(tmp_path, "name: tiny\nduration_s: 40\nsteady_after_s: 15\n"
                  "target: {speed_m_s: [2, 4]}\nlink: {latency_s: [0, 0.02]}\n")  # fmt: skip
    out = tmp_path / "cert"
    env = {**os.environ, "MPF_PURE_PYTHON": os.environ.get("MPF_PURE_PYTHON", "1")}
    cmd = [sys.executable, "-m", "mpf_mavlink.cli", "certify", str(ROOT / "configs" /
           "bridge_px4.yaml"), "--autopilot", "px4", "--conditions", str(cond), "--out",
           str(out), "--workers", "1", "--set", "target.type=constant_turn"]  # fmt: skip
    p = subprocess.run([*cmd, "--flights", "2"], capture_output=True, text=True, env=env,
                       cwd=ROOT, timeout=600)  # fmt: skip
    assert p.returncode == 0, p.stderr[-2000:]
    with (out / "flights.csv").open() as f:
        assert sorted(int(r["flight"]) for r in csv.DictReader(f)) == [0, 1]
    p = subprocess.run([*cmd, "--flights", "3"], capture_output=True, text=True, env=env,
                       cwd=ROOT, timeout=600)  # fmt: skip
    assert p.returncode == 0, p.stderr[-2000:]
    assert "1 flights to fly (2 already in" in p.stderr  # the re-run flew only flight 2
    with (out / "flights.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(int(r["flight"]) for r in rows) == [0, 1, 2]
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["flights"]["in_table"] == 3 and cert["mission"]["profile"].startswith("auto")
    assert cert["flights"]["needed"] == 59
    for name in ("report.md", "ecdf.png", "conditions.png"):
        assert (out / name).is_file()


def test_certify_refuses_bad_input_leaving_nothing(tmp_path):
    out = tmp_path / "never"
    cond = _write(tmp_path, "name: x\nwind: {speed_m_s: [3, 1]}\n")
    p = subprocess.run(
        [sys.executable, "-m", "mpf_mavlink.cli", "certify", str(DEMO), "--autopilot", "px4",
         "--conditions", str(cond), "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )  # fmt: skip
    assert p.returncode == 2 and not out.exists()
    assert p.stderr.strip().count("\n") == 0 and "wind.speed_m_s" in p.stderr


# --------------------------------------------------------------------------- model error
def test_the_model_error_factors_are_the_calibration_tables():
    """The ratios are the committed tables' real / SIL column, to their printed 2 decimals."""
    import re
    from pathlib import Path

    from mpf_mavlink.certify.model_error import CALIBRATION_RATIOS, model_error

    root = Path(__file__).resolve().parents[1]
    for name, ratios in CALIBRATION_RATIOS.items():
        doc = (root / f"docs/calibration-{name.split('-')[0]}.md").read_text()
        rows = re.findall(r"^\| (\w+) \| [\d.]+ \| [^|]+ \| ([\d.]+) \|", doc, re.M)
        assert {m: float(r) for m, r in rows[: len(ratios)]} == ratios
    px4 = model_error("auto: px4-1.16-sih (autopilot part)")
    assert px4 is not None and px4["factor"] == 1.33 and px4["worst_mission"] == "r200"
    # ArduPlane's SIL was pessimistic on every mission: the bound is not shrunk
    ap = model_error("auto: arduplane-4.7 (autopilot part)")
    assert ap is not None and ap["factor"] == 1.0
    assert model_error("none (the plain emulation)") is None


def test_the_bound_carries_the_model_error(tmp_path):
    c = parse_conditions(_write(tmp_path, "name: x\n"))
    cert = certificate(_rows([0.1 * (i + 1) for i in range(59)]), c,
                       {"name": "x", "profile": "auto: px4-1.16-sih (autopilot part)"})  # fmt: skip
    # the SIL's bound 5.9 m (the largest of 59) times the profile's worst ratio 1.33
    assert cert["steady_rms_m"]["bound_with_model_error"] == pytest.approx(5.9 * 1.33)
    assert cert["steady_max_m"]["bound_with_model_error"] == pytest.approx(11.8 * 1.33)
    assert any("x 1.33" in s for s in cert["not_modelled"])
