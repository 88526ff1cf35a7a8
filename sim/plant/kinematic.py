"""The paper's vehicle: constant airspeed, wind-frame kinematics and a first-order rate autopilot.

pdot = v_w w1 + eta(t, p)        (NED, m/s; eta: air-mass velocity)
Rdot_W^I = R_W^I hat([0, w2, w3]) (rad/s)
wdot = lambda_w (w_cmd - w)       (first-order autopilot of bandwidth lambda_w, rad/s)

``closed_loop_rk4`` integrates this with the MPF law evaluated at every RK4 stage, so the
closed loop is the paper's continuous-time system (no sample-and-hold).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.guidance.baselines import guidance_law
from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfDiagnostics,
    VehicleState,
)
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetMotion

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


def region_wind(
    steady: tuple[float, float, float],
    gusts: list[tuple[NDArray[np.float64], float, NDArray[np.float64]]],
) -> WindFn:
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
        law: str = "mpf",
    ) -> None:
        self.path, self.target, self.gains, self.ext = path, target, gains, ext
        self.v_w = v_w
        self.lambda_w = lambda_w  # None: perfect rate tracking (w = w_cmd)
        self.wind = wind
        self.law_name = law  # guidance.law: MPF or a baseline, the same command type
        self._tcache: tuple[float, object] | None = None
        self.last: Sample | None = None

    def target_state(self, t: float):  # noqa: ANN201
        c = self._tcache
        if c is not None and c[0] == t:
            return c[1]
        st = self.target.state(t)
        self._tcache = (t, st)
        return st

    def law(  # noqa: ANN201
        self, t: float, p: NDArray[np.float64], R: NDArray[np.float64], s: float, diag: bool
    ):
        eta = self.wind(t, p)
        veh = VehicleState(t, p, R, self.v_w, eta)
        st = self.target_state(t)
        return guidance_law(self.law_name, s, veh, st, self.path, self.gains, self.ext, diag), eta

    def deriv(
        self, t: float, p: list[float], R: list[float], w: list[float], s: float, keep: bool = False
    ) -> tuple[list[float], list[float], list[float], float, tuple[float, float]]:
        """(pdot, Rdot, wdot, sdot, w_cmd) with R a row-major list of 9 floats.

        keep: also build the diagnostics and keep them as ``self.last`` (the recorder reads
        them, so a recorded step costs no extra law evaluation)."""
        pa = np.array(p)
        Ra = np.array(R).reshape(3, 3)
        (cmd, diag), eta = self.law(t, pa, Ra, s, keep)
        if keep:
            self.last = Sample(
                t,
                pa,
                Ra,
                np.array(w),
                diag,
                (cmd.w2, cmd.w3),
                cmd.sdot,
                self.target_state(t).position,
                self.target_state(t).R_T_I,
                eta,
            )
        wc = (cmd.w2, cmd.w3)
        if self.lambda_w is None:
            w = list(wc)
            wdot = [0.0, 0.0]
        else:
            lam = self.lambda_w
            wdot = [lam * (wc[0] - w[0]), lam * (wc[1] - w[1])]
        v = self.v_w
        e = eta.tolist()
        pdot = [v * R[0] + e[0], v * R[3] + e[1], v * R[6] + e[2]]
        # R hat([0, w2, w3]): columns [R2 w3 - R3 w2, -R1 w3, R1 w2].
        w2, w3 = w[0], w[1]
        Rdot = []
        for i in (0, 3, 6):
            r0, r1, r2 = R[i], R[i + 1], R[i + 2]
            Rdot += [r1 * w3 - r2 * w2, -r0 * w3, r0 * w2]
        return pdot, Rdot, wdot, cmd.sdot, wc

    def step(self, x: KinematicState, dt: float) -> KinematicState:
        """One classical RK4 step of (p, R, w, s); R re-orthonormalised afterwards."""
        t, s = x.t, x.s
        p, R, w = x.p.tolist(), x.R.ravel().tolist(), x.w.tolist()

        def add(a: list[float], k: list[float], h: float) -> list[float]:
            return [a[i] + h * k[i] for i in range(len(a))]

        k1 = self.deriv(t, p, R, w, s, keep=True)
        h2 = dt / 2
        k2 = self.deriv(
            t + h2, add(p, k1[0], h2), add(R, k1[1], h2), add(w, k1[2], h2), s + h2 * k1[3]
        )
        k3 = self.deriv(
            t + h2, add(p, k2[0], h2), add(R, k2[1], h2), add(w, k2[2], h2), s + h2 * k2[3]
        )
        k4 = self.deriv(
            t + dt, add(p, k3[0], dt), add(R, k3[1], dt), add(w, k3[2], dt), s + dt * k3[3]
        )
        c = dt / 6

        def comb(
            a: list[float], ka: list[float], kb: list[float], kc: list[float], kd: list[float]
        ) -> list[float]:
            return [a[i] + c * (ka[i] + 2 * kb[i] + 2 * kc[i] + kd[i]) for i in range(len(a))]

        p2 = np.array(comb(p, k1[0], k2[0], k3[0], k4[0]))
        R2 = np.array(comb(R, k1[1], k2[1], k3[1], k4[1])).reshape(3, 3)
        w2 = np.array(comb(w, k1[2], k2[2], k3[2], k4[2]))
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
    path: TabulatedPath,
    target: TargetMotion,
    p0: NDArray[np.float64],
    R0: NDArray[np.float64],
    s0: float | None,
) -> KinematicState:
    """Start at rest rates; s at the closest point of the moving path unless given."""
    if s0 is None:
        st = target.state(0.0)
        s0 = path.closest(st.R_T_I.T @ (p0 - st.position))
    return KinematicState(0.0, np.asarray(p0, float), np.asarray(R0, float), np.zeros(2), float(s0))
