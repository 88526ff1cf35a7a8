"""ArduPilot SITL's random wind (``SIM_WIND_TURB``) as a per-physics-step wind for our plant.

What the firmware does (ArduPilot's SITL documentation calls SIM_WIND_TURB "random wind
variations", m/s; its simulator's wind update, described here in our words, not copied): once
per physics step, at ``SIM_RATE_HZ`` (1200 Hz by default; the real flight's dataflash log has
1200), it

- low-passes a Gaussian draw into a horizontal speed ``h`` and, independently, a vertical speed
  ``w``: each ``x <- a x + (1 - a) 10 T n`` with ``a = 0.98``, ``T`` = SIM_WIND_TURB and ``n`` a
  standard normal draw. Both are zero-mean with a standard deviation of
  ``10 T sqrt((1 - a) / (1 + a))`` = 1.005 T and a correlation time of 50 steps (42 ms);
- points ``h`` in a fresh random horizontal direction every step (the azimuth jumps by a random
  integer's worth of degrees each step), so each horizontal axis is white noise of variance
  ``E[h^2] / 2`` (1.42 m/s for T = 2), while the vertical wind is the correlated ``w``.

What the SIL flies: the same process at the firmware's rate, averaged over each of our (longer)
physics steps, because the aircraft integrates the force over the step. The average keeps the
power the airframe responds to (the spectrum below our step's Nyquist frequency is the
firmware's), where the firmware's per-step size at our step would put 8x (150 Hz) to 24x (50 Hz)
more power into the aircraft's band. So the per-step horizontal wind here is smaller than the
firmware's per-step value (0.50 m/s per axis at 150 Hz for T = 2), as it must be for the same
disturbance. The statistics per step are :func:`expected_statistics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SITL_PHYSICS_RATE_HZ = 1200.0  # ArduPilot SITL's SIM_RATE_HZ default (what the real flight ran)
SITL_IIR = 0.98  # the firmware's per-step low-pass coefficient of both speeds
SITL_GAIN = 10.0  # the firmware scales T by 10 so that the low-passed speed's sigma is ~T
# the draw's own stream: a seed's other random processes (the autopilot profile's) do not share it
_STREAM = 0x53494D57


@dataclass(frozen=True)
class TurbulenceStatistics:
    """What one of our physics steps' averaged wind has (m/s, (m/s)^2): per horizontal axis its
    variance and lag-one correlation (0: a fresh direction each firmware step), the vertical's."""

    horizontal_var: float
    horizontal_lag1: float
    vertical_var: float
    vertical_lag1: float
    firmware_steps: int  # firmware steps averaged per physics step


def firmware_steps(dt: float, source_rate_hz: float = SITL_PHYSICS_RATE_HZ) -> float:
    """Firmware physics steps per step of ``dt`` seconds (at least 1 are drawn per step)."""
    return float(dt) * float(source_rate_hz)


def expected_statistics(
    turbulence_m_s: float, dt: float, source_rate_hz: float = SITL_PHYSICS_RATE_HZ
) -> TurbulenceStatistics:
    """The exact per-step statistics of :class:`SitlTurbulence` when ``dt * source_rate_hz`` is
    a whole number ``n`` (the mean of ``n`` samples of the firmware's process).

    With ``a`` = :data:`SITL_IIR` and ``s2 = (10 T (1 - a))^2 / (1 - a^2)`` the stationary
    variance of ``h`` and ``w``: horizontal, ``s2 / (2 n)`` (the n directions are independent, so
    the cross terms vanish) and no correlation between steps; vertical, the block mean of an
    AR(1): ``s2 / n^2 (n + 2 sum_k (n - k) a^k)``, and between adjacent blocks the covariance
    ``s2 / n^2 a S^2`` with ``S = (1 - a^n) / (1 - a)``."""
    n = max(1, round(firmware_steps(dt, source_rate_hz)))
    a = SITL_IIR
    s2 = (SITL_GAIN * turbulence_m_s * (1.0 - a)) ** 2 / (1.0 - a * a)
    v_var = s2 / n**2 * (n + 2.0 * sum((n - k) * a**k for k in range(1, n)))
    S = (1.0 - a**n) / (1.0 - a)
    v_cov = s2 / n**2 * a * S * S
    return TurbulenceStatistics(
        horizontal_var=s2 / (2.0 * n),
        horizontal_lag1=0.0,
        vertical_var=v_var,
        vertical_lag1=v_cov / v_var if v_var > 0 else 0.0,
        firmware_steps=n,
    )


class SitlTurbulence:
    """The firmware's random wind (module docstring) for physics steps of ``dt`` seconds:
    :meth:`next` gives the air-mass velocity to add to the steady wind for the next step
    (NED, m/s, the direction the air moves toward). ``seed``: every seed its own draw; the same
    seed the same sequence (the flight is reproducible)."""

    def __init__(
        self,
        turbulence_m_s: float,
        dt: float,
        seed: int = 0,
        source_rate_hz: float = SITL_PHYSICS_RATE_HZ,
        block_steps: int = 1024,
    ) -> None:
        if not (math.isfinite(turbulence_m_s) and turbulence_m_s >= 0.0):
            raise ValueError(f"turbulence must be a finite speed >= 0 m/s, got {turbulence_m_s}")
        if not (dt > 0.0 and source_rate_hz > 0.0):
            raise ValueError("dt and source_rate_hz must be positive")
        self.turbulence_m_s = float(turbulence_m_s)
        self.dt = float(dt)
        self.ratio = firmware_steps(dt, source_rate_hz)
        self._rng = np.random.Generator(
            np.random.PCG64(np.random.SeedSequence([int(seed), _STREAM]))
        )
        self._b = SITL_GAIN * self.turbulence_m_s * (1.0 - SITL_IIR)
        self._hv = np.zeros(2)  # the firmware's low-passed horizontal and vertical speeds
        self._block = int(block_steps)
        self._k = 0  # our steps drawn so far
        self._buf: list[tuple[float, float, float]] = []
        self._i = 0

    def _refill(self) -> None:
        from scipy.signal import lfilter

        k0, m = self._k, self._block
        edges = np.floor((k0 + np.arange(m + 1)) * self.ratio + 1e-9).astype(np.int64)
        counts = np.maximum(np.diff(edges), 1)  # at least one firmware step per physics step
        starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
        n = int(counts.sum())
        rng, a = self._rng, SITL_IIR
        drive = rng.standard_normal((2, n)) * self._b
        hv, zf = lfilter([1.0], [1.0, -a], drive, axis=1, zi=(a * self._hv)[:, None])
        self._hv = zf[:, 0]
        az = rng.uniform(0.0, 2.0 * math.pi, n)
        h = hv[0]
        w = np.stack((h * np.cos(az), h * np.sin(az), hv[1]))
        mean = np.add.reduceat(w, starts, axis=1) / counts
        self._buf = list(zip(*mean.tolist(), strict=True))
        self._i = 0
        self._k = k0 + m

    def next(self) -> tuple[float, float, float]:
        """The random wind (m/s NED) over the next physics step."""
        i = self._i
        if i >= len(self._buf):
            self._refill()
            i = 0
        self._i = i + 1
        return self._buf[i]

    def series(self, n: int) -> np.ndarray:
        """The next ``n`` steps' random winds, shape (n, 3) (what ``n`` calls of :meth:`next`
        return)."""
        return np.array([self.next() for _ in range(int(n))], dtype=float).reshape(-1, 3)
