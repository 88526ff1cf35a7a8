"""YAML configuration, validated strictly: unknown keys, wrong types and impossible values are
errors naming the key and the file (one line). ``--set dotted.key=value`` overrides apply to the
raw mapping before validation, so they are checked exactly like the file.

Every section is a frozen dataclass and :class:`Config` hands each one out with its type
(``cfg.guidance``, ``cfg.mavlink``, ``cfg.sil``, ...). Units are in the key names (``_m``,
``_m_s``, ``_rad``, ``_rad_s``, ``_s``); angles in radians. The reference of every key,
docs/configuration.md, is generated from these classes (:mod:`mpf_mavlink.config.reference`).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, overload

import yaml

from mpf_mavlink.config.bridge import AdapterSection, MavlinkConfig
from mpf_mavlink.config.build import S, _build, parse_yaml
from mpf_mavlink.config.fields import Vec3, _doc, _fail, _nonneg, _open, _pos, _rng
from mpf_mavlink.config.fleet import FleetConfig, validate_fleet  # fleet: cooperative MPF
from mpf_mavlink.config.target import TargetEstimatorConfig
from mpf_mavlink.errors import ConfigError

if TYPE_CHECKING:
    from mpf_mavlink.config.sil import AircraftConfig, SilConfig


# ----------------------------------------------------------------------------- sections
@dataclass(frozen=True)
class PathConfig:
    """The path, fixed in the target frame {T} (x forward, y right, z down). Which keys a type
    needs: lemniscate ``size_m``; circle ``radius_m``; helix ``radius_m``, ``climb_per_turn_m``,
    ``turns``; line ``start_m``, ``end_m``; spline ``waypoints_m``. Keys of another type are
    errors."""

    type: Literal["line", "circle", "helix", "lemniscate", "spline"] = "lemniscate"
    size_m: float | None = field(default=None, metadata=_pos("lemniscate: half-length a"))
    center_m: Vec3 = field(default=(0.0, 0.0, 0.0), metadata=_doc("circle, helix, lemniscate"))
    radius_m: float | None = field(default=None, metadata=_pos("circle, helix"))
    clockwise: bool = field(default=True, metadata=_doc("circle, helix: seen from above"))
    climb_per_turn_m: float | None = field(default=None, metadata=_doc("helix: up > 0"))
    turns: float | None = field(default=None, metadata=_pos("helix"))
    start_m: Vec3 | None = field(default=None, metadata=_doc("line"))
    end_m: Vec3 | None = field(default=None, metadata=_doc("line"))
    waypoints_m: list[Vec3] | None = field(default=None, metadata=_doc("spline"))
    closed: bool = field(default=False, metadata=_doc("spline: a loop"))


_PATH_KEYS = {
    "lemniscate": ({"size_m"}, {"center_m"}),
    "circle": ({"radius_m"}, {"center_m", "clockwise"}),
    "helix": ({"radius_m", "climb_per_turn_m", "turns"}, {"center_m", "clockwise"}),
    "line": ({"start_m", "end_m"}, set()),
    "spline": ({"waypoints_m"}, {"closed"}),
}


@dataclass(frozen=True)
class TargetConfig:
    """The moving target {T}. ``paper``: Section V of the paper; ``constant_turn``: constant
    speed, turn and climb rates (stationary when speed = 0); ``mavlink``: live over MAVLink
    (bridge only, see the ``mavlink`` and ``target_estimator`` sections)."""

    type: Literal["stationary", "constant_turn", "paper", "mavlink"] = "stationary"
    position_ned_m: Vec3 = field(default=(0.0, 0.0, 0.0), metadata=_doc("initial position"))
    yaw_rad: float = field(default=0.0, metadata=_doc("stationary / paper: initial yaw"))
    speed_m_s: float = field(default=0.0, metadata=_nonneg("constant_turn"))
    heading_rad: float = field(default=0.0, metadata=_doc("constant_turn: initial heading"))
    turn_rate_rad_s: float = field(default=0.0, metadata=_doc("constant_turn"))
    climb_rate_m_s: float = field(default=0.0, metadata=_doc("constant_turn: up > 0"))


#: the guidance laws ``guidance.law`` names (the paper's MPF and the baselines)
LawName = Literal["mpf", "npfg", "npfg_static", "l1_loiter", "pursuit"]


@dataclass(frozen=True)
class GuidanceConfig:
    """Gains of Theorem 1 and the practical extensions (all off = the paper's law)."""

    law: LawName = field(
        default="mpf",
        metadata=_doc(
            "which guidance flies: mpf, or a baseline with the same command type and adapter "
            "(npfg: PX4's NPFG on the moving path; npfg_static: the path re-sent as if static; "
            "l1_loiter: ArduPlane's L1 loiter about the moving centre; pursuit: carrot chasing)"
        ),
    )
    K_p: float = field(
        default=4.0,
        metadata=_pos("gain of the virtual point's progression sdot on the along-path error"),
    )
    K_R: float = field(default=2.0, metadata=_pos("gain on the attitude error e"))
    alpha_m: float = field(
        default=1.0,
        metadata=_pos("look-ahead distance of the approach direction (small: aggressive capture)"),
    )
    rate_limit_rad_s: float | None = field(
        default=None, metadata=_pos("cap on the commanded rates w2, w3; null: none")
    )
    rate_limit_mode: Literal["per_axis", "magnitude"] = field(
        default="per_axis", metadata=_doc("per_axis: w2 and w3 each; magnitude: |[w2, w3]|")
    )
    psi_turn: bool = field(
        default=False,
        metadata=_doc("a defined constant-rate turn when Psi >= psi_turn_threshold (far off)"),
    )
    psi_turn_threshold: float = field(default=0.5, metadata=_rng(0.0, 1.0))
    psi_turn_rate_rad_s: float | None = field(
        default=None, metadata=_pos("the turn's rate; null: K_R / 2")
    )
    wind_compensation: bool = field(
        default=True, metadata=_doc("use the autopilot's wind (WIND / WIND_COV) in the law")
    )
    initial_s_m: float | None = field(
        default=None, metadata=_doc("initial path parameter; null: the closest point")
    )
    capture_guards: bool = field(
        default=True,
        metadata=_doc(
            "beyond capture_distance_m of the virtual point: sdot within +-airspeed of the "
            "on-path rate, the turn within the bank limit less capture_bank_margin_rad, the "
            "flight path within the pitch band and never sinking at the floor "
            "(core/guidance/capture.py); false: the law's command as it is"
        ),
    )
    capture_distance_m: float = field(
        default=150.0,
        metadata=_pos(
            "|pt| (m) beyond which the capture guards act (fully from 30 m further); within "
            "it the law is untouched"
        ),
    )
    capture_bank_margin_rad: float = field(
        default=0.0873,
        metadata=_nonneg("kept below the autopilot's bank limit while capturing (5 deg)"),
    )
    capture_floor_margin_m: float = field(
        default=5.0,
        metadata=_nonneg(
            "while capturing, the aircraft does not sink below the path's lowest point less "
            "this (nor below metrics.altitude_floor_m)"
        ),
    )


@dataclass(frozen=True)
class VehicleConfig:
    """Airspeed and the limits the feasibility check and the adapter respect."""

    airspeed_m_s: float = field(default=15.0, metadata=_pos("the airspeed flown"))
    airspeed_min_m_s: float | None = field(
        default=None, metadata=_pos("the envelope's floor; null: airspeed_m_s")
    )
    airspeed_max_m_s: float | None = field(
        default=None, metadata=_pos("the envelope's ceiling; null: airspeed_m_s")
    )
    max_bank_rad: float = field(default=0.785398, metadata=_open(0.0, 1.5707))
    max_turn_rate_rad_s: float | None = field(default=None, metadata=_pos())
    turn_gain: float = field(
        default=1.0,
        metadata=_open(
            0.0, 2.0,
            "turn per bank the aircraft really flies, as a fraction of g tan(phi) / V "
            "(the ArduPlane 4.7 SITL plane flies about 0.745)",
        ),
    )  # fmt: skip
    autopilot_bank_limit_rad: float | None = field(
        default=None,
        metadata=_open(
            0.0, 1.5707,
            "the autopilot's own roll limit (ArduPlane ROLL_LIMIT_DEG, PX4 FW_R_LIM): the "
            "checks and the verdict use the smaller of it and max_bank_rad",
        ),
    )  # fmt: skip
    max_climb_rate_m_s: float | None = field(
        default=None,
        metadata=_pos(
            "steady climb at full thrust at airspeed_m_s; null: measured from a JSBSim SIL "
            "airframe, else the climb check is skipped"
        ),
    )
    max_sink_rate_m_s: float | None = field(
        default=None, metadata=_pos("steady sink at idle at airspeed_m_s; null as above")
    )

    @property
    def v_min(self) -> float:
        return self.airspeed_min_m_s if self.airspeed_min_m_s is not None else self.airspeed_m_s

    @property
    def v_max(self) -> float:
        return self.airspeed_max_m_s if self.airspeed_max_m_s is not None else self.airspeed_m_s


@dataclass(frozen=True)
class GustConfig:
    """A region of wind (the paper's gusts acting at specified regions)."""

    center_ned_m: Vec3 = (0.0, 0.0, 0.0)
    radius_m: float = field(default=10.0, metadata=_pos())
    velocity_ned_m_s: Vec3 = field(
        default=(0.0, 0.0, 0.0), metadata=_doc("the extra air-mass velocity inside")
    )


@dataclass(frozen=True)
class WindConfig:
    """Wind for the kinematic plant: steady air-mass velocity (NED, blowing toward)."""

    steady_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    gusts: list[GustConfig] = field(default_factory=list)


@dataclass(frozen=True)
class KinematicConfig:
    """The paper's vehicle: constant airspeed, first-order rate autopilot of bandwidth lambda_w."""

    initial_position_ned_m: Vec3 = (0.0, 0.0, 0.0)
    initial_attitude_rpy_rad: Vec3 = field(
        default=(0.0, 0.0, 0.0), metadata=_doc("roll, pitch, yaw of the wind frame")
    )
    autopilot_bandwidth_rad_s: float = field(default=10.0, metadata=_pos("lambda_w"))
    dt_s: float = field(default=0.02, metadata=_open(0.0, 1.0))
    wind: WindConfig = field(default_factory=WindConfig)


@dataclass(frozen=True)
class SimConfig:
    """The paper's in-process closed loop (``mpf-mavlink sim`` with ``sil.link: none``)."""

    duration_s: float = field(default=300.0, metadata=_pos())
    plant: Literal["kinematic"] = "kinematic"
    record_every: int = field(
        default=1, metadata={"check": ("ge", 1), "doc": "keep every n-th step"}
    )


@dataclass(frozen=True)
class ChecksConfig:
    """Parameters of the theorem's checks (``mpf-mavlink check``, and before every flight)."""

    c1_m: float | None = field(default=None, metadata=_pos("bounds |pt(0)|; null: 1.25 |pt(0)|"))
    c2: float = field(default=0.25, metadata=_open(0.0, 0.5, "bounds Psi(0)"))
    horizon_s: float | None = field(
        default=None, metadata=_pos("for Assumption 1 and feasibility; null: the duration")
    )
    assumption1_margin_m_s: float = field(default=0.0, metadata=_nonneg())
    max_start_below_m: float = field(
        default=30.0,
        metadata=_pos(
            "how far below the path's lowest point the vehicle may start (further down the "
            "capture would be a climb the law never flies)"
        ),
    )
    bank_margin_rad: float = field(
        default=0.0873,
        metadata=_nonneg(
            "a path that needs a bank within this much of vehicle.max_bank_rad fails "
            "(the feedback needs room to correct)"
        ),
    )


@dataclass(frozen=True)
class MetricsConfig:
    """The steady-state window and the verdict's bounds (mpf_mavlink/runs/verdict.py)."""

    steady_after_s: float = field(default=100.0, metadata=_nonneg("capture time not judged"))
    converge_threshold_m: float = field(default=1.0, metadata=_pos())
    fail_pt_m: float = field(default=10.0, metadata=_pos("|pt| above this in steady state fails"))
    altitude_floor_m: float = 10.0
    airspeed_tolerance: float = field(
        default=0.15, metadata=_rng(0.0, 1.0, "fraction outside the envelope allowed")
    )
    bank_tolerance_rad: float = field(
        default=0.0873,
        metadata=_nonneg(
            "allowed above the bank limit (the roll loop's overshoot) for limit_hold_s"
        ),
    )
    pitch_limit_rad: float = field(default=0.6, metadata=_open(0.0, 1.5707))
    limit_hold_s: float = field(default=1.0, metadata=_nonneg())
    min_steady_s: float = field(
        default=20.0,
        metadata=_nonneg(
            "the steady window a verdict needs (one turn at 50 m and 16 m/s is 19.6 s); "
            "shorter flights are NOT JUDGED"
        ),
    )
    limit_fraction: float = field(
        default=0.2,
        metadata=_rng(
            0.0, 1.0,
            "fraction of the steady window thrust may spend at its ceiling, or the bank "
            "within checks.bank_margin_rad of its limit",
        ),
    )  # fmt: skip


@dataclass(frozen=True)
class EnvelopeConfig:
    """The bridge's envelope monitor (mpf_mavlink/bridge/envelope.py, docs/bridge.md): what
    the law demands (bank, pitch, climb, sink, airspeed, thrust, the wind) against what the
    aircraft can give, as episodes in metrics.json, the verdict and a STATUSTEXT each."""

    policy: Literal["hold", "warn"] = field(
        default="hold",
        metadata=_doc(
            "hold: hand back to the hold mode (exit 4) once one episode lasts exceeded_for_s; "
            "warn: only report"
        ),
    )
    exceeded_for_s: float = field(
        default=5.0,
        metadata=_pos(
            "how long an envelope may stay exceeded before the hold policy hands back (5 s: "
            "about two roll-loop settling times of a gust past, short of a lap of a 150 m "
            "circle's downwind leg)"
        ),
    )
    armed_after_s: float | None = field(
        default=None,
        metadata=_nonneg(
            "the policy acts from this long after engagement (the capture turns at the bank "
            "limit by design); null: metrics.steady_after_s"
        ),
    )
    clear_s: float = field(
        default=1.0,
        metadata=_nonneg(
            "an episode ends once its condition has been clear this long (one STATUSTEXT for "
            "a limit touched on and off)"
        ),
    )


#: the sections of the bridge and the target estimator, by their YAML name
SECTIONS: dict[str, type] = {
    "mavlink": MavlinkConfig,
    "adapter": AdapterSection,
    "target_estimator": TargetEstimatorConfig,
    "fleet": FleetConfig,
}
#: the sections the simulator owns (mpf_mavlink.config.sil): validated with the rest where a
#: simulated flight may be built (load_config's default), kept as read where only the bridge
#: flies (``sim_sections=False``: ``mpf-mavlink run``), which never reads them
SIM_SECTIONS = ("sil", "aircraft")


def section_types() -> dict[str, type]:
    """Every section's type by its YAML name, the simulator's included (imported here)."""
    from mpf_mavlink.config.sil import AircraftConfig, SilConfig

    sim = {"sil": SilConfig, "aircraft": AircraftConfig}
    order = ("mavlink", "adapter", "target_estimator", "sil", "aircraft", "fleet")
    return {name: sim[name] if name in sim else SECTIONS[name] for name in order}


@dataclass(frozen=True)
class _Unread:
    """A simulator's section as the file gave it, validated on first use."""

    data: dict[str, Any]


@dataclass(frozen=True)
class Config:
    """A whole scenario. ``source`` is the file it came from (for messages).

    The sections of the bridge, the SIL vehicle and the target estimator are properties typed
    like the rest (``cfg.mavlink``, ``cfg.adapter``, ``cfg.target_estimator``, ``cfg.sil``,
    ``cfg.aircraft``); ``extra`` holds them by name (``dataclasses.replace(cfg, extra=...)``
    swaps one) and a section left out of ``extra`` reads as its defaults."""

    name: str = "scenario"
    path: PathConfig = field(default_factory=PathConfig)
    target: TargetConfig = field(default_factory=TargetConfig)
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    kinematic: KinematicConfig = field(default_factory=KinematicConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    checks: ChecksConfig = field(default_factory=ChecksConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    envelope: EnvelopeConfig = field(default_factory=EnvelopeConfig)
    source: str = field(default="<config>", metadata={"internal": True})
    extra: dict[str, Any] = field(default_factory=dict, metadata={"internal": True})

    def _get(self, name: str, cls: type[S]) -> S:
        value = self.extra.get(name)
        if value is None:
            return cls()
        if isinstance(value, _Unread):
            value = self._read_sim_sections()[name]
        if not isinstance(value, cls):
            raise TypeError(f"section {name} is a {type(value).__name__}, not {cls.__name__}")
        return value

    @property
    def mavlink(self) -> MavlinkConfig:
        return self._get("mavlink", MavlinkConfig)

    @property
    def adapter(self) -> AdapterSection:
        return self._get("adapter", AdapterSection)

    @property
    def target_estimator(self) -> TargetEstimatorConfig:
        return self._get("target_estimator", TargetEstimatorConfig)

    def _read_sim_sections(self) -> dict[str, Any]:
        """Validate the simulator's sections kept as read (:data:`SIM_SECTIONS`), in place."""
        types = section_types()
        for name in SIM_SECTIONS:
            value = self.extra.get(name)
            if isinstance(value, _Unread):
                self.extra[name] = _build(types[name], value.data, self.source, name)
        _validate_sim(self)
        return self.extra

    @property
    def sil(self) -> SilConfig:
        from mpf_mavlink.config.sil import SilConfig

        return self._get("sil", SilConfig)

    @property
    def aircraft(self) -> AircraftConfig:
        from mpf_mavlink.config.sil import AircraftConfig

        return self._get("aircraft", AircraftConfig)

    @overload
    def section(self, name: Literal["mavlink"]) -> MavlinkConfig: ...
    @overload
    def section(self, name: Literal["adapter"]) -> AdapterSection: ...
    @overload
    def section(self, name: Literal["target_estimator"]) -> TargetEstimatorConfig: ...
    @overload
    def section(self, name: Literal["sil"]) -> SilConfig: ...
    @overload
    def section(self, name: Literal["aircraft"]) -> AircraftConfig: ...
    @overload
    def section(self, name: Literal["fleet"]) -> FleetConfig: ...
    def section(self, name: str) -> object:
        """The section called ``name`` (one of :data:`SECTIONS`), with its type."""
        types = SECTIONS if name in SECTIONS else section_types()
        if name not in types:
            raise KeyError(f"no configuration section {name!r} (known: {', '.join(types)})")
        return self._get(name, types[name])


def bank_limit_rad(cfg: Config) -> float:
    """The bank the vehicle may fly (rad): ours, or the autopilot's own when it is smaller."""
    v = cfg.vehicle
    ap = v.autopilot_bank_limit_rad
    return v.max_bank_rad if ap is None else min(v.max_bank_rad, ap)


def _validate_cross(cfg: Config) -> None:
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


def load_config(
    path: str | Path, overrides: list[str] | None = None, *, sim_sections: bool = True
) -> Config:
    """Read, override and validate a YAML configuration; raise ConfigError naming key and file.

    ``sim_sections=False``: the simulator's sections (:data:`SIM_SECTIONS`) are kept as read and
    validated only if something reads them (the live bridge does not)."""
    src = str(path)
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ConfigError(f"{src}: cannot read the configuration ({e.strerror})") from None
    raw = parse_yaml(text, src)
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{src}: the top level must be a mapping of sections")
    for ov in overrides or []:
        apply_override(raw, ov, src)
    _follow_sil_flavour(raw, overrides or [])
    return config_from_dict(raw, src, sim_sections=sim_sections)


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


def config_from_dict(
    raw: dict[str, Any], src: str = "<config>", *, sim_sections: bool = True
) -> Config:
    """Validate a raw mapping into a :class:`Config` (every section of :data:`SECTIONS` too, and
    those of :data:`SIM_SECTIONS` unless ``sim_sections`` is False: then on first use).

    Checks across sections (a section's ``validate(cfg, src)``) run once the whole
    configuration is built and raise ConfigError like the rest."""
    base = {k: v for k, v in raw.items() if k not in SECTIONS and k not in SIM_SECTIONS}
    cfg = _build(Config, base, src, "")
    extra: dict[str, Any] = {}
    for name in [*SECTIONS, *SIM_SECTIONS]:
        data = raw.get(name, {})
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise _fail(src, name, "must be a mapping")
        if name in SECTIONS:
            extra[name] = _build(SECTIONS[name], data, src, name)
        else:
            extra[name] = _Unread(copy.deepcopy(data))
    cfg = dataclasses.replace(cfg, source=src, extra=extra)
    _validate_cross(cfg)
    cfg.mavlink.validate(src, cfg.target.type)
    cfg.adapter.validate(src)
    cfg.target_estimator.validate(src)
    validate_fleet(cfg, src)
    if sim_sections:
        cfg._read_sim_sections()
    return cfg


def _validate_sim(cfg: Config) -> None:
    cfg.sil.validate(cfg.source, cfg.target.type, cfg.mavlink)
    cfg.aircraft.validate(cfg.source, cfg.sil)


def config_to_dict(cfg: Config, omit: tuple[str, ...] = ()) -> dict[str, Any]:
    """The mapping :func:`config_from_dict` turns back into ``cfg`` (every section, defaults
    included, tuples as lists), without the sections named in ``omit``: what a run directory
    keeps so that the flight can be re-run or replayed with the configuration it really had."""

    def plain(x: object) -> object:
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            return {
                f.name: plain(getattr(x, f.name))
                for f in dataclasses.fields(x)
                if not f.metadata.get("internal")
            }
        if isinstance(x, list | tuple):
            return [plain(v) for v in x]
        if isinstance(x, dict):
            return {k: plain(v) for k, v in x.items()}
        return x

    out: dict[str, Any] = {
        f.name: plain(getattr(cfg, f.name))
        for f in dataclasses.fields(cfg)
        if not f.metadata.get("internal")
    }
    for name in [*SECTIONS, *SIM_SECTIONS]:
        value = cfg.extra.get(name)
        if isinstance(value, _Unread):  # as read: the run that kept it never validated it
            out[name] = copy.deepcopy(value.data)
        else:
            out[name] = plain(cfg.section(name))  # type: ignore[call-overload]
    for k in omit:
        out.pop(k, None)
    return out
