"""JSBSim's own trim of the stock airframes, and the mission scale derived from it."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from mpf_mavlink.config import load_config
from mpf_mavlink.constants import GRAVITY_M_S2 as G
from sim.plant.airframe_trim import fdm_trim, mission_radius_m
from sim.sil import trim_of

ROOT = Path(__file__).resolve().parents[1]


def test_trim_of_a_stock_c172p_is_level_flight_whose_angle_of_attack_falls_with_speed():
    # Level flight: lift = weight, so C_L (and alpha, hence body pitch = alpha) falls as 1/V^2.
    slow, fast = fdm_trim("c172p", None, 35.0), fdm_trim("c172p", None, 55.0)
    assert slow.ok and fast.ok
    for t in (slow, fast):
        assert 0.0 < t.throttle < 1.0
        assert t.pitch_rad == pytest.approx(t.alpha_rad, abs=1e-3)  # gamma = 0
    assert slow.alpha_rad > fast.alpha_rad


def test_no_trim_beyond_the_airframes_power():
    # 90 m/s (175 kt) is far above a c172's maximum level speed (~120 kt): no trim with
    # throttle <= 1.
    assert not fdm_trim("c172p", None, 90.0).ok


def test_mission_radius_is_the_coordinated_turn_radius_at_the_usable_bank():
    r = mission_radius_m(45.0, math.radians(35.0), math.radians(5.0))
    assert r == pytest.approx(45.0**2 / (G * math.tan(math.radians(30.0))))
    with pytest.raises(ValueError):
        mission_radius_m(45.0, 0.05, 0.1)


def test_sil_takes_throttle_and_pitch_from_jsbsims_trim_when_asked():
    cfg = ROOT / "configs" / "sil_c172x.yaml"
    off = ["aircraft.gains_from_fdm=false"]
    own = trim_of(load_config(cfg, off + ["aircraft.trim_throttle=0.6"]))
    assert own == (0.6, None)  # the config's own numbers when trim_from_fdm is off
    thr, pitch = trim_of(load_config(cfg, off + ["aircraft.trim_from_fdm=true"]))
    tr = fdm_trim("c172x", None, 45.0, 488.0 + 300.0)
    assert (thr, pitch) == pytest.approx((tr.throttle, tr.pitch_rad))
    with pytest.raises(ValueError, match="aircraft.trim_airspeed_m_s"):
        trim_of(
            load_config(
                cfg,
                [
                    *off,
                    "aircraft.trim_from_fdm=true",
                    "aircraft.trim_airspeed_m_s=90",
                    "aircraft.airspeed_max_m_s=100",
                ],
            )
        )
