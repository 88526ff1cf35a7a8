"""The paper's vehicle: constant airspeed, wind-frame kinematics and a first-order rate autopilot.

pdot = v_w w1 + eta(t, p)        (NED, m/s; eta: air-mass velocity)
Rdot_W^I = R_W^I hat([0, w2, w3]) (rad/s)
wdot = lambda_w (w_cmd - w)       (first-order autopilot of bandwidth lambda_w, rad/s)

:meth:`ClosedLoop.step` integrates this with the MPF law evaluated at every RK4 stage, so the
closed loop is the paper's continuous-time system (no sample-and-hold).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.guidance.dispatch import guidance_law
from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    VehicleState,
)

# law.py's law written out on floats, bit for bit its numbers: 4 evaluations per RK4 step make
# the law most of this loop's time (law_unrolled.py's docstring has the figure).
from mpf_mavlink.core.guidance.law_unrolled import mpf_law_unrolled as mpf_law
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetMotion, TargetState

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
    # Read-only, so it is handed out as it is (no copy per call, ~4 per RK4 step).
    base = np.array(steady, float)
    base.flags.writeable = False
    regions = [(c.tolist(), r * r, v) for c, r, v in gusts]

    def f(t: float, p: NDArray[np.float64]) -> NDArray[np.float64]:
        w = base
        if regions:
            p0, p1, p2 = p.tolist()
            for (c0, c1, c2), rr, v in regions:
                if (p0 - c0) ** 2 + (p1 - c1) ** 2 + (p2 - c2) ** 2 <= rr:
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
        self._tcache: tuple[float, TargetState] | None = None
        self.last: Sample | None = None
        # The last step's result, its fields and its flat state, so that the next step need
        # not convert it back.
        self._x_cache: tuple[KinematicState, tuple[object, ...], list[float]] | None = None

    def target_state(self, t: float) -> TargetState:
        c = self._tcache
        if c is not None and c[0] == t:
            return c[1]
        st = self.target.state(t)
        self._tcache = (t, st)
        return st

    def law(
        self, t: float, p: NDArray[np.float64], R: NDArray[np.float64], s: float, diag: bool
    ) -> tuple[tuple[MpfCommand, MpfDiagnostics | None], NDArray[np.float64]]:
        eta = self.wind(t, p)
        veh = VehicleState(t, p, R, self.v_w, eta)
        st = self.target_state(t)
        return guidance_law(self.law_name, s, veh, st, self.path, self.gains, self.ext, diag), eta

    def deriv(
        self, t: float, X: list[float], keep: bool = False
    ) -> tuple[list[float], tuple[float, float]]:
        """(Xdot, w_cmd) of the state X = p (3), R_W^I row-major (9), w = [w2, w3] (2), s.

        keep: also build the diagnostics and keep them as ``self.last`` (the recorder reads
        them, so a recorded step costs no extra law evaluation)."""
        pa = np.array(X[0:3])
        Ra = np.array(X[3:12]).reshape(3, 3)
        # What self.law does, without its call (this runs four times per step).
        eta = self.wind(t, pa)
        st = self.target_state(t)
        veh = VehicleState(t, pa, Ra, self.v_w, eta)
        if self.law_name == "mpf":
            cmd, diag = mpf_law(X[14], veh, st, self.path, self.gains, self.ext, keep)
        else:
            name, s = self.law_name, X[14]
            cmd, diag = guidance_law(name, s, veh, st, self.path, self.gains, self.ext, keep)
        wc = (cmd.w2, cmd.w3)
        if keep:
            assert diag is not None
            self.last = Sample(
                t, pa, Ra, np.array(X[12:14]), diag, wc, cmd.sdot, st.position, st.R_T_I, eta
            )
        if self.lambda_w is None:
            w2, w3 = wc
            w2_dot = w3_dot = 0.0
        else:
            lam = self.lambda_w
            w2, w3 = X[12], X[13]
            w2_dot, w3_dot = lam * (wc[0] - w2), lam * (wc[1] - w3)
        v = self.v_w
        e0, e1, e2 = eta.tolist()
        _, _, _, r0, r1, r2, r3, r4, r5, r6, r7, r8 = X[0:12]
        # pdot = v_w w1 + eta; Rdot = R hat([0, w2, w3]), whose columns are
        # [R2 w3 - R3 w2, -R1 w3, R1 w2].
        Xdot = [
            v * r0 + e0, v * r3 + e1, v * r6 + e2,
            r1 * w3 - r2 * w2, -r0 * w3, r0 * w2,
            r4 * w3 - r5 * w2, -r3 * w3, r3 * w2,
            r7 * w3 - r8 * w2, -r6 * w3, r6 * w2,
            w2_dot, w3_dot, cmd.sdot,
        ]  # fmt: skip
        return Xdot, wc

    def step(self, x: KinematicState, dt: float) -> KinematicState:
        """One classical RK4 step of (p, R, w, s); R re-orthonormalised afterwards."""
        t = x.t
        cached = self._x_cache
        if (
            cached is not None
            and cached[0] is x
            and all(a is b for a, b in zip(cached[1], (x.p, x.R, x.w), strict=True))
            and cached[2][14] == x.s
        ):
            X = cached[2]
        else:
            X = x.p.tolist() + x.R.ravel().tolist() + x.w.tolist() + [float(x.s)]
        h2 = 0.5 * dt
        k1, _ = self.deriv(t, X, keep=True)
        k2, _ = self.deriv(t + h2, [a + h2 * k for a, k in zip(X, k1, strict=True)])
        k3, _ = self.deriv(t + h2, [a + h2 * k for a, k in zip(X, k2, strict=True)])
        k4, wc4 = self.deriv(t + dt, [a + dt * k for a, k in zip(X, k3, strict=True)])
        c = dt / 6
        X2 = [
            a + c * (ka + 2 * kb + 2 * kc + kd)
            for a, ka, kb, kc, kd in zip(X, k1, k2, k3, k4, strict=True)
        ]
        if self.lambda_w is None:
            X2[12], X2[13] = wc4
        # Gram-Schmidt on R's first two columns keeps R on SO(3) without an SVD every step.
        _, _, _, a0, b0, _, a1, b1, _, a2, b2, _ = X2[0:12]
        n = 1.0 / math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        a0, a1, a2 = a0 * n, a1 * n, a2 * n
        d = b0 * a0 + b1 * a1 + b2 * a2
        b0, b1, b2 = b0 - d * a0, b1 - d * a1, b2 - d * a2
        n = 1.0 / math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        b0, b1, b2 = b0 * n, b1 * n, b2 * n
        X2[3:12] = (
            a0, b0, a1 * b2 - a2 * b1,
            a1, b1, a2 * b0 - a0 * b2,
            a2, b2, a0 * b1 - a1 * b0,
        )  # fmt: skip
        p, R, w = np.array(X2[0:3]), np.array(X2[3:12]).reshape(3, 3), np.array(X2[12:14])
        # Read-only: the next step reads the flat copy, so an edit in place must fail loudly
        # (replacing a field, or passing a new state, is seen).
        p.flags.writeable = R.flags.writeable = w.flags.writeable = False
        x2 = KinematicState(t + dt, p, R, w, X2[14])
        self._x_cache = (x2, (p, R, w), X2)
        return x2


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
