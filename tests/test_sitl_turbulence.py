"""ArduPilot SITL's random wind (SIM_WIND_TURB) in our SIL: sim/plant/sitl_turbulence.py, the
JSBSim plant's per-step injection and ``sil.wind_turbulence_m_s``.

The statistics are asserted against the firmware's process written out here from its
definition (a = 0.98 low-pass of 10 T (1 - a) n per step, a fresh direction per step), with
tolerances from each series' own batch-means standard error (the estimates are of correlated
samples, so the i.i.d. formula would be too tight): 4.5 standard errors, a false failure well
under 1e-4 per assertion, and each standard error is checked to be small enough (a few %) that
a factor-of-two mistake in the gain, the rate or the averaging fails.
"""

from __future__ import annotations

import os
import socket

import numpy as np
import pytest

from sim.plant.sitl_turbulence import (
    SITL_PHYSICS_RATE_HZ,
    SitlTurbulence,
    expected_statistics,
)

T = 2.0  # SIM_WIND_TURB of the real flight (m/s)
A = 0.98
# the firmware's stationary variance of the low-passed speeds: (10 T (1 - a))^2 / (1 - a^2)
S2 = (10.0 * T * (1.0 - A)) ** 2 / (1.0 - A * A)
K_SE = 4.5


def batch_mean(y: np.ndarray, batches: int = 60) -> tuple[float, float]:
    """The mean of ``y`` and its standard error from the spread of ``batches`` batch means."""
    n = len(y) // batches * batches
    b = y[:n].reshape(batches, -1).mean(axis=1)
    return float(y.mean()), float(b.std(ddof=1) / np.sqrt(batches))


def assert_moment(y: np.ndarray, expected: float, scale: float, max_rel_se: float) -> None:
    m, se = batch_mean(y)
    assert se < max_rel_se * scale, f"too few samples: s.e. {se:.3g} of scale {scale:.3g}"
    assert abs(m - expected) < K_SE * se, f"{m:.5g} vs {expected:.5g} (s.e. {se:.2g})"


def check_series(w: np.ndarray, dt: float) -> None:
    """Variance and lag-one covariance of each axis against :func:`expected_statistics`."""
    e = expected_statistics(T, dt)
    for axis, var, lag1 in (
        (0, e.horizontal_var, e.horizontal_lag1),
        (1, e.horizontal_var, e.horizontal_lag1),
        (2, e.vertical_var, e.vertical_lag1),
    ):
        x = w[:, axis]
        assert_moment(x, 0.0, np.sqrt(var), 0.05)  # zero mean: no bias of the steady wind
        assert_moment(x * x, var, var, 0.05)
        assert_moment(x[1:] * x[:-1], lag1 * var, var, 0.05)


def test_the_firmware_rate_process_is_the_firmwares():
    # At the firmware's own step (1200 Hz) one sample per step: each horizontal axis white noise
    # of variance S2 / 2 (the direction is fresh every step, E[cos^2] = 1/2), the vertical the
    # low-passed speed itself (variance S2, lag-one correlation a)
    e = expected_statistics(T, 1.0 / SITL_PHYSICS_RATE_HZ)
    assert e.firmware_steps == 1
    assert e.horizontal_var == pytest.approx(S2 / 2.0)
    assert e.vertical_var == pytest.approx(S2)
    assert e.vertical_lag1 == pytest.approx(A)
    assert np.sqrt(S2) == pytest.approx(1.005 * T, rel=1e-3)  # "~T" as the firmware intends
    w = SitlTurbulence(T, 1.0 / SITL_PHYSICS_RATE_HZ, seed=11).series(240_000)  # 200 s
    check_series(w, 1.0 / SITL_PHYSICS_RATE_HZ)


@pytest.mark.parametrize("dt", [0.02 / 3.0, 0.02])  # the SIL's default step (150 Hz) and 50 Hz
def test_our_step_sees_the_firmwares_power(dt):
    # Averaged over n firmware steps: the horizontal variance is S2 / (2 n), so variance x dt
    # (the power density the airframe responds to) is the firmware's; the vertical is the block
    # mean of the low-passed speed. Checked against a direct simulation of the firmware's steps
    # averaged by hand (a different code path) and against the closed forms.
    n = round(dt * SITL_PHYSICS_RATE_HZ)
    e = expected_statistics(T, dt)
    assert e.firmware_steps == n
    assert e.horizontal_var == pytest.approx(S2 / (2.0 * n))
    assert e.horizontal_var * dt == pytest.approx(S2 / 2.0 / SITL_PHYSICS_RATE_HZ)
    rng = np.random.default_rng(3)
    m = 20_000 * n
    hv = np.zeros((2, m))
    h = v = 0.0
    g = rng.standard_normal((2, m)) * 10.0 * T * (1.0 - A)
    for k in range(m):  # the firmware's loop as it is defined, step by step
        h = A * h + g[0, k]
        v = A * v + g[1, k]
        hv[0, k], hv[1, k] = h, v
    az = rng.uniform(0.0, 2.0 * np.pi, m)
    direct = np.stack((hv[0] * np.cos(az), hv[0] * np.sin(az), hv[1]), axis=1)
    direct = direct.reshape(-1, n, 3).mean(axis=1)
    check_series(direct, dt)
    ours = SitlTurbulence(T, dt, seed=5).series(60_000)
    check_series(ours, dt)


