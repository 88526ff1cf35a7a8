"""The autopilot profile (sim/autopilot/profile.py): strict loading, and that each emulation does
what its docstring says on synthetic states (no SITL, no JSBSim)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from mpf_mavlink.config.autopilot_profile import (
    AttitudeResponse,
    AutopilotProfile,
    EstimatorModel,
    TurnResponse,
    load_profile,
)
from mpf_mavlink.errors import ConfigError
from sim.autopilot.profile import AttitudeShaper, RateWander, StateEstimate

ROOT = Path(__file__).resolve().parents[1]
G = 9.80665


@dataclasses.dataclass(frozen=True)
class _St:
    t: float
    euler: tuple[float, float, float]
    pqr: np.ndarray
    airspeed: float
    velocity_ned: np.ndarray
    position_ned: np.ndarray
    wind_ned: np.ndarray
    R_B_N: np.ndarray


def _turn(t: float, bank: float, k_plant: float, v: float = 22.0) -> _St:
    """A steady level turn flown at ``bank`` by a plant turning k_plant x the textbook."""
    psid = k_plant * G * math.tan(bank) / v
    chi = psid * t
    return _St(t, (bank, 0.0, chi), np.array((0.0, psid * math.sin(bank), psid * math.cos(bank))),
               v, np.array((v * math.cos(chi), v * math.sin(chi), 0.0)), np.zeros(3), np.zeros(3),
               np.eye(3))  # fmt: skip


@pytest.mark.parametrize("name", ["arduplane-4.7.yaml", "px4-1.16-sih.yaml"])
def test_shipped_profiles_load(name):
    p = load_profile(ROOT / "configs" / "autopilots" / name)
    assert p.autopilot in ("arduplane", "px4")


def test_unknown_key_is_a_one_line_error_naming_it(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("autopilot: arduplane\nturn:\n  turn_gian: 0.7\n")
    with pytest.raises(ConfigError, match=r"turn\.turn_gian") as e:
        load_profile(f)
    assert "\n" not in str(e.value)
    f.write_text("autopilot: arduplane\nturn:\n  turn_gain: 3.0\n")
    with pytest.raises(ConfigError, match=r"turn\.turn_gain"):
        load_profile(f)


def test_reported_bank_gives_the_profiles_turn_per_bank():
    # the plant turns 0.93x the textbook (the X8); the firmware's airframe 0.745x: in a steady
    # turn the reported bank must satisfy psi_dot = 0.745 g tan(bank_reported) / V
    prof = AutopilotProfile(turn=TurnResponse(turn_gain=0.745))
    est = StateEstimate(prof)
    bank = math.radians(20.0)
    for i in range(8000):  # 80 s at 100 Hz: ten KP_TAU_S of learning the plant's own gain
        rep = est(_turn(i * 0.01, bank, 0.93))
    st = _turn(80.0, bank, 0.93)
    psid = st.pqr[1] * math.sin(bank) + st.pqr[2] * math.cos(bank)
    k_seen = psid / (G * math.tan(rep.euler[0]) / st.airspeed)
    assert k_seen == pytest.approx(0.745, rel=1e-3)


def test_apparent_wind_is_lagged_and_turned_by_the_turn():
    # the steady state of a first-order lag of a vector rotating at omega: (a + i s)/(1 + i w tau)
    e = EstimatorModel(wind_apparent_along_m_s=0.4, wind_apparent_side_m_s=-0.1, wind_tau_s=10.0)
    est = StateEstimate(AutopilotProfile(estimator=e))
    bank, dt = math.radians(24.0), 0.01
    for i in range(12000):  # 120 s: 12 time constants
        st = _turn(i * dt, bank, 1.0)
        rep = est(st)
    v = st.velocity_ned / np.linalg.norm(st.velocity_ned)
    along = float(rep.wind_ned[:2] @ v[:2])
    right = float(rep.wind_ned[0] * -v[1] + rep.wind_ned[1] * v[0])
    w = G * math.tan(bank) / st.airspeed
    want = complex(0.4, -0.1) / complex(1.0, w * 10.0)
    assert along == pytest.approx(want.real, abs=2e-3)
    assert right == pytest.approx(want.imag, abs=2e-3)


def test_attitude_shaper_settles_at_gain_times_command_plus_bias_after_the_dead_time():
    r = AttitudeResponse(roll_delay_s=0.2, roll_tau_s=0.9, roll_gain=0.95, roll_bias_rad=0.01)
    sh = AttitudeShaper(r, 0.01, native_tau_s=0.4)
    out = [sh(0.3, 0.0)[0] for _ in range(20)]  # the first 0.2 s: the dead time (initial value)
    assert out[-1] == pytest.approx(0.95 * 0.3 + 0.01)  # first sample initialises at the command
    sh = AttitudeShaper(r, 0.01, native_tau_s=0.4)
    sh(0.0, 0.0)
    ys = [sh(0.3, 0.0)[0] for _ in range(2000)]
    assert ys[15] == pytest.approx(0.01)  # still inside the dead time
    assert ys[-1] == pytest.approx(0.95 * 0.3 + 0.01, abs=1e-6)


def _through_native_loop(ys: list[float], tau: float, dt: float) -> list[float]:
    """The SIL's own attitude loop as a first-order lag of time constant ``tau``."""
    out, y = [], ys[0]
    for x in ys:
        y += (1.0 - math.exp(-dt / tau)) * (x - y)
        out.append(y)
    return out


