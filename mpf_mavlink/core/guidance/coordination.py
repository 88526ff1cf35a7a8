"""Coordination of N aircraft on one moving path (cooperative moving path following). Pure.

Each aircraft i follows the same path fixed to the target (the MPF law, unchanged) and has a
slot ``sigma_i`` (a fraction of a closed path's length L). Its coordination state is the
along-path position less its slot, ``xi_i = s_i - sigma_i L`` (m, wrapped to one lap). The fleet
is in formation when every ``xi_i`` agrees; the along-path spacing error of a pair is
``wrap(xi_j - xi_i)`` (m).

The law (Ghabcheloo, Aguiar, Pascoal, Silvestre, Kaminer, Hespanha, "Coordinated
path-following in the presence of communication losses and time delays", SIAM J. Control
Optim. 47(1), 2009; the virtual-leader speed of Xargay et al., "Time-critical cooperative path
following of multiple UAVs", IEEE CSM 2013): every aircraft flies the common reference speed
``u_ref`` along the path plus a consensus correction on the neighbours it hears,

    e_i  = (1 / |N_i|) sum_j wrap(xi_i - xi_j_hat),   xi_j_hat = xi_j + sdot_j (t - t_j)
    du_i = -du_max tanh(k_c e_i / du_max)

where ``xi_j_hat`` is peer j's last report propagated to now with its own sdot (the delay
compensation: a report t - t_j old is as good as a fresh one while the peer holds its speed).
``tanh``: slope k_c at the origin, never more than ``du_max`` (m/s): the correction is smooth
and bounded, so an aircraft is asked only for a speed inside its airspeed window and the MPF
law (which takes sdot from the aircraft's own motion) keeps it on the path.

The correction acts through the airspeed: the aircraft's along-path speed relative to the
moving path is ``u = (v_air + wind - v_point) . f1``; the airspeed set-point that makes it
``u_ref + du`` is ``|(u_ref + du) f1 + v_point - wind|`` (:func:`airspeed_for`), which also
feeds forward the speed variation a moving target imposes around the path (at a constant
airspeed an aircraft on the target's downwind side is faster along the path than one on its
upwind side, and the spacing would oscillate by tens of metres).

Convergence (the condition ``check`` states, :func:`convergence_margin`): with all-to-all
communication the averaged Laplacian's largest eigenvalue is ``N / (N - 1)``; a consensus
``xi_dot = -k_c Lbar xi(t - tau)`` with a delay tau converges iff ``k_c lambda_max tau < pi/2``
(Olfati-Saber and Murray 2004, the delayed case of the cited papers). The delay here is the
uncompensated information age (one update period plus the worst link latency) plus the speed
loop's lag ``tau_V`` (the energy control's time constant, treated as a delay: conservative), so
the condition checked is ``k_c N/(N-1) (1/rate + latency + tau_V) < pi/2``.

Spacing in time (``fleet.spacing: time``, :class:`LapClock`): where a common along-path speed
asks airspeeds outside the window (a figure-eight over a moving boat in wind), every aircraft
flies the reference airspeed instead and the fleet is spaced in lap time: the consensus above
runs on ``shat = L tau(s) / T`` (tau the time to reach s at that airspeed, T the lap's) in place
of s, and the correction is added to the airspeed. ``shat`` advances at ``L / T`` wherever an
aircraft flying the reference airspeed is, so equal slots of ``shat`` are equal gaps in time;
a correction du changes its rate by about ``du (L / T) / nu(s)`` (nu the along-path speed), so
the gain the consensus sees is k_c times up to ``max (L / T) / nu``: the condition checked.
The clock is computed in the wind averaged over laps (:class:`LapWind`; the bridge also averages
it over the fleet), and an inner loop on the along-path speed measured (:class:`GroundSpeedLoop`)
may hold each aircraft to the clock's speed; the consensus' condition through that loop is
:func:`consensus_phase_margin`'s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class PeerReport:
    """What one peer said: its slot (fraction of L), s (m, along the path), sdot (m/s) and the
    common time t (s) at which s held."""

    slot: float
    s_m: float
    sdot_m_s: float
    t_s: float


@dataclass(frozen=True)
class CoordParams:
    """L (m) of the closed path, k_c (1/s) the consensus gain, du_max (m/s) the largest
    speed correction, u_ref (m/s) the common along-path reference speed."""

    length_m: float
    k_c: float
    du_max_m_s: float
    u_ref_m_s: float


def wrap_m(x: float, length_m: float) -> float:
    """x (m) wrapped to [-L/2, L/2): the shorter way round a closed path of length L."""
    return (x + 0.5 * length_m) % length_m - 0.5 * length_m


def xi_m(s_m: float, slot: float, length_m: float) -> float:
    """The coordination state s - slot L (m), wrapped to [0, L)."""
    return (s_m - slot * length_m) % length_m


def coordination_error_m(
    s_m: float, slot: float, peers: Iterable[PeerReport], now_s: float, length_m: float
) -> tuple[float, int]:
    """(e, n): the mean wrapped coordination error (m) of this aircraft against the ``peers``
    propagated to ``now_s`` (s, common time), and how many were used; (0, 0) without peers.
    e > 0: this aircraft is ahead of its slot and must slow down."""
    own = xi_m(s_m, slot, length_m)
    tot, n = 0.0, 0
    for p in peers:
        age = max(0.0, now_s - p.t_s)  # a clock ahead of ours is no reason to go back
        other = xi_m(p.s_m + p.sdot_m_s * age, p.slot, length_m)
        tot += wrap_m(own - other, length_m)
        n += 1
    return (tot / n if n else 0.0), n


def speed_correction(e_m: float, k_c: float, du_max_m_s: float) -> float:
    """du (m/s) = -du_max tanh(k_c e / du_max): slope -k_c at e = 0, |du| < du_max."""
    if du_max_m_s <= 0.0:
        return 0.0
    return -du_max_m_s * math.tanh(k_c * e_m / du_max_m_s)


def airspeed_for(u_m_s: float, f1_I: Vec3, v_point_I: Vec3, wind_I: Vec3) -> float:
    """The airspeed (m/s) at which an aircraft on the path moves along it at u (m/s) relative
    to the moving path: |u f1 + v_point - wind|, all in NED (f1 the unit tangent, v_point the
    inertial velocity of the path point, wind the air mass's)."""
    a = (u_m_s * f1_I[0] + v_point_I[0] - wind_I[0],
         u_m_s * f1_I[1] + v_point_I[1] - wind_I[1],
         u_m_s * f1_I[2] + v_point_I[2] - wind_I[2])  # fmt: skip
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def along_path_speed(v_air_m_s: float, f1_I: Vec3, v_point_I: Vec3, wind_I: Vec3) -> float:
    """The along-path speed nu (m/s) relative to the moving path of an aircraft on it at the
    airspeed v_air: the positive root of |nu f1 + d| = v_air, d = v_point - wind (NED); nan
    where there is none (the point's motion through the air outruns the airspeed)."""
    d = (v_point_I[0] - wind_I[0], v_point_I[1] - wind_I[1], v_point_I[2] - wind_I[2])
    b = f1_I[0] * d[0] + f1_I[1] * d[1] + f1_I[2] * d[2]
    disc = b * b - (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + v_air_m_s * v_air_m_s
    nu = -b + math.sqrt(disc) if disc >= 0.0 else math.nan
    return nu if nu > 0.0 else math.nan


class LapClock:
    """Spacing in time (module docstring): ``shat(s)`` (m) for a path fixed to the target,
    sampled at ``n`` points of its closed length L.

    :meth:`update` takes the target's attitude R_T_I, velocity (m/s NED) and angular velocity
    omega_T (rad/s, target frame), the wind (m/s NED) and the airspeed (m/s); it returns False
    (and keeps the previous table) where the along-path speed has no root somewhere."""

    def __init__(self, path: Any, n: int = 256) -> None:
        self.L = L = float(path.length)
        self.s = np.linspace(0.0, L, n + 1)
        pts = [path.eval(float(x)) for x in self.s[:-1]]
        self.p_T = np.array([np.asarray(q[0], float) for q in pts])  # (n, 3) target frame
        self.f1_T = np.array([np.asarray(q[1], float) for q in pts])
        self.shat_grid = self.s.copy()  # before any update: shat = s
        self.rate_ratio_max = 1.0  # max over the path of (L / T) / nu
        self.lap_s = math.nan  # T (s)

    def update(
        self, R_T_I: Any, v_target_I: Any, omega_T: Any, wind_I: Any, v_air_m_s: float
    ) -> bool:
        R = np.asarray(R_T_I, float)
        f1 = self.f1_T @ R.T
        vp = np.asarray(v_target_I, float) + np.cross(np.asarray(omega_T, float), self.p_T) @ R.T
        d = vp - np.asarray(wind_I, float)
        b = np.einsum("ij,ij->i", f1, d)
        disc = b * b - np.einsum("ij,ij->i", d, d) + v_air_m_s * v_air_m_s
        if not np.all(disc > 0.0):
            return False
        nu = -b + np.sqrt(disc)
        if not np.all(nu > 0.0):
            return False
        inv = 1.0 / np.append(nu, nu[0])
        tau = np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(self.s))))
        T = float(tau[-1])
        self.lap_s = T
        self.shat_grid = self.L * tau / T
        self.rate_ratio_max = float(np.max((self.L / T) / nu))
        return True

    def shat(self, s_m: float) -> float:
        """shat (m) of s (m), laps counted: continuous and increasing in s."""
        laps = math.floor(s_m / self.L)
        return laps * self.L + float(np.interp(s_m - laps * self.L, self.s, self.shat_grid))


def along_path_slope(
    nu_m_s: float, v_air_m_s: float, f1_I: Vec3, v_point_I: Vec3, wind_I: Vec3
) -> float:
    """d nu / d V_air (dimensionless) where :func:`along_path_speed` gives nu at V_air:
    differentiating |nu f1 + d|^2 = V^2 (d = v_point - wind), V / (nu + f1 . d); 1 in calm air
    over a still path, more where the aircraft crabs; nan where it is not defined."""
    b = sum(f1_I[k] * (v_point_I[k] - wind_I[k]) for k in range(3))
    den = nu_m_s + b
    return v_air_m_s / den if den > 0.0 and math.isfinite(den) else math.nan


class GroundSpeedLoop:
    """The coordination's inner loop on the along-path speed it measures (spacing in time,
    ``fleet.ground_speed_gain`` k_v > 0; docs/fleet.md).

    The correction du of the consensus reaches the along-path speed only through the energy
    control, while a gust along the track and the energy control's own airspeed error move the
    aircraft along the path by as much again, mostly at periods of the order of a lap
    (docs/fleet.md). This loop measures that along-path speed error,
    ``sdot - nu_c`` (nu_c the along-path speed the airspeed u_ref + du gives where the aircraft
    is, in the lap clock's wind, :class:`LapWind`), low-passes it over ``tau_s`` (gusts shorter
    than that are left to the airspeed hold) and takes ``k_v`` of it off the airspeed
    set-point, divided by the slope d nu / dV so that k_v is in along-path units:

        du_v = -k_v F(sdot - nu_c) / (d nu / dV),  F = 1 / (tau_s s + 1)

    Closed around a speed response G (airspeed set-point -> along-path speed, |G| <= 1: the
    energy control does not amplify), the disturbance d at low frequency is divided by
    1 + k_v, and the consensus sees H = G (1 + k_v F) / (1 + k_v F G) (module docstring). The
    loop k_v F G has gain at most k_v, so with k_v <= 1 it is stable for any such G (small
    gain: the Nyquist curve stays in the unit disc, on its edge only at 0 Hz, where it is +1),
    whatever the energy control's time constant: the condition the check states."""

    def __init__(self, k_v: float, tau_s: float) -> None:
        self.k_v = k_v
        self.lp = LowPass(tau_s)
        self.du = 0.0

    def __call__(
        self, err_m_s: float, slope: float, dt: float, span_m_s: float = math.inf
    ) -> float:
        """du_v (m/s of airspeed) for the along-path speed error ``err_m_s`` (sdot - nu_c) and
        the slope d nu / dV; where either is not finite, the previous du_v (filter untouched).
        An error beyond ``span_m_s`` (the along-path speed the whole airspeed window spans)
        is not one the airspeed made: the virtual point is catching up with the aircraft (a
        capture; the MPF law's sdot then has a distance-driven part): 0, the filter reset."""
        if not (math.isfinite(err_m_s) and math.isfinite(slope) and slope > 0.0):
            return self.du
        if abs(err_m_s) > span_m_s:
            self.lp.y = None
            self.du = 0.0
        else:
            self.du = -self.k_v * self.lp(err_m_s, dt) / slope
        return self.du


def inner_loop_response(
    omega: np.ndarray, k_v: float, filter_tau_s: float, speed_tau_s: float
) -> np.ndarray:
    """H(j omega) = G (1 + k_v F) / (1 + k_v F G) with the speed loop G = 1 / (tau_V s + 1)
    and F = 1 / (tau_F s + 1): what the consensus' correction becomes along the path through
    :class:`GroundSpeedLoop` (k_v 0: G itself)."""
    s = 1j * np.asarray(omega, float)
    G = 1.0 / (speed_tau_s * s + 1.0)
    F = 1.0 / (filter_tau_s * s + 1.0)
    return G * (1.0 + k_v * F) / (1.0 + k_v * F * G)


def consensus_phase_margin(
    gain_1_s: float, delay_s: float, H: Any = None, omega: np.ndarray | None = None
) -> float:
    """The least phase margin (rad) of the consensus mode K H(s) e^{-s tau} / s over the
    frequencies where its loop gain is at least 1 (K = ``gain_1_s``, k_c times the gain factor
    times the Laplacian's eigenvalue; tau = ``delay_s``; ``H`` a callable of omega giving the
    inner response, None: 1). > 0 for every eigenvalue up to K means the Nyquist curve
    crosses the negative real axis only inside the unit circle: no encirclement of -1, the
    consensus converges (sufficient). With H = 1 it is pi/2 - K tau, the closed form."""
    w = np.geomspace(1e-4, 1e2, 20001) if omega is None else omega
    h = np.ones(len(w), complex) if H is None else np.asarray(H(w), complex)
    mag = gain_1_s * np.abs(h) / w
    ph = np.unwrap(np.angle(h)) - w * delay_s - 0.5 * math.pi
    on = mag >= 1.0
    if not np.any(on):
        return math.pi
    return float(np.min(ph[on] + math.pi))


class LapWind:
    """The wind (m/s NED) the lap clock is computed in: the bridge's estimate low-passed over
    ``tau_s`` (0: as estimated).

    The lap clock maps every aircraft's s to lap time through one wind, so each bridge's
    coordination error e carries its own wind estimate: a third of a lap of shat moves by
    metres per m/s of wind, and estimates in turbulence swing and differ between the aircraft,
    so with each bridge's own estimate the consensus chases its own clock (docs/fleet.md has the
    figures). A gust moves the
    aircraft (the consensus sees that through s); the lap's time is set by the wind over laps.
    Averaging over tau_s divides the estimate's noise of correlation time T_c by about
    sqrt(2 tau_s / T_c); the wind in NED changes over minutes, the target's turn is the lap
    clock's own (its attitude), so tau_s of a few laps costs only a lag to a real wind shift."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = tau_s
        self.y: list[float] | None = None
        self.n = 0  # estimates averaged so far

    def __call__(self, wind_I: Vec3, dt: float) -> Vec3:
        """The average after the estimate ``wind_I`` (m/s NED), ``dt`` (s) after the last: the
        running mean of the estimates so far while it weighs the newest more than the
        low-pass would (about tau_s / dt of them: one estimate at the start is one gust), then
        the first-order low-pass over tau_s; a non-finite estimate changes nothing."""
        if not all(math.isfinite(w) for w in wind_I):
            return wind_I if self.y is None else (self.y[0], self.y[1], self.y[2])
        if self.y is None or self.tau_s <= 0.0:
            self.y = [float(wind_I[0]), float(wind_I[1]), float(wind_I[2])]
            self.n = 1
        elif dt > 0.0:
            a = max(1.0 - math.exp(-dt / self.tau_s), 1.0 / (self.n + 1))
            self.n += 1
            self.y = [y + a * (w - y) for y, w in zip(self.y, wind_I, strict=True)]
        return (self.y[0], self.y[1], self.y[2])


def reference_speed(fleet: Any, vehicle: Any) -> float:
    """u_ref (m/s): ``fleet.u_ref_m_s``, else the vehicle's cruise airspeed."""
    return float(fleet.u_ref_m_s if fleet.u_ref_m_s is not None else vehicle.airspeed_m_s)


def airspeed_window(fleet: Any, vehicle: Any) -> tuple[float, float]:
    """The airspeeds (m/s) the coordination may ask: the vehicle's window less
    ``fleet.airspeed_margin_m_s`` at each end (0 and inf where the vehicle gives none)."""
    lo = vehicle.airspeed_min_m_s if vehicle.airspeed_min_m_s is not None else 0.0
    hi = vehicle.airspeed_max_m_s if vehicle.airspeed_max_m_s is not None else math.inf
    m = fleet.airspeed_margin_m_s
    return float(lo + m), float(hi - m)


def respaced_slots(slots: Sequence[float], alive: Sequence[bool]) -> list[float | None]:
    """The slots the living members fly after a loss (``on_peer_lost: respace``): in their
    configured order, evenly spaced from the first living one's own slot; None for the dead.
    Every survivor computes the same from the same living set."""
    order = sorted((s % 1.0, k) for k, s in enumerate(slots) if alive[k])
    out: list[float | None] = [None] * len(slots)
    if not order:
        return out
    base, n = order[0][0], len(order)
    for rank, (_, k) in enumerate(order):
        out[k] = (base + rank / n) % 1.0
    return out


def lambda_max(n: int) -> float:
    """Largest eigenvalue of the averaged Laplacian of n all-to-all members, n / (n - 1)."""
    return n / (n - 1) if n > 1 else 0.0


def convergence_margin(
    k_c: float, n: int, rate_hz: float, latency_s: float, speed_tau_s: float
) -> float:
    """pi/2 - k_c lambda_max (1/rate + latency + tau_V): > 0 where the consensus converges."""
    tau = 1.0 / rate_hz + latency_s + speed_tau_s
    return 0.5 * math.pi - k_c * lambda_max(n) * tau


@dataclass(frozen=True)
class Feasibility:
    """The airspeed (m/s) the coordination asks for over the path: at u_ref alone (lo, hi) and
    with the full correction (lo_full at u_ref - du_max, hi_full at u_ref + du_max)."""

    lo: float
    hi: float
    lo_full: float
    hi_full: float


def feasibility(
    tangents_I: Iterable[Vec3], v_points_I: Iterable[Vec3], wind_I: Vec3, u_ref: float, du: float
) -> Feasibility:
    """The airspeeds :func:`airspeed_for` gives at sampled path points (tangent f1 and point
    velocity, NED), at u_ref and u_ref -/+ du (m/s)."""
    lo = hi = lo_f = hi_f = float("nan")
    first = True
    for f1, vp in zip(tangents_I, v_points_I, strict=True):
        a = airspeed_for(u_ref, f1, vp, wind_I)
        a_lo = airspeed_for(max(0.0, u_ref - du), f1, vp, wind_I)
        a_hi = airspeed_for(u_ref + du, f1, vp, wind_I)
        if first:
            lo, hi, lo_f, hi_f, first = a, a, a_lo, a_hi, False
        else:
            lo, hi = min(lo, a), max(hi, a)
            lo_f, hi_f = min(lo_f, a_lo), max(hi_f, a_hi)
    return Feasibility(lo, hi, lo_f, hi_f)


class LowPass:
    """First-order low-pass (time constant tau s) of the speed correction: the airspeed
    set-point moves smoothly, so that the energy control's thrust steps do not disturb the
    attitude loop (the lost run's spacing and tracking both suffered from a raw correction)."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = tau_s
        self.y: float | None = None

    def __call__(self, x: float, dt: float) -> float:
        if self.y is None or self.tau_s <= 0.0:
            self.y = x
        elif dt > 0.0:
            self.y += (x - self.y) * (1.0 - math.exp(-dt / self.tau_s))
        return self.y


def fleet_checks(
    fleet: Any,
    vehicle: Any,
    path: Any,
    target: Any,
    wind_I: Vec3,
    horizon_s: float,
    speed_tau_s: float,
) -> tuple[list[Any], float]:
    """The fleet's pre-flight checks (``check`` and the bridge before engaging) and the fastest
    airspeed (m/s) the coordination may ask, for the bank feasibility at it:

    - ``fleet_convergence``: :func:`convergence_margin` > 0 (fail otherwise);
    - ``fleet_speed``: at u_ref the airspeed :func:`airspeed_for` asks over the path and the
      target's motion stays inside the window less ``airspeed_margin_m_s`` (fail otherwise: the
      formation cannot be held); with the full correction -/+ du_max outside it, a warning
      (the window clips the correction there and convergence is slower).
    """
    from mpf_mavlink.core.guidance.checks import CheckResult

    if fleet.spacing == "time":
        return _time_checks(fleet, vehicle, path, target, wind_I, horizon_s, speed_tau_s)
    n = len(fleet.slots_deg)
    m = convergence_margin(fleet.k_c, n, fleet.rate_hz, fleet.max_latency_s + fleet.filter_tau_s,
                           speed_tau_s)  # fmt: skip
    tau = 1.0 / fleet.rate_hz + fleet.max_latency_s + fleet.filter_tau_s + speed_tau_s
    conv = CheckResult(
        "fleet_convergence",
        "pass" if m > 0.0 else "fail",
        f"k_c lambda_max tau = {fleet.k_c:g} x {lambda_max(n):.2f} x {tau:.2f} s = "
        f"{0.5 * math.pi - m:.2f} {'<' if m > 0 else '>='} pi/2 (N {n}; tau: 1/rate + latency "
        f"+ filter + speed lag)",
        {"margin": m, "tau_s": tau},
    )
    u = reference_speed(fleet, vehicle)
    L = float(path.length)
    ss = [L * k / 240.0 for k in range(240)]
    ts = [horizon_s * k / 12.0 for k in range(13)]
    tangents: list[Vec3] = []
    vps: list[Vec3] = []
    for t in ts:
        st = target.state(t)
        R = st.R_T_I
        w = st.omega_T
        for s in ss:
            pt = path.eval(s)
            p, f = pt[0], pt[1]
            f1 = R @ f
            wxp = (w[1] * p[2] - w[2] * p[1], w[2] * p[0] - w[0] * p[2], w[0] * p[1] - w[1] * p[0])
            rot = R @ wxp
            tangents.append((float(f1[0]), float(f1[1]), float(f1[2])))
            vps.append(tuple(float(st.velocity[k] + rot[k]) for k in range(3)))  # type: ignore[arg-type]
    fe = feasibility(tangents, vps, wind_I, u, fleet.du_max_m_s)
    lo_w, hi_w = airspeed_window(fleet, vehicle)
    figs: dict[str, float | bool | None] = {
        "airspeed_lo_m_s": fe.lo, "airspeed_hi_m_s": fe.hi, "with_du_lo_m_s": fe.lo_full,
        "with_du_hi_m_s": fe.hi_full, "window_lo_m_s": lo_w, "window_hi_m_s": hi_w,
    }  # fmt: skip
    if fe.lo < lo_w or fe.hi > hi_w:
        st_, why = "fail", "outside"
    elif fe.lo_full < lo_w or fe.hi_full > hi_w:
        st_, why = "warn", "inside; the full correction is clipped by"
    else:
        st_, why = "pass", "inside"
    speed = CheckResult(
        "fleet_speed",
        st_,
        f"u_ref {u:.1f} m/s along the path asks {fe.lo:.1f}-{fe.hi:.1f} m/s of airspeed "
        f"({fe.lo_full:.1f}-{fe.hi_full:.1f} with du_max {fleet.du_max_m_s:g}): {why} the "
        f"window {lo_w:.1f}-{hi_w:.1f} m/s",
        figs,
    )
    return [conv, speed], min(fe.hi_full, hi_w)


def _time_checks(
    fleet: Any,
    vehicle: Any,
    path: Any,
    target: Any,
    wind_I: Vec3,
    horizon_s: float,
    speed_tau_s: float,
) -> tuple[list[Any], float]:
    """:func:`fleet_checks` of ``spacing: time``: the lap clock solvable at u_ref of airspeed
    over the target's motion (fail otherwise), u_ref -/+ du_max inside the window (fail for
    u_ref, warn for the correction), and the convergence condition with the gain's largest
    factor ``max (L / T) / nu`` over the path and the motion."""
    from mpf_mavlink.core.guidance.checks import CheckResult

    n = len(fleet.slots_deg)
    u = reference_speed(fleet, vehicle)
    lap = LapClock(path, 240)
    ratios, laps, unsolved = [], [], []
    for k in range(13):
        t = horizon_s * k / 12.0
        st = target.state(t)
        if lap.update(st.R_T_I, st.velocity, st.omega_T, wind_I, u):
            ratios.append(lap.rate_ratio_max)
            laps.append(lap.lap_s)
        else:
            unsolved.append(t)
    g = max(ratios) if ratios else math.inf
    k_v = fleet.ground_speed_gain
    if k_v > 0.0:
        conv = _inner_loop_check(fleet, n, g, speed_tau_s)
    else:
        tau = 1.0 / fleet.rate_hz + fleet.max_latency_s + fleet.filter_tau_s + speed_tau_s
        x = fleet.k_c * g * lambda_max(n) * tau
        conv = CheckResult(
            "fleet_convergence",
            "pass" if x < 0.5 * math.pi else "fail",
            f"k_c g lambda_max tau = {fleet.k_c:g} x {g:.2f} x {lambda_max(n):.2f} x {tau:.2f} s "
            f"= {x:.2f} {'<' if x < 0.5 * math.pi else '>='} pi/2 (N {n}; spacing in time, g the "
            "largest (L/T)/nu; tau: 1/rate + latency + filter + speed lag)",
            {"margin": 0.5 * math.pi - x, "tau_s": tau, "gain_factor": g},
        )
    lo_w, hi_w = airspeed_window(fleet, vehicle)
    du = fleet.du_max_m_s
    if unsolved or not lo_w <= u <= hi_w:
        st_ = "fail"
    elif u - du < lo_w or u + du > hi_w:
        st_ = "warn"
    else:
        st_ = "pass"
    why = (
        f"no along-path speed at {u:.1f} m/s of airspeed at t = {unsolved[0]:.0f} s"
        if unsolved
        else f"laps of {min(laps):.1f}-{max(laps):.1f} s"
    )
    speed = CheckResult(
        "fleet_speed",
        st_,
        f"spacing in time at u_ref {u:.1f} m/s of airspeed ({u - du:.1f}-{u + du:.1f} with "
        f"du_max {du:g}) against the window {lo_w:.1f}-{hi_w:.1f} m/s: {why}",
        {
            "lap_lo_s": min(laps, default=math.nan),
            "lap_hi_s": max(laps, default=math.nan),
            "window_lo_m_s": lo_w,
            "window_hi_m_s": hi_w,
        },  # fmt: skip
    )
    return [conv, speed], min(u + du, hi_w)


def _inner_loop_check(fleet: Any, n: int, g: float, speed_tau_s: float) -> Any:
    """``fleet_convergence`` with the along-path speed loop (:class:`GroundSpeedLoop`): the
    inner loop by small gain (k_v <= 1), and the consensus mode K H(s) e^{-s tau} / s by
    :func:`consensus_phase_margin` at K = k_c g lambda_max, H the inner response with the
    energy control's speed loop as the first-order lag tau_V (its design: V_dot demand =
    (V_sp - V) / tau_V), tau the pure delays 1/rate + latency + the correction's low-pass."""
    from mpf_mavlink.core.guidance.checks import CheckResult

    k_v, tau_f = fleet.ground_speed_gain, fleet.ground_speed_tau_s
    K = fleet.k_c * g * lambda_max(n)
    tau = 1.0 / fleet.rate_hz + fleet.max_latency_s + fleet.filter_tau_s
    pm = consensus_phase_margin(
        K, tau, lambda w: inner_loop_response(w, k_v, tau_f, speed_tau_s)
    ) if math.isfinite(K) else -math.inf  # fmt: skip
    ok = k_v <= 1.0 and pm > 0.0
    why = (
        f"along-path speed loop k_v {k_v:g} {'<=' if k_v <= 1.0 else '>'} 1 (small gain); "
        f"consensus K = k_c g lambda_max = {fleet.k_c:g} x {g:.2f} x {lambda_max(n):.2f} = "
        f"{K:.3f} 1/s through the inner loop (speed lag {speed_tau_s:g} s, filter {tau_f:g} s) "
        f"and {tau:.2f} s of delay: phase margin {math.degrees(pm):.0f} deg (N {n}; spacing in "
        "time)"
    )
    return CheckResult(
        "fleet_convergence", "pass" if ok else "fail", why,
        {"margin": pm, "tau_s": tau, "gain_factor": g, "inner_gain": k_v},
    )  # fmt: skip
