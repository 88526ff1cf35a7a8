"""Configuration section ``target_estimator``: how the bridge estimates a live target.

Validated strictly by :mod:`mpf_mavlink.config.schema` like every section. The keys are those of
:class:`mpf_mavlink.core.target_filter.TargetFilterParams` (see its module for the model) plus
``mode``: ``filter`` (the EKF) or ``last_sample`` (no estimator: the latest
report extrapolated, stale after ``mavlink.target_timeout_s``; kept to measure against).
``mavlink.target_timeout_s`` applies to ``last_sample`` only: the filter is stale when its
predicted position 1-sigma exceeds ``max_position_sigma_m`` (or after ``max_age_s``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Literal

from mpf_mavlink.config.fields import _doc, _fail, _ge, _nonneg, _open, _pos
from mpf_mavlink.core.target_report import TargetFilterParams


@dataclass(frozen=True)
class TargetEstimatorConfig:
    """See the module docstring; units in the key names (noise: 1-sigma; process noise: square
    roots of white-noise spectral densities)."""

    mode: Literal["filter", "last_sample"] = field(
        default="filter",
        metadata=_doc("filter: the EKF; last_sample: the latest report extrapolated"),
    )
    accel_noise_m_s2: float = field(
        default=TargetFilterParams.accel_noise_m_s2,
        metadata=_pos("horizontal acceleration, m/s^2/sqrt(Hz)"),
    )
    vertical_accel_noise_m_s2: float = field(
        default=TargetFilterParams.vertical_accel_noise_m_s2, metadata=_pos("m/s^2/sqrt(Hz)")
    )
    turn_accel_noise_rad_s2: float = field(
        default=TargetFilterParams.turn_accel_noise_rad_s2,
        metadata=_pos("turn-rate random walk, rad/s/sqrt(s)"),
    )
    position_noise_m: float = field(
        default=TargetFilterParams.position_noise_m,
        metadata=_pos("horizontal, per axis, when the report carries none"),
    )
    vertical_noise_m: float = field(default=TargetFilterParams.vertical_noise_m, metadata=_pos())
    velocity_noise_m_s: float = field(
        default=TargetFilterParams.velocity_noise_m_s, metadata=_pos("per axis")
    )
    turn_rate_noise_rad_s: float = field(
        default=TargetFilterParams.turn_rate_noise_rad_s,
        metadata=_pos("the attitude-derived turn rate"),
    )
    gate_probability: float = field(
        default=TargetFilterParams.gate_probability,
        metadata=_open(0.5, 1.0),
    )
    reinit_after: int = field(default=TargetFilterParams.reinit_after, metadata=_ge(1))
    max_position_sigma_m: float = field(
        default=TargetFilterParams.max_position_sigma_m,
        metadata=_pos("stale beyond this predicted 1-sigma"),
    )
    manoeuvre_accel_m_s2: float = field(
        default=TargetFilterParams.manoeuvre_accel_m_s2,
        metadata=_nonneg("what the target may do unseen (staleness only)"),
    )
    max_age_s: float = field(
        default=TargetFilterParams.max_age_s,
        metadata=_pos("stale beyond, whatever the uncertainty"),
    )
    latency_s: float = field(
        default=TargetFilterParams.latency_s,
        metadata=_nonneg("known smallest transport delay of the reports"),
    )
    history_s: float = field(
        default=TargetFilterParams.history_s,
        metadata=_pos("reports kept for re-ordering late ones"),
    )
    attitude_timeout_s: float = field(
        default=TargetFilterParams.attitude_timeout_s,
        metadata=_pos("a reported attitude older than this no longer sets {T}"),
    )

    def params(self) -> TargetFilterParams:
        """The filter's parameters (every key but ``mode``: the filter's fields, by name)."""
        return TargetFilterParams(
            **{f.name: getattr(self, f.name) for f in fields(TargetFilterParams)}
        )

    def validate(self, src: str) -> None:
        if self.history_s > self.max_age_s:
            raise _fail(
                src, "target_estimator.history_s", "must not exceed target_estimator.max_age_s"
            )