@pytest.mark.parametrize("tau_fw", [0.15, 0.9])
def test_shaper_and_the_sil_loop_together_follow_the_firmwares_lag(tau_fw):
    # the shaper's lead-lag cancels the SIL loop's own 0.4 s lag and leaves the firmware's:
    # a step reaches 63 % one firmware time constant after the dead time, whether the firmware
    # is faster than the SIL's loop (ArduPlane's roll, 0.15 s) or slower
    dt, delay, tau_n = 0.002, 0.24, 0.4
    r = AttitudeResponse(roll_delay_s=delay, roll_tau_s=tau_fw)
    sh = AttitudeShaper(r, dt, native_tau_s=tau_n)
    sh(0.0, 0.0)
    ys = _through_native_loop([0.0] + [sh(0.3, 0.0)[0] for _ in range(8000)], tau_n, dt)
    i63 = next(i for i, y in enumerate(ys) if y >= 0.632 * 0.3)
    # one sample of discretisation each for the delay line, the lead-lag and the loop
    assert i63 * dt == pytest.approx(delay + tau_fw, abs=3 * dt + 0.01 * tau_fw)
    assert ys[-1] == pytest.approx(0.3, abs=1e-4)


def test_turn_emulation_holds_the_turn_per_bank_at_every_instant_of_a_varying_turn():
    # an orbit in wind: the bank swings 14-35 deg once per ~43 s orbit; the firmware's airframe
    # turns 0.745x the textbook at every instant, so the reported bank must give that turn gain
    # all the way round (a low-passed offset lagged it, +-3 % around a wind orbit)
    prof = AutopilotProfile(turn=TurnResponse(turn_gain=0.745))
    est = StateEstimate(prof)
    dt, k_plant, v = 0.02, 0.93, 22.0
    ks = []
    for i in range(int(130 / dt)):
        t = i * dt
        bank = math.radians(24.5 + 10.5 * math.sin(2 * math.pi * t / 43.0))
        st = _turn(t, bank, k_plant, v)
        rep = est(st)
        psid = st.pqr[1] * math.sin(bank) + st.pqr[2] * math.cos(bank)
        if t > 80:  # ten KP_TAU_S of learning the plant's own gain (in the slow roll)
            ks.append(psid / (G * math.tan(rep.euler[0]) / v))
    assert max(ks) == pytest.approx(0.745, rel=2e-3)
    assert min(ks) == pytest.approx(0.745, rel=2e-3)


