"""What the live target's filter (:mod:`mpf_mavlink.core.target_filter`) takes: its tuning and
the reports of the target, apart so that the configuration and a flight without a live target
need not load the filter."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Vec = Sequence[float]


@dataclass(frozen=True)
class TargetFilterParams:
    """Tuning and limits of :class:`TargetEstimator` (SI units; noise terms are 1-sigma, the
    process terms square roots of white-noise spectral densities)."""

    accel_noise_m_s2: float = 0.15  # horizontal acceleration, m/s^2/sqrt(Hz)
    vertical_accel_noise_m_s2: float = 0.05  # m/s^2/sqrt(Hz)
    turn_accel_noise_rad_s2: float = 0.003  # turn-rate random walk, rad/s/sqrt(s)
    position_noise_m: float = 2.0  # horizontal, per axis, when the report carries none
    vertical_noise_m: float = 3.0
    velocity_noise_m_s: float = 0.3  # per axis
    turn_rate_noise_rad_s: float = 0.01  # attitude-derived turn rate
    gate_probability: float = 0.9999
    reinit_after: int = 3
    max_position_sigma_m: float = 4.0  # stale beyond (predicted, radial, see position_sigma)
    manoeuvre_accel_m_s2: float = 0.3  # what the target may do unseen (staleness only)
    max_age_s: float = 10.0  # stale beyond, whatever the uncertainty
    latency_s: float = 0.0  # known smallest transport delay of the reports
    history_s: float = 10.0  # reports kept for re-ordering late ones
    attitude_timeout_s: float = 1.0  # a reported attitude older than this no longer sets {T}


@dataclass(frozen=True)
class Report:
    """One report of the target. ``t``: the sender's timestamp (s). position / velocity: NED (m,
    m/s; arrays or sequences of 3 floats) or None; pos_var: variances (m^2, n/e/d) or None for
    the configured noise; turn_rate: rad/s about down or None; yaw: rad or None (only used to
    hold the frame at low speed)."""

    t: float
    position: NDArray[np.float64] | Vec | None = None
    velocity: NDArray[np.float64] | Vec | None = None
    turn_rate: float | None = None
    yaw: float | None = None
    pos_var: NDArray[np.float64] | Vec | None = None
    attitude: bool = False  # yaw is the target's measured attitude (not a heading hint)
