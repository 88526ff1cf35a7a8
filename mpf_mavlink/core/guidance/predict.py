"""Delay compensation: the vehicle's state at the time a setpoint acts, not when it was measured.

A setpoint answers an ATTITUDE sample of time t but acts from t + d (telemetry latency, the
bridge, the command link: the loop delay d, measured from the autopilot's ATTITUDE_TARGET echo
or known from the config) and is held until the next one, a telemetry period T later. The law
is therefore evaluated on the state predicted to t + d, when its setpoint starts acting.
Unpredicted, d is phase lag in the guidance loop: measured in SIL, 60 ms of command latency
turned the demo's 0.2 m into 2 m RMS with the turn-rate command banging between its limits.

Why the start of the hold and not its middle (t + d + T/2, the zero-order hold's half-period
delay of a continuous design): the commands are rates, integrated by the vehicle over the
hold. A loop p_k = G (x_ref - x_hat_k), x_{k+1} = x_k + d p_{k-1} + (T - d) p_k evaluated on
x_hat_k predicted c s ahead (by p_{k-1}) has the poles z^2 + (G (c + T - d) - 1) z - G (c - d)
= 0: with c = d they are 0 and 1 - G T, the discrete twin of the continuous exp(-G T); with
c = d + T/2 one is negative, -0.36 at 10 Hz for the guidance loop (G = v/alpha + K_R/2 = 4.7
1/s) and -0.58 for the adapter's roll loop, and the rate loop's own lag pushed those toward
the unit circle (SIL, the demo at 10 Hz ATTITUDE, 600 s: the roll-rate set-point banged +-70
deg/s at 5 Hz, 0.63 m RMS, 1.9 m max; 0.53 / 1.48 m at t + d with the roll loop's hold gain).

The prediction is the rigid-body kinematics over tau at constant body rates (ATTITUDE's p, q,
r) and constant wind: the attitude R_B^N advances by the body rotation, the air-relative
velocity direction w1 turns with it (constant angle of attack and sideslip over tau), and the
position advances with the average ground velocity v_w w1 + eta. Over tau <= 0.2 s the neglected
terms (a roll rate changes the turn rate: g sec^2(phi) phi_dot tau^2 / 2) are centimetres.
Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.guidance.law import VehicleState

#: Longest prediction (s). A delay beyond this is not a link to compensate but a fault
#: (the bridge's telemetry timeout handles it); the prediction error grows as tau^2.
MAX_PREDICTION_S = 0.25


def _exp(x: float, y: float, z: float) -> NDArray[np.float64]:
    """Rotation matrix exp(hat([x, y, z])) (Rodrigues)."""
    th2 = x * x + y * y + z * z
    th = math.sqrt(th2)
    if th < 1e-9:
        c1, c2 = 1.0, 0.5
    else:
        c1, c2 = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    return np.array(
        (
            (1.0 + c2 * (x * x - th2), -c1 * z + c2 * x * y, c1 * y + c2 * x * z),
            (c1 * z + c2 * x * y, 1.0 + c2 * (y * y - th2), -c1 * x + c2 * y * z),
            (-c1 * y + c2 * x * z, c1 * x + c2 * y * z, 1.0 + c2 * (z * z - th2)),
        )
    )


#: Phase (rad) the guidance loop may lose, at its crossover, to what prediction cannot remove:
#: the hold of each setpoint over a telemetry period (T/2) and the prediction's own error,
#: taken as a quarter of the loop delay (SIL, 60 ms: 0.21 -> 0.25 m RMS with prediction).
#: 0.2 rad keeps the demo's 5 m look-ahead at 50 Hz and 25 Hz and widens it at 10 Hz, where the
#: fixed 5 m flew bursts of 1.9 m (10 m: 0.9 m).
HOLD_PHASE_RAD = 0.2


def look_ahead(alpha_m: float, K_R: float, v_w: float, delay_s: float, period_s: float) -> float:
    """The look-ahead alpha (m) for the measured loop delay (s) and telemetry period (s).

    Near the path the law turns w1 at about (v_w / alpha + K_R / 2) per radian of heading error
    (the transient frame's own turn plus the attitude feedback): that is the guidance loop's
    crossover wc. The lag prediction leaves, T/2 + delay/4, may cost at most HOLD_PHASE_RAD
    there; alpha grows until it does, never below the configured ``alpha_m``."""
    T = period_s if math.isfinite(period_s) and period_s > 0.0 else 0.0
    d = delay_s if math.isfinite(delay_s) and delay_s > 0.0 else 0.0
    lag = 0.5 * T + 0.25 * d
    if lag <= 0.0 or not v_w > 0.0:
        return alpha_m
    room = HOLD_PHASE_RAD / lag - 0.5 * K_R  # what is left for v_w / alpha
    if room <= 0.0:
        return max(alpha_m, 4.0 * v_w * lag / HOLD_PHASE_RAD)  # the feedback alone uses it all
    return max(alpha_m, v_w / room)


def prediction_horizon(delay_s: float) -> float:
    """tau (s): the loop delay, when the setpoint starts acting (module docstring), clipped to
    [0, MAX_PREDICTION_S]. A non-finite input counts as 0."""
    d = delay_s if math.isfinite(delay_s) and delay_s > 0.0 else 0.0
    return min(d, MAX_PREDICTION_S)


def predict(
    vs: VehicleState, R_B_N: Any, rates_frd: Any, tau: float
) -> tuple[VehicleState, NDArray[np.float64]]:
    """(vehicle state, R_B^N) tau seconds after ``vs`` at constant body rates (see the module
    docstring). vs: the measured state (t s, NED position m, wind frame, airspeed m/s, wind m/s
    NED); R_B_N: body FRD -> NED; rates_frd: body rates (p, q, r) rad/s. tau <= 0: the inputs."""
    return predict_segments(vs, R_B_N, [(tau, rates_frd)])


def predict_segments(
    vs: VehicleState, R_B_N: Any, segments: list[tuple[float, Any]]
) -> tuple[VehicleState, NDArray[np.float64]]:
    """As :func:`predict`, over consecutive segments (duration s, body rates rad/s): the body
    rates the autopilot's rate loop is known to fly next (setpoints already sent and not yet
    acting), then the latest. Each segment turns the body (and w1 with it) at its rates."""
    R = np.asarray(R_B_N, float)
    R_W = np.asarray(vs.R_W_I, float)
    pos = np.asarray(vs.position, float)
    tau = 0.0
    for dur, rates in segments:
        if not dur > 0.0:
            continue
        wi = R @ np.asarray(rates, float)  # the body's angular velocity in NED
        x, y, z = (float(v) * dur for v in wi)
        half = _exp(0.5 * x, 0.5 * y, 0.5 * z)
        pos = pos + dur * (vs.airspeed * (half @ R_W[:, 0]) + vs.wind)
        dR = _exp(x, y, z)
        R_W = dR @ R_W
        R = dR @ R
        tau += dur
    if tau == 0.0:
        return vs, R
    return VehicleState(vs.t + tau, pos, R_W, vs.airspeed, vs.wind), R


__all__ = [
    "HOLD_PHASE_RAD",
    "MAX_PREDICTION_S",
    "look_ahead",
    "predict",
    "predict_segments",
    "prediction_horizon",
]
