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
from mpf_mavlink.core.float_arrays import FloatArrays


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
    # The same numbers as floats, when whoever built the state had them at hand (extrapolate,
    # PaperProfile.state: :func:`with_floats`; :func:`target_state_of_floats`): R_T^I by rows
    # (9), then p_t, v_t, a_t, omega_T, omega_dot_T (3 each). The law reads these instead of
    # converting the arrays back. Not an init argument, so
    # dataclasses.replace drops it (the law then reads the arrays) and it cannot go stale.
    floats: tuple[float, ...] | None = field(default=None, init=False, repr=False, compare=False)

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
        p = (p0 + h * v0 + hh * a0, p1 + h * v1 + hh * a1, p2 + h * v2 + hh * a2)
        v = (v0 + h * a0, v1 + h * a1, v2 + h * a2)
        w = (w0 + h * d0, w1 + h * d1, w2 + h * d2)
        return target_state_of_floats(t, (*R[0], *R[1], *R[2], *p, *v, a0, a1, a2, *w, d0, d1, d2))


_ARRAYS = FloatArrays(
    (("R_T_I", 0, 9), ("position", 9, 12), ("velocity", 12, 15), ("acceleration", 15, 18),
     ("omega_T", 18, 21), ("omega_dot_T", 21, 24))
)  # fmt: skip
_ARRAYS.install(TargetState)


def target_state_of_floats(t: float, floats: tuple[float, ...]) -> TargetState:
    """The :class:`TargetState` at time t (s) of 24 floats in the order of
    :attr:`TargetState.floats` (R_T^I by rows, p_t, v_t, a_t, omega_T, omega_dot_T), whose
    arrays are built when first read: the law reads the floats, and most states the bridge
    makes (the target predicted to when its setpoint acts, every control step) are never read
    as arrays. Its arrays are read-only."""
    st = _new(TargetState)
    d = st.__dict__
    d["t"], d["floats"] = t, floats
    return st


_new = object.__new__


def with_floats(st: TargetState, floats: tuple[float, ...]) -> TargetState:
    """st with its :attr:`TargetState.floats` set (the caller's floats, equal to the arrays':
    R_T^I by rows, p_t, v_t, a_t, omega_T, omega_dot_T)."""
    object.__setattr__(st, "floats", floats)
    return st


def state_floats(st: TargetState) -> tuple[float, ...]:
    """The 24 floats of :attr:`TargetState.floats` (R_T^I by rows, p_t, v_t, a_t, omega_T,
    omega_dot_T): its own when it kept them, else its arrays' values."""
    if st.floats is not None:
        return st.floats
    arrays = (st.R_T_I, st.position, st.velocity, st.acceleration, st.omega_T, st.omega_dot_T)
    return tuple(x for a in arrays for x in np.asarray(a, float).ravel().tolist())


class TargetMotion(Protocol):
    """Anything that gives the target's state at time t (s)."""

    def state(self, t: float) -> TargetState: ...


