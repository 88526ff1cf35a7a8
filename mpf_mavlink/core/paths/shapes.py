"""Path shapes in the target frame {T} (x forward, y right, z down; metres)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mpf_mavlink.core.paths.base import TabulatedPath
from mpf_mavlink.errors import ConfigError


def line(start: ArrayLike, end: ArrayLike) -> TabulatedPath:
    """Straight segment from start to end (m); continued straight beyond both ends."""
    a = np.asarray(start, dtype=float)
    b = np.asarray(end, dtype=float)
    if np.linalg.norm(b - a) < 1e-6:
        raise ConfigError("line: start and end coincide (zero length)")

    def c(u: NDArray[np.float64]) -> NDArray[np.float64]:
        pts: NDArray[np.float64] = a[None, :] + u[:, None] * (b - a)[None, :]
        return pts

    return TabulatedPath(c, 0.0, 1.0, closed=False, name="line", dense=2000)


def circle(center: ArrayLike, radius: float, clockwise: bool = True) -> TabulatedPath:
    """Horizontal circle of radius (m) about center; clockwise as seen from above (NED)."""
    if not radius > 0:
        raise ConfigError("circle: radius must be > 0")
    c0 = np.asarray(center, dtype=float)
    sgn = 1.0 if clockwise else -1.0

    def c(u: NDArray[np.float64]) -> NDArray[np.float64]:
        return c0[None, :] + radius * np.column_stack(
            [np.cos(u), sgn * np.sin(u), np.zeros_like(u)]
        )

    return TabulatedPath(c, 0.0, 2 * math.pi, closed=True, name="circle")


def helix(
    center: ArrayLike, radius: float, climb_per_turn: float, turns: float, clockwise: bool = True
) -> TabulatedPath:
    """Helix about a vertical axis through center: radius (m), climb per turn (m, up > 0)."""
    if not radius > 0:
        raise ConfigError("helix: radius must be > 0")
    if not turns > 0:
        raise ConfigError("helix: turns must be > 0")
    c0 = np.asarray(center, dtype=float)
    sgn = 1.0 if clockwise else -1.0

    def c(u: NDArray[np.float64]) -> NDArray[np.float64]:
        return c0[None, :] + np.column_stack(
            [radius * np.cos(u), sgn * radius * np.sin(u), -climb_per_turn * u / (2 * math.pi)]
        )

    return TabulatedPath(c, 0.0, 2 * math.pi * turns, closed=False, name="helix")


def lemniscate(size: float, center: ArrayLike = (0.0, 0.0, 0.0)) -> TabulatedPath:
    """The paper's lemniscate: [a sin u cos u, a cos u] / (sin^2 u + 1), u in [0, 2 pi).

    ``size`` is a (m): the half-length along y. s = 0 is the tip at [0, a, 0] (u = 0), as in
    the paper's parameterisation u = 0.01 s', re-parameterised by arc length.
    """
    if not size > 0:
        raise ConfigError("lemniscate: size must be > 0")
    c0 = np.asarray(center, dtype=float)

    def c(u: NDArray[np.float64]) -> NDArray[np.float64]:
        su, cu = np.sin(u), np.cos(u)
        den = su * su + 1.0
        return c0[None, :] + np.column_stack(
            [size * su * cu / den, size * cu / den, np.zeros_like(u)]
        )

    return TabulatedPath(c, 0.0, 2 * math.pi, closed=True, name="lemniscate")


def spline(waypoints: ArrayLike, closed: bool) -> TabulatedPath:
    """C2 cubic spline through 3D waypoints (m), chord-length parameterised; periodic if closed."""
    from scipy.interpolate import CubicSpline

    W = np.asarray(waypoints, dtype=float)
    if W.ndim != 2 or W.shape[1] != 3 or len(W) < (3 if closed else 2):
        raise ConfigError(
            f"spline: needs at least {3 if closed else 2} waypoints of 3 coordinates each"
        )
    if closed:
        W = np.vstack([W, W[:1]])
    chord = np.linalg.norm(np.diff(W, axis=0), axis=1)
    if np.any(chord < 1e-6):
        raise ConfigError("spline: two consecutive waypoints coincide")
    u = np.concatenate([[0.0], np.cumsum(chord)])
    cs = CubicSpline(u, W, bc_type="periodic" if closed else "not-a-knot")
    if not closed and len(W) == 2:
        cs = CubicSpline(u, W, bc_type="natural")
    u_end = float(u[-1])

    def c(x: NDArray[np.float64]) -> NDArray[np.float64]:
        if closed:
            x = np.mod(x, u_end)
        return cs(x)

    return TabulatedPath(c, 0.0, u_end, closed=closed, name="spline")
