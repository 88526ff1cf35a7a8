"""YAML configuration, validated strictly: unknown keys, wrong types and impossible values are
errors naming the key and the file (one line). ``--set dotted.key=value`` overrides apply to the
raw mapping before validation, so they are checked exactly like the file.

Units are in the key names (``_m``, ``_m_s``, ``_rad``, ``_rad_s``, ``_s``); angles in radians.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from mpf_mavlink.config.fields import EXTRA_SECTIONS, Vec3, _fail, _nonneg, _pos
from mpf_mavlink.errors import ConfigError


# ----------------------------------------------------------------------------- sections
@dataclass(frozen=True)
class PathConfig:
    """The path, fixed in the target frame {T} (x forward, y right, z down)."""

    type: Literal["line", "circle", "helix", "lemniscate", "spline"] = "lemniscate"
    size_m: float | None = field(default=None, metadata=_pos())  # lemniscate half-length a
    center_m: Vec3 = (0.0, 0.0, 0.0)  # circle, helix, lemniscate
    radius_m: float | None = field(default=None, metadata=_pos())  # circle, helix
    clockwise: bool = True  # circle, helix (seen from above)
    climb_per_turn_m: float | None = None  # helix (up > 0)
    turns: float | None = field(default=None, metadata=_pos())  # helix
    start_m: Vec3 | None = None  # line
    end_m: Vec3 | None = None  # line
    waypoints_m: list[Vec3] | None = None  # spline
    closed: bool = False  # spline


_PATH_KEYS = {
    "lemniscate": ({"size_m"}, {"center_m"}),
    "circle": ({"radius_m"}, {"center_m", "clockwise"}),
    "helix": ({"radius_m", "climb_per_turn_m", "turns"}, {"center_m", "clockwise"}),
    "line": ({"start_m", "end_m"}, set()),
    "spline": ({"waypoints_m"}, {"closed"}),
}


@dataclass(frozen=True)
class TargetConfig:
    """The moving target {T}. ``paper``: Section V; ``constant_turn``: constant speed,
    turn and climb rates (stationary when speed = 0); ``mavlink``: live over MAVLink
    (bridge only, see the ``mavlink`` section)."""

    type: Literal["stationary", "constant_turn", "paper", "mavlink"] = "stationary"
    position_ned_m: Vec3 = (0.0, 0.0, 0.0)
    yaw_rad: float = 0.0  # stationary / paper initial yaw
    speed_m_s: float = field(default=0.0, metadata=_nonneg())
    heading_rad: float = 0.0
    turn_rate_rad_s: float = 0.0
    climb_rate_m_s: float = 0.0


@dataclass(frozen=True)
class GuidanceConfig:
    """Gains of Theorem 1 and the practical extensions (all off = the paper's law).

    law: which guidance flies (``mpf``; or a baseline of core/guidance/baselines.py, same
    command type and adapter: ``npfg`` PX4's NPFG on the moving path with path-relative
    velocities, ``npfg_static`` the same path re-sent as if static, ``l1_loiter`` ArduPlane's
    L1 loiter about the moving centre, ``pursuit`` carrot chasing). The gains below are MPF's."""

    law: Literal["mpf", "npfg", "npfg_static", "l1_loiter", "pursuit"] = "mpf"
    K_p: float = field(default=4.0, metadata=_pos())
    K_R: float = field(default=2.0, metadata=_pos())
    alpha_m: float = field(default=1.0, metadata=_pos())
    rate_limit_rad_s: float | None = field(default=None, metadata=_pos())
    # per_axis: w2 and w3 capped each on its own; magnitude: |[w2, w3]| (core/guidance/law.py)
    rate_limit_mode: Literal["per_axis", "magnitude"] = "per_axis"
    psi_turn: bool = False
    psi_turn_threshold: float = field(default=0.5, metadata={"check": ("range", 0.0, 1.0)})
    psi_turn_rate_rad_s: float | None = field(default=None, metadata=_pos())
    wind_compensation: bool = True  # eta_hat of the autopilot's WIND / WIND_COV; false by choice
    initial_s_m: float | None = None  # None: closest point of the moving path


@dataclass(frozen=True)
class VehicleConfig:
    """Airspeed and the limits the feasibility check and the adapter respect."""

    airspeed_m_s: float = field(default=15.0, metadata=_pos())
    airspeed_min_m_s: float | None = field(default=None, metadata=_pos())
    airspeed_max_m_s: float | None = field(default=None, metadata=_pos())
    max_bank_rad: float = field(default=0.785398, metadata={"check": ("range_open", 0.0, 1.5707)})
    max_turn_rate_rad_s: float | None = field(default=None, metadata=_pos())
    # turn per bank the aircraft really flies, as a fraction of the coordinated turn g tan(phi)/V
    # (the adapter's learned turn_gain; the ArduPlane 4.7 SITL 'plane' learns ~0.745)
    turn_gain: float = field(default=1.0, metadata={"check": ("range_open", 0.0, 2.0)})
    # the autopilot's own roll limit (ArduPlane ROLL_LIMIT_DEG, PX4 FW_R_LIM) when known:
    # the checks and the verdict use the smaller of it and max_bank_rad
    autopilot_bank_limit_rad: float | None = field(
        default=None, metadata={"check": ("range_open", 0.0, 1.5707)}
    )
    # steady climb at full thrust and sink at idle, both at airspeed_m_s (m/s, > 0); null:
    # unknown (check measures them from a JSBSim SIL airframe, else skips the climb check)
    max_climb_rate_m_s: float | None = field(default=None, metadata=_pos())
    max_sink_rate_m_s: float | None = field(default=None, metadata=_pos())

    @property
    def v_min(self) -> float:
        return self.airspeed_min_m_s if self.airspeed_min_m_s is not None else self.airspeed_m_s

    @property
    def v_max(self) -> float:
        return self.airspeed_max_m_s if self.airspeed_max_m_s is not None else self.airspeed_m_s


@dataclass(frozen=True)
class GustConfig:
    """A region of wind (the paper's gusts acting at specified regions): NED centre (m),
    radius (m) and the extra air-mass velocity inside it (NED, m/s)."""

    center_ned_m: Vec3 = (0.0, 0.0, 0.0)
    radius_m: float = field(default=10.0, metadata=_pos())
    velocity_ned_m_s: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class WindConfig:
    """Wind for the kinematic plant: steady air-mass velocity (NED, m/s, blowing toward)."""

    steady_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    gusts: list[GustConfig] = field(default_factory=list)


@dataclass(frozen=True)
class KinematicConfig:
    """The paper's vehicle: constant airspeed, first-order rate autopilot of bandwidth lambda_w."""

    initial_position_ned_m: Vec3 = (0.0, 0.0, 0.0)
    initial_attitude_rpy_rad: Vec3 = (0.0, 0.0, 0.0)  # roll, pitch, yaw of the wind frame
    autopilot_bandwidth_rad_s: float = field(default=10.0, metadata=_pos())  # lambda_w
    dt_s: float = field(default=0.02, metadata={"check": ("range_open", 0.0, 1.0)})
    wind: WindConfig = field(default_factory=WindConfig)


@dataclass(frozen=True)
class SimConfig:
    duration_s: float = field(default=300.0, metadata=_pos())
    plant: Literal["kinematic"] = "kinematic"
    record_every: int = field(default=1, metadata={"check": ("ge", 1)})


@dataclass(frozen=True)
class ChecksConfig:
    """Parameters of the theorem's checks. c1 (m) bounds |pt(0)| (None: 1.25 |pt(0)|);
    c2 < 1/2 bounds Psi(0); the horizon (s) for Assumption 1 and feasibility (None: duration)."""

    c1_m: float | None = field(default=None, metadata=_pos())
    c2: float = field(default=0.25, metadata={"check": ("range_open", 0.0, 0.5)})
    horizon_s: float | None = field(default=None, metadata=_pos())
    assumption1_margin_m_s: float = field(default=0.0, metadata=_nonneg())
    # the vehicle may start at most this far (m) below the path's lowest point: further down
    # (on the ground under a path 100 m up) the capture would be a climb the law never flies
    max_start_below_m: float = field(default=30.0, metadata=_pos())
    # feasibility: a path that needs a bank within this much of vehicle.max_bank_rad fails
    # (the feedback needs room to correct; 44.6 of 45 deg flew 2.9 m RMS in SIL)
    bank_margin_rad: float = field(default=0.0873, metadata=_nonneg())


@dataclass(frozen=True)
class MetricsConfig:
    """Steady-state window and the verdict's bounds (mpf_mavlink/runs/verdict.py; SIL and run)."""

    steady_after_s: float = field(default=100.0, metadata=_nonneg())
    converge_threshold_m: float = field(default=1.0, metadata=_pos())
    fail_pt_m: float = field(default=10.0, metadata=_pos())
    altitude_floor_m: float = 10.0
    airspeed_tolerance: float = field(default=0.15, metadata={"check": ("range", 0.0, 1.0)})
    # 5 deg: the margin checks.bank_margin_rad keeps below the limit for the feedback and gusts,
    # allowed above it too (the roll loop's overshoot of a clipped set-point), for limit_hold_s
    bank_tolerance_rad: float = field(default=0.0873, metadata=_nonneg())
    pitch_limit_rad: float = field(default=0.6, metadata={"check": ("range_open", 0.0, 1.5707)})
    limit_hold_s: float = field(default=1.0, metadata=_nonneg())
    # the steady window a verdict needs (s): one turn at the demo's tightest radius (2 pi 50 m
    # at 16 m/s = 19.6 s); shorter flights are NOT JUDGED
    min_steady_s: float = field(default=20.0, metadata=_nonneg())
    # the fraction of the steady window that thrust may spend at its ceiling, or the bank
    # within checks.bank_margin_rad of its limit, before the verdict fails
    limit_fraction: float = field(default=0.2, metadata={"check": ("range", 0.0, 1.0)})


@dataclass(frozen=True)
class Config:
    """A whole scenario. ``source`` is the file it came from (for messages)."""

    name: str = "scenario"
    path: PathConfig = field(default_factory=PathConfig)
    target: TargetConfig = field(default_factory=TargetConfig)
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    kinematic: KinematicConfig = field(default_factory=KinematicConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    checks: ChecksConfig = field(default_factory=ChecksConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    source: str = field(default="<config>", metadata={"internal": True})
    extra: dict[str, Any] = field(default_factory=dict, metadata={"internal": True})

    def section(self, name: str) -> Any:
        """A section registered in EXTRA_SECTIONS (bridge, SIL), validated like the rest."""
        return self.extra[name]


# ----------------------------------------------------------------------------- validation
def _describe(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    if origin is tuple:
        return f"a list of {len(typing.get_args(tp))} numbers"
    if origin is list:
        return "a list"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    return str(tp)


def _convert(tp: Any, value: Any, src: str, key: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _convert(inner[0], value, src, key)
        raise _fail(src, key, "unsupported union")  # pragma: no cover
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise _fail(src, key, f"must be {_describe(tp)}, got {value!r}")
        return _build(tp, value, src, key)  # type: ignore[arg-type]
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _fail(src, key, f"must be a number, got {value!r}")
        v = float(value)
        if not math.isfinite(v):
            raise _fail(src, key, f"must be finite, got {value!r}")
        return v
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _fail(src, key, f"must be an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _fail(src, key, f"must be true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _fail(src, key, f"must be a string, got {value!r}")
        return value
    if origin is Literal:
        if value not in typing.get_args(tp):
            raise _fail(src, key, f"must be {_describe(tp)}, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list | tuple) or len(value) != len(args):
            raise _fail(src, key, f"must be {_describe(tp)}, got {value!r}")
        return tuple(
            _convert(a, v, src, f"{key}[{i}]")
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin is list:
        (a,) = typing.get_args(tp)
        if not isinstance(value, list):
            raise _fail(src, key, f"must be a list, got {value!r}")
        return [_convert(a, v, src, f"{key}[{i}]") for i, v in enumerate(value)]
    raise _fail(src, key, f"unsupported type {tp}")  # pragma: no cover


def _check(meta: Any, v: Any, src: str, key: str) -> None:
    chk = meta.get("check") if meta else None
    if chk is None or v is None:
        return
    kind = chk[0]
    if kind == "gt" and not v > chk[1]:
        raise _fail(src, key, f"must be > {chk[1]:g}, got {v!r}")
    if kind == "ge" and not v >= chk[1]:
        raise _fail(src, key, f"must be >= {chk[1]:g}, got {v!r}")
    if kind == "range" and not chk[1] <= v <= chk[2]:
        raise _fail(src, key, f"must be in [{chk[1]:g}, {chk[2]:g}], got {v!r}")
    if kind == "range_open" and not chk[1] < v < chk[2]:
        raise _fail(src, key, f"must be in ({chk[1]:g}, {chk[2]:g}), got {v!r}")
    if kind == "sign" and v not in (-1.0, 1.0):
        raise _fail(src, key, f"must be 1 or -1, got {v!r}")


def _build(cls: type, data: dict[str, Any], src: str, prefix: str) -> Any:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    kwargs: dict[str, Any] = {}
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if k not in fields:
            known = ", ".join(sorted(fields))
            raise _fail(src, key, f"unknown key (known here: {known})")
        val = _convert(hints[k], v, src, key)
        _check(fields[k].metadata, val, src, key)
        kwargs[k] = val
    return cls(**kwargs)


def _validate_cross(cfg: Config, extra: dict[str, Any]) -> None:
    src = cfg.source
    p = cfg.path
    need, opt = _PATH_KEYS[p.type]
    defaults = PathConfig()
    for name in need:
        if getattr(p, name) is None:
            raise _fail(src, f"path.{name}", f"required for path type {p.type!r}")
    for f in dataclasses.fields(PathConfig):
        if f.name in ("type",) or f.name in need or f.name in opt:
            continue
        if getattr(p, f.name) != getattr(defaults, f.name):
            raise _fail(src, f"path.{f.name}", f"not used by path type {p.type!r}")
    if p.type == "line" and p.start_m is not None and p.end_m is not None:
        if math.dist(p.start_m, p.end_m) < 1e-6:
            raise _fail(src, "path.end_m", "equals path.start_m: the path has zero length")
    if (
        p.type == "spline"
        and p.waypoints_m is not None
        and len(p.waypoints_m) < (3 if p.closed else 2)
    ):
        raise _fail(src, "path.waypoints_m", f"needs at least {3 if p.closed else 2} waypoints")
    v = cfg.vehicle
    if v.v_min > v.airspeed_m_s or v.v_max < v.airspeed_m_s:
        raise _fail(
            src, "vehicle.airspeed_m_s", "must lie within [airspeed_min_m_s, airspeed_max_m_s]"
        )


def load_config(path: str | Path, overrides: list[str] | None = None) -> Any:
    """Read, override and validate a YAML configuration; raise ConfigError naming key and file."""
    src = str(path)
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ConfigError(f"{src}: cannot read the configuration ({e.strerror})") from None
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{src}: not valid YAML{where}") from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{src}: the top level must be a mapping of sections")
    for ov in overrides or []:
        apply_override(raw, ov, src)
    _follow_sil_flavour(raw, overrides or [])
    return config_from_dict(raw, src)


def _follow_sil_flavour(raw: dict[str, Any], overrides: list[str]) -> None:
    """``--set sil.flavour=X`` is the one key that switches the SIL's autopilot: the bridge's
    ``mavlink.flavour`` follows it and a hold mode of the other autopilot is dropped (the
    flavour's own is the default), unless those keys are set on the command line too."""
    keys = {ov.split("=", 1)[0].strip() for ov in overrides}
    sil, mav = raw.get("sil"), raw.get("mavlink")
    if "sil.flavour" not in keys or not isinstance(sil, dict) or not isinstance(mav, dict):
        return
    flavour = sil.get("flavour")
    if "mavlink.flavour" not in keys and mav.get("flavour") not in (None, "auto", flavour):
        mav["flavour"] = flavour
        if "mavlink.hold_mode" not in keys:
            mav.pop("hold_mode", None)


def apply_override(raw: dict[str, Any], spec: str, src: str = "--set") -> None:
    """Apply one ``dotted.key=value`` (value parsed as YAML) to a raw mapping, in place."""
    if "=" not in spec:
        raise ConfigError(f"--set {spec}: expected dotted.key=value")
    key, _, text = spec.partition("=")
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise ConfigError(f"--set {spec}: expected dotted.key=value")
    try:
        value = yaml.safe_load(text) if text.strip() else None
    except yaml.YAMLError:
        raise ConfigError(f"--set {spec}: the value is not valid YAML") from None
    parts = key.split(".")
    node = raw
    for part in parts[:-1]:
        nxt = node.get(part)
        if nxt is None:
            nxt = {}
            node[part] = nxt
        if not isinstance(nxt, dict):
            raise ConfigError(f"--set {spec}: {part} is not a section")
        node = nxt
    node[parts[-1]] = value


def config_from_dict(raw: dict[str, Any], src: str = "<config>") -> Any:
    """Validate a raw mapping into a :class:`Config` (plus registered extra sections).

    A section class may define ``validate(cfg, src)`` for checks across sections; it runs once
    the whole configuration is built and raises ConfigError like the rest."""
    base = {k: v for k, v in raw.items() if k not in EXTRA_SECTIONS}
    cfg = _build(Config, base, src, "")
    cfg = dataclasses.replace(cfg, source=src)
    extra = {}
    for name, cls in EXTRA_SECTIONS.items():
        data = raw.get(name, {})
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise _fail(src, name, "must be a mapping")
        extra[name] = _build(cls, data, src, name)
    _validate_cross(cfg, extra)
    cfg = dataclasses.replace(cfg, extra=extra)
    for section in extra.values():
        validate = getattr(section, "validate", None)
        if validate is not None:
            validate(cfg, src)
    return cfg


def config_to_dict(cfg: Any, omit: tuple[str, ...] = ()) -> dict[str, Any]:
    """The mapping :func:`config_from_dict` turns back into ``cfg`` (every section, defaults
    included, tuples as lists), without the sections named in ``omit``: what a run directory
    keeps so that the flight can be re-run or replayed with the configuration it really had."""

    def plain(x: Any) -> Any:
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            return {
                f.name: plain(getattr(x, f.name))
                for f in dataclasses.fields(x)
                if not f.metadata.get("internal")
            }
        if isinstance(x, (list, tuple)):
            return [plain(v) for v in x]
        if isinstance(x, dict):
            return {k: plain(v) for k, v in x.items()}
        return x

    out = plain(cfg)
    out.update({k: plain(v) for k, v in cfg.extra.items()})
    for k in omit:
        out.pop(k, None)
    return out
