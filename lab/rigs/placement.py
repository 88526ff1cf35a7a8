"""Where the rig puts a config's path: every shape, near the aircraft or at a given offset.

Pure geometry (no I/O): given where the aircraft will be when the bridge engages (NED, m) and
its track there (rad from north), the target's position that puts the path

- with no offset, through the aircraft, tangent to its flight: at the path node whose
  horizontal tangent is closest to the aircraft's track (a clockwise circle: the aircraft on
  it, the centre to its right, as :func:`lab.rigs.common.place_mission` places it);
- with ``--start-offset X,Y,D`` (m: X along the aircraft's track, Y to its right, D down), with
  the aircraft that far from the path: a horizontal offset puts it beyond the path's support
  point in that direction (the node farthest out that way, so every other point of the path is
  at least |(X, Y)| away and, X > 0, the aircraft flies away from the path); a vertical one
  only shifts it below (D > 0) or above the path.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray


def parse_offset(text: str) -> tuple[float, float, float]:
    """``X,Y,D`` (m) -> floats; ValueError naming what is wrong."""
    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(f"{text!r}: expected X,Y,D in metres (e.g. 300,0,0)")
    try:
        out = tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{text!r}: expected three numbers X,Y,D in metres") from None
    if not all(math.isfinite(x) for x in out):
        raise ValueError(f"{text!r}: expected finite numbers")
    return out[0], out[1], out[2]


def place_path(
    nodes_T: NDArray[np.float64],
    R_T_I: NDArray[np.float64],
    aircraft_ned: tuple[float, float, float],
    track_rad: float,
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[list[float], list[float]]:
    """(target position NED m, the path point the aircraft is placed from NED m).

    nodes_T: the path's nodes in the target's frame {T} (n, 3); R_T_I: {T} in NED at the
    engagement (its columns are {T}'s axes in NED); aircraft_ned, track_rad: where the aircraft
    will be and its track then; offset: (X along track, Y right, D down) of the aircraft from
    the path (m)."""
    P = np.asarray(nodes_T, dtype=float) @ np.asarray(R_T_I, dtype=float).T  # nodes in NED
    h = np.array([math.cos(track_rad), math.sin(track_rad)])
    r = np.array([-h[1], h[0]])  # right of the track (NED: east of north)
    ox, oy, od = offset
    o_h = ox * h + oy * r
    if math.hypot(*o_h) > 1e-9:
        k = int(np.argmax(P[:, :2] @ (o_h / math.hypot(*o_h))))  # the support point that way
    else:
        T = np.gradient(P, axis=0)  # along the nodes (one-sided at an open path's ends)
        T = T[:, :2] / np.maximum(np.linalg.norm(T[:, :2], axis=1, keepdims=True), 1e-9)
        k = int(np.argmax(T @ h))  # the tangent closest to the flight
    anchor = P[k]
    a = np.asarray(aircraft_ned, dtype=float)
    point = a - np.array([o_h[0], o_h[1], od])
    return (point - anchor).tolist(), point.tolist()
