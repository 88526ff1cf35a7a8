"""An autopilot profile: what the real firmware does that the SIL's emulation must reproduce,
identified from flights of the firmware (``python -m lab.calibration.identify``) and loaded by the
SIL with ``sil.autopilot_profile: configs/autopilots/<name>.yaml``.

The profile is validated as strictly as a config (unknown keys, wrong types and impossible values
are one-line errors naming the key and the file). What each section changes in the SIL:

* ``attitude``: the firmware's attitude loop as the bridge sees it. The flown bank follows the
  commanded one through a dead time and a first-order lag and settles at
  ``roll_gain * roll_sp + roll_bias_rad`` (likewise pitch); the SIL shapes the set-point its own
  loop is given so that the whole (its loop's own lag included) matches.
* ``turn``: heading rate per bank, ``turn_gain = psi_dot / (g tan(bank) / V)`` as the bridge's
  adapter measures it from the reported attitude. A turn gain below 1 (the airframe slips in the
  turn, rudder neutral) is emulated by reporting the bank ``atan((k_plant / turn_gain)
  tan(roll))`` for the plant's roll, with the plant's own turn per bank ``k_plant`` fitted in its
  held turns, so the autopilot's loops and the bridge bank more for the same turn (a static map
  of the roll, not the bank the plant's instantaneous heading rate implies: that carries the
  gusts, which a firmware's reported roll does not).
* ``estimator``: what the reported state adds to the truth: white noise on position, velocity,
  attitude; a first-order Gauss-Markov position wander (sigma, correlation time); a lag.

The profile's schema and loader are mpf_mavlink/config/autopilot_profile.py (a profile is
configuration). Units SI, radians. Pure: no I/O, no clock (the estimate's random processes
advance with the time stamps they are given).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from mpf_mavlink.config.autopilot_profile import (
    AttitudeResponse,
    AutopilotProfile,
    EstimatorModel,
    ThrustResponse,
)
from mpf_mavlink.constants import GRAVITY_M_S2 as G

TURN_TAU_S = 2.0  # s, the low-pass of the reported heading's offset (StateEstimate._yaw_offset)
# s of held turns over which the plant's own turn per bank (StateEstimate._bank_offset) takes over
# from the profile's: several seconds of turning, so that the yaw's lag behind a roll transient
# averages out
KP_TAU_S = 8.0
# s, the longest memory of that fit (it grows with the time learned, up to this): the turn per
# bank is a property of the airframe at the flown airspeed, constant over a mission, while in
# gusts the heading rate per bank of a stretch of a few seconds scatters by several per cent (the
# lift's horizontal part); ArduPlane's own in SIM_WIND_TURB 2 scatters by 0.5 % between 60 s
# stretches (docs/calibration.md, `identify arduplane --dataflash`), a short memory would pass
# the rest into the reported bank
KP_MEMORY_S = 60.0
MIN_LEARN_BANK_RAD = 0.05  # below this bank the heading rate per bank is mostly noise
MAX_LEARN_ROLL_RATE_RAD_S = 0.05  # a held turn: rolling faster, the heading rate lags the bank
# s, the low-pass of the roll rate that the held-turn test looks at: a roll transient lasts
# seconds, a gust's roll rate (SIM_WIND_TURB: +-0.1 rad/s at tens of Hz) averages out
ROLL_RATE_TAU_S = 1.0
MAX_LEAD = 5.0  # largest high-frequency gain of the attitude shaper's lead-lag


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


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


class RateWander:
    """The Gauss-Markov roll-rate error of :class:`AttitudeResponse` (rad/s), sampled at dt."""

    def __init__(self, resp: AttitudeResponse, dt: float, seed: int = 0) -> None:
        self.sigma = resp.roll_rate_wander_rad_s
        self.phi = math.exp(-dt / resp.rate_wander_tau_s)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 25]))
        self.x = self.sigma * float(self.rng.standard_normal()) if self.sigma else 0.0

    def __call__(self) -> float:
        if self.sigma:
            q = self.sigma * math.sqrt(1.0 - self.phi * self.phi)
            self.x = self.phi * self.x + q * float(self.rng.standard_normal())
        return self.x


def thrust_scale(resp: ThrustResponse, trim_throttle: float, trim_airspeed: float) -> float:
    """Plant throttle per unit of offboard thrust so that full thrust holds about
    ``full_thrust_airspeed_m_s`` level: the trim throttle scaled by the cube of the airspeed ratio
    (the power of parasitic drag; an approximation, checked by the calibration flights)."""
    v = resp.full_thrust_airspeed_m_s
    if v is None:
        return 1.0
    return min(1.0, trim_throttle * (v / trim_airspeed) ** 3)


class _LeadLag:
    """``(1 + tau_num s) / (1 + tau_den s)`` sampled at dt (backward Euler on the lag's state):
    through a first-order loop of time constant ``tau_num`` it leaves a first-order lag
    ``tau_den``. ``tau_den`` is held at or above ``tau_num / MAX_LEAD`` (a command step is
    amplified at most MAX_LEAD times); ``tau_den`` 0 (a profile without an identified attitude
    loop) passes the command through: the SIL's own loop stays as it is."""

    def __init__(self, tau_num: float, tau_den: float, dt: float) -> None:
        self.through = tau_den <= 0.0
        self.tn = max(0.0, tau_num)
        self.td = max(tau_den, self.tn / MAX_LEAD, dt)
        self.a = 1.0 - math.exp(-dt / self.td)
        self.z: float | None = None

    def __call__(self, x: float) -> float:
        if self.through:
            return x
        if self.z is None:
            self.z = x
        else:
            self.z += self.a * (x - self.z)
        return self.z + self.tn / self.td * (x - self.z)


class AttitudeShaper:
    """The set-point the SIL's own attitude loop is given so that its bank and pitch follow the
    command as the firmware's do (:class:`AttitudeResponse`): the firmware's dead time, then a
    lead-lag that trades the SIL loop's own first-order lag (``native_tau_s``, its roll/pitch
    time constant) for the firmware's. (Only adding the difference of the lags, as before, left
    the SIL's 0.4 s loop in place of ArduPlane's 0.15 s: the slow orbit-rate bank of a wind
    circle followed the command 0.56 s late in the SIL, 0.28 s on the firmware.)"""

    def __init__(
        self,
        resp: AttitudeResponse,
        dt: float,
        native_tau_s: float = 0.4,
        native_pitch_tau_s: float | None = None,
    ) -> None:
        self.resp = resp
        tp = native_tau_s if native_pitch_tau_s is None else native_pitch_tau_s
        self._roll = _Lag(resp.roll_delay_s, 0.0, dt)
        self._pitch = _Lag(resp.pitch_delay_s, 0.0, dt)
        self._roll_ll = _LeadLag(native_tau_s, resp.roll_tau_s, dt)
        self._pitch_ll = _LeadLag(tp, resp.pitch_tau_s, dt)

    def __call__(self, roll_sp: float, pitch_sp: float) -> tuple[float, float]:
        r = self.resp
        roll = r.roll_gain * self._roll_ll(self._roll(roll_sp)) + r.roll_bias_rad
        pitch = r.pitch_gain * self._pitch_ll(self._pitch(pitch_sp)) + r.pitch_bias_rad
        return roll, pitch


class GaussMarkov:
    """Independent first-order Gauss-Markov processes (1-sigma ``sigma``, correlation times
    ``tau_s``), advanced by the time stamps they are given (stationary from the first call)."""

    def __init__(self, sigma: Any, tau_s: Any, rng: np.random.Generator) -> None:
        self.sigma = np.asarray(sigma, float)
        self.tau = np.maximum(np.asarray(tau_s, float), 1e-6)
        self.rng = rng
        self.x = self.sigma * rng.standard_normal(self.sigma.shape)
        self.t: float | None = None

    def __call__(self, t: float) -> np.ndarray:
        if self.t is not None and t > self.t:
            phi = np.exp(-(t - self.t) / self.tau)
            q = self.sigma * np.sqrt(1.0 - phi * phi)
            self.x = phi * self.x + q * self.rng.standard_normal(self.sigma.shape)
        if self.t is None or t > self.t:
            self.t = t
        return self.x


class StateEstimate:
    """The state the autopilot reports (and controls on) from the plant's truth: the turn-per-bank
    emulation on the bank, noise and a Gauss-Markov wander (:class:`EstimatorModel`). ``seed``:
    every seed its own draw."""

    def __init__(self, prof: AutopilotProfile, seed: int = 0) -> None:
        self.k_turn = prof.turn.turn_gain
        self.slip = prof.turn.slip_per_tan_bank_rad
        self.est = prof.estimator
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 24]))
        self._w: np.ndarray | None = None
        # the plant's own turn gain, from the profile's (no offset) until turns have taught it
        self._kp = self.k_turn
        # the least-squares sums of the plant's turn per bank, V psi_dot tan(roll) and
        # g tan(roll)^2 (means over the time learned, at most KP_MEMORY_S), the time learned
        self._kn = 0.0
        self._kd = 0.0
        self._kl = 0.0
        self._pl = 0.0  # the plant's roll rate low-passed over ROLL_RATE_TAU_S
        self._kt: float | None = None
        self._y = 0.0
        self._yt: float | None = None
        self._wt: float | None = None
        e = prof.estimator
        tau_v = e.wander_tau_s if e.vertical_wander_tau_s is None else e.vertical_wander_tau_s
        self._pos_gm = (
            GaussMarkov(
                (e.horizontal_wander_m,) * 2 + (e.vertical_wander_m,),
                (e.wander_tau_s, e.wander_tau_s, tau_v),
                self.rng,
            )  # fmt: skip
            if e.horizontal_wander_m or e.vertical_wander_m
            else None
        )
        vs, vt = e.velocity_wander_m_s, e.velocity_wander_tau_s
        self._vel_gm = (
            GaussMarkov((vs[0], vs[0], vs[1]), (vt[0], vt[0], vt[1]), self.rng) if any(vs) else None
        )
        self._att_gm = (
            GaussMarkov(e.attitude_wander_rad, e.attitude_wander_tau_s, self.rng)
            if any(e.attitude_wander_rad)
            else None
        )
        self._wind_gm = (
            GaussMarkov((e.wind_wander_m_s,) * 2, (e.wind_wander_tau_s,) * 2, self.rng)
            if e.wind_wander_m_s
            else None
        )

    def _bank_offset(self, st: Any) -> float:
        """What the reported bank adds to the plant's: the bank the profile's turn gain needs for
        the plant's turn, ``atan((k_plant / k) tan(roll))``, minus the plant's own. A static map
        of the plant's roll (a real airframe's turn per bank is the same at every instant of a
        varying turn, and a firmware reports its own estimate of the roll, not the bank its
        heading rate implies), with the plant's own turn gain ``k_plant`` (the X8 turns ~0.93x
        the textbook) learned in held turns: the profile's own (no offset) at the start, the
        plant's fitted one after KP_TAU_S of held turns (blended in between).

        The fit is the least-squares ``V psi_dot = k_plant g tan(roll)`` over the time learned
        (at most KP_MEMORY_S): the ratio of the mean ``V psi_dot tan(roll)`` to the mean
        ``g tan(roll)^2``, which averages the gusts of the plant's heading rate out linearly.
        A low-passed ratio of each sample would not do in turbulence (sil.wind_turbulence_m_s):
        the gusts throw most per-sample ratios outside any sane clip, whose clipped mean then
        sits above the fit, so the gain creeps up through the flight; and a memory of KP_TAU_S
        alone lets the fit wander with the gusts. Either moves the reported bank off the
        plant's by degrees, where a firmware's report (its estimate of the roll) follows the
        true roll (docs/calibration.md has the figures). A held turn: the roll rate low-passed over
        ROLL_RATE_TAU_S below MAX_LEARN_ROLL_RATE_RAD_S."""
        roll, pitch, _ = st.euler
        t = float(st.t)
        p, q, r = (float(x) for x in st.pqr)
        dt = 0.0 if self._kt is None else max(0.0, t - self._kt)
        self._kt = t
        self._pl += (1.0 - math.exp(-dt / ROLL_RATE_TAU_S)) * (p - self._pl)
        # learn in held turns only: in a roll transient the heading rate lags the bank
        if (
            dt > 0.0
            and abs(roll) > MIN_LEARN_BANK_RAD
            and abs(self._pl) < MAX_LEARN_ROLL_RATE_RAD_S
        ):
            psid = (q * math.sin(roll) + r * math.cos(roll)) / max(math.cos(pitch), 0.2)
            v = max(float(st.airspeed), 1.0)
            tr = math.tan(_clip(roll, -1.2, 1.2))
            self._kl += dt
            a = dt / min(self._kl, KP_MEMORY_S)  # the running mean, then a memory of KP_MEMORY_S
            self._kn += a * (v * psid * tr - self._kn)
            self._kd += a * (G * tr * tr - self._kd)
            w = min(1.0, self._kl / KP_TAU_S)
            self._kp = self.k_turn + w * (_clip(self._kn / self._kd, 0.5, 1.5) - self.k_turn)
        rc = _clip(roll, -1.2, 1.2)
        return _clip(math.atan(self._kp / self.k_turn * math.tan(rc)) - rc, -0.3, 0.3)

    def _yaw_offset(self, st: Any, roll_rep: float) -> float:
        """What the reported heading adds to the plant's: the profile's sideslip for the reported
        bank minus the plant's own (heading - course), low-passed like the bank's offset."""
        vn, ve = float(st.velocity_ned[0]), float(st.velocity_ned[1])
        if math.hypot(vn, ve) < 1.0:
            return self._y
        own = (float(st.euler[2]) - math.atan2(ve, vn) + math.pi) % (2.0 * math.pi) - math.pi
        d = _clip(self.slip * math.tan(_clip(roll_rep, -1.2, 1.2)) - own, -0.3, 0.3)
        t = float(st.t)
        if self._yt is None:
            self._y = d
        else:
            self._y += (1.0 - math.exp(-max(0.0, t - self._yt) / TURN_TAU_S)) * (d - self._y)
        self._yt = t
        return self._y

    def _wind(self, st: Any, e: EstimatorModel) -> np.ndarray:
        """The reported wind: lag of (air mass + apparent wind) with time constant wind_tau_s."""
        vn, ve = float(st.velocity_ned[0]), float(st.velocity_ned[1])
        v = math.hypot(vn, ve)
        u = e.wind_scale * np.array(st.wind_ned, float)
        if v > 1.0:
            a, s = e.wind_apparent_along_m_s, e.wind_apparent_side_m_s
            u = u + np.array(((vn * a - ve * s) / v, (ve * a + vn * s) / v, 0.0))
        t = float(st.t)
        if self._w is None or self._wt is None:
            self._w = u
        else:
            tau = float(e.wind_tau_s or 0.0)
            k = 1.0 if tau <= 0.0 else 1.0 - math.exp(-max(0.0, t - self._wt) / tau)
            self._w = self._w + k * (u - self._w)
        self._wt = t
        return self._w

    def __call__(self, st: Any) -> Any:
        e = self.est
        roll, pitch, yaw = st.euler
        if self.k_turn != 1.0:
            roll = roll + self._bank_offset(st)
        if self.slip:
            yaw = yaw + self._yaw_offset(st, roll)
        upd: dict[str, Any] = {}
        if e.airspeed_scale != 1.0:
            upd["airspeed"] = e.airspeed_scale * float(st.airspeed)
        t = float(st.t)
        pos = st.position_ned
        if e.position_lead_s:
            pos = pos + e.position_lead_s * np.asarray(st.velocity_ned, float)
        if self._pos_gm is not None:
            pos = pos + self._pos_gm(t)
        if e.position_noise_m or e.vertical_noise_m:
            sd = (e.position_noise_m, e.position_noise_m, e.vertical_noise_m)
            pos = pos + np.asarray(sd) * self.rng.standard_normal(3)
        if pos is not st.position_ned:
            upd["position_ned"] = pos
        if e.wind_tau_s is not None:
            upd["wind_ned"] = self._wind(st, e)
        if self._wind_gm is not None:
            w = np.array(upd.get("wind_ned", st.wind_ned), float)
            w[:2] += self._wind_gm(t)
            upd["wind_ned"] = w
        vel = st.velocity_ned
        if self._vel_gm is not None:
            vel = vel + self._vel_gm(t)
        if e.velocity_noise_m_s:
            vel = vel + e.velocity_noise_m_s * self.rng.standard_normal(3)
        if vel is not st.velocity_ned:
            upd["velocity_ned"] = vel
        if self._att_gm is not None:
            da = self._att_gm(t)
            roll, pitch, yaw = roll + da[0], pitch + da[1], yaw + da[2]
        pqr = np.asarray(st.pqr, float)
        if (roll, pitch, yaw) != tuple(st.euler):
            # the reported gyro rates are the body's angular velocity in the REPORTED body
            # frame, as a firmware's are consistent with its own attitude: the plant's rates
            # rotated through the turn emulation's attitude offset (else psi_dot from q, r and
            # the reported bank reads the plant's bank: the adapter learned the turn gain 1 %
            # low on the ArduPlane profile)
            pqr = _euler_to_R(roll, pitch, yaw).T @ (np.asarray(st.R_B_N, float) @ pqr)
            upd["pqr"] = pqr
        if any(e.rate_noise_rad_s):
            upd["pqr"] = pqr + np.asarray(e.rate_noise_rad_s) * self.rng.standard_normal(3)
        if e.attitude_noise_rad:
            n = e.attitude_noise_rad * self.rng.standard_normal(3)
            roll, pitch, yaw = roll + n[0], pitch + n[1], yaw + n[2]
        if (roll, pitch, yaw) != tuple(st.euler):
            upd["euler"] = (roll, pitch, yaw)
            upd["R_B_N"] = _euler_to_R(roll, pitch, yaw)
        return dataclasses.replace(st, **upd) if upd else st


def _euler_to_R(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R_B_N (body FRD -> NED) of ZYX Euler angles (rad)."""
    cf, sf = math.cos(roll), math.sin(roll)
    ct, s_t = math.cos(pitch), math.sin(pitch)
    cp, sp = math.cos(yaw), math.sin(yaw)
    return np.array(
        (
            ct * cp, sf * s_t * cp - cf * sp, cf * s_t * cp + sf * sp,
            ct * sp, sf * s_t * sp + cf * cp, cf * s_t * sp - sf * cp,
            -s_t, sf * ct, cf * ct,
        )
    ).reshape(3, 3)  # fmt: skip
