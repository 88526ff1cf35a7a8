"""The autopilot profile's schema: what the real firmware does that the SIL's emulation must
reproduce, identified from flights of the firmware (``python -m lab.calibration.identify``) and
named by ``sil.autopilot_profile: configs/autopilots/<name>.yaml``. The emulation that uses it is
sim/autopilot/profile.py (its docstring says what each section changes in the SIL).

Validated as strictly as a config: unknown keys, wrong types and impossible values are one-line
errors naming the key and the file. Units SI, radians.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from mpf_mavlink.config.build import _build
from mpf_mavlink.config.fields import _nonneg, _pos
from mpf_mavlink.errors import ConfigError


@dataclass(frozen=True)
class AttitudeResponse:
    """Flown attitude vs commanded: dead time (s), first-order lag (s), gain and bias (rad)."""

    roll_delay_s: float = field(default=0.0, metadata={"check": ("range", 0.0, 1.0)})
    roll_tau_s: float = field(default=0.0, metadata={"check": ("range", 0.0, 5.0)})
    roll_gain: float = field(default=1.0, metadata={"check": ("range", 0.5, 1.5)})
    roll_bias_rad: float = field(default=0.0, metadata={"check": ("range", -0.2, 0.2)})
    pitch_delay_s: float = field(default=0.0, metadata={"check": ("range", 0.0, 1.0)})
    pitch_tau_s: float = field(default=0.0, metadata={"check": ("range", 0.0, 5.0)})
    pitch_gain: float = field(default=1.0, metadata={"check": ("range", 0.5, 1.5)})
    pitch_bias_rad: float = field(default=0.0, metadata={"check": ("range", -0.2, 0.2)})
    # body-rate offboard: a slow random roll-rate error of the firmware's rate loop (Gauss-Markov,
    # 1-sigma rad/s, correlation time s), as PX4 SIH's noisy gyros leave in its integrators: the
    # slow +-2-5 m radial wander of real PX4 (an empirical disturbance, fitted to its flights)
    roll_rate_wander_rad_s: float = field(default=0.0, metadata=_nonneg())
    rate_wander_tau_s: float = field(default=30.0, metadata=_pos())


@dataclass(frozen=True)
class TurnResponse:
    """Heading rate per bank relative to the coordinated turn (1: textbook)."""

    turn_gain: float = field(default=1.0, metadata={"check": ("range", 0.5, 1.5)})
    # heading minus ground course in a steady turn, per unit tan(bank) (rad; the sideslip of the
    # slipping turn: the nose points outside the turn, ArduPlane -0.075)
    slip_per_tan_bank_rad: float = field(default=0.0, metadata={"check": ("range", -0.5, 0.5)})


@dataclass(frozen=True)
class ThrustResponse:
    """What full offboard thrust flies: the level airspeed (m/s) at thrust 1 (None: the plant's
    own). PX4 SIH's airplane holds ~13.6 m/s at full throttle, short of FW_AIRSPD_TRIM 15."""

    full_thrust_airspeed_m_s: float | None = field(default=None, metadata=_pos())


@dataclass(frozen=True)
class EstimatorModel:
    """What the reported state adds to the truth (1-sigma; m, m/s, rad; s)."""

    position_noise_m: float = field(default=0.0, metadata=_nonneg())
    velocity_noise_m_s: float = field(default=0.0, metadata=_nonneg())
    attitude_noise_rad: float = field(default=0.0, metadata=_nonneg())
    rate_noise_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)  # p, q, r reported, 1-sigma
    vertical_noise_m: float = field(default=0.0, metadata=_nonneg())
    # first-order Gauss-Markov errors of the estimate (1-sigma, correlation time), as an EKF's
    # error against the truth: position (horizontal, vertical), velocity (horizontal,
    # vertical), attitude (roll, pitch, yaw; the attitude the autopilot reports AND controls on,
    # so a roll error turns the aircraft as a bank error does), the reported wind (N and E)
    horizontal_wander_m: float = field(default=0.0, metadata=_nonneg())
    vertical_wander_m: float = field(default=0.0, metadata=_nonneg())
    wander_tau_s: float = field(default=30.0, metadata=_pos())
    vertical_wander_tau_s: float | None = field(default=None, metadata=_pos())
    velocity_wander_m_s: tuple[float, float] = (0.0, 0.0)
    velocity_wander_tau_s: tuple[float, float] = (5.0, 5.0)
    attitude_wander_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude_wander_tau_s: tuple[float, float, float] = (5.0, 5.0, 5.0)
    # the reported position ahead of the truth along the ground velocity (s): what ArduPlane's
    # EKF3 output predicts past its own attitude/velocity instant (dataflash POS against SIM)
    position_lead_s: float = field(default=0.0, metadata={"check": ("range", -1.0, 1.0)})
    # the reported airspeed (VFR_HUD) over the SIL's equivalent airspeed of the same flight: the
    # firmware flies its airspeed as the SIL does, and reports this much of it
    airspeed_scale: float = field(default=1.0, metadata={"check": ("range", 0.8, 1.2)})
    wind_wander_m_s: float = field(default=0.0, metadata=_nonneg())
    wind_wander_tau_s: float = field(default=10.0, metadata=_pos())
    # The firmware's wind estimate: a first-order lag (wind_tau_s; None: the vehicle's
    # sil.wind_estimate_tau_s) of the air mass plus an apparent wind fixed to the ground velocity
    # (along it and to its right, m/s): an airspeed scale error and the sideslip of a turn that
    # an estimator assuming no sideslip reads as wind. Turning at omega, the lag turns it by
    # atan(omega tau) and shrinks it by sqrt(1 + (omega tau)^2), as seen on ArduPlane.
    wind_apparent_along_m_s: float = 0.0
    wind_scale: float = field(
        default=1.0, metadata={"check": ("range", 0.5, 1.5)}
    )  # of the air mass
    wind_apparent_side_m_s: float = 0.0
    wind_tau_s: float | None = field(default=None, metadata=_nonneg())


