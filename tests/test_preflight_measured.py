"""The pre-engage checks on the measured state (bridge/preflight.py MeasuredInputs, issue 40):
the autopilot's wind, its airspeed and a live target's estimated motion replace what the config
assumes."""

from __future__ import annotations

import math

import pytest

from mpf_mavlink.bridge.controller import target_as_constant_turn
from mpf_mavlink.bridge.preflight import MeasuredInputs, run_checks, wind_words
from mpf_mavlink.config import load_config
from mpf_mavlink.config.scenario import build_target
from mpf_mavlink.config.schema import TargetConfig

G = 9.80665
AP = "configs/bridge_arduplane.yaml"
# the shipped ArduPlane mission about a target held still: a 150 m ground circle at 22 m/s,
# turn gain 0.745, bank limit 0.61 rad (34.95 deg) less the 5 deg margin
STILL = ["target.speed_m_s=0"]


def _bank_deg(v: float, w: float, r: float = 150.0, k: float = 0.745) -> float:
    """The peak bank a ground circle of radius r needs at airspeed v in a steady wind w: on the
    downwind side the ground speed is v + w along the air velocity, so the air-relative
    acceleration (steady wind: the inertial one) is (v + w)^2 / r, all of it normal to the air
    velocity; tan(bank) = a / g, asked of an airframe that turns k of the coordinated turn."""
    return math.degrees(math.atan((v + w) ** 2 / (G * r) / k))


def _by_name(results):
    return {r.name: r for r in results}


def test_the_measured_wind_replaces_the_configs_and_is_named_in_the_failure():
    cfg = load_config(AP, STILL)
    calm = _by_name(run_checks(cfg))["feasibility"]
    # (22 + 0)^2 / (9.81 150) / 0.745: 23.8 deg; the check differences wd1 in 0.05 s steps over
    # a 150 m circle: 0.3 deg covers that discretisation
    assert math.degrees(calm.figures["peak_bank_rad"]) == pytest.approx(_bank_deg(22, 0), abs=0.3)
    assert calm.ok
    m = MeasuredInputs((-7.7, 0.0, 0.0), "WIND")  # 7.7 m/s blowing south: from the north
    r = _by_name(run_checks(cfg, measured=m))
    f = r["feasibility"]
    # (22 + 7.7)^2 / (9.81 150) / 0.745: 38.8 deg, beyond 34.95 - 5 deg
    assert math.degrees(f.figures["peak_bank_rad"]) == pytest.approx(_bank_deg(22, 7.7), abs=0.3)
    assert not f.ok
    assert f.summary.startswith(
        f"peak bank {math.degrees(f.figures['peak_bank_rad']):.1f} deg needed with the measured "
        "wind 7.7 m/s from 0 deg (WIND), limit 29.9 deg"
    )
    # the margin without WIND_COV's variance: max(1 m/s, 20 % of 7.7) = 1.54 m/s
    wm = r["wind_margin"]
    assert wm.figures["wind_margin_m_s"] == pytest.approx(1.54)
    assert wm.status == "warn" and "9.2 m/s from 0 deg" in wm.summary


def test_a_calm_measured_wind_passes_what_the_configs_wind_would_refuse():
    # the config assumes the SIL's 7.7 m/s; the autopilot measures 1 m/s: the measurement decides
    cfg = load_config(AP, [*STILL, "sil.link=udp", "sil.wind_ned_m_s=[-7.7,0,0]"])
    assert not _by_name(run_checks(cfg))["feasibility"].ok
    f = _by_name(run_checks(cfg, measured=MeasuredInputs((0.0, 1.0, 0.0), "WIND_COV")))
    assert f["feasibility"].ok
    bank = math.degrees(f["feasibility"].figures["peak_bank_rad"])
    assert bank == pytest.approx(_bank_deg(22, 1.0), abs=0.3)
    assert "1.0 m/s from 270 deg (WIND_COV)" in f["feasibility"].summary


