"""Samples of a campaign: unit-cube points (seeded random, Latin hypercube or Sobol from
``scipy.stats.qmc``) mapped through each variable's distribution, and the ``--set`` overrides
that turn one sample into one flight's configuration."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import stats

from mpf_mavlink.campaign.spec import (
    INITIAL_KEYS,
    CampaignSpec,
    Variable,
    parse_campaign,
    probe_values,
    split_indexed,
    yaml_text,
)
from mpf_mavlink.config.schema import Config, load_config
from mpf_mavlink.errors import ConfigError


def load_campaign(path: str | Path) -> CampaignSpec:
    """Read and validate a campaign file, and try every varied key on the base configuration
    at the ends of its range (its mean, its choices): a campaign of a thousand flights must
    not die on its first sample."""
    spec = parse_campaign(path)
    base = load_config(spec.base_path, spec.set)
    for v in spec.vary:
        for value in probe_values(v):
            try:
                load_config(spec.base_path, [*spec.set, *overrides_for(base, {v.key: value})])
            except ConfigError as e:
                raise ConfigError(f"{spec.source}: vary {v.key} = {value!r}: {e}") from None
    return spec


def unit_points(spec: CampaignSpec) -> np.ndarray:
    """(samples, dims) points in [0, 1): the same for the same file, whatever the machine."""
    d = len(spec.vary)
    if spec.design == "random":
        return np.random.default_rng(spec.seed).random((spec.samples, d))
    if spec.design == "lhs":
        return stats.qmc.LatinHypercube(d=d, seed=spec.seed).random(spec.samples)
    # scrambled Sobol: balanced for powers of two, any count is still a valid low-discrepancy set
    eng = stats.qmc.Sobol(d=d, scramble=True, seed=spec.seed)
    m = max(0, math.ceil(math.log2(spec.samples)))
    return eng.random_base2(m)[: spec.samples]


def _value(v: Variable, u: float) -> Any:
    u = min(max(u, 1e-12), 1.0 - 1e-12)  # the normal's tails are finite
    if v.dist == "uniform":
        assert v.low is not None and v.high is not None
        return v.low + u * (v.high - v.low)
    if v.dist == "loguniform":
        assert v.low is not None and v.high is not None
        return math.exp(math.log(v.low) + u * (math.log(v.high) - math.log(v.low)))
    if v.dist == "normal":
        assert v.mean is not None and v.sd is not None
        return float(stats.norm.ppf(u, loc=v.mean, scale=v.sd))
    assert v.values is not None
    return yaml.safe_load(v.values[min(int(u * len(v.values)), len(v.values) - 1)])


def samples(spec: CampaignSpec) -> list[dict[str, Any]]:
    """Every sample as {key: value}, index = sample id."""
    pts = unit_points(spec)
    return [
        {v.key: _value(v, float(pts[i, j])) for j, v in enumerate(spec.vary)}
        for i in range(spec.samples)
    ]


def _current(cfg: Config, dotted: str) -> object:
    """The value of a dotted key (``vehicle.airspeed_m_s``, ``sil.wind_ned_m_s``) in ``cfg``;
    the campaign's keys were checked against the schema when the spec was read."""
    node: object = cfg
    for part in dotted.split("."):
        node = getattr(node, part)
    return node


def overrides_for(base: Config, sample: dict[str, Any]) -> list[str]:
    """``--set`` strings for one sample (vector components filled from the base config)."""
    out: list[str] = []
    vectors: dict[str, list[Any]] = {}
    for key, value in sample.items():
        if key in INITIAL_KEYS:
            continue
        name, i = split_indexed(key)
        if i is None:
            out.append(f"{name}={yaml_text(value)}")
            continue
        if name not in vectors:
            cur = _current(base, name)
            if not isinstance(cur, tuple | list):
                raise ConfigError(f"vary {key}: {name} is not a vector")
            vectors[name] = list(cur)
        vec = vectors[name]
        if i >= len(vec):
            raise ConfigError(f"vary {key}: {name} has {len(vec)} components")
        vec[i] = value
    for name, vec in vectors.items():
        out.append(f"{name}=[{', '.join(yaml_text(float(x)) for x in vec)}]")
    initial = {k: sample[k] for k in INITIAL_KEYS if k in sample}
    if initial:
        out += initial_overrides(base, initial)
    return out


def initial_overrides(base: Config, initial: dict[str, float]) -> list[str]:
    """The kinematic start placed relative to the moving path at t = 0: ``initial.distance_m``
    from the path's closest point to the configured start, in the direction
    ``initial.bearing_rad`` about the path tangent (0 = f2, pi/2 = f3), with the course of
    the tangent turned by ``initial.heading_rad`` (level wings, level flight)."""
    from mpf_mavlink.config.scenario import build_path, build_target

    path, target = build_path(base.path), build_target(base.target)
    st = target.state(0.0)
    p0 = np.asarray(base.kinematic.initial_position_ned_m, float)
    s0 = base.guidance.initial_s_m
    if s0 is None:
        s0 = path.closest(st.R_T_I.T @ (p0 - st.position))
    smp = path.sample(s0)
    R = np.asarray(st.R_T_I, float)
    p_path = np.asarray(st.position, float) + R @ smp.position
    f1, f2, f3 = (R @ smp.R_F_T[:, k] for k in range(3))
    b = float(initial.get("initial.bearing_rad", 0.0))
    d = float(initial.get("initial.distance_m", 0.0))
    p = p_path + d * (math.cos(b) * f2 + math.sin(b) * f3)
    course = math.atan2(float(f1[1]), float(f1[0])) + float(initial.get("initial.heading_rad", 0.0))
    course = math.atan2(math.sin(course), math.cos(course))
    return [
        f"kinematic.initial_position_ned_m=[{', '.join(yaml_text(float(x)) for x in p)}]",
        f"kinematic.initial_attitude_rpy_rad=[0.0, 0.0, {yaml_text(course)}]",
        f"guidance.initial_s_m={yaml_text(float(s0))}",
    ]
