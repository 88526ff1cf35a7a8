"""Function-level SO(3) core: hat, vee, exp, log, re-orthonormalisation, elementary rotations.

Conventions: a rotation matrix ``R_A^B`` maps coordinates in frame A to frame B; its columns
are A's axes expressed in B. ``hat(a) @ b == cross(a, b)``. Angles in radians.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Vec3 = NDArray[np.float64]
Mat3 = NDArray[np.float64]


def hat(v: ArrayLike) -> Mat3:
    """Skew-symmetric matrix of a 3-vector: ``hat(a) @ b = a x b``."""
    x, y, z = np.asarray(v, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def vee(M: ArrayLike) -> Vec3:
    """Inverse of :func:`hat`; uses the skew part, so it is safe on slightly non-skew input."""
    A = np.asarray(M, dtype=float)
    return 0.5 * np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])


def exp(w: ArrayLike) -> Mat3:
    """Rodrigues' formula: the rotation ``expm(hat(w))`` for a rotation vector w (rad)."""
    w = np.asarray(w, dtype=float)
    th = float(np.linalg.norm(w))
    K = hat(w)
    if th < 1e-8:
        # Second-order series keeps the result orthonormal to ~1e-24 for tiny angles.
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + (math.sin(th) / th) * K + ((1.0 - math.cos(th)) / th**2) * K @ K


def log(R: ArrayLike) -> Vec3:
    """Rotation vector w (rad, |w| <= pi) with ``exp(w) == R``; robust near 0 and near pi."""
    R = np.asarray(R, dtype=float)
    c = max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0)))
    th = math.acos(c)
    if th < 1e-6:
        return vee(R)  # sin(th)/th -> 1
    if math.pi - th < 1e-4:
        # Near pi the skew part vanishes: recover the axis from the symmetric part.
        B = 0.5 * (R + np.eye(3))
        i = int(np.argmax(np.diag(B)))
        axis = B[:, i] / math.sqrt(max(B[i, i], 1e-300))
        # Fix the sign with whatever skew part remains.
        if np.dot(axis, vee(R)) < 0:
            axis = -axis
        return th * axis / np.linalg.norm(axis)
    return (th / (2.0 * math.sin(th))) * np.array(
        [R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]
    )


def orthonormalize(R: ArrayLike) -> Mat3:
    """Nearest rotation matrix (polar decomposition via SVD); removes integration drift."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float))
    Q: NDArray[np.float64] = U @ Vt
    if np.linalg.det(Q) < 0:
        U[:, -1] = -U[:, -1]
        Q = U @ Vt
    return Q


def rot_x(a: float) -> Mat3:
    """Rotation by angle a (rad) about the x axis (columns: rotated axes in the original frame)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> Mat3:
    """Rotation by angle a (rad) about the y axis."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> Mat3:
    """Rotation by angle a (rad) about the z axis."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def is_rotation(R: ArrayLike, tol: float = 1e-9) -> bool:
    """True when R is orthonormal with determinant +1 within tol."""
    R = np.asarray(R, dtype=float)
    return bool(
        R.shape == (3, 3)
        and np.all(np.isfinite(R))
        and np.allclose(R.T @ R, np.eye(3), atol=tol)
        and abs(np.linalg.det(R) - 1.0) < tol
    )
