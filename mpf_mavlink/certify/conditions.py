"""The conditions a certificate holds for: what the user expects the mission to meet, as ranges
drawn uniformly and independently for every flight. Validated strictly (unknown keys, wrong
types, a range whose low exceeds its high: one-line errors naming the key and the file).

Example (configs/certify/px4_turning.yaml)::

    name: px4-turning-target
    set: [target.type=constant_turn]      # the mission's fixed overrides of CONFIG
    duration_s: 300                       # mission length (s of tracking)
    steady_after_s: 60
    wind: {speed_m_s: [0, 6], from_rad: [0, 6.2832]}
    turbulence: {sitl_m_s: [0, 1]}        # ArduPilot SIM_WIND_TURB (m/s)
    start: {north_m: [-30, 30], east_m: [-30, 30], heading_rad: [-0.3, 0.3]}
    target: {speed_m_s: [3, 5], turn_rate_rad_s: [-0.015, -0.008]}
    link: {latency_s: [0.0, 0.04], target_rate_hz: [2, 10]}

Every range is ``[low, high]`` in SI units and radians (``low == high``: held at that value).
The wind is horizontal, ``from_rad`` the direction it blows from, clockwise from north (as
ArduPilot's SIM_WIND_DIR). ``start`` offsets the aircraft's start (``kinematic.initial_*``) from
the config's. Flight ``i`` draws from its own seeded stream (``seed``, ``i``), so the first N
flights are the same whatever the number flown: a re-run with more flights keeps the old ones.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mpf_mavlink.config.build import _build, parse_yaml
from mpf_mavlink.config.fields import _fail, _open, _pos
from mpf_mavlink.errors import ConfigError

Range = tuple[float, float]


@dataclass(frozen=True)
class WindRanges:
    """Steady horizontal wind: speed (m/s) and the direction it blows from (rad from north)."""

    speed_m_s: Range = (0.0, 0.0)
    from_rad: Range = (0.0, 2.0 * math.pi)


@dataclass(frozen=True)
class TurbulenceRanges:
    """``sitl_m_s``: ArduPilot SITL's SIM_WIND_TURB (m/s, sil.wind_turbulence_m_s); ``dryden``:
    the MIL-F-8785C levels (sil.turbulence) a flight picks among, equally likely."""

    sitl_m_s: Range = (0.0, 0.0)
    dryden: list[Literal["none", "light", "moderate", "severe"]] = field(
        default_factory=lambda: ["none"]
    )


@dataclass(frozen=True)
class StartRanges:
    """The start's offset from the config's ``kinematic.initial_*`` (m NED; heading rad)."""

    north_m: Range = (0.0, 0.0)
    east_m: Range = (0.0, 0.0)
    down_m: Range = (0.0, 0.0)
    heading_rad: Range = (0.0, 0.0)


@dataclass(frozen=True)
class TargetRanges:
    """The target's speed (m/s), turn rate (rad/s) and climb rate (m/s, up; None: the
    config's). Needs a ``constant_turn`` target (the mission's ``set`` may make it one)."""

    speed_m_s: Range | None = None
    turn_rate_rad_s: Range | None = None
    climb_rate_m_s: Range | None = None


@dataclass(frozen=True)
class LinkRanges:
    """The companion link: latency of a setpoint (s, sil.command_latency_s) and the live
    target's rate (Hz, sil.target_rate_hz; None: the config's)."""

    latency_s: Range = (0.0, 0.0)
    target_rate_hz: Range | None = None


@dataclass(frozen=True)
class Conditions:
    """What a certificate holds for (module docstring)."""

    name: str
    set: list[str] = field(default_factory=list)
    duration_s: float | None = field(default=None, metadata=_pos("s of tracking"))
    steady_after_s: float | None = field(default=None, metadata=_pos())
    wind: WindRanges = field(default_factory=WindRanges)
    turbulence: TurbulenceRanges = field(default_factory=TurbulenceRanges)
    start: StartRanges = field(default_factory=StartRanges)
    target: TargetRanges = field(default_factory=TargetRanges)
    link: LinkRanges = field(default_factory=LinkRanges)
    seed: int = 0
    quantile: float = field(default=0.95, metadata=_open(0.0, 1.0))
    confidence: float = field(default=0.95, metadata=_open(0.0, 1.0))
    timeout_s: float = field(default=900.0, metadata=_pos("one flight, wall clock"))
    source: str = field(default="<conditions>", metadata={"internal": True})


_NONNEG = {"wind.speed_m_s", "turbulence.sitl_m_s", "link.latency_s", "target.speed_m_s"}
_POSITIVE = {"link.target_rate_hz"}


def _ranges(c: Conditions) -> dict[str, Range]:
    """Every range given, by its dotted key."""
    out: dict[str, Range] = {}
    for sec in ("wind", "turbulence", "start", "target", "link"):
        for k, v in asdict(getattr(c, sec)).items():
            if isinstance(v, tuple | list) and len(v) == 2 and not isinstance(v[0], str):
                out[f"{sec}.{k}"] = (float(v[0]), float(v[1]))
    return out


def parse_conditions(path: str | Path) -> Conditions:
    """Read and validate a conditions file (ConfigError naming the key on anything wrong)."""
    src = str(path)
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{src}: no such conditions file")
    raw = parse_yaml(p.read_text(), src)
    if not isinstance(raw, dict):
        raise ConfigError(f"{src}: the top level must be a mapping")
    if not isinstance(raw.get("name"), str) or not raw["name"]:
        raise _fail(src, "name", "required (a name for the certificate)")
    c: Conditions = _build(Conditions, raw, src, "")
    c = Conditions(**{**c.__dict__, "source": src})
    for key, (lo, hi) in _ranges(c).items():
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise _fail(src, key, "must be finite")
        if lo > hi:
            raise _fail(src, key, f"low {lo:g} exceeds high {hi:g}")
        if key in _NONNEG and lo < 0.0:
            raise _fail(src, key, f"must be >= 0 (got {lo:g})")
        if key in _POSITIVE and lo <= 0.0:
            raise _fail(src, key, f"must be > 0 (got {lo:g})")
    if not c.turbulence.dryden:
        raise _fail(src, "turbulence.dryden", "must name at least one level")
    if c.steady_after_s is not None and c.duration_s is not None:
        if c.steady_after_s >= c.duration_s:
            raise _fail(src, "steady_after_s", f"must be < duration_s ({c.duration_s:g})")
    return c


def draw(c: Conditions, i: int) -> dict[str, Any]:
    """Flight ``i``'s conditions: one uniform draw per range from the stream (seed, i)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(c.seed), int(i), 41]))
    out: dict[str, Any] = {}
    for key, (lo, hi) in _ranges(c).items():
        out[key] = float(lo + (hi - lo) * rng.random())
    levels = c.turbulence.dryden
    out["turbulence.dryden"] = levels[min(int(rng.random() * len(levels)), len(levels) - 1)]
    out["seed"] = int(c.seed) * 100003 + int(i)  # the SIL's noise seed (< 2^31 - 2)
    return out


