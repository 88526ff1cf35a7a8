"""Target motions: the moving frame {T} that carries the path.

A :class:`TargetState` gives, at time t (s): position p_t (NED, m), velocity and acceleration
(NED, m/s, m/s^2), attitude R_T^I, angular velocity omega_TI^T and its rate (both in {T},
rad/s, rad/s^2). Motions are pure functions of t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mpf_mavlink.core import so3


@dataclass(frozen=True)
class TargetState:
    """Target kinematics at time t. Vectors in NED except the angular ones (in {T})."""

    t: float
    position: NDArray[np.float64]
    velocity: NDArray[np.float64]
    acceleration: NDArray[np.float64]
    R_T_I: NDArray[np.float64]
    omega_T: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    omega_dot_T: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))

    def extrapolate(self, t: float) -> TargetState:
        """Constant-acceleration, constant-angular-acceleration prediction to time t (s)."""
        # Scalar arithmetic (called at every control step, where numpy's per-call cost
        # dominates): the same formulas as p + h v + h^2/2 a and R exp(h w + h^2/2 w').
        h = t - self.t
        hh = 0.5 * h * h
        p0, p1, p2 = self.position.tolist()
        v0, v1, v2 = self.velocity.tolist()
        a0, a1, a2 = self.acceleration.tolist()
        w0, w1, w2 = self.omega_T.tolist()
        d0, d1, d2 = self.omega_dot_T.tolist()
        x, y, z = h * w0 + hh * d0, h * w1 + hh * d1, h * w2 + hh * d2
        th2 = x * x + y * y + z * z
        th = math.sqrt(th2)
        if th < 1e-8:
            c1, c2 = 1.0, 0.5
        else:
            c1, c2 = math.sin(th) / th, (1.0 - math.cos(th)) / th2
        # exp(phi) = I + c1 K + c2 K^2, K = hat(phi); K^2 = phi phi^T - |phi|^2 I
        E = (
            (1.0 + c2 * (x * x - th2), -c1 * z + c2 * x * y, c1 * y + c2 * x * z),
            (c1 * z + c2 * x * y, 1.0 + c2 * (y * y - th2), -c1 * x + c2 * y * z),
            (-c1 * y + c2 * x * z, c1 * x + c2 * y * z, 1.0 + c2 * (z * z - th2)),
        )
        R = [
            [r[0] * E[0][j] + r[1] * E[1][j] + r[2] * E[2][j] for j in range(3)]
            for r in self.R_T_I.tolist()
        ]
        return TargetState(
            t,
            np.array((p0 + h * v0 + hh * a0, p1 + h * v1 + hh * a1, p2 + h * v2 + hh * a2)),
            np.array((v0 + h * a0, v1 + h * a1, v2 + h * a2)),
            self.acceleration,
            np.array(R),
            np.array((w0 + h * d0, w1 + h * d1, w2 + h * d2)),
            self.omega_dot_T,
        )


class TargetMotion(Protocol):
    """Anything that gives the target's state at time t (s)."""

    def state(self, t: float) -> TargetState: ...