def test_turn_emulation_in_gusts_reports_the_plants_mean_turn_per_bank():
    # SIM_WIND_TURB's vertical gusts make a banked plant's heading rate noisy (the lift's
    # horizontal part) while its roll is held; a firmware reports its own roll, so the turn per
    # reported bank must stay the profile's, neither creeping up nor wandering with the gusts.
    # White heading-rate noise of half the turn's own rate at 100 Hz (a third of the per-sample
    # ratios outside 0.5-1.5 of the textbook; SIM_WIND_TURB 2 m/s puts more there): the fit's
    # standard error is 0.5 sqrt(dt / (2 KP_MEMORY_S)) of the plant's gain (the variance of a
    # running mean of white noise), 0.5 % here; allowed: 4 of them
    from sim.autopilot.profile import KP_MEMORY_S

    prof = AutopilotProfile(turn=TurnResponse(turn_gain=0.745))
    est = StateEstimate(prof)
    rng = np.random.default_rng(3)
    dt, k_plant, v, bank = 0.01, 0.93, 22.0, math.radians(20.0)
    psid0 = k_plant * G * math.tan(bank) / v
    se = 0.5 * math.sqrt(dt / (2.0 * KP_MEMORY_S))
    ks = []
    for i in range(int(3 * KP_MEMORY_S / dt)):
        t = i * dt
        psid = psid0 * (1.0 + 0.5 * float(rng.standard_normal()))
        st = _turn(t, bank, k_plant, v)
        st = dataclasses.replace(
            st, pqr=np.array((0.0, psid * math.sin(bank), psid * math.cos(bank)))
        )
        rep = est(st)
        if t > KP_MEMORY_S:  # the fit's memory full
            ks.append(psid0 / (G * math.tan(rep.euler[0]) / v) / 0.745)
    ks = np.array(ks)
    assert abs(ks.mean() - 1.0) < 4 * se  # no bias: the mean gain is the profile's
    assert ks.max() - ks.min() < 2 * 4 * se  # no wander beyond the fit's own error


def test_airspeed_scale_changes_the_report_not_what_the_autopilot_flies():
    # real ArduPlane reports 0.936 of the true airspeed where the SIL's EAS is 0.972 of it: the
    # report is scaled, and the emulated autopilot's loops undo the scale (they fly the truth)
    from sim.autopilot.emulation import flown_state

    e = EstimatorModel(airspeed_scale=0.963)
    rep = StateEstimate(AutopilotProfile(estimator=e))(_turn(1.0, 0.2, 1.0, 22.0))
    assert rep.airspeed == pytest.approx(0.963 * 22.0)
    assert flown_state(rep, 0.963).airspeed == pytest.approx(22.0)
    assert flown_state(rep, 1.0) is rep


def test_rate_wander_has_the_configured_sigma_and_every_seed_its_own_draw():
    r = AttitudeResponse(roll_rate_wander_rad_s=0.03, rate_wander_tau_s=1.0)
    a, b = RateWander(r, 0.05, seed=0), RateWander(r, 0.05, seed=1)
    xa = np.array([a() for _ in range(40000)])  # 2000 correlation times
    xb = np.array([b() for _ in range(100)])
    # the sample sigma of 2000 independent-ish stretches: within ~3/sqrt(2 * 2000 / 2) of 0.03
    assert float(np.std(xa)) == pytest.approx(0.03, rel=0.1)
    assert not np.allclose(xa[:100], xb)


def test_config_key_checks_the_file_and_the_flavour():
    from mpf_mavlink.config.schema import load_config

    cfg = ROOT / "configs" / "bridge_arduplane.yaml"
    ok = load_config(
        cfg, ["sil.link=udp", "sil.autopilot_profile=configs/autopilots/arduplane-4.7.yaml"]
    )
    assert ok.section("sil").profile_path(ok.source).is_file()
    with pytest.raises(ConfigError, match="sil.autopilot_profile.*px4 profile"):
        load_config(
            cfg, ["sil.link=udp", "sil.autopilot_profile=configs/autopilots/px4-1.16-sih.yaml"]
        )
    with pytest.raises(ConfigError, match="sil.autopilot_profile.*no such"):
        load_config(cfg, ["sil.link=udp", "sil.autopilot_profile=nowhere.yaml"])


def _R(roll: float, pitch: float, yaw: float) -> np.ndarray:
    from sim.autopilot.profile import _euler_to_R

    return _euler_to_R(roll, pitch, yaw)


def test_reported_rates_are_consistent_with_the_reported_bank():
    # the plant banks less than it reports (its own turn per bank is higher): the reported gyro
    # rates must be the angular velocity in the REPORTED body frame, so that the heading rate
    # the bridge's adapter derives from them, (q sin(phi) + r cos(phi)) / cos(theta) with the
    # reported phi, is the plant's true heading rate
    prof = AutopilotProfile(turn=TurnResponse(turn_gain=0.745))
    est = StateEstimate(prof)
    bank, v, k = math.radians(20.0), 22.0, 0.93
    psid = k * G * math.tan(bank) / v
    for i in range(2000):
        t = i * 0.01
        st = dataclasses.replace(_turn(t, bank, k, v), R_B_N=_R(bank, 0.0, psid * t))
        rep = est(st)
    phi, theta = rep.euler[0], rep.euler[1]
    q, r = float(rep.pqr[1]), float(rep.pqr[2])
    assert phi > bank + 0.02  # the emulation reports more bank than the plant flies
    assert (q * math.sin(phi) + r * math.cos(phi)) / math.cos(theta) == pytest.approx(
        psid, rel=1e-3
    )


