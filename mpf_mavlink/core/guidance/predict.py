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

from mpf_mavlink.core.guidance.law import VehicleState, vehicle_state_of_floats

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]  # by rows

#: Longest prediction (s). A delay beyond this is not a link to compensate but a fault
#: (the bridge's telemetry timeout handles it); the prediction error grows as tau^2.
MAX_PREDICTION_S = 0.25


def _rodrigues(x: float, y: float, z: float) -> tuple[float, float, float]:
    """|k|^2, sin|k|/|k| and (1 - cos|k|)/|k|^2 for k = [x, y, z] (their limits near 0)."""
    th2 = x * x + y * y + z * z
    th = math.sqrt(th2)
    if th < 1e-9:
        return th2, 1.0, 0.5
    return th2, math.sin(th) / th, (1.0 - math.cos(th)) / th2


def _exp(x: float, y: float, z: float) -> Mat3:
    """Rotation matrix exp(hat([x, y, z])) (Rodrigues), by rows."""
    th2, c1, c2 = _rodrigues(x, y, z)
    return (
        (1.0 + c2 * (x * x - th2), -c1 * z + c2 * x * y, c1 * y + c2 * x * z),
        (c1 * z + c2 * x * y, 1.0 + c2 * (y * y - th2), -c1 * x + c2 * y * z),
        (-c1 * y + c2 * x * z, c1 * x + c2 * y * z, 1.0 + c2 * (z * z - th2)),
    )


def _turn(x: float, y: float, z: float, a: float, b: float, c: float) -> Vec3:
    """exp(hat(k)) u for k = [x, y, z], u = [a, b, c] (Rodrigues on the vector:
    u + sin|k|/|k| k x u + (1 - cos|k|)/|k|^2 k x (k x u))."""
    th2, c1, c2 = _rodrigues(x, y, z)
    k_u = x * a + y * b + z * c  # k x (k x u) = k (k . u) - |k|^2 u
    return (
        a + c1 * (y * c - z * b) + c2 * (x * k_u - th2 * a),
        b + c1 * (z * a - x * c) + c2 * (y * k_u - th2 * b),
        c + c1 * (x * b - y * a) + c2 * (z * k_u - th2 * c),
    )


def _mul(A: Mat3, B: Mat3) -> Mat3:
    """A B, 3x3 by rows."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = A
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = B
    return (
        (a00 * b00 + a01 * b10 + a02 * b20, a00 * b01 + a01 * b11 + a02 * b21,
         a00 * b02 + a01 * b12 + a02 * b22),
        (a10 * b00 + a11 * b10 + a12 * b20, a10 * b01 + a11 * b11 + a12 * b21,
         a10 * b02 + a11 * b12 + a12 * b22),
        (a20 * b00 + a21 * b10 + a22 * b20, a20 * b01 + a21 * b11 + a22 * b21,
         a20 * b02 + a21 * b12 + a22 * b22),
    )  # fmt: skip


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
    vp, R, _ = predict_rows(vs, R_B_N, segments)
    return vp, np.array(R)


def predict_rows(
    vs: VehicleState, R_B_N: Any, segments: list[tuple[float, Any]]
) -> tuple[VehicleState, Mat3, Vec3]:
    """:func:`predict_segments` with R_B^N as a tuple of rows, and the predicted w1 (NED, the
    first column of R_W^I) as a tuple: what the adapter takes. Scalar arithmetic on tuples:
    this runs at every control step, where numpy's per-call cost on 3-vectors and 3x3
    matrices (~1 us a call) was most of the prediction's."""
    R: Mat3 = R_B_N.tolist() if isinstance(R_B_N, np.ndarray) else R_B_N
    vf = vs.floats
    R_W: Any  # rows (tuples or lists)
    if vf is not None:  # the bridge's states (VehicleState.floats): no numpy
        R_W = vf[0:3], vf[3:6], vf[6:9]
        p0, p1, p2, e0, e1, e2 = vf[9:15]
    else:
        R_W = np.asarray(vs.R_W_I, float).tolist()
        p0, p1, p2 = np.asarray(vs.position, float).tolist()
        e0, e1, e2 = np.asarray(vs.wind, float).tolist()
    v = float(vs.airspeed)
    tau = 0.0
    for dur, rates in segments:
        if not dur > 0.0:
            continue
        r0, r1, r2 = rates
        # the body's angular velocity in NED, times the duration: the rotation vector
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = R
        x = (a00 * r0 + a01 * r1 + a02 * r2) * dur
        y = (a10 * r0 + a11 * r1 + a12 * r2) * dur
        z = (a20 * r0 + a21 * r1 + a22 * r2) * dur
        # the position advances with w1 turned half-way (the midpoint rule), plus the wind
        h0, h1, h2 = _turn(0.5 * x, 0.5 * y, 0.5 * z, R_W[0][0], R_W[1][0], R_W[2][0])
        p0 = p0 + dur * (v * h0 + e0)
        p1 = p1 + dur * (v * h1 + e1)
        p2 = p2 + dur * (v * h2 + e2)
        dR = _exp(x, y, z)
        R_W = _mul(dR, R_W)
        R = _mul(dR, R)
        tau += dur
    w1_I = (R_W[0][0], R_W[1][0], R_W[2][0])
    if tau == 0.0:
        return vs, R, w1_I
    vp = vehicle_state_of_floats(vs.t + tau, (*R_W[0], *R_W[1], *R_W[2], p0, p1, p2, e0, e1, e2), v)
    return vp, R, w1_I
