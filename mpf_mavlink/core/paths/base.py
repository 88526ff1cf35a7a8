"""Arc-length parameterised paths with a parallel-transport (Bishop) frame.

Every path is fixed in the target frame {T} (metres, axes x forward, y right, z down). Any
regular curve ``c(u)`` is tabulated once at uniform arc-length nodes (ds ~ 0.25 m): position,
unit tangent f1, transported normal f2 (double-reflection rotation-minimising frame, Wang et
al. 2008) and the curvature components k1 = kappa . f2, k2 = kappa . f3. Between nodes the
position is a cubic Hermite interpolant (exact tangents), f1 its normalised derivative and f2
the node's f2 carried onto f1 by the minimal rotation, then turned about f1 by a linearly
growing share of the angle that meets the next node's f2, so the frame is continuous
everywhere. :meth:`TabulatedPath.eval_with_rate` also gives dp_d/ds and the exact angular
velocity of this interpolated frame (the cells are C1: its curvature jumps slightly at nodes).

Closed paths: a transported frame generally comes back rotated about f1 after one lap
(holonomy angle theta). We spread -theta evenly along the lap, so f2/f3 never jump at the
seam, and report the resulting constant twist ``tau = -theta / L`` (rad/m); the frame's
angular velocity is then ``omega_FT^F = sdot * [tau, -k2, k1]``.

Initial normal: f3 is "down" projected orthogonal to f1 (f2 = f3 x f1), so a horizontal
path has f2 pointing right and f3 down, like FRD, and k1 > 0 means turning right.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.vec3 import Vec3, add_scaled, cross
from mpf_mavlink.errors import ConfigError

CurveFn = Callable[[NDArray[np.float64]], NDArray[np.float64]]
Tuple3 = Vec3
# (p_d, f1, f2, f3, k1, k2) and, with the rate, the frame's angular velocity per metre in {F}.
PathPoint = tuple[Vec3, Vec3, Vec3, Vec3, float, float]
PathPointRate = tuple[Vec3, Vec3, Vec3, Vec3, float, float, Vec3, Vec3]
PathPointFlat = tuple[float, ...]  # PathPointRate's 20 floats in order, see eval_flat
_Cell = tuple[float, ...]  # 27 floats, see TabulatedPath._hermite_cells
_ZERO: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class PathSample:
    """The path at arc length s, all vectors in the target frame {T}.

    s: arc length (m, unwrapped as given); position: p_d(s) (m); R_F_T: columns f1, f2, f3;
    k1, k2: curvature components along f2, f3 (1/m); tau: frame twist about f1 (rad/m).
    """

    s: float
    position: NDArray[np.float64]
    R_F_T: NDArray[np.float64]
    k1: float
    k2: float
    tau: float

    @property
    def f1(self) -> NDArray[np.float64]:
        return self.R_F_T[:, 0]


def _floats3(v: NDArray[np.float64]) -> Tuple3:
    return (float(v[0]), float(v[1]), float(v[2]))


def _arc_length_table(
    curve: CurveFn, u0: float, u1: float, dense: int, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """(u, s(u), du): the cumulative arc length (m) on a dense grid of the parameter and the
    parameter step of the central differences. Raises ConfigError for a curve that is not
    finite, has zero length or is not regular."""
    u = np.linspace(u0, u1, dense + 1)
    du = (u1 - u0) * 1e-5
    c = curve(u)
    d1 = (curve(u + du) - curve(u - du)) / (2 * du)
    speed = np.linalg.norm(d1, axis=1)
    if not np.all(np.isfinite(c)) or not np.all(np.isfinite(speed)):
        raise ConfigError(f"{name}: the curve is not finite everywhere")
    seg = 0.5 * (speed[1:] + speed[:-1]) * np.diff(u)
    # Simpson-quality length from the trapezoid on a dense grid is ample (error ~1e-9 L).
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    L = float(cum[-1])
    if not L > 1e-6:
        raise ConfigError(f"{name}: the path has zero length")
    if np.min(speed) < 1e-9 * max(1.0, float(np.max(speed))):
        raise ConfigError(f"{name}: the curve is not regular (zero speed somewhere)")
    return u, cum, du


def _nodes(
    curve: CurveFn,
    u_nodes: NDArray[np.float64],
    du: float,
    closed: bool,
    L: float,
    name: str,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(P, T, kappa) at the nodes: positions, unit tangents and curvature vectors (1/m), the
    last node made the first of a closed path. Raises ConfigError when it does not close."""
    P = curve(u_nodes)
    D1 = (curve(u_nodes + du) - curve(u_nodes - du)) / (2 * du)
    D2 = (curve(u_nodes + du) - 2 * P + curve(u_nodes - du)) / (du * du)
    sp = np.linalg.norm(D1, axis=1)
    T = D1 / sp[:, None]
    kappa = (D2 - np.sum(D2 * T, axis=1)[:, None] * T) / (sp * sp)[:, None]
    if closed:
        gap = float(np.linalg.norm(P[-1] - P[0]))
        if gap > 1e-6 * max(1.0, L):
            raise ConfigError(f"{name}: closed path does not close (gap {gap:.3g} m)")
        P[-1], T[-1], kappa[-1] = P[0], T[0], kappa[0]
    return P, T, kappa


