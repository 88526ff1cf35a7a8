"""The climb check's capability at altitude (bridge/preflight.py, issue 25)."""

from __future__ import annotations

import pytest

from mpf_mavlink.bridge.preflight import density_ratio, run_checks
from mpf_mavlink.config import load_config

CLIMBING = "configs/compare/helix_climbing_target.yaml"


def test_density_ratio_is_the_isa_table():
    # ISA (ICAO Doc 7488 table): rho(1000 m) = 1.1117, rho(3000 m) = 0.9093, rho0 = 1.2250 kg/m^3.
    # The table is by geometric height, the formula takes heights as geopotential (1.4 m lower
    # at 3000 m: 1.5e-4 of the ratio), plus the table's rounding (5e-5 kg/m^3 each): 3e-4.
    assert density_ratio(0.0, 0.0) == 1.0
    assert density_ratio(1000.0, 0.0) == pytest.approx(1.1117 / 1.2250, abs=3e-4)
    assert density_ratio(3000.0, 1000.0) == pytest.approx(0.9093 / 1.1117, abs=3e-4)


def _climb(overrides: list[str]):
    cfg = load_config(CLIMBING, overrides)
    return next(r for r in run_checks(cfg) if r.name == "climb")


def test_climb_capability_is_scaled_to_the_top_of_a_climbing_path():
    # 240 s of a target climbing 1.5 m/s under a circle 100 m above it, from sea level: the path
    # tops at 100 + 360 = 460 m; the aircraft starts at 100 m (the capability is its there)
    r = _climb(["sim.duration_s=240"])
    top = r.figures["top_asl_m"]
    assert top == pytest.approx(460.0, abs=0.2)  # the horizon's last sample: 0.05 s x 1.5 m/s
    k = density_ratio(top, 100.0)
    assert r.figures["density_ratio"] == pytest.approx(k)
    assert r.figures["max_climb_m_s"] == pytest.approx(4.1 * k, abs=0.005)  # rounded to 0.01
    assert r.figures["max_sink_m_s"] == pytest.approx(1.5 * k, abs=0.005)
    assert "460 m above sea level" in r.summary


def test_a_level_path_keeps_the_capability():
    r = _climb(["target.climb_rate_m_s=0", "sim.duration_s=120"])
    assert r.figures["density_ratio"] == 1.0
    assert r.figures["max_climb_m_s"] == 4.1 and r.figures["max_sink_m_s"] == 1.5