@dataclass(frozen=True)
class FitResiduals:
    """The identification's residuals (for the record): attitude fits (rad), wind fit (m/s)."""

    roll_rms_rad: float | None = field(default=None, metadata=_nonneg())
    pitch_rms_rad: float | None = field(default=None, metadata=_nonneg())
    wind_rms_m_s: float | None = field(default=None, metadata=_nonneg())


@dataclass(frozen=True)
class AutopilotProfile:
    """One firmware's identified behaviour (module docstring). ``source``: how it was found."""

    autopilot: Literal["arduplane", "px4"] = "arduplane"
    firmware: str = ""
    source: str = ""
    attitude: AttitudeResponse = field(default_factory=AttitudeResponse)
    turn: TurnResponse = field(default_factory=TurnResponse)
    thrust: ThrustResponse = field(default_factory=ThrustResponse)
    estimator: EstimatorModel = field(default_factory=EstimatorModel)
    fit: FitResiduals = field(default_factory=FitResiduals)


def load_profile(path: str | Path) -> AutopilotProfile:
    """Read and validate a profile YAML (ConfigError naming the key on anything wrong)."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such autopilot profile")
    try:
        raw = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise ConfigError(f"{p}: not YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(raw, dict):
        raise ConfigError(f"{p}: an autopilot profile is a mapping")
    return _build(AutopilotProfile, raw, str(p), "")


_REPO = Path(__file__).resolve().parents[2]

# the identified firmware of each flavour that ``sil.autopilot_profile: auto`` flies
SHIPPED = {
    "px4": _REPO / "configs" / "autopilots" / "px4-1.16-sih.yaml",
    "arduplane": _REPO / "configs" / "autopilots" / "arduplane-4.7.yaml",
}


@dataclass(frozen=True)
class ResolvedProfile:
    """The profile a SIL flies: ``profile`` as applied, ``path`` its file, ``label`` the
    words a flow prints for it, ``split``: only the autopilot's part (the airframe's dropped)."""

    profile: AutopilotProfile
    path: Path
    label: str
    split: bool


def autopilot_part(p: AutopilotProfile) -> AutopilotProfile:
    """What belongs to the autopilot (estimator errors, attitude loops and lags, turn and
    sideslip): the profile without its ``thrust`` section, which is the identified airframe's
    (PX4 SIH's thrust ceiling), so that it applies to any JSBSim airframe."""
    return dataclasses.replace(p, thrust=ThrustResponse())


def resolve_profile(value: str | None, flavour: str, base: Path | None) -> ResolvedProfile | None:
    """``sil.autopilot_profile``: None or ``none``: the plain emulation (None); ``auto``: the
    shipped identified profile of ``flavour`` (px4 / ardupilot), its autopilot part; a FILE
    (absolute, relative to ``base`` or to the repository): applied as written, thrust too."""
    if value is None or value == "none":
        return None
    want = "px4" if flavour == "px4" else "arduplane"
    if value == "auto":
        path = SHIPPED[want]
        prof = autopilot_part(load_profile(path))
        return ResolvedProfile(prof, path, f"auto: {path.stem} (autopilot part)", True)
    p = Path(value).expanduser()
    if not p.is_absolute():
        for b in ([base] if base is not None else []) + [_REPO]:
            if (b / p).is_file():
                p = b / p
                break
    prof = load_profile(p)
    return ResolvedProfile(prof, p, f"file: {value}", False)


def calibrated_sets(cfg: object) -> tuple[list[str], str]:
    """The overrides that make a SIL flow (the rig's ``--sil`` leg, ``compare --plant sil``,
    ``campaign``, ``certify``) fly the calibrated SIL: ``sil.autopilot_profile=auto`` when the
    config names no profile (a config's own choice, ``none`` included, stands), and the words
    naming the profile flown."""
    sil = getattr(cfg, "extra", {}).get("sil")
    if sil is None:
        return [], "none"
    sets = [] if sil.autopilot_profile is not None else ["sil.autopilot_profile=auto"]
    value = sil.autopilot_profile if sil.autopilot_profile is not None else "auto"
    src = str(getattr(cfg, "source", ""))
    base = Path(src).resolve().parent if src and not src.startswith("<") else None
    res = resolve_profile(value, sil.flavour, base)
    return sets, "none (the plain emulation)" if res is None else res.label
