"""Inner-loop gains of a stock JSBSim airframe, derived from a short identification of the FDM.

No number here is tuned per aircraft. For a model, an airspeed and an altitude:

1. JSBSim's own trim (``simulation/do_simple_trim`` = 1) gives level flight and the trim of
   every command channel (aileron, elevator incl. the pitch-trim wheel, rudder, throttle).
2. From that trim, three open-loop steps, each on a freshly trimmed FDM: aileron, elevator
   (nose up) and rudder, through the config's command mapping (JSBSim property and sign), so the
   measured rates are per unit of the *autopilot's* command. Each body-rate response is fitted
   by a first-order lag with a dead time, ``y(t) = b du (1 - exp(-(t - td) / tau))``, over a
   window short enough to exclude the slow modes (spiral, phugoid): :class:`AxisFit`. Pitch is
   second order (the short period; lightly damped on the pa28: q peaks at 4x its quasi-steady
   value): its gain is the quasi-steady q, the mean over the second half of the window (after
   the short period, before the phugoid), and the lag is fitted with that gain held.
3. The PX4-structured rate loops (sim.autopilot.inner_loop.RateController:
   ``u = trim + s^2 (P e + I int e) + s FF w_sp``) follow from the fits (:func:`derive_gains`):

   * ``FF = 1 / b``: the steady rate per unit command is b, so FF alone makes w = w_sp;
   * ``P = max(tau / tau_t - 1, 1/2) / b``: with FF, proportional feedback shortens the plant's
     lag tau to ``tau / (1 + b P)``; tau_t is a third of the attitude loop's time constant (a
     rate loop three times faster than the loop it serves), and the floor 1/2 keeps a
     disturbance-rejecting feedback when the plant is already fast enough;
   * ``I = 1 / (b T_i)``, T_i = 1 s: a steady rate error is worked off within about a second
     (roll: the dihedral effect that eats the roll rate as sideslip builds; pitch: speed change);
   * yaw: a damper, ``P = 1/(2 b_r)``, no FF (the airframe's weathercock stability turns it), no I;
     an airframe whose rudder moves nothing (|b_r| below a threshold) gets no yaw loop;
   * IMAX covers the trim offset the loop may have to find plus a margin.

   A command channel whose measured effect has the wrong sign (the config's ``sign`` says
   positive rudder yaws right, the model yaws left) is an error naming the config key: the loop
   would be a positive feedback.

JSBSim cannot trim a constant-speed propeller with its lever forward (sim.plant.airframe_trim), so
the steps start from the lever-at-0 trim; the surfaces' effect does not depend on the propeller,
and the trim throttle it gives is only the vehicle trim flight's first guess.

Units SI, radians; body rates FRD (p roll right, q nose up, r nose right).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .airframe_trim import trimmed_fdm
from .jsbsim_plant import DEFAULT_CONTROLS

DT = 0.01  # s, the identification's FDM step (the SIL's physics rate is 100 Hz too)
# channel -> (step of the rate loop's output, fitted body rate, fit window s, surface per output)
# Elevator: the pitch loop's output is nose-up positive and elevator > 0 is nose down, so its
# step is a negative elevator command (surface per output -1). The amplitudes are well above the
# stock c172x elevator actuator's 0.05 rad hysteresis and small enough to stay linear.
STEPS: dict[str, tuple[float, int, float, float]] = {
    "aileron": (0.1, 0, 1.0, 1.0),
    "elevator": (0.15, 1, 1.2, -1.0),
    "rudder": (0.1, 2, 0.5, 1.0),
}
RUDDER_MIN_GAIN = 0.02  # rad/s per unit: below it the rudder moves nothing (the X8 has none)


class IdentError(ValueError):
    """The airframe cannot be identified as configured (message names the config key)."""


@dataclass(frozen=True)
class AxisFit:
    """First-order fit of one body-rate response to one command step.

    gain: steady rate per unit of the rate loop's output (rad/s), signed; tau_s, delay_s: lag
    and dead time (s); residual: RMS fit error over RMS response (0 = a perfect first order).
    """

    gain: float
    tau_s: float
    delay_s: float
    residual: float


@dataclass(frozen=True)
class AirframeModel:
    """What the identification found for one model at one flight condition."""

    model: str
    airspeed_m_s: float
    altitude_m: float
    trim: dict[str, float]  # autopilot-convention trims: aileron, elevator, rudder, throttle
    pitch_rad: float
    roll: AxisFit
    pitch: AxisFit
    yaw: AxisFit
    # yaw rate per unit aileron (rad/s) 0.4-0.5 s into the aileron step, before the turn's own
    # yaw rate builds: negative = adverse yaw (the nose swings away from the roll)
    aileron_yaw: float = 0.0


def fit_first_order(t: np.ndarray, y: np.ndarray, du: float, gain: float | None = None) -> AxisFit:
    """Least-squares ``y = b du (1 - exp(-(t - td)/tau))`` (y 0 before td): grid over tau, td,
    closed-form b (or b = ``gain`` held). t in s from the step, y in rad/s about the trim."""
    best: tuple[float, float, float, float] | None = None
    ss = float(np.dot(y, y))
    for td in np.arange(0.0, 0.105, 0.01):
        tt = np.clip(t - td, 0.0, None)
        for tau in np.geomspace(0.02, 3.0, 120):
            x = du * (1.0 - np.exp(-tt / tau))
            xx = float(np.dot(x, x))
            if xx <= 0.0:
                continue
            b = float(np.dot(x, y)) / xx if gain is None else gain
            err = float(np.sum((y - b * x) ** 2))
            if best is None or err < best[0]:
                best = (err, b, float(tau), float(td))
    assert best is not None
    err, b, tau, td = best
    return AxisFit(b, tau, td, math.sqrt(max(err, 0.0) / ss) if ss > 0 else 1.0)


def _trimmed(
    model: str, root: str | os.PathLike[str] | None, airspeed_m_s: float, altitude_m: float
) -> Any:
    """sim.plant.airframe_trim.trimmed_fdm at the identification's step, the load error named."""
    try:
        return trimmed_fdm(model, root, airspeed_m_s, altitude_m, DT)
    except RuntimeError as e:
        raise IdentError(f"aircraft.model: {e}") from None