def test_position_lead_moves_the_reported_position_along_the_ground_velocity():
    est = StateEstimate(AutopilotProfile(estimator=EstimatorModel(position_lead_s=0.025)))
    st = _turn(3.0, math.radians(24.0), 1.0)
    rep = est(st)
    assert np.allclose(rep.position_ned - st.position_ned, 0.025 * st.velocity_ned)
    assert np.allclose(rep.velocity_ned, st.velocity_ned)  # the velocity is not led


def test_gauss_markov_errors_have_their_sigma_and_correlation_time_and_every_seed_its_own():
    from sim.autopilot.profile import GaussMarkov

    dt, tau, sig = 0.1, 2.0, 0.02
    gm = GaussMarkov((sig,), (tau,), np.random.default_rng(0))
    x = np.array([gm(i * dt)[0] for i in range(100000)])  # 5000 correlation times
    assert float(np.std(x)) == pytest.approx(sig, rel=0.06)  # ~3 / sqrt(2 * 5000 / 2) relative
    k = int(tau / dt)
    r = float(np.mean((x[:-k] - x.mean()) * (x[k:] - x.mean())) / np.var(x))
    assert r == pytest.approx(math.exp(-1.0), abs=0.05)
    e = EstimatorModel(attitude_wander_rad=(0.017, 0.01, 0.017), horizontal_wander_m=0.2)
    a = StateEstimate(AutopilotProfile(estimator=e), seed=0)
    b = StateEstimate(AutopilotProfile(estimator=e), seed=1)
    st = _turn(1.0, 0.3, 1.0)
    assert not np.allclose(a(st).euler, b(st).euler)
    assert not np.allclose(a(st).position_ned, b(st).position_ned)


def test_the_ekf_error_fit_recovers_a_gauss_markov_process():
    from lab.calibration.identify import _gm_fit
    from sim.autopilot.profile import GaussMarkov

    dt, tau, sig = 0.1, 3.0, 0.25
    gm = GaussMarkov((sig,), (tau,), np.random.default_rng(3))
    x = np.array([gm(i * dt)[0] for i in range(18000)])  # 30 min, 600 correlation times
    s, t = _gm_fit(x, dt)
    # 600 correlation times: sigma to ~3 / sqrt(600) ~ 12 %, tau to ~20 %
    assert s == pytest.approx(sig, rel=0.15)
    assert t == pytest.approx(tau, rel=0.25)


def test_turn_per_bank_fit_of_a_gusty_turn_recovers_the_gain_and_its_window_scatter():
    # the dataflash analysis of identify (--dataflash): a turn of gain 0.74 whose heading rate
    # carries white noise of 0.3 of its own rate at 25 Hz (ATT's rate): the whole fit is the gain
    # to its standard error, and a window of w s scatters by 0.3 / sqrt(25 w) of it (white
    # noise's mean over 25 w samples); allowed: 30 % on that scatter (50 windows of 5 s: the
    # sample sd of 50 draws is good to ~1/sqrt(2 * 49) = 10 %, three of those)
    from lab.calibration.identify import turn_per_bank_windows

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 250.02, 0.04)  # 250 s: fifty windows of 5 s
    roll = np.radians(22.0 + 8.0 * np.sin(2 * np.pi * t / 43.0))
    v = np.full_like(t, 22.0)
    psid = 0.74 * G * np.tan(roll) / v * (1.0 + 0.3 * rng.standard_normal(t.size))
    r = turn_per_bank_windows(t, roll, psid, v, windows=(5.0,))
    assert r["turn_gain"] == pytest.approx(0.74, abs=4 * 0.74 * 0.3 / math.sqrt(t.size))
    w5 = r["windows"]["5"]
    assert w5["n"] == 50
    assert w5["sd_rel"] == pytest.approx(0.3 / math.sqrt(25 * 5.0), rel=0.3)


def test_shaper_without_an_identified_attitude_loop_passes_the_command_through():
    # the PX4 profile identifies no attitude loop (body-rate offboard): the SIL's own stays
    sh = AttitudeShaper(AttitudeResponse(), 0.01, native_tau_s=0.4)
    assert [sh(x, -x) for x in (0.0, 0.3, 0.1)] == [(0.0, -0.0), (0.3, -0.3), (0.1, -0.1)]