def _transported_f2(P: NDArray[np.float64], T: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """f2 at the nodes by double reflection (the rotation-minimising frame), from f3 = down
    projected orthogonal to f1 and f2 = f3 x f1 at the first node."""
    down = np.array([0.0, 0.0, 1.0])
    f3 = down - np.dot(down, T[0]) * T[0]
    if np.linalg.norm(f3) < 1e-6:
        f3 = np.array([1.0, 0.0, 0.0]) - T[0, 0] * T[0]
    f3 /= np.linalg.norm(f3)
    # the reflections' planes depend only on the nodes (vectorised); the carried f2 is the one
    # sequential part, on floats (a numpy call per node costs ~20x the arithmetic)
    V1 = P[1:] - P[:-1]
    c1 = np.einsum("ij,ij->i", V1, V1)
    k1 = np.divide(2.0, c1, out=np.zeros_like(c1), where=c1 >= 1e-30)
    V2 = T[1:] - (T[:-1] - (k1 * np.einsum("ij,ij->i", V1, T[:-1]))[:, None] * V1)
    c2 = np.einsum("ij,ij->i", V2, V2)
    k2 = np.divide(2.0, c2, out=np.zeros_like(c2), where=c2 > 1e-30)
    x, y, z = (float(v) for v in np.cross(f3, T[0]))
    out = [(x, y, z)]
    for (a0, a1, a2), ka, (b0, b1, b2), kb, (t0, t1, t2), deg in zip(
        V1.tolist(),
        k1.tolist(),
        V2.tolist(),
        k2.tolist(),
        T[1:].tolist(),
        (c1 < 1e-30).tolist(),
        strict=True,
    ):
        if deg:  # coincident nodes: f2 carried unchanged
            out.append((x, y, z))
            continue
        d = ka * (a0 * x + a1 * y + a2 * z)
        x, y, z = x - d * a0, y - d * a1, z - d * a2
        d = kb * (b0 * x + b1 * y + b2 * z)
        x, y, z = x - d * b0, y - d * b1, z - d * b2
        d = x * t0 + y * t1 + z * t2
        x, y, z = x - d * t0, y - d * t1, z - d * t2
        r = math.sqrt(x * x + y * y + z * z)
        x, y, z = x / r, y / r, z / r
        out.append((x, y, z))
    return np.array(out, dtype=float)


def _closing_twist(
    F2: NDArray[np.float64], T: NDArray[np.float64], s_nodes: NDArray[np.floating[Any]], L: float
) -> tuple[NDArray[np.float64], float]:
    """(F2, tau) of a closed path: the transported frame's mismatch after one lap spread
    evenly along it as a constant twist tau (rad/m), so that the frame closes."""
    a, b = F2[0], F2[-1]
    theta = math.atan2(float(np.cross(a, b) @ T[0]), float(a @ b))
    tau = -theta / L
    ang = tau * s_nodes
    F3 = np.cross(T, F2)
    F2 = np.cos(ang)[:, None] * F2 + np.sin(ang)[:, None] * F3
    F2[-1] = F2[0]
    return F2, tau


def _closing_angles(T: NDArray[np.float64], F2: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per cell: the angle about f1_{i+1} between f2_i carried to node i+1 and f2_{i+1}.
    Interpolating it linearly makes the frame continuous at every node with one transport."""
    a, b, v = T[:-1], T[1:], F2[:-1]
    # f2_i carried by the minimal rotation taking f1_i onto f1_{i+1} (Rodrigues: c x v and
    # c x (c x v) scaled by 1/(1+d), exact for d > -1)
    c = np.cross(a, b)
    d = np.einsum("ij,ij->i", a, b)
    k = np.divide(1.0, 1.0 + d, out=np.zeros_like(d), where=d > -0.999999)
    u = np.cross(c, v)
    r = v + u + k[:, None] * np.cross(c, u)
    f2b = F2[1:]
    cos_ = np.einsum("ij,ij->i", r, f2b)
    sin_ = np.einsum("ij,ij->i", np.cross(r, f2b), b)
    out: NDArray[np.float64] = np.arctan2(sin_, cos_)
    return out


def _cell_point(cell: _Cell, s: float) -> PathPointFlat:
    """:meth:`TabulatedPath.eval_flat` at arc length s (m) inside the cell ``cell`` (see
    :meth:`TabulatedPath._hermite_cells`), on floats (it runs once per law evaluation)."""
    (si, p0, p1, p2, ta0, ta1, ta2, b0, b1, b2, c0, c1, c2, bb0, bb1, bb2, cc0, cc1, cc2,
     v0, v1, v2, twist, k1a, k1s, k2a, k2s) = cell  # fmt: skip
    x = s - si
    # Written out on scalars (this runs once per law evaluation): the cell's cubic by
    # Horner, its first derivative dp (= dp_d/ds) and its second, ddp.
    p0 = p0 + x * (ta0 + x * (b0 + x * c0))
    p1 = p1 + x * (ta1 + x * (b1 + x * c1))
    p2 = p2 + x * (ta2 + x * (b2 + x * c2))
    dp0 = ta0 + x * (bb0 + x * cc0)
    dp1 = ta1 + x * (bb1 + x * cc1)
    dp2 = ta2 + x * (bb2 + x * cc2)
    x2 = x + x
    ddp0, ddp1, ddp2 = bb0 + x2 * cc0, bb1 + x2 * cc1, bb2 + x2 * cc2
    g = 1.0 / math.sqrt(dp0 * dp0 + dp1 * dp1 + dp2 * dp2)
    e0, e1, e2 = dp0 * g, dp1 * g, dp2 * g  # f1
    # r: the node's f2 (v, orthogonal to t_i) carried by the minimal rotation t_i -> f1,
    # I + C + C^2 / (1 + d) with C = [c]x, c = t_i x f1, d = t_i . f1; for v orthogonal
    # to t_i it reduces to v - (v . f1) (t_i + f1) / (1 + d).
    cx = ta1 * e2 - ta2 * e1
    cy = ta2 * e0 - ta0 * e2
    cz = ta0 * e1 - ta1 * e0
    d = ta0 * e0 + ta1 * e1 + ta2 * e2
    if d > -0.999999:
        k = 1.0 / (1.0 + d)
        m = (v0 * e0 + v1 * e1 + v2 * e2) * k
        r0, r1, r2 = v0 - m * (ta0 + e0), v1 - m * (ta1 + e1), v2 - m * (ta2 + e2)
    else:  # f1 opposite t_i (not in a regular path's cell): v + c x v, re-normalised
        k = 0.0
        r0, r1, r2 = v0 + cy * v2 - cz * v1, v1 + cz * v0 - cx * v2, v2 + cx * v1 - cy * v0
        nr = 1.0 / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        r0, r1, r2 = r0 * nr, r1 * nr, r2 * nr
    q0 = e1 * r2 - e2 * r1  # f1 x r
    q1 = e2 * r0 - e0 * r2
    q2 = e0 * r1 - e1 * r0
    # Turned about f1 by this cell's share of the closing angle (exactly 0 on open and
    # planar paths, which skip the turn).
    if twist:
        ang = x * twist
        ca, sa = math.cos(ang), math.sin(ang)
        r0, r1, r2, q0, q1, q2 = (
            ca * r0 + sa * q0, ca * r1 + sa * q1, ca * r2 + sa * q2,
            ca * q0 - sa * r0, ca * q1 - sa * r1, ca * q2 - sa * r2,
        )  # fmt: skip
    # f2 = r, f3 = q. The frame's rate per metre: f1' = (I - f1 f1^T) p'' / |p'| gives the
    # curvatures f1'.f2 and f1'.f3; the minimal rotation from the fixed t_i turns r about
    # f1 at -(c . f1') / (1 + d) = -(c . p'') / ((1 + d) |p'|); the closing share adds
    # `twist`.
    kappa_1 = (ddp0 * r0 + ddp1 * r1 + ddp2 * r2) * g
    kappa_2 = (ddp0 * q0 + ddp1 * q1 + ddp2 * q2) * g
    tau = twist - k * (cx * ddp0 + cy * ddp1 + cz * ddp2) * g
    return (
        p0, p1, p2, e0, e1, e2, r0, r1, r2, q0, q1, q2, k1a + x * k1s, k2a + x * k2s,
        dp0, dp1, dp2, tau, -kappa_2, kappa_1,
    )  # fmt: skip


class TabulatedPath:
    """A regular curve re-parameterised by arc length, with a continuous transported frame."""

    def __init__(
        self,
        curve: CurveFn,
        u0: float,
        u1: float,
        closed: bool,
        name: str = "path",
        ds_target: float = 0.25,
        dense: int = 40000,
    ) -> None:
        self.name = name
        self.closed = closed
        u, cum, du = _arc_length_table(curve, u0, u1, dense, name)
        L = float(cum[-1])
        self.length = L
        n = int(min(200000, max(512, math.ceil(L / ds_target))))
        self.n = n
        self.ds = L / n
        s_nodes = np.arange(n + 1) * self.ds
        u_nodes = np.interp(s_nodes, cum, u)
        # One Newton pass on arc length tightens u(s) from the linear inverse.
        P, T, kappa = _nodes(curve, u_nodes, du, closed, L, name)
        F2 = _transported_f2(P, T, n)
        self.tau = 0.0
        if closed:
            F2, self.tau = _closing_twist(F2, T, s_nodes, L)
        F3 = np.cross(T, F2)
        self._P = P
        self._T = T
        self._F2 = F2
        self._K1 = np.sum(kappa * F2, axis=1)
        self._K2 = np.sum(kappa * F3, axis=1)
        self._cells = self._hermite_cells(_closing_angles(T, F2))
        # the end nodes on floats: beyond an open end the path continues straight
        self._ends: dict[int, tuple[Tuple3, Tuple3, Tuple3]] = {
            j: (_floats3(P[j]), _floats3(T[j]), _floats3(F2[j])) for j in (0, n)
        }

    def _hermite_cells(self, C: NDArray[np.float64]) -> list[_Cell]:
        """Per cell, what evaluation needs in one flat tuple of floats (unpacked at once): the
        cell's start s_i = i ds (m), the Hermite cubic in the arc length from there, p(x) = p_i
        + x (t_i + x (B + x C)) (x = s - s_i; t_i is the node's tangent), 2 B and 3 C (the
        derivatives' coefficients, formed once here rather than at every evaluation), the
        node's f2, the cell's closing angle per metre (``C``: :func:`_closing_angles`) and the
        curvatures k1, k2 at its start and their slopes (1/m^2)."""
        h, n = self.ds, self.n
        pa, pb, ta, tb = self._P[:-1], self._P[1:], self._T[:-1], self._T[1:]
        # From the power form in w = x / h: b / h^2 and c / h^3.
        B = (3.0 * (pb - pa) - h * (2.0 * ta + tb)) / (h * h)
        Cc = (2.0 * (pa - pb) + h * (ta + tb)) / (h * h * h)
        K1, K2 = self._K1, self._K2
        cols = np.column_stack([
            np.arange(n) * h, pa, ta, B, Cc, B + B, 3.0 * Cc, self._F2[:-1], C / h,
            K1[:-1], (K1[1:] - K1[:-1]) / h, K2[:-1], (K2[1:] - K2[:-1]) / h,
        ])  # fmt: skip
        return [tuple(row) for row in cols.tolist()]

    # ------------------------------------------------------------------ evaluation
    def eval(self, s: float) -> PathPoint:
        """(p_d, f1, f2, f3, k1, k2) at arc length s (m), vectors in {T}; k1, k2 (1/m) are the
        nodes' curvatures interpolated linearly."""
        return self.eval_with_rate(s)[:6]

    def eval_with_rate(self, s: float) -> PathPointRate:
        """:meth:`eval` and the rates: (p_d, f1, f2, f3, k1, k2, dp_ds, rate_F).

        dp_ds = dp_d/ds, f1 times the interpolant's speed (1 to ~1e-8: the cubic is arc-length
        parameterised only approximately); rate_F = (tau, -kappa_2, kappa_1) (rad/m) is the
        angular velocity of the interpolated frame {F} per unit s, in {F}: omega_FT^F =
        sdot rate_F. Both are the exact derivatives of what :meth:`eval` returns (the
        interpolant's own curvature and twist), so they agree with differencing eval.
        """
        (p0, p1, p2, e0, e1, e2, r0, r1, r2, q0, q1, q2, k1, k2,
         dp0, dp1, dp2, tau, m_kappa_2, kappa_1) = self.eval_flat(s)  # fmt: skip
        return (
            (p0, p1, p2), (e0, e1, e2), (r0, r1, r2), (q0, q1, q2), k1, k2,
            (dp0, dp1, dp2), (tau, m_kappa_2, kappa_1),
        )  # fmt: skip

    def eval_flat(self, s: float) -> PathPointFlat:
        """:meth:`eval_with_rate` as one flat tuple of 20 floats: p_d, f1, f2, f3 (3 each), k1,
        k2, dp_ds and rate_F (3 each). The law evaluates the path once per call and unpacks
        it at once: one tuple instead of seven (each costs more than a product)."""
        L = self.length
        if self.closed:
            s = s % L
        elif s <= 0.0 or s >= L:
            # Beyond an open end the path continues straight along the end tangent.
            j = 0 if s <= 0.0 else self.n
            p, t, f2 = self._ends[j]
            ds = s if j == 0 else s - L
            return (*add_scaled(p, ds, t), *t, *f2, *cross(t, f2), 0.0, 0.0, *t, *_ZERO)
        i = int(s / self.ds)
        if i >= self.n:
            i = self.n - 1
        return _cell_point(self._cells[i], s)

    def sample(self, s: float) -> PathSample:
        """The path at arc length s (m) as a :class:`PathSample` (numpy, for callers and tests)."""
        p, f1, f2, f3, k1, k2 = self.eval(float(s))
        tau = self.tau if (self.closed or 0.0 < s < self.length) else 0.0
        return PathSample(float(s), np.array(p), np.column_stack([f1, f2, f3]), k1, k2, tau)

    # ------------------------------------------------------------------ closest point
    def closest(
        self, q_T: NDArray[np.float64], s_guess: float | None = None, window: float | None = None
    ) -> float:
        """Arc length of the point of the path closest to q_T (m, in {T}).

        Global search over all nodes, or over ``s_guess +- window`` when both are given;
        then Newton steps on (q - p(s)) . f1 = 0. Returns s in [0, L) for closed paths.
        """
        q = np.asarray(q_T, dtype=float)
        ql = [float(v) for v in q]
        P = self._P[:-1] if self.closed else self._P
        d2 = np.sum((P - q) ** 2, axis=1)
        if s_guess is not None and window is not None:
            idx = np.arange(len(P))
            sn = idx * self.ds
            if self.closed:
                ds = (sn - s_guess + 0.5 * self.length) % self.length - 0.5 * self.length
            else:
                ds = sn - s_guess
            d2 = np.where(np.abs(ds) <= window, d2, np.inf)
        s = float(np.argmin(d2)) * self.ds
        for _ in range(4):
            p, f1, *_ = self.eval(s)
            step = sum((ql[k] - p[k]) * f1[k] for k in range(3))
            step = max(-self.ds, min(self.ds, step))
            s += step
            if abs(step) < 1e-9:
                break
        if self.closed:
            s %= self.length
        else:
            s = min(max(s, 0.0), self.length)
        return float(s)

    def positions(self) -> NDArray[np.float64]:
        """The node positions (n+1, 3) in {T}, for plots."""
        return self._P.copy()
