"""An autopilot profile: what the real firmware does that the SIL's emulation must reproduce,
identified from flights of the firmware (``python -m sim.identify``) and loaded by the SIL with
``sil.autopilot_profile: configs/autopilots/<name>.yaml``.

The profile is validated as strictly as a config (unknown keys, wrong types and impossible values
are one-line errors naming the key and the file). What each section changes in the SIL:

* ``attitude``: the firmware's attitude loop as the bridge sees it. The flown bank follows the
  commanded one through a dead time and a first-order lag and settles at
  ``roll_gain * roll_sp + roll_bias_rad`` (likewise pitch); the SIL shapes the set-point its own
  loop is given so that the whole (its loop's own lag included) matches.
* ``turn``: heading rate per bank, ``turn_gain = psi_dot / (g tan(bank) / V)`` as the bridge's
  adapter measures it from the reported attitude. A turn gain below 1 (the airframe slips in the
  turn, rudder neutral) is emulated by reporting a bank ``atan(tan(bank) / turn_gain)``.
* ``estimator``: what the reported state adds to the truth: white noise on position, velocity,
  attitude; a first-order Gauss-Markov position wander (sigma, correlation time); a lag.

Units SI, radians. Pure: no I/O besides :func:`load_profile`, no clock (the estimate's random
processes advance with the time stamps they are given).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mpf_mavlink.config.fields import _fail, _nonneg, _pos
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


@dataclass(frozen=True)
class TurnResponse:
    """Heading rate per bank relative to the coordinated turn (1: textbook)."""

    turn_gain: float = field(default=1.0, metadata={"check": ("range", 0.5, 1.5)})


@dataclass(frozen=True)
class EstimatorModel:
    """What the reported state adds to the truth (1-sigma; m, m/s, rad; s)."""

    position_noise_m: float = field(default=0.0, metadata=_nonneg())
    velocity_noise_m_s: float = field(default=0.0, metadata=_nonneg())
    attitude_noise_rad: float = field(default=0.0, metadata=_nonneg())
    horizontal_wander_m: float = field(default=0.0, metadata=_nonneg())
    vertical_wander_m: float = field(default=0.0, metadata=_nonneg())
    wander_tau_s: float = field(default=30.0, metadata=_pos())


@dataclass(frozen=True)
class AutopilotProfile:
    """One firmware's identified behaviour (module docstring). ``source``: how it was found."""

    autopilot: Literal["arduplane", "px4"] = "arduplane"
    firmware: str = ""
    source: str = ""
    attitude: AttitudeResponse = field(default_factory=AttitudeResponse)
    turn: TurnResponse = field(default_factory=TurnResponse)
    estimator: EstimatorModel = field(default_factory=EstimatorModel)
    fit: dict[str, float] = field(default_factory=dict)  # the fits' residuals, for the record


