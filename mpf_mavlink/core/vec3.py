"""Small helpers on 3-vectors and 3x3 matrices held as plain tuples of floats.

The guidance law and the path evaluation run once per ATTITUDE sample (four times per step
inside the kinematic simulator's RK4); on 3-vectors a numpy call costs ~1 us of overhead where
these cost ~0.1 us. Pure functions, no I/O.

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


def scale(k: float, a: Vec3) -> Vec3:
    """k a"""
    return (k * a[0], k * a[1], k * a[2])


def add_scaled(a: Vec3, k: float, b: Vec3) -> Vec3:
    """a + k b"""
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