def test_a_step_that_is_not_a_whole_number_of_firmware_steps():
    # 1.2 firmware steps per step (1000 Hz): steps of 1 and 2 samples alternate; the power per
    # unit time is still the firmware's within the batch-means tolerance of the mean square
    dt = 1.0 / 1000.0
    w = SitlTurbulence(T, dt, seed=2).series(200_000)
    hx = w[:, 0] ** 2
    # a step of c samples has variance S2 / (2 c): 4 of 5 steps have 1 sample, 1 of 5 has 2
    expected = (4 * S2 / 2.0 + S2 / 4.0) / 5.0
    assert_moment(hx, expected, expected, 0.05)
    assert np.all(np.isfinite(w))


def test_every_seed_its_own_draw_and_the_same_seed_the_same():
    dt = 0.02 / 3.0
    a0, a0b = SitlTurbulence(T, dt, 0).series(30_000), SitlTurbulence(T, dt, 0).series(30_000)
    a1 = SitlTurbulence(T, dt, 1).series(30_000)
    assert np.array_equal(a0, a0b)
    # independent draws: their sample correlation is ~N(0, 1/N) for the white horizontal axes
    # (the vertical's correlation time of ~10 steps widens it by ~sqrt(2 tau) = 4.5)
    for axis, width in ((0, 1.0), (1, 1.0), (2, 4.5)):
        r = np.corrcoef(a0[:, axis], a1[:, axis])[0, 1]
        assert abs(r) < K_SE * width / np.sqrt(len(a0))
    assert not np.allclose(a0[:10], a1[:10])
    with pytest.raises(ValueError):
        SitlTurbulence(-1.0, dt)
    with pytest.raises(ValueError):
        SitlTurbulence(float("nan"), dt)


jsbsim = pytest.importorskip("jsbsim")
os.environ.setdefault("JSBSIM_DEBUG", "0")


def test_the_plant_adds_it_to_the_steady_wind_every_step():
    from sim.plant.jsbsim_plant import JSBSimPlant

    plant = JSBSimPlant(airspeed=16.0)
    steady = np.array([0.0, -6.0, 0.0])
    plant.set_wind(steady)
    plant.set_random_wind(T, seed=4)
    ref = SitlTurbulence(T, plant.dt, seed=4)
    for _ in range(50):
        plant.step(0.0, 0.0, 0.0, 0.5)
        # JSBSim's total wind is the steady wind we set plus this step's random wind (ft/s
        # round trip: 1e-9 m/s)
        assert np.allclose(plant.state().wind_ned, steady + ref.next(), atol=1e-9)
    plant.set_wind([3.0, 0.0, 0.0])  # SIM_WIND_* changed in flight: the random part stays
    plant.step(0.0, 0.0, 0.0, 0.5)
    assert np.allclose(plant.state().wind_ned, np.array([3.0, 0.0, 0.0]) + ref.next(), atol=1e-9)
    plant.set_random_wind(0.0)
    plant.step(0.0, 0.0, 0.0, 0.5)
    assert np.allclose(plant.state().wind_ned, [3.0, 0.0, 0.0], atol=1e-12)


def _free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_the_vehicle_flies_it_seeded_by_sil_seed():
    from sim.vehicle.vehicle import SimVehicle

    def air(seed: int) -> np.ndarray:
        v = SimVehicle.build(
            "ardupilot",
            f"udpin:127.0.0.1:{_free_port()}",
            plant="jsbsim",
            trim_seconds=1.0,
            wind_ned=(6.0, 0.0, 0.0),
            wind_turbulence_m_s=T,
            seed=seed,
        )
        try:
            for _ in range(100):  # 2 s
                v.step_once()
            return v.truth()["wind_ned"]
        finally:
            v.close()

    a, b, c = air(0), air(0), air(1)
    assert np.array_equal(a, b)  # the same seed, the same flight
    assert not np.allclose(a, c)  # seeds 0 and 1 differ (JSBSim's Dryden once mixed them up)
    # the truth samples one step per frame: per-axis spread of the step's random wind (0.5 m/s
    # north/east at 150 Hz) about the steady wind, within a generous factor for 100 samples
    sd = (a - [6.0, 0.0, 0.0]).std(axis=0)
    e = expected_statistics(T, 0.02 / 3.0)
    assert 0.5 * np.sqrt(e.horizontal_var) < sd[0] < 2.0 * np.sqrt(e.horizontal_var)
    with pytest.raises(ValueError, match="jsbsim"):
        SimVehicle.build(
            "ardupilot", f"udpin:127.0.0.1:{_free_port()}", plant="kinematic",
            trim_seconds=0.0, wind_turbulence_m_s=T,
        )  # fmt: skip