def flight_sets(cfg: Any, d: dict[str, Any]) -> list[str]:
    """The ``--set`` overrides that fly drawn conditions ``d`` on config ``cfg`` (already
    loaded with the conditions' own ``set``)."""
    s: list[str] = []
    spd, frm = d.get("wind.speed_m_s", 0.0), d.get("wind.from_rad", 0.0)
    # a wind from direction psi blows toward psi + pi
    s.append(f"sil.wind_ned_m_s=[{-spd * math.cos(frm):.4f},{-spd * math.sin(frm):.4f},0.0]")
    s.append(f"sil.wind_turbulence_m_s={d.get('turbulence.sitl_m_s', 0.0):.4f}")
    s.append(f"sil.turbulence={d['turbulence.dryden']}")
    s.append(f"sil.seed={int(d['seed']) % (2**31 - 3)}")
    p0 = cfg.kinematic.initial_position_ned_m
    dn, de, dd = (d.get(f"start.{k}", 0.0) for k in ("north_m", "east_m", "down_m"))
    s.append(
        f"kinematic.initial_position_ned_m=[{p0[0] + dn:.3f},{p0[1] + de:.3f},{p0[2] + dd:.3f}]"
    )
    r0 = cfg.kinematic.initial_attitude_rpy_rad
    s.append(
        f"kinematic.initial_attitude_rpy_rad=[{r0[0]:.5f},{r0[1]:.5f},"
        f"{r0[2] + d.get('start.heading_rad', 0.0):.5f}]"
    )
    for k in ("speed_m_s", "turn_rate_rad_s", "climb_rate_m_s"):
        if f"target.{k}" in d:
            s.append(f"target.{k}={d[f'target.{k}']:.5f}")
    s.append(f"sil.command_latency_s={d.get('link.latency_s', 0.0):.4f}")
    if "link.target_rate_hz" in d:
        s.append(f"sil.target_rate_hz={d['link.target_rate_hz']:.3f}")
    return s


def describe(d: dict[str, Any]) -> str:
    """One flight's conditions in words (for the tables)."""
    parts = [
        f"wind {d.get('wind.speed_m_s', 0.0):.1f} m/s from "
        f"{math.degrees(d.get('wind.from_rad', 0.0)) % 360:.0f} deg"
    ]
    if d.get("turbulence.sitl_m_s", 0.0) > 0.0:
        parts.append(f"turb {d['turbulence.sitl_m_s']:.2f} m/s")
    if d.get("turbulence.dryden", "none") != "none":
        parts.append(f"dryden {d['turbulence.dryden']}")
    for k, w in (("target.speed_m_s", "target {:.2f} m/s"),
                 ("target.turn_rate_rad_s", "turn {:+.4f} rad/s"),
                 ("target.climb_rate_m_s", "climb {:.2f} m/s"),
                 ("link.latency_s", "latency {:.3f} s")):  # fmt: skip
        if k in d:
            parts.append(w.format(d[k]))
    return ", ".join(parts)
