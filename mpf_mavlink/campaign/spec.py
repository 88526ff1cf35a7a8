"""The campaign file: which mission, what varies and how, how many flights, on which plant.

Validated like every configuration (unknown keys, wrong types and impossible values are one-line
errors naming the key and the file), and every varied key is checked against the base
configuration before a single flight starts: a campaign of a thousand flights must not die on
its first sample. Example (configs/campaign_roa.yaml)::

    name: roa-paper
    base: paper_lemniscate.yaml        # relative to this file
    plant: kinematic                   # kinematic (in-process) | sil (mpf-mavlink sim, UDP)
    samples: 1000
    design: sobol                      # random | lhs | sobol (scipy.stats.qmc), seeded
    seed: 1
    set: [sim.duration_s=120]          # fixed overrides of every flight
    vary:
      - {key: initial.distance_m, dist: uniform, low: 0, high: 400}
      - {key: initial.heading_rad, dist: uniform, low: -3.14, high: 3.14}
    stop_after_converged_s: 20         # kinematic: a flight ends once |pt| stayed below the
                                       # threshold this long (the rest would only repeat it)

Keys are the configuration's dotted keys (``sil.turbulence``, ``guidance.K_p``); a component of
a vector is ``key[i]`` (``sil.wind_ned_m_s[1]``). Three more place the start relative to the
moving path at t = 0 (kinematic plant): ``initial.distance_m`` (from the path's closest point,
m), ``initial.bearing_rad`` (direction of that offset about the path tangent, 0 = the path's
f2 axis) and ``initial.heading_rad`` (yaw of the start relative to the path tangent's course).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from mpf_mavlink.config.build import _build, parse_yaml
from mpf_mavlink.config.fields import _fail, _nonneg, _pos
from mpf_mavlink.errors import ConfigError

INITIAL_KEYS = ("initial.distance_m", "initial.bearing_rad", "initial.heading_rad")
DEFAULT_METRICS = [
    "first_within_s", "convergence_time_s", "steady_rms_m", "steady_max_m", "steady_psi_max",
    "max_rate_cmd_rad_s", "final_pt_m", "initial_pt_m", "verdict",
]  # fmt: skip
_INDEXED = re.compile(r"^(?P<key>[A-Za-z_][\w.]*)\[(?P<i>\d+)\]$")


@dataclass(frozen=True)
class Variable:
    """One varied key and its distribution (units of the key)."""

    key: str
    dist: Literal["uniform", "normal", "loguniform", "choice"]
    low: float | None = None  # uniform, loguniform (> 0)
    high: float | None = None
    mean: float | None = None  # normal
    sd: float | None = field(default=None, metadata=_pos())
    values: list[str] | None = None  # choice: YAML texts, as after --set KEY=

    def check(self, src: str, where: str) -> None:
        need = {
            "uniform": ("low", "high"),
            "loguniform": ("low", "high"),
            "normal": ("mean", "sd"),
            "choice": ("values",),
        }[self.dist]
        for name in ("low", "high", "mean", "sd", "values"):
            given = getattr(self, name) is not None
            if name in need and not given:
                raise _fail(src, f"{where}.{name}", f"required for dist {self.dist!r}")
            if name not in need and given:
                raise _fail(src, f"{where}.{name}", f"not used by dist {self.dist!r}")
        if self.dist in ("uniform", "loguniform"):
            assert self.low is not None and self.high is not None
            if not self.low < self.high:
                raise _fail(src, f"{where}.high", f"must be > low ({self.low:g})")
            if self.dist == "loguniform" and not self.low > 0.0:
                raise _fail(src, f"{where}.low", "must be > 0 for a log-uniform distribution")
        if self.dist == "choice" and not self.values:
            raise _fail(src, f"{where}.values", "must name at least one value")


@dataclass(frozen=True)
class CampaignSpec:
    name: str
    base: str
    samples: int = field(metadata=_pos())
    vary: list[Variable]
    design: Literal["random", "lhs", "sobol"] = "random"
    seed: int = 0
    plant: Literal["kinematic", "sil"] = "kinematic"
    set: list[str] = field(default_factory=list)
    metrics: list[str] = field(default_factory=lambda: list(DEFAULT_METRICS))
    timeout_s: float = field(default=900.0, metadata=_pos())  # one flight, wall clock
    stop_after_converged_s: float | None = field(default=None, metadata=_pos())
    force: bool = False  # fly what the pre-flight gate refuses (SIL plant)
    keep_worst: int = field(default=3, metadata=_nonneg())  # run directories re-flown and kept
    rank_by: str = "steady_rms_m"  # the metric that names the worst flights (larger = worse)
    success_rms_m: float | None = field(default=None, metadata=_pos())  # success also needs this
    source: str = field(default="<campaign>", metadata={"internal": True})

    @property
    def base_path(self) -> Path:
        return (Path(self.source).parent / self.base).resolve()


def _normalise(raw: dict[str, Any]) -> dict[str, Any]:
    """Choice values are kept as the YAML text --set would take, whatever their YAML type."""
    out = dict(raw)
    vary = out.get("vary")
    if isinstance(vary, list):
        new = []
        for v in vary:
            if isinstance(v, dict) and isinstance(v.get("values"), list):
                v = {**v, "values": [yaml_text(x, keep_str=True) for x in v["values"]]}
            new.append(v)
        out["vary"] = new
    return out


def yaml_text(x: Any, keep_str: bool = False) -> str:
    """``x`` as the YAML text that ``--set`` reads back as the same value. Floats exactly, and
    as floats: PyYAML writes 1e-05 as 1.0e-05 (Python's repr, 1e-05, has no dot, and PyYAML
    reads that as a string). ``keep_str``: a str is YAML text already (the choice values of a
    campaign file, kept as written) and passes through."""
    if keep_str and isinstance(x, str):
        return x
    if isinstance(x, float):
        x = float(x)  # numpy's floats: the safe dumper knows only Python's
    return yaml.safe_dump(x, default_flow_style=True).strip().removesuffix("...").strip()


def parse_campaign(path: str | Path) -> CampaignSpec:
    """Read and validate a campaign file (its keys are checked against the base configuration
    by :func:`mpf_mavlink.campaign.design.load_campaign`)."""
    src = str(path)
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ConfigError(f"{src}: cannot read the campaign ({e.strerror})") from None
    raw = parse_yaml(text, src)
    if not isinstance(raw, dict):
        raise ConfigError(f"{src}: the top level must be a mapping")
    spec: CampaignSpec = _build(CampaignSpec, _normalise(raw), src, "")
    spec = CampaignSpec(**{**spec.__dict__, "source": src})
    if not spec.vary:
        raise _fail(src, "vary", "must name at least one key")
    keys = [v.key for v in spec.vary]
    for i, v in enumerate(spec.vary):
        v.check(src, f"vary[{i}]")
        if keys.count(v.key) > 1:
            raise _fail(src, f"vary[{i}].key", f"{v.key} is varied twice")
        if v.key in INITIAL_KEYS and spec.plant != "kinematic":
            raise _fail(src, f"vary[{i}].key", f"{v.key} places the kinematic plant's start")
    if not spec.base_path.is_file():
        raise _fail(src, "base", f"no configuration {spec.base_path}")
    if spec.plant == "kinematic" and spec.design == "sobol" and spec.samples & (spec.samples - 1):
        pass  # scipy warns that balance needs powers of two; any count still works
    if spec.rank_by not in spec.metrics:
        raise _fail(src, "rank_by", f"{spec.rank_by} is not among the metrics kept")
    return spec


def probe_values(v: Variable) -> list[Any]:
    if v.dist == "choice":
        assert v.values is not None
        return [yaml.safe_load(x) for x in v.values]
    if v.dist == "normal":
        assert v.mean is not None and v.sd is not None
        return [v.mean]
    assert v.low is not None and v.high is not None
    return [v.low, v.high]


def split_indexed(key: str) -> tuple[str, int | None]:
    """``a.b[1]`` -> (``a.b``, 1); ``a.b`` -> (``a.b``, None)."""
    m = _INDEXED.match(key)
    if m is None:
        return key, None
    return m.group("key"), int(m.group("i"))


def finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
