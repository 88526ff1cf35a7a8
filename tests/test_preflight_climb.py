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


# ------------------------------------------------ gusts over several windows (issue 25, round 4)
def _dryden_window_time_domain(sigma: float, tau: float, T: float) -> tuple[float, float]:
    """(sigma_T, nu_0) of a T-s mean of Dryden vertical turbulence from its correlation in time,
    R(x) = sigma^2 (1 - x / (2 tau)) exp(-x / tau) (MIL-F-8785C, tau = L_w / V), independently of
    the spectrum :func:`windowed_gust` integrates: var = (2 / T) int_0^T (1 - x / T) R(x) dx, and
    the mean's derivative (w(t + T) - w(t)) / T has variance m2 = 2 (R(0) - R(T)) / T^2."""
    import math

    from scipy import integrate

    def R(x: float) -> float:
        return sigma * sigma * (1.0 - x / (2.0 * tau)) * math.exp(-x / tau)

    var = 2.0 / T * integrate.quad(lambda x: (1.0 - x / T) * R(x), 0.0, T, limit=200)[0]
    m2 = 2.0 * (R(0.0) - R(T)) / (T * T)
    return math.sqrt(var), math.sqrt(m2 / var) / (2.0 * math.pi)


@pytest.mark.parametrize("T", [2.0, 9.0, 35.0, 52.0])
def test_windowed_gust_is_the_dryden_correlation_averaged_over_the_window(T):
    from mpf_mavlink.core.guidance.checks import windowed_gust

    # light turbulence at 430 m ASL (sigma_w 1.30 m/s, L_w 399 m) flown at 16 m/s. Tolerances:
    # the spectrum is integrated on 4000 log-spaced points over 7 decades (sigma_T within
    # 1e-4 of the time-domain figure); nu_0 needs the w^2 tail, which the grid's top
    # (1000 / tau rad/s) cuts: 0.4 % at T = 2 s, less for longer windows
    s_t, nu = windowed_gust(1.30, 399.0, 16.0, T)
    s_ref, nu_ref = _dryden_window_time_domain(1.30, 399.0 / 16.0, T)
    assert s_t == pytest.approx(s_ref, rel=1e-3)
    assert nu == pytest.approx(nu_ref, rel=1e-2)


def test_gust_odds_is_rices_count_over_the_horizon():
    import math

    import numpy as np

    from mpf_mavlink.core.guidance.checks import gust_odds, vertical_gust_scale, windowed_gust

    # a steady demand 1 m/s inside the capability, a 3 m reserve, one 10 s window, 430 m ASL:
    # a 10 s mean downdraft above u = (3 + 1 m tolerance) / 10 + 1 = 1.4 m/s costs more than the
    # reserve; windows that start within T / 2 of the horizon's end are not whole: 595 s count
    dt = 0.05
    ts = np.arange(0.0, 600.0 + dt / 2, dt)
    need = np.full(len(ts), -1.0)
    res = np.full(len(ts), 3.0)
    o = gust_odds(ts, need, res, "light", np.full(len(ts), 430.0), 16.0, windows_s=(10.0,))
    s_w, L_w = vertical_gust_scale("light", 430.0)
    s_t, nu = windowed_gust(s_w, L_w, 16.0, 10.0)
    n_exp = 595.0 * nu * math.exp(-0.5 * (1.4 / s_t) ** 2)
    # the count's sum has one sample per dt over 595 s: within dt / 595 of the integral
    assert o.p == pytest.approx(1.0 - math.exp(-n_exp), rel=2e-3)
    assert o.window_s == 10.0 and o.gust_m_s == pytest.approx(1.4, abs=1e-9)
    # no turbulence, no odds; a larger reserve, smaller odds
    assert gust_odds(ts, need, res, "none", np.full(len(ts), 430.0), 16.0).p == 0.0
    o2 = gust_odds(ts, need, res + 5.0, "light", np.full(len(ts), 430.0), 16.0, windows_s=(10.0,))
    assert o2.p < o.p


def test_climb_check_refuses_a_climb_the_turbulence_most_likely_breaks():
    import numpy as np

    from mpf_mavlink.core.guidance.checks import GUST_REFUSE_P, GUST_WARN_P, climb_feasibility

    # 2.5 m/s of climb at 700 m ASL for 600 s against 4.1: 1.6 m/s spare, sigma_w ~2.1 m/s. Over
    # the reserve of slowing 16 -> 14 m/s (3.06 m) a gust of ~2 m/s for 10 s (1 sigma of the
    # 10 s mean) is enough: certain over 600 s -> refused, naming the window and the odds
    ts = np.arange(0.0, 600.0 + 0.05, 0.05)
    g = np.arcsin(2.5 / 16.0)
    W1 = np.tile([np.cos(g), 0.0, -np.sin(g)], (len(ts), 1))
    h = np.full(len(ts), 700.0)
    r3 = np.full(len(ts), 3.06)
    r = climb_feasibility(
        ts, W1, 16.0, 14.0, 18.0, 4.1, 1.5, turbulence=("light", h, r3, np.full(len(ts), 3.5))
    )
    assert r.status == "fail" and r.figures["gust_p_down"] >= GUST_REFUSE_P
    assert "downdraft" in r.summary and "likely over the 600 s" in r.summary
    # the same climb near the sea (sigma_w 0.76 m/s): odds below the warning's
    r = climb_feasibility(
        ts, W1, 16.0, 14.0, 18.0, 4.1, 1.5,
        turbulence=("light", np.full(len(ts), 100.0), r3, np.full(len(ts), 3.5)),
    )  # fmt: skip
    assert r.figures["gust_p_down"] < GUST_WARN_P


def test_energy_reserves_are_the_adapters_airspeeds():
    import numpy as np

    from mpf_mavlink.bridge.preflight import energy_reserves
    from mpf_mavlink.constants import GRAVITY_M_S2 as G

    # the climbing target (1.5 m/s, 4.1 m/s capability, 3 m/s / 10 s design downdraft): the
    # reserve set-point is min(18, sqrt(16^2 + 2 g 4)) = 18, so the climb reserve is
    # (18^2 - 14^2) / (2 g) = 6.52 m and none is left toward 18 m/s
    cfg = load_config(CLIMBING, ["sim.duration_s=240"])
    ts = np.arange(0.0, 240.0, 0.05)
    P = np.zeros((len(ts), 3))
    P[:, 2] = -100.0 - 1.5 * ts
    up, dn = energy_reserves(cfg, ts, P)
    assert up[-1] == pytest.approx((18.0**2 - 14.0**2) / (2 * G), rel=1e-9)
    assert dn[-1] == pytest.approx(0.0, abs=1e-9)
    # a level path, or the reserve off: the set-point's 16 m/s
    P[:, 2] = -100.0
    up, dn = energy_reserves(cfg, ts, P)
    assert up[0] == pytest.approx((16.0**2 - 14.0**2) / (2 * G), rel=1e-9)
    assert dn[0] == pytest.approx((18.0**2 - 16.0**2) / (2 * G), rel=1e-9)
