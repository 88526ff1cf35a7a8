"""The paper's vehicle: constant airspeed, wind-frame kinematics and a first-order rate autopilot.

pdot = v_w w1 + eta(t, p)        (NED, m/s; eta: air-mass velocity)
Rdot_W^I = R_W^I hat([0, w2, w3]) (rad/s)
wdot = lambda_w (w_cmd - w)       (first-order autopilot of bandwidth lambda_w, rad/s)

``closed_loop_rk4`` integrates this with the MPF law evaluated at every RK4 stage, so the
closed loop is the paper's continuous-time system (no sample-and-hold).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink import so3
from mpf_mavlink.guidance.law import (
    Extensions,
    Gains,
    MpfDiagnostics,
    VehicleState,
    mpf_law,
)
from mpf_mavlink.paths import TabulatedPath
from mpf_mavlink.target import TargetMotion

WindFn = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]


def no_wind(t: float, p: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.zeros(3)


@dataclass
class KinematicState:
    """t (s), p (NED m), R_W_I, w = [w2, w3] actual rates (rad/s), s (m)."""

    t: float
    p: NDArray[np.float64]
    R: NDArray[np.float64]
    w: NDArray[np.float64]
    s: float


def region_wind(steady: tuple[float, float, float], gusts: list[tuple[NDArray[np.float64], float, NDArray[np.float64]]]) -> WindFn:
    """Steady wind plus gust regions (centre NED m, radius m, extra velocity NED m/s)."""
    base = np.asarray(steady, float)

    def f(t: float, p: NDArray[np.float64]) -> NDArray[np.float64]:
        w = base.copy()
        for c, r, v in gusts:
            if float(np.sum((p - c) ** 2)) <= r * r:
                w = w + v
        return w

    return f


class ClosedLoop:
    """The paper's closed loop: state derivative with the law inside (pure, deterministic)."""

    def __init__(
        self,
        path: TabulatedPath,
        target: TargetMotion,
        gains: Gains,
        ext: Extensions,
        v_w: float,
        lambda_w: float | None,
        wind: WindFn = no_wind,
    ) -> None:
        self.path, self.target, self.gains, self.ext = path, target, gains, ext
        self.v_w = v_w
        self.lambda_w = lambda_w  # None: perfect rate tracking (w = w_cmd)
        self.wind = wind
        self._tcache: tuple[float, object] | None = None

    def target_state(self, t: float):  # noqa: ANN201
        c = self._tcache
        if c is not None and c[0] == t:
            return c[1]
        st = self.target.state(t)
        self._tcache = (t, st)
        return st

    def law(self, t: float, p: NDArray[np.float64], R: NDArray[np.float64], s: float, diag: bool):  # noqa: ANN201
        eta = self.wind(t, p)
        veh = VehicleState(t, p, R, self.v_w, eta)
        return mpf_law(s, veh, self.target_state(t), self.path, self.gains, self.ext, diag), eta

    def deriv(
        self, t: float, p: NDArray[np.float64], R: NDArray[np.float64], w: NDArray[np.float64], s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float, tuple[float, float]]:
        (cmd, _), eta = self.law(t, p, R, s, False)
        wc = (cmd.w2, cmd.w3)
        if self.lambda_w is None:
            w = np.array(wc)
            wdot = np.zeros(2)
        else:
            wdot = self.lambda_w * (np.array(wc) - w)
        pdot = self.v_w * R[:, 0] + eta
        Rdot = R @ so3.hat((0.0, float(w[0]), float(w[1])))
        return pdot, Rdot, wdot, cmd.sdot, wc

    def step(self, x: KinematicState, dt: float) -> KinematicState:
        """One classical RK4 step of (p, R, w, s); R re-orthonormalised afterwards."""
        t, p, R, w, s = x.t, x.p, x.R, x.w, x.s
        k1 = self.deriv(t, p, R, w, s)
        h2 = dt / 2
        k2 = self.deriv(t + h2, p + h2 * k1[0], R + h2 * k1[1], w + h2 * k1[2], s + h2 * k1[3])
        k3 = self.deriv(t + h2, p + h2 * k2[0], R + h2 * k2[1], w + h2 * k2[2], s + h2 * k2[3])
        k4 = self.deriv(t + dt, p + dt * k3[0], R + dt * k3[1], w + dt * k3[2], s + dt * k3[3])
        c = dt / 6
        p2 = p + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        R2 = R + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        w2 = w + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        s2 = s + c * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3])
        if self.lambda_w is None:
            w2 = np.array(k4[4])
        # Gram-Schmidt keeps R on SO(3) without the cost of an SVD every step.
        a = R2[:, 0] / np.linalg.norm(R2[:, 0])
        b = R2[:, 1] - (R2[:, 1] @ a) * a
        b /= np.linalg.norm(b)
        R2 = np.column_stack([a, b, np.cross(a, b)])
        return KinematicState(t + dt, p2, R2, w2, s2)


@dataclass
class Sample:
    """One recorded step: the state, the law's diagnostics and the command it produced."""

    t: float
    p: NDArray[np.float64]
    R: NDArray[np.float64]
    w: NDArray[np.float64]
    diag: MpfDiagnostics
    w_cmd: tuple[float, float]
    sdot: float
    target_p: NDArray[np.float64]
    target_R: NDArray[np.float64]
    wind: NDArray[np.float64]


def record(loop: ClosedLoop, x: KinematicState) -> Sample:
    (cmd, diag), eta = loop.law(x.t, x.p, x.R, x.s, True)
    assert diag is not None
    st = loop.target_state(x.t)
    return Sample(x.t, x.p, x.R, x.w, diag, (cmd.w2, cmd.w3), cmd.sdot, st.position, st.R_T_I, eta)


def initial_state(
    path: TabulatedPath, target: TargetMotion, p0: NDArray[np.float64], R0: NDArray[np.float64], s0: float | None
) -> KinematicState:
    """Start at rest rates; s at the closest point of the moving path unless given."""
    if s0 is None:
        st = target.state(0.0)
        s0 = path.closest(st.R_T_I.T @ (p0 - st.position))
    return KinematicState(0.0, np.asarray(p0, float), np.asarray(R0, float), np.zeros(2), float(s0))


def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi
