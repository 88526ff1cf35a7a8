"""From the law's command (the angular velocity of w1) to what a fixed-wing autopilot accepts.

Pure functions: no I/O. Frames: NED inertial, FRD body. The bank needed to turn the velocity
vector is set by the specific force the wing must produce: ``f = a - g`` (gravity g = [0, 0, g]
in NED), of which the part normal to w1 is lift; the bank is the angle of the lift about w1.
"""

from __future__ import annotations

import math

from .frames import GRAVITY_M_S2

Vec = tuple[float, float, float]


def bank_and_load_factor(w1: Vec, accel: Vec, g: float = GRAVITY_M_S2) -> tuple[float, float]:
    """Bank angle (rad, > 0 right wing down) and load factor n (g) that produce ``accel``.

    w1: unit air-relative velocity direction (NED); accel: the acceleration of the vehicle
    normal to w1 that the turn needs (NED, m/s^2), e.g. ``v_w * (omega x w1)``.
    Level flight (accel = 0) gives (0, 1); a level right turn of centripetal acceleration a
    gives (atan(a/g), sqrt(1 + (a/g)^2)).
    """
    fx, fy, fz = accel[0], accel[1], accel[2] - g
    d = fx * w1[0] + fy * w1[1] + fz * w1[2]
    fx, fy, fz = fx - d * w1[0], fy - d * w1[1], fz - d * w1[2]
    # Local "down" normal to w1, and "right" = down x w1.
    k = w1[2]
    nx, ny, nz = -k * w1[0], -k * w1[1], 1.0 - k * w1[2]
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn < 1e-9:  # vertical flight: bank is undefined; report it about north
        nx, ny, nz = 1.0, 0.0, 0.0
        nn = 1.0
    nx, ny, nz = nx / nn, ny / nn, nz / nn
    rx = ny * w1[2] - nz * w1[1]
    ry = nz * w1[0] - nx * w1[2]
    rz = nx * w1[1] - ny * w1[0]
    bank = math.atan2(fx * rx + fy * ry + fz * rz, -(fx * nx + fy * ny + fz * nz))
    load = math.sqrt(fx * fx + fy * fy + fz * fz) / g
    return bank, load