def load_profile(path: str | Path) -> AutopilotProfile:
    """Read and validate a profile YAML (ConfigError naming the key on anything wrong)."""
    import yaml

    from mpf_mavlink.config.schema import _build

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such autopilot profile")
    try:
        raw = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise ConfigError(f"{p}: not YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(raw, dict):
        raise ConfigError(f"{p}: an autopilot profile is a mapping")
    prof = _build(AutopilotProfile, raw, str(p), "")
    for k, v in prof.fit.items():
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            raise _fail(str(p), f"fit.{k}", "must be a finite number")
    return prof


def profile_to_dict(prof: AutopilotProfile) -> dict[str, Any]:
    return dataclasses.asdict(prof)


class _Lag:
    """Dead time (a ring of past inputs) then a first-order lag, sampled at a fixed dt."""

    def __init__(self, delay_s: float, tau_s: float, dt: float) -> None:
        self.n = max(0, int(round(delay_s / dt)))
        self.a = 1.0 if tau_s <= 0.0 else 1.0 - math.exp(-dt / tau_s)
        self.buf: list[float] = []
        self.y: float | None = None

    def __call__(self, x: float) -> float:
        if self.n:
            self.buf.append(x)
            if len(self.buf) > self.n:
                x = self.buf.pop(0)
            else:
                x = self.buf[0]
        if self.y is None:
            self.y = x
        else:
            self.y += self.a * (x - self.y)
        return self.y


class AttitudeShaper:
    """The set-point the SIL's own attitude loop is given so that its bank and pitch follow the
    command as the firmware's do (:class:`AttitudeResponse`). ``native_tau_s``: the lag of the
    SIL's own loop (its roll/pitch time constant), taken off the firmware's lag."""

    def __init__(self, resp: AttitudeResponse, dt: float, native_tau_s: float = 0.4) -> None:
        self.resp = resp
        self._roll = _Lag(resp.roll_delay_s, max(0.0, resp.roll_tau_s - native_tau_s), dt)
        self._pitch = _Lag(resp.pitch_delay_s, max(0.0, resp.pitch_tau_s - native_tau_s), dt)

    def __call__(self, roll_sp: float, pitch_sp: float) -> tuple[float, float]:
        r = self.resp
        roll = r.roll_gain * self._roll(roll_sp) + r.roll_bias_rad
        pitch = r.pitch_gain * self._pitch(pitch_sp) + r.pitch_bias_rad
        return roll, pitch


class StateEstimate:
    """The state the autopilot reports (and controls on) from the plant's truth: the turn-per-bank
    emulation on the bank, noise and a Gauss-Markov wander (:class:`EstimatorModel`). ``seed``:
    every seed its own draw."""

    def __init__(self, prof: AutopilotProfile, seed: int = 0) -> None:
        self.k_turn = prof.turn.turn_gain
        self.est = prof.estimator
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 24]))
        self._walk = np.zeros(3)
        self._t: float | None = None

    def __call__(self, st: Any) -> Any:
        e = self.est
        roll, pitch, yaw = st.euler
        if self.k_turn != 1.0:
            roll = math.atan2(math.sin(roll), math.cos(roll) * self.k_turn)
        upd: dict[str, Any] = {}
        sig = (e.horizontal_wander_m, e.horizontal_wander_m, e.vertical_wander_m)
        if any(sig):
            t = float(st.t)
            dt = 0.0 if self._t is None else max(0.0, t - self._t)
            self._t = t
            phi = math.exp(-dt / e.wander_tau_s)
            self._walk = self._walk * phi + np.asarray(sig) * math.sqrt(
                max(0.0, 1.0 - phi * phi)
            ) * self.rng.standard_normal(3)
        pos = st.position_ned + self._walk
        if e.position_noise_m:
            pos = pos + e.position_noise_m * self.rng.standard_normal(3)
        if any(sig) or e.position_noise_m:
            upd["position_ned"] = pos
        if e.velocity_noise_m_s:
            upd["velocity_ned"] = st.velocity_ned + e.velocity_noise_m_s * self.rng.standard_normal(
                3
            )
        if e.attitude_noise_rad:
            n = e.attitude_noise_rad * self.rng.standard_normal(3)
            roll, pitch, yaw = roll + n[0], pitch + n[1], yaw + n[2]
        if (roll, pitch, yaw) != tuple(st.euler):
            upd["euler"] = (roll, pitch, yaw)
            cf, sf = math.cos(roll), math.sin(roll)
            ct, s_t = math.cos(pitch), math.sin(pitch)
            cp, sp = math.cos(yaw), math.sin(yaw)
            upd["R_B_N"] = np.array(
                (
                    ct * cp, sf * s_t * cp - cf * sp, cf * s_t * cp + sf * sp,
                    ct * sp, sf * s_t * sp + cf * cp, cf * s_t * sp - sf * cp,
                    -s_t, sf * ct, cf * ct,
                )
            ).reshape(3, 3)  # fmt: skip
        return dataclasses.replace(st, **upd) if upd else st