def _has(fdm: Any, prop: str) -> bool:
    return bool(fdm.get_property_manager().hasNode(prop))


def identify(
    model: str,
    root_dir: str | os.PathLike[str] | None,
    airspeed_m_s: float,
    altitude_m: float,
    controls: dict[str, tuple[str, float]] | None = None,
) -> AirframeModel:
    """Trim ``model`` at ``airspeed_m_s`` (true) and ``altitude_m`` MSL, and fit the three
    rate responses (module docstring). root_dir None: the aircraft shipped in the jsbsim
    package. controls: channel -> (JSBSim property, sign) as in the SIL plant."""
    ctl = dict(DEFAULT_CONTROLS, **(controls or {}))
    probe = _trimmed(model, root_dir, airspeed_m_s, altitude_m)
    if probe is None:
        raise IdentError(
            f"aircraft.trim_airspeed_m_s: JSBSim finds no level-flight trim of {model} at "
            f"{airspeed_m_s:g} m/s (python -m sim.plant.airframe_trim {model} lists its range)"
        )
    trim: dict[str, float] = {}
    for ch, (prop, sign) in ctl.items():
        if not _has(probe, prop):
            raise IdentError(f"aircraft.controls.{ch}.property: {model} has no {prop!r}")
        v = float(probe[prop])
        # The trim wheels (FlightGear convention: summed with the command before the surface)
        # belong to the trim the rate loop has to supply once the wheel is not used.
        wheel = {"aileron": "roll", "elevator": "pitch", "rudder": "yaw"}.get(ch)
        if wheel and _has(probe, f"fcs/{wheel}-trim-cmd-norm"):
            v += float(probe[f"fcs/{wheel}-trim-cmd-norm"])
        trim[ch] = v * sign
    pitch_rad = float(probe["attitude/theta-rad"])
    fits: dict[str, AxisFit] = {}
    aileron_yaw = 0.0
    for ch, (du, axis, window, surface) in STEPS.items():
        fdm = _trimmed(model, root_dir, airspeed_m_s, altitude_m)
        prop, sign = ctl[ch]
        rate_prop = ("velocities/p-rad_sec", "velocities/q-rad_sec", "velocities/r-rad_sec")[axis]
        y0 = float(fdm[rate_prop])
        r0 = float(fdm["velocities/r-rad_sec"])
        fdm[prop] = float(fdm[prop]) + du * surface * sign
        n = int(round(window / DT))
        t = np.empty(n)
        y = np.empty(n)
        yaw = np.empty(n)
        for k in range(n):
            fdm.run()
            t[k] = (k + 1) * DT
            y[k] = float(fdm[rate_prop]) - y0
            yaw[k] = float(fdm["velocities/r-rad_sec"]) - r0
        if ch == "aileron":
            aileron_yaw = float(np.mean(yaw[(t > 0.4) & (t <= 0.5)])) / du
        quasi_steady = float(np.mean(y[n // 2 :])) / du if ch == "elevator" else None
        fits[ch] = fit_first_order(t, y, du, quasi_steady)
    return AirframeModel(
        model,
        airspeed_m_s,
        altitude_m,
        trim,
        pitch_rad,
        fits["aileron"],
        fits["elevator"],
        fits["rudder"],
        aileron_yaw,
    )


def _check_sign(fit: AxisFit, ch: str, model: str, what: str) -> None:
    if fit.gain <= 0.0:
        raise IdentError(
            f"aircraft.controls.{ch}.sign: a positive {ch} command gives {fit.gain:+.3f} rad/s "
            f"of {what} per unit on {model}; the loop would feed back positively (flip the sign)"
        )


def derive_gains(
    m: AirframeModel, roll_tc_s: float = 0.4, pitch_tc_s: float = 0.4, integral_s: float = 1.0
) -> dict[str, float]:
    """RateLoopGains fields (sim.autopilot.inner_loop) from an identified model (module docstring).

    roll_tc_s / pitch_tc_s: the attitude loop's time constants the rate loops serve (s)."""
    _check_sign(m.roll, "aileron", m.model, "roll rate")
    _check_sign(m.pitch, "elevator", m.model, "pitch rate (nose up for a negative elevator)")
    out: dict[str, float] = {}
    for axis, fit, tc, trim in (
        ("roll", m.roll, roll_tc_s, m.trim["aileron"]),
        ("pitch", m.pitch, pitch_tc_s, -m.trim["elevator"]),
    ):
        b, tau_eff = fit.gain, fit.tau_s + fit.delay_s
        tau_t = tc / 3.0
        out[f"{axis}_ff"] = 1.0 / b
        out[f"{axis}_p"] = max(tau_eff / tau_t - 1.0, 0.5) / b
        out[f"{axis}_i"] = 1.0 / (b * integral_s)
        # what the integrator may have to find: the trim (not given to the loop on a real
        # aircraft) plus the surface for a rate error of a tenth of a rad/s
        out[f"{axis}_imax"] = min(1.0, abs(trim) + 0.1 / b + 0.1)
    if abs(m.yaw.gain) < RUDDER_MIN_GAIN:
        out.update(yaw_p=0.0, yaw_i=0.0, yaw_ff=0.0, yaw_imax=0.0)
    else:
        _check_sign(m.yaw, "rudder", m.model, "yaw rate (nose right)")
        out.update(yaw_p=0.5 / m.yaw.gain, yaw_i=0.0, yaw_ff=0.0, yaw_imax=0.0)
        # the rudder that cancels the aileron's adverse yaw (none for a proverse one)
        out["rudder_mix"] = min(max(-m.aileron_yaw / m.yaw.gain, 0.0), 1.0)
    return out


def trims(m: AirframeModel) -> dict[str, float]:
    """RateLoopGains trim fields (surface convention: elevator > 0 nose down)."""
    return {
        "trim_aileron": m.trim["aileron"],
        "trim_elevator": m.trim["elevator"],
        "trim_rudder": m.trim["rudder"],
        "trim_throttle": m.trim["throttle"],
    }


def describe(m: AirframeModel, gains: dict[str, float]) -> str:
    """A few lines for people: the fits and the gains."""
    lines = [
        f"{m.model} at {m.airspeed_m_s:g} m/s, {m.altitude_m:g} m MSL: throttle "
        f"{m.trim['throttle']:.3f}, pitch {math.degrees(m.pitch_rad):.1f} deg, trims aileron "
        f"{m.trim['aileron']:+.3f} elevator {m.trim['elevator']:+.3f} "
        f"rudder {m.trim['rudder']:+.3f}"
    ]
    for name, f in (("roll", m.roll), ("pitch", m.pitch), ("yaw", m.yaw)):
        lines.append(
            f"  {name:5s} b {f.gain:+.3f} rad/s per unit, tau {f.tau_s:.3f} s, dead time "
            f"{f.delay_s:.2f} s, fit residual {f.residual:.2f}"
        )
    lines.append("  gains " + " ".join(f"{k}={v:.3g}" for k, v in sorted(gains.items())))
    return "\n".join(lines)


if __name__ == "__main__":  # python -m sim.plant.airframe_ident c172p c172x c182 pa28 [--speed 45]
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="*", default=["c172p", "c172x", "c182", "pa28"])
    ap.add_argument("--speed", type=float, default=45.0, help="true airspeed, m/s")
    ap.add_argument("--altitude", type=float, default=800.0, help="m MSL")
    ap.add_argument("--rudder-sign", type=float, default=-1.0, help="config sign of the rudder")
    a = ap.parse_args()
    for name in a.models:
        ctl = {"rudder": ("fcs/rudder-cmd-norm", a.rudder_sign)}
        mod = identify(name, None, a.speed, a.altitude, ctl)
        print(describe(mod, derive_gains(mod)))
