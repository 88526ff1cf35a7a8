"""Configuration section ``target_estimator``: how the bridge estimates a live target.

Importing this module registers it in :data:`mpf_mavlink.config.schema.EXTRA_SECTIONS` (config.py does
it for every load), validated strictly like the rest. The keys are those of
:class:`mpf_mavlink.core.target_filter.TargetFilterParams` (see its module for the model) plus
``mode``: ``filter`` (the EKF) or ``last_sample`` (the bridge before the estimator: the latest
report extrapolated, stale after ``mavlink.target_timeout_s``; kept to measure against).
``mavlink.target_timeout_s`` applies to ``last_sample`` only: the filter is stale when its
predicted position 1-sigma exceeds ``max_position_sigma_m`` (or after ``max_age_s``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

from mpf_mavlink.config.fields import EXTRA_SECTIONS, _fail, _nonneg, _pos
from mpf_mavlink.core.target_filter import TargetFilterParams


@dataclass(frozen=True)
class TargetEstimatorConfig:
    """See the module docstring; units in the key names (noise: 1-sigma; process noise: square
    roots of white-noise spectral densities)."""

    mode: Literal["filter", "last_sample"] = "filter"
    accel_noise_m_s2: float = field(default=TargetFilterParams.accel_noise_m_s2, metadata=_pos())
    vertical_accel_noise_m_s2: float = field(
        default=TargetFilterParams.vertical_accel_noise_m_s2, metadata=_pos()
    )
    turn_accel_noise_rad_s2: float = field(
        default=TargetFilterParams.turn_accel_noise_rad_s2, metadata=_pos()
    )
    position_noise_m: float = field(default=TargetFilterParams.position_noise_m, metadata=_pos())
    vertical_noise_m: float = field(default=TargetFilterParams.vertical_noise_m, metadata=_pos())
    velocity_noise_m_s: float = field(
        default=TargetFilterParams.velocity_noise_m_s, metadata=_pos()
    )
    turn_rate_noise_rad_s: float = field(
        default=TargetFilterParams.turn_rate_noise_rad_s, metadata=_pos()
    )
    gate_probability: float = field(
        default=TargetFilterParams.gate_probability,
        metadata={"check": ("range_open", 0.5, 1.0)},
    )
    reinit_after: int = field(
        default=TargetFilterParams.reinit_after, metadata={"check": ("ge", 1)}
    )
    max_position_sigma_m: float = field(
        default=TargetFilterParams.max_position_sigma_m, metadata=_pos()
    )
    manoeuvre_accel_m_s2: float = field(
        default=TargetFilterParams.manoeuvre_accel_m_s2, metadata=_nonneg()
    )
    max_age_s: float = field(default=TargetFilterParams.max_age_s, metadata=_pos())
    latency_s: float = field(default=TargetFilterParams.latency_s, metadata=_nonneg())
    history_s: float = field(default=TargetFilterParams.history_s, metadata=_pos())
    attitude_timeout_s: float = field(
        default=TargetFilterParams.attitude_timeout_s, metadata=_pos()
    )

    def params(self) -> TargetFilterParams:
        """The filter's parameters (every key but ``mode``)."""
        names = {f.name for f in dataclasses.fields(TargetFilterParams)}
        return TargetFilterParams(**{k: getattr(self, k) for k in names})

    def validate(self, cfg: Any, src: str) -> None:
        if self.history_s > self.max_age_s:
            raise _fail(
                src, "target_estimator.history_s", "must not exceed target_estimator.max_age_s"
            )


EXTRA_SECTIONS["target_estimator"] = TargetEstimatorConfig
