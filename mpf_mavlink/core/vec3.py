"""Small helpers on 3-vectors and 3x3 matrices held as plain tuples of floats.

The guidance law runs once per ATTITUDE sample and evaluates its frames three times (centre
and the two finite-difference states); on 3-vectors a numpy call costs ~1 us of overhead
where these cost ~0.1 us. Pure functions, no I/O.

Matrices are tuples of COLUMNS: ``R = (c1, c2, c3)``. A rotation ``R_A^B`` is then literally
the tuple of frame A's axes written in frame B, as the paper writes ``R_F^T = [f1 f2 f3]``.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]  # columns


def dot(a: Vec3, b: Vec3) -> float:
    """a . b"""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: Vec3, b: Vec3) -> Vec3:
    """a x b"""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def add(a: Vec3, b: Vec3) -> Vec3:
    """a + b"""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a: Vec3, b: Vec3) -> Vec3:
    """a - b"""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def add_scaled(a: Vec3, k: float, b: Vec3) -> Vec3:
    """a + k b (one step of a state along its rate b)."""
    return (a[0] + k * b[0], a[1] + k * b[1], a[2] + k * b[2])


def norm(a: Vec3) -> float:
    """|a|"""
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def mat_vec(M: Mat3, v: Vec3) -> Vec3:
    """M v = v1 c1 + v2 c2 + v3 c3 (M by columns): a vector from frame A into B for M = R_A^B."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = M
    v0, v1, v2 = v
    return (a0 * v0 + b0 * v1 + c0 * v2, a1 * v0 + b1 * v1 + c1 * v2, a2 * v0 + b2 * v1 + c2 * v2)


def mat_T_vec(M: Mat3, v: Vec3) -> Vec3:
    """M^T v = (c1 . v, c2 . v, c3 . v): a vector from frame B into A for M = R_A^B."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = M
    v0, v1, v2 = v
    return (a0 * v0 + a1 * v1 + a2 * v2, b0 * v0 + b1 * v1 + b2 * v2, c0 * v0 + c1 * v1 + c2 * v2)


def mat_mul(A: Mat3, B: Mat3) -> Mat3:
    """A B, whose columns are A b1, A b2, A b3: R_B^C R_A^B = R_A^C."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = A
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = B
    return (
        (a0 * x0 + b0 * x1 + c0 * x2, a1 * x0 + b1 * x1 + c1 * x2, a2 * x0 + b2 * x1 + c2 * x2),
        (a0 * y0 + b0 * y1 + c0 * y2, a1 * y0 + b1 * y1 + c1 * y2, a2 * y0 + b2 * y1 + c2 * y2),
        (a0 * z0 + b0 * z1 + c0 * z2, a1 * z0 + b1 * z1 + c1 * z2, a2 * z0 + b2 * z1 + c2 * z2),
    )


def rotation_rate(R_plus: Mat3, R_minus: Mat3, R: Mat3, two_h: float) -> Vec3:
    """vee(dR/dt R^T) for a rotation R(t) given at t - h, t, t + h (dR/dt by central
    differences): the angular velocity of R's frame, in the frame R maps into (rad/s).

    dR R^T = sum_k d(r_k) r_k^T over the columns r_k; it is skew up to the differencing
    error, and we take the vee of its skew part, vee((M - M^T) / 2).
    """
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = R_plus
    (A0, A1, A2), (B0, B1, B2), (C0, C1, C2) = R_minus
    (p0, p1, p2), (q0, q1, q2), (r0, r1, r2) = R
    a0, a1, a2 = a0 - A0, a1 - A1, a2 - A2  # 2 h dr_1/dt
    b0, b1, b2 = b0 - B0, b1 - B1, b2 - B2
    c0, c1, c2 = c0 - C0, c1 - C1, c2 - C2
    m21 = a2 * p1 + b2 * q1 + c2 * r1
    m12 = a1 * p2 + b1 * q2 + c1 * r2
    m02 = a0 * p2 + b0 * q2 + c0 * r2
    m20 = a2 * p0 + b2 * q0 + c2 * r0
    m10 = a1 * p0 + b1 * q0 + c1 * r0
    m01 = a0 * p1 + b0 * q1 + c0 * r1
    k = 0.5 / two_h
    return (k * (m21 - m12), k * (m02 - m20), k * (m10 - m01))