def test_the_wind_margin_is_two_sigma_of_the_variance_when_the_autopilot_sends_one():
    m = MeasuredInputs((3.0, 4.0, 0.0), "WIND_COV", wind_var_m2_s2=0.25)
    assert m.wind_margin_m_s()[0] == pytest.approx(1.0)  # 2 sqrt(0.25)
    # without it: max(1, 0.2 * 5) = 1 m/s; at 10 m/s, 20 %: 2 m/s
    assert MeasuredInputs((3.0, 4.0, 0.0), "WIND").wind_margin_m_s()[0] == pytest.approx(1.0)
    assert MeasuredInputs((0.0, 10.0, 0.0), "WIND").wind_margin_m_s()[0] == pytest.approx(2.0)
    # from: atan2(-e, -n); blowing toward the east is a wind from 270 deg
    assert wind_words((0.0, 5.0, 0.0), "WIND") == "5.0 m/s from 270 deg (WIND)"


def test_a_faster_measured_airspeed_warns_when_it_needs_more_bank():
    cfg = load_config(AP, STILL)
    r = _by_name(run_checks(cfg, measured=MeasuredInputs((0.0, 0.0, 0.0), "WIND", None, 26.0)))
    a = r["measured_airspeed"]
    # 26^2 / (9.81 150) / 0.745: 31.7 deg > 29.9: a warning (it slows to 22 after engaging)
    assert math.degrees(a.figures["peak_bank_rad"]) == pytest.approx(_bank_deg(26, 0), abs=0.3)
    assert a.status == "warn" and r["feasibility"].ok
    # at the law's airspeed (within 0.5 m/s) there is nothing to add
    r = _by_name(run_checks(cfg, measured=MeasuredInputs((0.0, 0.0, 0.0), "WIND", None, 22.3)))
    assert "measured_airspeed" not in r


def test_a_live_targets_estimate_is_judged_like_a_scripted_target():
    # the estimate at mission time 0 of a target turning and climbing, as a constant turn: the
    # same motion (the state at t = 0 of ConstantTurn rebuilt from it is the original's)
    tc = TargetConfig(type="constant_turn", position_ned_m=(10.0, -5.0, -100.0), speed_m_s=3.0,
                      heading_rad=1.2, turn_rate_rad_s=0.01, climb_rate_m_s=0.5)  # fmt: skip
    st = build_target(tc).state(0.0)
    got = target_as_constant_turn(st, TargetConfig)
    assert got.position_ned_m == pytest.approx(tc.position_ned_m, abs=1e-9)
    assert got.speed_m_s == pytest.approx(3.0, abs=1e-9)
    assert got.heading_rad == pytest.approx(1.2, abs=1e-9)
    assert got.turn_rate_rad_s == pytest.approx(0.01, abs=1e-9)
    assert got.climb_rate_m_s == pytest.approx(0.5, abs=1e-9)
    # with a live target only the gain condition can be checked ... unless it is measured
    cfg = load_config(AP, ["target.type=mavlink", "mavlink.target_sysid=2"])
    assert [r.name for r in run_checks(cfg, scripted_target=False)] == ["gain_condition"]
    m = MeasuredInputs((0.0, 0.0, 0.0), "WIND", target=got)
    names = [r.name for r in run_checks(cfg, scripted_target=False, measured=m)]
    assert "feasibility" in names and "assumption_1" in names


def test_wind_cov_carries_its_variance_and_unknown_is_none():
    # WIND_COV.var_horiz (m^2/s^2): the margin is 2 sigma of it; 0 and NaN are MAVLink's
    # "unknown" (our SIL sends 0), WIND has none
    from mpf_mavlink.mavlink import dialect
    from mpf_mavlink.mavlink.codec import decode_wind_cov

    def cov(var: float):
        return dialect.MAVLink_wind_cov_message(1_000_000, 1.0, 2.0, 0.0, var, 0.0, 100.0, 0, 0)

    assert decode_wind_cov(cov(0.36)).var_horiz_m2_s2 == pytest.approx(0.36)
    assert decode_wind_cov(cov(0.0)).var_horiz_m2_s2 is None
    assert decode_wind_cov(cov(float("nan"))).var_horiz_m2_s2 is None
    m = MeasuredInputs((1.0, 2.0, 0.0), "WIND_COV", decode_wind_cov(cov(0.36)).var_horiz_m2_s2)
    assert m.wind_margin_m_s()[0] == pytest.approx(1.2)  # 2 sqrt(0.36)