@dataclass(frozen=True)
class Stationary:
    """A target that does not move: position (NED, m), yaw (rad)."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0

    def state(self, t: float) -> TargetState:
        z = np.zeros(3)
        return TargetState(t, np.array(self.position, float), z, z.copy(), so3.rot_z(self.yaw))


@dataclass(frozen=True)
class ConstantTurn:
    """Constant ground speed (m/s), turn rate (rad/s, > 0 turns right) and climb rate (m/s, up).

    {T} is the level heading frame (x along the horizontal velocity, z down); its angular
    velocity is [0, 0, turn_rate].
    """

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    speed: float = 0.0
    heading: float = 0.0
    turn_rate: float = 0.0
    climb_rate: float = 0.0

    def state(self, t: float) -> TargetState:
        V, w, psi0 = self.speed, self.turn_rate, self.heading
        psi = psi0 + w * t
        p0 = np.array(self.position, float)
        if abs(w) > 1e-9:
            dn = V / w * (math.sin(psi) - math.sin(psi0))
            de = V / w * (math.cos(psi0) - math.cos(psi))
        else:
            dn, de = V * t * math.cos(psi0), V * t * math.sin(psi0)
        pos = p0 + np.array([dn, de, -self.climb_rate * t])
        vel = np.array([V * math.cos(psi), V * math.sin(psi), -self.climb_rate])
        acc = np.array([-V * w * math.sin(psi), V * w * math.cos(psi), 0.0])
        return TargetState(t, pos, vel, acc, so3.rot_z(psi), np.array([0.0, 0.0, w]), np.zeros(3))


class PaperProfile:
    """Section V of the paper: body-frame speed and angular velocity given as functions of t.

    pdot_t^T = [3 sqrt((cos 0.1t + 1)^2 + 1), 0, 0],
    omega_TI^T = [0, -0.001 cos 0.03t, -sin 0.1t / (10 ((cos 0.1t + 1)^2 + 1)^1.5)],
    p_t(0) = position, R_T^I(0) = Rz(yaw). Position and attitude have no closed form: they
    are integrated by RK4 on a 0.01 s grid (kept as it grows) and one RK4 step of the
    remaining fraction, so state(t) is a deterministic pure function of t.
    """

    DT = 0.01

    def __init__(self, position: ArrayLike = (0.0, 0.0, 5.0), yaw: float = math.pi / 4) -> None:
        # Grid of (position, row-major R_T^I) every DT seconds, as plain floats for speed.
        self._grid_p: list[list[float]] = [[float(v) for v in np.asarray(position, float)]]
        self._grid_R: list[list[float]] = [so3.rot_z(yaw).ravel().tolist()]

    @staticmethod
    def speed(t: float) -> tuple[float, float]:
        """Body-axis speed v (m/s) and its rate (m/s^2)."""
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        return 3.0 * math.sqrt(g), -0.3 * (c + 1.0) * s / math.sqrt(g)

    @staticmethod
    def omega(t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """omega_TI^T (rad/s) and its time derivative (rad/s^2)."""
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        gdot = -0.2 * (c + 1.0) * s
        w3 = -s / (10.0 * g**1.5)
        w3dot = -(0.1 * c) / (10.0 * g**1.5) + s * 1.5 * gdot / (10.0 * g**2.5)
        w = np.array([0.0, -0.001 * math.cos(0.03 * t), w3])
        wd = np.array([0.0, 0.00003 * math.sin(0.03 * t), w3dot])
        return w, wd

    def _f(self, t: float, R: list[float]) -> tuple[list[float], list[float]]:
        """(pdot, Rdot) with R a row-major list of 9 floats: pdot = R e1 v, Rdot = R hat(w)."""
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        v = 3.0 * math.sqrt(g)
        wy = -0.001 * math.cos(0.03 * t)
        wz = -s / (10.0 * g**1.5)
        pd = [R[0] * v, R[3] * v, R[6] * v]
        # R hat(w) with w = (0, wy, wz): columns [R2 wz - R3 wy, -R1 wz, R1 wy].
        Rd = []
        for i in (0, 3, 6):
            r0, r1, r2 = R[i], R[i + 1], R[i + 2]
            Rd += [r1 * wz - r2 * wy, -r0 * wz, r0 * wy]
        return pd, Rd

    def _rk4(
        self, t: float, p: list[float], R: list[float], h: float
    ) -> tuple[list[float], list[float]]:
        k1p, k1R = self._f(t, R)
        k2p, k2R = self._f(t + h / 2, [R[i] + h / 2 * k1R[i] for i in range(9)])
        k3p, k3R = self._f(t + h / 2, [R[i] + h / 2 * k2R[i] for i in range(9)])
        k4p, k4R = self._f(t + h, [R[i] + h * k3R[i] for i in range(9)])
        c = h / 6
        p2 = [p[i] + c * (k1p[i] + 2 * k2p[i] + 2 * k3p[i] + k4p[i]) for i in range(3)]
        R2 = [R[i] + c * (k1R[i] + 2 * k2R[i] + 2 * k3R[i] + k4R[i]) for i in range(9)]
        return p2, R2

    def state(self, t: float) -> TargetState:
        if t < 0:
            raise ValueError("the paper's target profile starts at t = 0")
        x = t / self.DT
        k = int(round(x))
        if abs(x - k) > 1e-9:  # not on the grid (up to float round-off)
            k = int(x)
        while len(self._grid_p) <= k:
            j = len(self._grid_p) - 1
            p2, R2 = self._rk4(j * self.DT, self._grid_p[j], self._grid_R[j], self.DT)
            if j % 100 == 0:
                R2 = so3.orthonormalize(np.array(R2).reshape(3, 3)).ravel().tolist()
            self._grid_p.append(p2)
            self._grid_R.append(R2)
        h = t - k * self.DT
        p, R = self._grid_p[k], self._grid_R[k]
        if h > 1e-12:
            p, R = self._rk4(k * self.DT, p, R, h)
        v, vdot = self.speed(t)
        w, wd = self.omega(t)
        Rm = np.array(R).reshape(3, 3)
        vel = Rm[:, 0] * v
        # a = R (vdot e1 + omega x (v e1)) in body components.
        acc = Rm @ np.array([vdot, w[2] * v, -w[1] * v])
        return TargetState(t, np.array(p), vel, acc, Rm, w, wd)
