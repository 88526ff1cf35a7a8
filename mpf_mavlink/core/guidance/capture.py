"""Capture guards: what the MPF law may command while the aircraft is far from the path.

The law's certificate (Theorem 1) holds for |pt(0)| <= checks.c1_m and says nothing about the
transient's bank, flight path or where the virtual point goes. From far away (measured on real
ArduPlane, a closed 3D spline over a moving target, start 207 m off) the virtual point ran
backwards at 82 m/s, the pitch command reached -20 deg and the aircraft dove 30 m below the
path's lowest point while banking 4 deg beyond the autopilot's limit. Three guards act on the
law's output (never on its inputs or its body), and only beyond ``distance_m`` of the virtual
point, blended in over ``blend_m`` so that nothing jumps at the threshold:

(a) progression: sdot within +-v_w (m/s) of the on-path rate sdot_0 = v_w (wd1 . f1) - u . f1,
    the rate at which the point moves when the aircraft flies the steady-state direction wd1;
    the law's sdot (22) differs from it by K_p pt . f1 + v_w (w1 - wd1) . f1, which grows with
    the distance and is what raced;
(b) turn: |w3| within the turn that the autopilot's bank limit less ``bank_margin_rad`` gives,
    bank = atan(v w3 / (g k cos gamma)) with k the vehicle's turn gain (the adapter's bank
    set-point is atan(tan(bank) / k));
(c) flight path: the flight-path angle the adapter will ask for, gamma + gamma_dot tau, within
    the pitch band less ``pitch_margin_rad``, and above a floor-dependent lower bound: the sink
    allowed is the height above the floor over ``floor_tau_s`` (so at the floor, or below it,
    the aircraft never descends). The floor is the moving path's lowest point less
    ``floor_margin_m``, never below ``metrics.altitude_floor_m`` above home. Symmetrically it
    does not climb above the path's highest point plus the margin (measured on real ArduPlane,
    circle, 300 m off: the aircraft pitched up in the reversal turn, the adapter held that
    flight path while the law's vertical feedback is weak far off, it climbed 54 m above the
    path and then dove at the pitch limit to come back).

Inside ``distance_m`` the command is the law's, bit for bit. Pure: no I/O, no clock. Frames:
NED, the wind frame's columns w1, w2, w3 in NED; SI units, radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.core.guidance.law import MpfCommand, MpfDiagnostics, VehicleState
from mpf_mavlink.core.target import TargetState

Vec = tuple[float, float, float]


@dataclass(frozen=True)
class CaptureParams:
    """The guards' limits (SI, radians).

    distance_m: |pt| (m) beyond which the guards start to act (guidance.capture_distance_m);
    blend_m: they act fully from distance_m + blend_m (a C1 ramp between);
    bank_limit_rad: the bank the autopilot flies at most (the smaller of vehicle.max_bank_rad
    and vehicle.autopilot_bank_limit_rad); bank_margin_rad: kept below it;
    turn_gain: turn per bank flown, as a fraction of g tan(phi) / V (vehicle.turn_gain);
    pitch_min_rad, pitch_max_rad: the flight-path band (the adapter's pitch band less its trim);
    pitch_margin_rad: kept inside it; tau_s: the lead of the adapter's pitch set-point
    (gamma + gamma_dot tau, adapter.tau_pitch_s);
    floor_margin_m: below the path's lowest point; altitude_floor_m: above home (up, m);
    floor_tau_s: the sink allowed is the height above the floor over this (m/s per m).
    """

    distance_m: float = 150.0
    blend_m: float = 30.0
    bank_limit_rad: float = 0.61
    bank_margin_rad: float = 0.0873
    turn_gain: float = 1.0
    pitch_min_rad: float = -0.38
    pitch_max_rad: float = 0.32
    pitch_margin_rad: float = 0.08
    tau_s: float = 1.0
    floor_margin_m: float = 5.0
    altitude_floor_m: float = 10.0
    floor_tau_s: float = 4.0


def capture_weight(pt_norm: float, distance_m: float, blend_m: float) -> float:
    """How much the guards act (0..1) at |pt| = pt_norm (m): 0 within distance_m, 1 beyond
    distance_m + blend_m, a smoothstep between (continuous with its first derivative)."""
    if pt_norm <= distance_m:
        return 0.0
    if blend_m <= 0.0 or pt_norm >= distance_m + blend_m:
        return 1.0
    x = (pt_norm - distance_m) / blend_m
    return x * x * (3.0 - 2.0 * x)


def on_path_rate(sdot: float, K_p: float, pt_along: float, v_w: float, w1_f1: float,
                 wd1_f1: float) -> float:  # fmt: skip
    """sdot_0 (m/s): the law's sdot (22) less its distance-driven part K_p pt . f1 and with the
    steady-state direction wd1 in place of w1 (pt_along = pt . f1 in m, w1_f1, wd1_f1 the
    cosines of w1 and wd1 on the tangent f1)."""
    return sdot - K_p * pt_along + v_w * (wd1_f1 - w1_f1)


def guard_progression(sdot: float, sdot_0: float, v_w: float) -> float:
    """(a) sdot (m/s) clipped to [sdot_0 - v_w, sdot_0 + v_w]."""
    return min(max(sdot, sdot_0 - v_w), sdot_0 + v_w)


def turn_rate_limit(v_w: float, w3_down: float, p: CaptureParams, g: float = GRAVITY_M_S2) -> float:
    """(b) the largest |w3| (rad/s) whose bank set-point stays within the limit less the margin:
    w3 = g k tan(bank) cos(gamma) / v_w, cos(gamma) ~ w3's down component (w3_down)."""
    bank = max(p.bank_limit_rad - p.bank_margin_rad, 0.0)
    return g * p.turn_gain * math.tan(bank) * max(w3_down, 0.1) / max(v_w, 1.0)


def floor_down(target: TargetState, path_nodes_T: NDArray[np.float64], p: CaptureParams) -> float:
    """The floor (NED down, m): the moving path's lowest point (its nodes in {T} placed by the
    target now) less floor_margin_m, never lower than altitude_floor_m above home."""
    return floor_and_ceiling_down(target, path_nodes_T, p)[0]


def floor_and_ceiling_down(
    target: TargetState, path_nodes_T: NDArray[np.float64], p: CaptureParams
) -> tuple[float, float]:
    """(floor, ceiling) NED down (m): :func:`floor_down`, and the moving path's highest point
    plus floor_margin_m (above which the capture does not climb)."""
    r3 = np.asarray(target.R_T_I)[2]  # NED down of each {T} axis
    downs = path_nodes_T @ r3
    td = float(target.position[2])
    lowest, highest = td + float(downs.max()), td + float(downs.min())
    return min(lowest + p.floor_margin_m, -p.altitude_floor_m), highest - p.floor_margin_m


def flight_path_band(gamma: float, v_w: float, height_above_floor_m: float,
                     p: CaptureParams, depth_below_ceiling_m: float = math.inf,
                     ) -> tuple[float, float]:  # fmt: skip
    """(c) [lo, hi] (rad/s) for the flight-path rate gamma_dot at flight-path angle gamma (rad):
    gamma + gamma_dot tau within the pitch band less its margin, and above
    -asin(h / (floor_tau v_w)) (h the height above the floor, m): no sink at or below the floor,
    a climb back (at most the band's top) below it. Symmetrically no climb above the ceiling
    (depth_below_ceiling_m <= 0; the path's highest point plus the same margin), but no forced
    descent either: a start above the path comes down at the law's own rate."""
    top = p.pitch_max_rad - p.pitch_margin_rad
    bottom = p.pitch_min_rad + p.pitch_margin_rad
    x = height_above_floor_m / (p.floor_tau_s * max(v_w, 1.0))
    g_floor = -math.asin(min(x, 1.0)) if x >= 0.0 else math.asin(min(-x, math.sin(top)))
    bottom = min(max(bottom, g_floor), top)
    y = depth_below_ceiling_m / (p.floor_tau_s * max(v_w, 1.0))
    top = max(min(top, math.asin(min(max(y, 0.0), 1.0))), bottom)
    tau = max(p.tau_s, 1e-3)
    return (bottom - gamma) / tau, (top - gamma) / tau


def guard_limited(
    cmd: MpfCommand,
    diag: MpfDiagnostics,
    vehicle: VehicleState,
    floor_down_m: float,
    K_p: float,
    p: CaptureParams,
    ceiling_down_m: float = -math.inf,
) -> tuple[MpfCommand, float, tuple[str, ...]]:
    """The law's command with the guards applied, blended by :func:`capture_weight` of |pt|
    (0: the law's command itself, returned as it is), that weight, and which guards changed the
    law's command: a subset of ("sdot", "turn", "path") in that order, (a), (b), (c); empty when
    the law's command was inside every bound.

    floor_down_m, ceiling_down_m: :func:`floor_and_ceiling_down` (NED down, m); K_p (1/s) the
    gain sdot (22) used."""
    beta = capture_weight(diag.pt_norm, p.distance_m, p.blend_m)
    if beta == 0.0:
        return cmd, 0.0, ()
    (w1n, w2n, w3n), (w1e, w2e, w3e), (w1d, w2d, w3d) = np.asarray(vehicle.R_W_I).tolist()
    v_w = float(vehicle.airspeed)
    f1, wd1 = diag.f1, diag.wd1
    w1_f1 = w1n * f1[0] + w1e * f1[1] + w1d * f1[2]
    wd1_f1 = wd1[0] * f1[0] + wd1[1] * f1[1] + wd1[2] * f1[2]
    sdot_0 = on_path_rate(cmd.sdot, K_p, diag.pt_F[0], v_w, w1_f1, wd1_f1)
    sdot = guard_progression(cmd.sdot, sdot_0, v_w)
    lim3 = turn_rate_limit(v_w, w3d, p)
    w3 = min(max(cmd.w3, -lim3), lim3)
    # gamma = asin(-w1d); w1_dot = w3 w2_axis - w2 w3_axis, so gamma_dot cos(gamma) =
    # w2 w3d - w3 w2d: the w2 that gives a bounded gamma_dot with this w3.
    gamma = math.asin(min(max(-w1d, -1.0), 1.0))
    cg = max(math.cos(gamma), 1e-3)
    h = floor_down_m - float(vehicle.position[2])
    lo, hi = flight_path_band(gamma, v_w, h, p, float(vehicle.position[2]) - ceiling_down_m)
    w3d_safe = w3d if abs(w3d) > 0.1 else math.copysign(0.1, w3d or 1.0)
    gamma_dot_law = (cmd.w2 * w3d - w3 * w2d) / cg
    gamma_dot = min(max(gamma_dot_law, lo), hi)
    w2 = (gamma_dot * cg + w3 * w2d) / w3d_safe
    limited = tuple(
        name
        for name, hit in (
            ("sdot", sdot != cmd.sdot),
            ("turn", w3 != cmd.w3),
            ("path", gamma_dot != gamma_dot_law),
        )
        if hit
    )
    # blended: a convex mix of the law's and the guarded values (each bound is an interval)
    w2 = cmd.w2 + beta * (w2 - cmd.w2)
    w3 = cmd.w3 + beta * (w3 - cmd.w3)
    sdot = cmd.sdot + beta * (sdot - cmd.sdot)
    om: Vec = (w2 * w2n + w3 * w3n, w2 * w2e + w3 * w3e, w2 * w2d + w3 * w3d)
    return tuple.__new__(MpfCommand, (cmd.t, w2, w3, sdot, om)), beta, limited


@dataclass(frozen=True)
class GuardAction:
    """What the guards did at one step: their weight (0..1), which of them changed the law's
    command (:func:`guard_limited`) and the distance |pt| (m) they acted at."""

    weight: float
    limited: tuple[str, ...]
    pt_m: float


class CaptureGuard:
    """:func:`guard_limited` for one path: its nodes in {T} (for the floor) and the limits."""

    def __init__(self, path_nodes_T: NDArray[np.float64], params: CaptureParams) -> None:
        self.nodes = np.asarray(path_nodes_T, dtype=float)
        self.params = params
        #: the last step's action; None when the guards did not act (within distance_m)
        self.last: GuardAction | None = None

    def apply(
        self,
        cmd: MpfCommand,
        diag: MpfDiagnostics,
        vehicle: VehicleState,
        target: TargetState,
        K_p: float,
    ) -> tuple[MpfCommand, MpfDiagnostics]:
        """The guarded command and the diagnostics, their mode marked "+capture" when the
        guards acted (weight > 0); :attr:`last` says which of them changed the command."""
        if capture_weight(diag.pt_norm, self.params.distance_m, self.params.blend_m) == 0.0:
            self.last = None
            return cmd, diag
        fd, cd = floor_and_ceiling_down(target, self.nodes, self.params)
        out, beta, limited = guard_limited(cmd, diag, vehicle, fd, K_p, self.params, cd)
        self.last = GuardAction(beta, limited, diag.pt_norm)
        return out, diag._replace(mode=diag.mode + "+capture")