@dataclass(frozen=True)
class Stationary:
    """A target that does not move: position (NED, m), yaw (rad)."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0

    def state(self, t: float) -> TargetState:
        # as floats (the law reads them; the arrays are built if read): rot_z(yaw) by rows
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        n, e, d = (float(x) for x in self.position)
        return target_state_of_floats(
            t, (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0, n, e, d) + (0.0,) * 12
        )


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
        """The state at t (s), on Python floats only (the SIL's target stream evaluates it for
        every fix; numpy's per-call cost was most of it): the same IEEE operations as
        ``position + [dn, de, -climb_rate t]`` in float64, so the same bits."""
        V, w, psi0 = self.speed, self.turn_rate, self.heading
        tf = float(t)  # (a numpy scalar t would make every number below one)
        psi = psi0 + w * tf
        if abs(w) > 1e-9:
            dn = V / w * (math.sin(psi) - math.sin(psi0))
            de = V / w * (math.cos(psi0) - math.cos(psi))
        else:
            dn, de = V * tf * math.cos(psi0), V * tf * math.sin(psi0)
        n0, e0, d0 = self.position
        dd = -self.climb_rate * tf
        c, s = math.cos(psi), math.sin(psi)
        # as floats (the law reads them; the arrays are built if read): R = rot_z(psi) by rows,
        # p, v, a, omega, omega_dot
        return target_state_of_floats(t, (
            c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0,
            float(n0) + dn, float(e0) + de, float(d0) + dd,
            V * c, V * s, -self.climb_rate,
            -V * w * s, V * w * c, 0.0,
            0.0, 0.0, w, 0.0, 0.0, 0.0,
        ))  # fmt: skip


class PaperProfile:
    """Section V of the paper: body-frame speed and angular velocity given as functions of t.

    pdot_t^T = [3 sqrt((cos 0.1t + 1)^2 + 1), 0, 0],
    omega_TI^T = [0, -0.001 cos 0.03t, -sin 0.1t / (10 ((cos 0.1t + 1)^2 + 1)^1.5)],
    p_t(0) = position, R_T^I(0) = Rz(yaw). Position and attitude have no closed form: they
    are integrated by RK4 on a 0.01 s grid (kept as it grows) and one step from the nearest
    node to t (RK4; a first-order step when t is within 1e-6 s of the node, whose error,
    ~1e-13 m, is below the RK4's own), so state(t) is a deterministic pure function of t.
    """

    DT = 0.01
    # Below this distance (s) from a node one Euler step is exact to rounding in practice.
    _NEAR_NODE_S = 1e-6
    _CHUNK = 256  # grid nodes computed at once

    def __init__(self, position: ArrayLike = (0.0, 0.0, 5.0), yaw: float = math.pi / 4) -> None:
        # Grid of (position, row-major R_T^I) every DT seconds, as plain floats for speed.
        p0 = np.asarray(position, float).tolist()
        self._grid_p: list[tuple[float, ...]] = [tuple(p0)]
        self._grid_R: list[tuple[float, ...]] = [tuple(so3.rot_z(yaw).ravel().tolist())]

    @staticmethod
    def speed(t: float) -> tuple[float, float]:
        """Body-axis speed v (m/s) and its rate (m/s^2)."""
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        return 3.0 * math.sqrt(g), -0.3 * (c + 1.0) * s / math.sqrt(g)

    @staticmethod
    def _omega(t: float) -> tuple[float, float, float, float]:
        """omega_TI^T = (0, wy, wz) (rad/s) and its rate (0, wy_dot, wz_dot) (rad/s^2)."""
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        gdot = -0.2 * (c + 1.0) * s
        w3 = -s / (10.0 * g**1.5)
        w3dot = -(0.1 * c) / (10.0 * g**1.5) + s * 1.5 * gdot / (10.0 * g**2.5)
        return -0.001 * math.cos(0.03 * t), w3, 0.00003 * math.sin(0.03 * t), w3dot

    @classmethod
    def omega(cls, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """omega_TI^T (rad/s) and its time derivative (rad/s^2)."""
        wy, wz, wy_dot, wz_dot = cls._omega(t)
        return np.array([0.0, wy, wz]), np.array([0.0, wy_dot, wz_dot])

    @staticmethod
    def _vw(t: float) -> tuple[float, float, float]:
        """(v, wy, wz): the speed and omega_TI^T = (0, wy, wz) the ODE needs at t."""
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        return 3.0 * math.sqrt(g), -0.001 * math.cos(0.03 * t), -s / (10.0 * g**1.5)

    @staticmethod
    def _f(
        R: tuple[float, ...], v: float, wy: float, wz: float
    ) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(pdot, Rdot) with R row-major (9 floats): pdot = R e1 v, Rdot = R hat(w),
        w = (0, wy, wz), whose columns are [R2 wz - R3 wy, -R1 wz, R1 wy]."""
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        return (r0 * v, r3 * v, r6 * v), (
            r1 * wz - r2 * wy, -r0 * wz, r0 * wy,
            r4 * wz - r5 * wy, -r3 * wz, r3 * wy,
            r7 * wz - r8 * wy, -r6 * wz, r6 * wy,
        )  # fmt: skip

    def _rk4(
        self, t: float, p: tuple[float, ...], R: tuple[float, ...], h: float
    ) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """One classical RK4 step of h (s) of (p, R) from t, written out on scalars: each row
        r of R obeys r' = r hat(w) on its own, and p' = v R e1 takes the rows' first
        elements at the same stages."""
        h2, h6 = 0.5 * h, h / 6.0
        va, ya, za = self._vw(t)
        vb, yb, zb = self._vw(t + h2)
        vc, yc, zc = self._vw(t + h)
        vb2 = 2.0 * vb  # float constants: CPython's int * float takes its slow generic path
        p2: list[float] = []
        R2: list[float] = []
        for i in range(3):
            r0, r1, r2 = R[3 * i], R[3 * i + 1], R[3 * i + 2]
            a0, a1, a2 = r1 * za - r2 * ya, -r0 * za, r0 * ya  # k1
            s0, s1, s2 = r0 + h2 * a0, r1 + h2 * a1, r2 + h2 * a2
            b0, b1, b2 = s1 * zb - s2 * yb, -s0 * zb, s0 * yb  # k2
            u0, u1, u2 = r0 + h2 * b0, r1 + h2 * b1, r2 + h2 * b2
            c0, c1, c2 = u1 * zb - u2 * yb, -u0 * zb, u0 * yb  # k3
            x0, x1, x2 = r0 + h * c0, r1 + h * c1, r2 + h * c2
            d0, d1, d2 = x1 * zc - x2 * yc, -x0 * zc, x0 * yc  # k4
            p2.append(p[i] + h6 * (va * r0 + vb2 * s0 + vb2 * u0 + vc * x0))
            R2 += (
                r0 + h6 * (a0 + 2.0 * b0 + 2.0 * c0 + d0),
                r1 + h6 * (a1 + 2.0 * b1 + 2.0 * c1 + d1),
                r2 + h6 * (a2 + 2.0 * b2 + 2.0 * c2 + d2),
            )
        return tuple(p2), tuple(R2)

    def _extend(self) -> None:
        """Extend the grid by _CHUNK RK4 steps of DT (always the same chunks, from node 0, so
        every node has the same bits whatever the order of the queries).

        The ODE is linear in (p, R) with coefficients that depend on t only, so one RK4 step
        is (p, R) -> (p + R b, R Phi) exactly (the rows' stages R M_i, M_1 = I, M_2 = I +
        h/2 W_a, M_3 = I + h/2 M_2 W_b, M_4 = I + h M_3 W_b, with W = hat(w) at t, t + h/2,
        t + h): Phi and b are computed for the whole chunk at once and only the products
        run node by node. R is re-orthonormalised every 100 nodes.
        """
        gp, gR = self._grid_p, self._grid_R
        j0 = len(gp) - 1
        n = self._CHUNK
        h = self.DT
        t: NDArray[np.float64] = (j0 + np.arange(n, dtype=float)) * h

        def vw(tt: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            c, s = np.cos(0.1 * tt), np.sin(0.1 * tt)
            g = (c + 1.0) ** 2 + 1.0
            wy, wz = -0.001 * np.cos(0.03 * tt), -s / (10.0 * g**1.5)
            W = np.zeros((len(tt), 3, 3))  # r hat(w) = r W for a row r, w = (0, wy, wz)
            W[:, 0, 1], W[:, 0, 2], W[:, 1, 0], W[:, 2, 0] = -wz, wy, wz, -wy
            return 3.0 * np.sqrt(g), W

        va, Wa = vw(t)
        vb, Wb = vw(t + 0.5 * h)
        vc, Wc = vw(t + h)
        eye = np.eye(3)
        M2 = eye + 0.5 * h * Wa
        K2 = M2 @ Wb
        M3 = eye + 0.5 * h * K2
        K3 = M3 @ Wb
        M4 = eye + h * K3
        Phi = eye + (h / 6.0) * (Wa + 2.0 * K2 + 2.0 * K3 + M4 @ Wc)
        b = (h / 6.0) * (
            va[:, None] * eye[0] + 2.0 * vb[:, None] * (M2[:, :, 0] + M3[:, :, 0])
            + vc[:, None] * M4[:, :, 0]
        )  # fmt: skip
        p0, p1, p2 = gp[-1]
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = gR[-1]
        j = j0
        for (f0, f1, f2, f3, f4, f5, f6, f7, f8), (b0, b1, b2) in zip(
            Phi.reshape(n, 9).tolist(), b.tolist(), strict=True
        ):
            p0 += r0 * b0 + r1 * b1 + r2 * b2
            p1 += r3 * b0 + r4 * b1 + r5 * b2
            p2 += r6 * b0 + r7 * b1 + r8 * b2
            R: tuple[float, ...] = (
                r0 * f0 + r1 * f3 + r2 * f6, r0 * f1 + r1 * f4 + r2 * f7,
                r0 * f2 + r1 * f5 + r2 * f8,
                r3 * f0 + r4 * f3 + r5 * f6, r3 * f1 + r4 * f4 + r5 * f7,
                r3 * f2 + r4 * f5 + r5 * f8,
                r6 * f0 + r7 * f3 + r8 * f6, r6 * f1 + r7 * f4 + r8 * f7,
                r6 * f2 + r7 * f5 + r8 * f8,
            )  # fmt: skip
            if j % 100 == 0:
                R = tuple(so3.orthonormalize(np.reshape(R, (3, 3))).ravel().tolist())
            r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
            gp.append((p0, p1, p2))
            gR.append(R)
            j += 1

    def state(self, t: float) -> TargetState:
        if t < 0:
            raise ValueError("the paper's target profile starts at t = 0")
        k = int(round(t / self.DT))  # the nearest node
        gp, gR = self._grid_p, self._grid_R
        while len(gp) <= k:
            self._extend()
        h = t - k * self.DT  # |h| <= DT / 2, either sign
        p, R = gp[k], gR[k]
        near = abs(h) <= self._NEAR_NODE_S
        if not near:
            p, R = self._rk4(k * self.DT, p, R, h)
        # speed(t) and _omega(t) on one evaluation of the trigonometry.
        c, s = math.cos(0.1 * t), math.sin(0.1 * t)
        g = (c + 1.0) ** 2 + 1.0
        sg = math.sqrt(g)
        g15 = 10.0 * g * sg
        v, vdot = 3.0 * sg, -0.3 * (c + 1.0) * s / sg
        wy, wz = -0.001 * math.cos(0.03 * t), -s / g15
        wy_dot = 0.00003 * math.sin(0.03 * t)
        wz_dot = -(0.1 * c) / g15 + s * 1.5 * (-0.2 * (c + 1.0) * s) / (g15 * g)
        p0, p1, p2 = p
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        if near and h != 0.0:
            # One Euler step: p' = v R e1, each row r' = r hat(w) (w = (0, wy, wz)).
            p0, p1, p2 = p0 + h * v * r0, p1 + h * v * r3, p2 + h * v * r6
            r0, r1, r2 = r0 + h * (r1 * wz - r2 * wy), r1 - h * r0 * wz, r2 + h * r0 * wy
            r3, r4, r5 = r3 + h * (r4 * wz - r5 * wy), r4 - h * r3 * wz, r5 + h * r3 * wy
            r6, r7, r8 = r6 + h * (r7 * wz - r8 * wy), r7 - h * r6 * wz, r8 + h * r6 * wy
        # a = R (vdot e1 + omega x (v e1)) in body components (vdot, wz v, -wy v).
        b0, b1, b2 = vdot, wz * v, -wy * v
        f = (
            r0, r1, r2, r3, r4, r5, r6, r7, r8, p0, p1, p2, r0 * v, r3 * v, r6 * v,
            r0 * b0 + r1 * b1 + r2 * b2, r3 * b0 + r4 * b1 + r5 * b2, r6 * b0 + r7 * b1 + r8 * b2,
            0.0, wy, wz, 0.0, wy_dot, wz_dot,
        )  # fmt: skip
        a = np.array(f)  # one array, its fields views of it
        st = TargetState(t, a[9:12], a[12:15], a[15:18], a[0:9].reshape(3, 3), a[18:21], a[21:])
        return with_floats(st, f)
