"""Target estimator: the moving frame {T} from sparse, noisy, late position reports.

Pure code: no I/O, no clock. Time comes from the reports' own timestamps (the sender's clock)
and from the receive times the caller passes in (the control time base, s).

Model (an EKF on a manoeuvring target, Bar-Shalom's coordinated turn in the horizontal plane
plus constant vertical velocity), state ``x = [n, e, d, vn, ve, vd, w]`` (NED m, m/s, turn
rate w in rad/s, > 0 turns right, i.e. clockwise seen from above)::

    d/dt [n, e] = [vn, ve]      d/dt [vn, ve] = w [-ve, vn]      d/dt d = vd
    d/dt vd = white noise       d/dt w = white noise  (a random walk of the turn rate)
    plus white horizontal acceleration noise

Exact discretisation over T for a fixed w (the mean)::

    [n, e]' = [n, e] + [[s, -c], [c, s]] [vn, ve],   s = sin(wT)/w,  c = (1 - cos wT)/w
    [vn, ve]' = Rot(wT) [vn, ve]

with its Jacobian F (w enters through s, c and Rot) and the usual white-noise process matrix
per axis ``q [[T^3/3, T^2/2], [T^2/2, T]]`` (horizontal ``accel_noise^2``, vertical
``vertical_accel_noise^2``) and ``turn_accel_noise^2 T`` on w. Every measurement is linear in x:
position (3), velocity (3), turn rate (1, from the target's attitude and body rates). Each is
gated on its squared Mahalanobis distance ``nu' S^-1 nu`` against the chi-square quantile of
``gate_probability`` for its dimension; ``reinit_after`` gated reports in a row re-initialise
the filter on the latest one (a target that really did something the model calls impossible).

Late and out-of-order reports: the reports of the last ``history_s`` seconds are kept in time
order with the posterior after each; a report older than the newest is inserted and the filter
is re-run from the posterior before it (buffer and replay), so it gives the same estimate as if
it had arrived in order. Older than the history: dropped.

Computation, in scalars (at 7 states numpy's per-call cost would be most of a fix's). No term of
F, Q, H or R couples the vertical channel ``[d, vd]`` with the horizontal one ``[n, e, vn, ve,
w]``, so P is block diagonal and the filter runs as a 5-state and a 2-state block. A report's
components (R diagonal) are fused one at a time (sequential scalar updates, the same posterior
as the vector update); the gate's ``nu' S^-1 nu`` is the sum of the scalar innovations' ``nu_j^2
/ s_j`` (the LDL' factorisation of S), computed before anything is kept.

Clock: the sender's clock is not ours. ``off`` = min over reports of (receive time - report
time) is the clock offset plus the smallest transport delay (it leaks upward by
:data:`CLOCK_DRIFT` to follow a drifting clock); a report's time in our base is its stamp plus
``off - latency_s``, with ``latency_s`` the known smallest transport delay (0: unknown, the
estimate then lags by the true delay). A sender clock that restarts or jumps by more than
``max_age_s`` resets the filter.

Output at control time t: the prediction of the latest posterior to t. {T} is level (z down,
the frame of the scripted targets): its yaw is the target's reported attitude yaw while that is
younger than ``attitude_timeout_s`` (turned on at the estimated turn rate), else the course
(x along the horizontal velocity); below 0.5 m/s the course is undefined and the yaw is held
(last course, or the reported heading). Angular velocity ``[0, 0, w]``, acceleration
``w [-ve, vn, 0]``, angular acceleration 0. The target's roll and pitch are not followed.
Stale (a reason string, no state) when the predicted position uncertainty ``sqrt(trace P_pos) +
manoeuvre_accel_m_s2 tau^2 / 2`` exceeds ``max_position_sigma_m`` (tau: time since the newest fused
position) or that position is older than ``max_age_s``. The second term is what a target that starts
to manoeuvre while unseen can have moved away from the prediction: the filter's own covariance
reflects its (small) process noise, tuned for smoothing, and would let a quiet model fly on a long
outage.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.target import TargetState, target_state_of_floats
from mpf_mavlink.core.target_report import Report, TargetFilterParams, Vec

#: Upward leak of the clock-offset minimum (s per s): follows a sender clock drifting by up to
#: 100 ppm (crystal clocks: 20-50 ppm) while a single fast report does not fix it for ever.
CLOCK_DRIFT = 1e-4
#: Below this horizontal speed (m/s) the course does not define the frame's yaw.
MIN_COURSE_SPEED_M_S = 0.5
#: Initial 1-sigma of what the first report does not carry.
INIT_VEL_SIGMA_M_S = 5.0
INIT_TURN_SIGMA_RAD_S = 0.05

N = 7  # state size
#: The state's indices in the horizontal block [n, e, vn, ve, w] and in the vertical [d, vd]
HORIZONTAL = (0, 1, 3, 4, 6)
VERTICAL = (2, 5)
#: state index -> (block: 0 horizontal, 1 vertical; index in the block)
_IN_BLOCK = {0: (0, 0), 1: (0, 1), 3: (0, 2), 4: (0, 3), 6: (0, 4), 2: (1, 0), 5: (1, 1)}
#: A block's covariance is kept as its upper triangle, row by row: the horizontal block's 15
#: entries (p00, p01, p02, p03, p04, p11, ..., p44), the vertical's 3 (p_dd, p_dv, p_vv).
#: _COL[i]: where column i of the horizontal block is in it.
_COL = ((0, 1, 2, 3, 4), (1, 5, 6, 7, 8), (2, 6, 9, 10, 11), (3, 7, 10, 12, 13), (4, 8, 11, 13, 14))


def _floats(v: NDArray[np.float64] | Vec) -> list[float]:
    """A report's vector as a list of floats."""
    if type(v) is np.ndarray:
        out: list[float] = v.tolist()
        return out
    return [float(a) for a in v]


@dataclass(frozen=True)
class _Post:
    """The posterior after a report: time (sender clock), mean ``[n, e, d, vn, ve, vd, w]``,
    covariance as the upper triangles of its horizontal and vertical blocks (:data:`_COL`),
    gated reports in a row, the yaw held for low speeds, and the time of the newest fused
    position (what places the target: the staleness counts from it, not from attitude-only or
    gated reports)."""

    t: float
    x: Vec
    Ph: Vec
    Pv: Vec
    nrej: int
    yaw: float
    t_fix: float

    @property
    def P(self) -> NDArray[np.float64]:
        """The full 7 x 7 covariance (the blocks in place, zeros between them)."""
        return full_covariance(self.Ph, self.Pv)


def full_covariance(Ph: Vec, Pv: Vec) -> NDArray[np.float64]:
    """The 7 x 7 covariance of the state from its blocks' upper triangles (:data:`_COL`)."""
    P = np.zeros((N, N))
    for i, j in enumerate(HORIZONTAL):
        P[j, HORIZONTAL] = [Ph[k] for k in _COL[i]]
    pdd, pdv, pvv = Pv
    P[2, 2], P[2, 5], P[5, 2], P[5, 5] = pdd, pdv, pdv, pvv
    return P


def chi2_sf(x: float, k: int) -> float:
    """Survival function of the chi-square distribution with k dof (closed forms: a finite
    Poisson sum for even k, the normal tail plus a finite sum for odd k)."""
    if x <= 0.0:
        return 1.0
    h = 0.5 * x
    if k % 2 == 0:
        term, total = 1.0, 1.0
        for i in range(1, k // 2):
            term *= h / i
            total += term
        return math.exp(-h) * total
    r = math.sqrt(x)
    sf = 2.0 * (1.0 - NormalDist().cdf(r))
    term, total = r, 0.0
    for i in range(1, (k - 1) // 2 + 1):
        total += term
        term *= x / (2 * i + 1)
    return sf + math.sqrt(2.0 / math.pi) * math.exp(-h) * total


def chi2_quantile(p: float, k: int) -> float:
    """Chi-square quantile of probability p for k dof (bisection on :func:`chi2_sf`)."""
    lo, hi = 0.0, 10.0 * k + 100.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if chi2_sf(mid, k) > 1.0 - p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _turn_terms(w: float, T: float) -> tuple[float, float, float, float, float, float]:
    """(cos wT, sin wT, s, c, ds/dw, dc/dw) of the coordinated turn over T (s) at turn rate w
    (rad/s): s = sin(wT)/w, c = (1 - cos wT)/w. One place, so the mean, its Jacobian and the
    position variance use the same floats."""
    wT = w * T
    cw, sw = math.cos(wT), math.sin(wT)
    if abs(wT) < 1e-4:  # series: sin(wT)/w and (1 - cos wT)/w lose digits as w -> 0
        s = T * (1.0 - wT * wT / 6.0)
        c = T * (wT / 2.0 - wT**3 / 24.0)
        ds = -w * T**3 / 3.0
        dc = T * T / 2.0 - w * w * T**4 / 8.0
    else:
        s, c = sw / w, (1.0 - cw) / w
        ds, dc = (T * cw - s) / w, (T * sw - c) / w
    return cw, sw, s, c, ds, dc


def _mean(x: Vec, T: float, cw: float, sw: float, s: float, c: float) -> tuple[float, ...]:
    """The coordinated-turn mean over T (s) with the turn terms of :func:`_turn_terms`."""
    n, e, d, vn, ve, vd, w = x
    return (n + s * vn - c * ve, e + c * vn + s * ve, d + T * vd,
            cw * vn - sw * ve, sw * vn + cw * ve, vd, w)  # fmt: skip


def transition_mean(x: Vec, T: float) -> tuple[float, ...]:
    """The coordinated-turn mean over T (s) of x ``[n, e, d, vn, ve, vd, w]``."""
    cw, sw, s, c, _, _ = _turn_terms(x[6], T)
    return _mean(x, T, cw, sw, s, c)


def position_variance(x: Vec, Ph: Vec, Pv: Vec, T: float) -> float:
    """trace(Fp P Fp'), Fp the position rows of the transition's Jacobian at x over T (s):
    the predicted position variance before the process noise, in scalars. Fp is sparse: in the
    horizontal block [n, e, vn, ve, w] the rows [1 0 s -c F06] and [0 1 c s F16], in the
    vertical [d, vd] the row [1 T]."""
    _, _, s, c, ds, dc = _turn_terms(x[6], T)
    return _position_variance(x, Ph, Pv, T, s, c, ds, dc)


def _position_variance(
    x: Vec, Ph: Vec, Pv: Vec, T: float, s: float, c: float, ds: float, dc: float
) -> float:
    """:func:`position_variance` with the turn terms (:func:`_turn_terms`) given."""
    vn, ve = x[3], x[4]
    f06 = ds * vn - dc * ve
    f16 = dc * vn + ds * ve
    p00, p01, p02, p03, p04, p11, p12, p13, p14, p22, p23, p24, p33, p34, p44 = Ph
    pdd, pdv, pvv = Pv
    var = pdd + 2.0 * T * pdv + T * T * pvv  # row [1 T]
    # row [1 0 a b f]: sum over its entries k of f_k (P f')_k, then row [0 1 a b f]
    for pi_i, pi_2, pi_3, pi_4, a, b, f in (
        (p00, p02, p03, p04, s, -c, f06),
        (p11, p12, p13, p14, c, s, f16),
    ):
        var += (
            (pi_i + a * pi_2 + b * pi_3 + f * pi_4)
            + a * (pi_2 + a * p22 + b * p23 + f * p24)
            + b * (pi_3 + a * p23 + b * p33 + f * p34)
            + f * (pi_4 + a * p24 + b * p34 + f * p44)
        )
    return var


def _predict(
    x: Vec, Ph: Vec, Pv: Vec, T: float, q: tuple[float, float, float]
) -> tuple[Vec, Vec, Vec]:
    """The prior over T (s): mean, F P F' + Q per block. ``q``: the squared process noise
    densities (horizontal acceleration, vertical acceleration, turn rate); Q per axis
    ``q [[T^3/3, T^2/2], [T^2/2, T]]``, ``q_w T`` on w. T = 0: unchanged; T < 0 (a control time
    before the posterior): the mean only.

    Hand-unrolled scalars (numpy's per-call cost would be most of a fix): F of the horizontal block
    ``[n, e, vn, ve, w]`` is ``[[1, 0, s, -c, a], [0, 1, c, s, b], [0, 0, cw, -sw, g],
    [0, 0, sw, cw, h], [0, 0, 0, 0, 1]]`` (a, b, g, h: the mean's derivatives in w); ``Bkj =
    (P F')_kj`` for the entries that F P F' = F B needs, then that product's upper triangle."""
    if T == 0.0:
        return x, Ph, Pv
    vn, ve, w = x[3], x[4], x[6]
    cw, sw, s, c, ds, dc = _turn_terms(w, T)
    xp = _mean(x, T, cw, sw, s, c)
    if T < 0.0:
        return xp, Ph, Pv
    a = ds * vn - dc * ve
    b = dc * vn + ds * ve
    g = -T * (sw * vn + cw * ve)
    h = T * (cw * vn - sw * ve)
    p00, p01, p02, p03, p04, p11, p12, p13, p14, p22, p23, p24, p33, p34, p44 = Ph
    # B = P F': row k of P times the rows of F (column 4 of B is P's column 4)
    B00 = p00 + s * p02 - c * p03 + a * p04
    B01 = p01 + c * p02 + s * p03 + b * p04
    B02 = cw * p02 - sw * p03 + g * p04
    B03 = sw * p02 + cw * p03 + h * p04
    B11 = p11 + c * p12 + s * p13 + b * p14
    B12 = cw * p12 - sw * p13 + g * p14
    B13 = sw * p12 + cw * p13 + h * p14
    B20 = p02 + s * p22 - c * p23 + a * p24
    B21 = p12 + c * p22 + s * p23 + b * p24
    B22 = cw * p22 - sw * p23 + g * p24
    B23 = sw * p22 + cw * p23 + h * p24
    B30 = p03 + s * p23 - c * p33 + a * p34
    B31 = p13 + c * p23 + s * p33 + b * p34
    B32 = cw * p23 - sw * p33 + g * p34
    B33 = sw * p23 + cw * p33 + h * p34
    B40 = p04 + s * p24 - c * p34 + a * p44
    B41 = p14 + c * p24 + s * p34 + b * p44
    B42 = cw * p24 - sw * p34 + g * p44
    B43 = sw * p24 + cw * p34 + h * p44
    qh, qv, qw = q
    q3, q2, q1 = qh * T**3 / 3.0, qh * T**2 / 2.0, qh * T
    # F B + Q, upper triangle (column 4 of F B is F's rows times P's column 4: B4j)
    Ph = (
        B00 + s * B20 - c * B30 + a * B40 + q3,
        B01 + s * B21 - c * B31 + a * B41,
        B02 + s * B22 - c * B32 + a * B42 + q2,
        B03 + s * B23 - c * B33 + a * B43,
        B40,
        B11 + c * B21 + s * B31 + b * B41 + q3,
        B12 + c * B22 + s * B32 + b * B42,
        B13 + c * B23 + s * B33 + b * B43 + q2,
        B41,
        cw * B22 - sw * B32 + g * B42 + q1,
        cw * B23 - sw * B33 + g * B43,
        B42,
        sw * B23 + cw * B33 + h * B43 + q1,
        B43,
        p44 + qw * T,
    )
    pdd, pdv, pvv = Pv
    dv = pdv + T * pvv  # F P F' of [[1, T], [0, 1]]
    Pv = (pdd + T * pdv + T * dv + qv * T**3 / 3.0, dv + qv * T**2 / 2.0, pvv + qv * T)
    return xp, Ph, Pv


def _innovation(s: float, nu: float, g: float) -> float:
    """nu^2 / s (g = 1 / s), nan unless s is finite and > 0 (the gate then refuses it)."""
    return nu * nu * g if 0.0 < s < math.inf else math.nan


def _update_horizontal(
    xh: Vec, Ph: Vec, i: int, z: float, r: float
) -> tuple[list[float], list[float], float]:
    """One scalar measurement z (variance r) of the horizontal block's state i: (mean,
    covariance, nu^2 / s). The covariance is the Schur complement ``P - k c'`` (c = P[:, i],
    s = c_i + r, gain k = c / s), its row and column i computed as ``c r / s`` (no cancellation
    when r << P_ii, where ``P_ii - P_ii^2 / s`` could come out negative). Hand-unrolled."""
    c = [Ph[k] for k in _COL[i]]
    c0, c1, c2, c3, c4 = c
    s = c[i] + r
    g = 1.0 / s
    k0, k1, k2, k3, k4 = c0 * g, c1 * g, c2 * g, c3 * g, c4 * g
    x0, x1, x2, x3, x4 = xh
    nu = z - xh[i]
    x = [x0 + k0 * nu, x1 + k1 * nu, x2 + k2 * nu, x3 + k3 * nu, x4 + k4 * nu]
    p00, p01, p02, p03, p04, p11, p12, p13, p14, p22, p23, p24, p33, p34, p44 = Ph
    P = [
        p00 - k0 * c0, p01 - k0 * c1, p02 - k0 * c2, p03 - k0 * c3, p04 - k0 * c4,
        p11 - k1 * c1, p12 - k1 * c2, p13 - k1 * c3, p14 - k1 * c4,
        p22 - k2 * c2, p23 - k2 * c3, p24 - k2 * c4,
        p33 - k3 * c3, p34 - k3 * c4,
        p44 - k4 * c4,
    ]  # fmt: skip
    f = r * g
    for k, ca in zip(_COL[i], c, strict=True):
        P[k] = ca * f
    return x, P, _innovation(s, nu, g)


def _update_vertical(
    xv: Vec, Pv: Vec, i: int, z: float, r: float
) -> tuple[list[float], list[float], float]:
    """:func:`_update_horizontal` for the vertical block [d, vd]."""
    pdd, pdv, pvv = Pv
    c0, c1 = (pdd, pdv) if i == 0 else (pdv, pvv)
    s = (c0, c1)[i] + r
    g = 1.0 / s
    k0, k1 = c0 * g, c1 * g
    nu = z - xv[i]
    x = [xv[0] + k0 * nu, xv[1] + k1 * nu]
    f = r * g
    if i == 0:
        P = [c0 * f, c1 * f, pvv - k1 * c1]
    else:
        P = [pdd - k0 * c0, c0 * f, c1 * f]
    return x, P, _innovation(s, nu, g)


def _course(x: Sequence[float] | NDArray[np.float64], held: float) -> float:
    """The course (rad) of the state's ground velocity, or ``held`` when too slow to tell."""
    vn, ve = float(x[3]), float(x[4])
    if vn * vn + ve * ve > MIN_COURSE_SPEED_M_S**2:
        return math.atan2(ve, vn)
    return held


class TargetEkf:
    """One step of the EKF (module docstring): a report fused into the posterior before it,
    with ``params``'s noises and gate; it keeps no state of its own."""

    def __init__(self, params: TargetFilterParams) -> None:
        self.p = params
        self.gates = [0.0] + [chi2_quantile(params.gate_probability, k) for k in range(1, 8)]
        self.q = (
            params.accel_noise_m_s2**2,
            params.vertical_accel_noise_m_s2**2,
            params.turn_accel_noise_rad_s2**2,
        )  # the process noise densities squared (_predict)

    def init(self, r: Report, nrej: int = 0) -> _Post:
        assert r.position is not None
        pn, pe, pd = self._pos_var(r)
        n, e, d = _floats(r.position)
        if r.velocity is not None:
            vn, ve, vd = _floats(r.velocity)
            vv = self.p.velocity_noise_m_s**2
        else:
            vn = ve = vd = 0.0
            vv = INIT_VEL_SIGMA_M_S**2
        if r.turn_rate is not None:
            w, ww = float(r.turn_rate), self.p.turn_rate_noise_rad_s**2
        else:
            w, ww = 0.0, INIT_TURN_SIGMA_RAD_S**2
        x = (n, e, d, vn, ve, vd, w)
        Ph = (pn, 0.0, 0.0, 0.0, 0.0, pe, 0.0, 0.0, 0.0, vv, 0.0, 0.0, vv, 0.0, ww)
        Pv = (pd, 0.0, vv)
        yaw = r.yaw if r.yaw is not None else 0.0
        return _Post(r.t, x, Ph, Pv, nrej, _course(x, yaw), r.t)

    def _pos_var(self, r: Report) -> list[float]:
        if r.pos_var is not None:
            return _floats(r.pos_var)
        h, v = self.p.position_noise_m**2, self.p.vertical_noise_m**2
        return [h, h, v]

    def fuse(self, prev: _Post | None, r: Report) -> tuple[_Post | None, str]:
        """The posterior after ``r`` from ``prev`` (None: none yet) and what became of it."""
        if prev is None:
            if r.position is None:
                return None, "waiting"
            return self.init(r), "fused"
        x, Ph, Pv = _predict(prev.x, prev.Ph, prev.Pv, r.t - prev.t, self.q)
        held = r.yaw if r.yaw is not None else prev.yaw
        meas = self._measurements(r)
        if not meas:
            return _Post(r.t, x, Ph, Pv, prev.nrej, _course(x, held), prev.t_fix), "fused"
        # the components one at a time (module docstring); the gate's distance is their sum,
        # and once it is past the gate the rest cannot bring it back (each term is >= 0)
        gate = self.gates[len(meas)]
        xh: Vec = (x[0], x[1], x[3], x[4], x[6])
        xv: Vec = (x[2], x[5])
        d2 = 0.0
        for j, z, rv in meas:
            block, i = _IN_BLOCK[j]
            if block == 0:
                xh, Ph, term = _update_horizontal(xh, Ph, i, z, rv)
            else:
                xv, Pv, term = _update_vertical(xv, Pv, i, z, rv)
            d2 += term
            if not d2 <= gate:  # nan, or past the gate (the terms are >= 0): gated
                break
        if not math.isfinite(d2) or d2 > gate:
            nrej = prev.nrej + 1
            if nrej >= self.p.reinit_after and r.position is not None:
                return self.init(r), "reinit"
            return _Post(prev.t, prev.x, prev.Ph, prev.Pv, nrej, prev.yaw, prev.t_fix), "gated"
        x = (xh[0], xh[1], xv[0], xh[2], xh[3], xv[1], xh[4])
        t_fix = r.t if r.position is not None else prev.t_fix
        return _Post(r.t, x, Ph, Pv, 0, _course(x, held), t_fix), "fused"

    def _measurements(self, r: Report) -> list[tuple[int, float, float]]:
        """(state index, value, variance) of each component the report measures."""
        meas: list[tuple[int, float, float]] = []
        if r.position is not None:
            meas += zip((0, 1, 2), _floats(r.position), self._pos_var(r), strict=True)
        if r.velocity is not None:
            vv = self.p.velocity_noise_m_s**2
            meas += ((j, z, vv) for j, z in zip((3, 4, 5), _floats(r.velocity), strict=True))
        if r.turn_rate is not None:
            meas.append((6, float(r.turn_rate), self.p.turn_rate_noise_rad_s**2))
        return meas


class TargetEstimator:
    """The EKF with its report history and clock offset (see the module docstring).

    ``add(report, t_rx)`` with the receive time in the control base (s); ``state(t)`` at a
    control time t (s) gives a :class:`TargetState` or the reason why none.
    """

    def __init__(self, params: TargetFilterParams) -> None:
        self.p = params
        self.ekf = TargetEkf(params)
        self.q = self.ekf.q
        self.hist: list[Report] = []
        self.times: list[float] = []  # hist's report times, for bisect
        self.posts: list[_Post | None] = []
        self.anchor: _Post | None = None  # the posterior before hist[0]
        self.off: float | None = None  # clock offset + smallest delay (control - sender, s)
        self.rx_last = 0.0
        self.t_last = -math.inf  # newest report time (sender clock)
        self.att: tuple[float, float] | None = None  # newest reported attitude: (t, yaw)
        # trace of Q's position block over T: q_pos T^3 / 3 (state())
        self.q_pos = 2.0 * params.accel_noise_m_s2**2 + params.vertical_accel_noise_m_s2**2
        self.counts = dict(
            fused=0, gated=0, reinit=0, out_of_order=0, duplicate=0, too_late=0,
            clock_reset=0,
        )  # fmt: skip

    # -- clock -----------------------------------------------------------------------------
    def _clock(self, t: float, t_rx: float) -> bool:
        """Update the offset; False when the report is too late to use."""
        d = t_rx - t
        if self.off is not None:
            restarted = t < self.t_last - self.p.max_age_s  # the sender's clock went back
            jumped = d < self.off - self.p.max_age_s  # ... or forward
            if restarted or jumped:
                self.counts["clock_reset"] += 1
                self._reset()
        if self.off is None:
            self.off, self.rx_last = d, t_rx
            return True
        if d > self.off + self.p.max_age_s:
            self.counts["too_late"] += 1
            return False
        leaked = self.off + CLOCK_DRIFT * max(0.0, t_rx - self.rx_last)
        self.off = min(leaked, d)
        self.rx_last = max(self.rx_last, t_rx)
        return True

    def _reset(self) -> None:
        self.hist, self.times, self.posts, self.anchor = [], [], [], None
        self.off, self.t_last, self.att = None, -math.inf, None

    def shift_time_base(self, dt: float) -> None:
        """The control time base moved: new = old - dt (s)."""
        if self.off is not None:
            self.off -= dt
        self.rx_last -= dt

    def to_sender(self, t: float) -> float | None:
        """Control time t (s) -> the sender's clock, or None before any report."""
        if self.off is None:
            return None
        return t - self.off + self.p.latency_s

    # -- reports ---------------------------------------------------------------------------
    def add(self, r: Report, t_rx: float) -> str:
        """Take one report; returns what became of it: fused, gated, reinit, duplicate,
        too_late, waiting (no position yet to start from)."""
        if not self._clock(r.t, t_rx):
            return "too_late"
        if r.attitude and r.yaw is not None and (self.att is None or r.t >= self.att[0]):
            self.att = (r.t, float(r.yaw))
        hist = self.hist
        if r.position is not None:
            # FOLLOW_TARGET and GLOBAL_POSITION_INT of one instant carry the same fix
            i = bisect.bisect_left(self.times, r.t)
            j = i
            while j < len(hist) and hist[j].t == r.t:
                if hist[j].position is not None:
                    self.counts["duplicate"] += 1
                    return "duplicate"
                j += 1
        if hist and r.t < self.anchor_t():
            self.counts["too_late"] += 1
            return "too_late"
        k = bisect.bisect_right(self.times, r.t)
        if k < len(hist):
            self.counts["out_of_order"] += 1
        hist.insert(k, r)
        self.times.insert(k, r.t)
        self.posts.insert(k, None)
        outcome = ""
        for i in range(k, len(hist)):  # replay from the insertion on
            prev = self.anchor if i == 0 else self.posts[i - 1]
            post, what = self.ekf.fuse(prev, hist[i])
            self.posts[i] = post
            if i == k:
                outcome = what
        self.t_last = max(self.t_last, r.t)
        if outcome in ("fused", "gated", "reinit"):
            self.counts[outcome] += 1
        self._prune()
        return outcome

    def known_position(self, t: float, t_rx: float) -> str | None:
        """For a position-only report (no attitude) at sender time t (s) received at t_rx (s),
        what :meth:`add` would make of it before the report itself matters: "too_late", or
        "duplicate" (another report of that instant already carries a position: FOLLOW_TARGET
        and GLOBAL_POSITION_INT of one fix), with the same clock update and counts; else None,
        and :meth:`add` takes the report (its clock update then repeats this one: a no-op).
        Lets the caller skip building a report (geodetic conversion) that would be dropped."""
        if not self._clock(t, t_rx):
            return "too_late"
        hist, j = self.hist, bisect.bisect_left(self.times, t)
        while j < len(hist) and hist[j].t == t:
            if hist[j].position is not None:
                self.counts["duplicate"] += 1
                return "duplicate"
            j += 1
        return None

    def anchor_t(self) -> float:
        return self.anchor.t if self.anchor is not None else -math.inf

    def _prune(self) -> None:
        keep_from = self.t_last - self.p.history_s
        while len(self.hist) > 1 and self.hist[0].t < keep_from:
            self.hist.pop(0)
            self.times.pop(0)
            self.anchor = self.posts.pop(0)

    # -- output ----------------------------------------------------------------------------
    def latest(self) -> _Post | None:
        for post in reversed(self.posts):
            if post is not None:
                return post
        return self.anchor

    def predicted(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float] | None:
        """(mean, 7 x 7 covariance, held yaw) at control time t (s), or None without a state."""
        ts = self.to_sender(t)
        post = self.latest()
        if ts is None or post is None:
            return None
        x, Ph, Pv = _predict(post.x, post.Ph, post.Pv, ts - post.t, self.q)
        return np.array(x), full_covariance(Ph, Pv), post.yaw

    def position_sigma(self, t: float) -> float:
        """Predicted position uncertainty (m) at control time t (s): the radial 1-sigma plus
        the manoeuvre term (module docstring); inf without a state."""
        pr = self.predicted(t)
        ts = self.to_sender(t)
        post = self.latest()
        if pr is None or ts is None or post is None:
            return math.inf
        return self._sigma(pr[1], ts - post.t_fix)

    def _sigma(self, P: NDArray[np.float64], age: float) -> float:
        tau = max(0.0, age)
        sig = math.sqrt(max(0.0, float(P[0, 0] + P[1, 1] + P[2, 2])))
        return sig + 0.5 * self.p.manoeuvre_accel_m_s2 * tau * tau

    def state(self, t: float) -> TargetState | str:
        """The target at control time t (s), or why it cannot be placed."""
        placed = self.place(t)
        return placed if isinstance(placed, str) else self.build(t, placed)

    def place(self, t: float) -> tuple[float, ...] | str:
        """Where :meth:`state` puts the target at control time t (s): the predicted mean
        ``(n, e, d, vn, ve, vd, w)`` and the frame's yaw, or why it cannot be placed;
        :meth:`build` makes the state of it. Apart so that the bridge decides now whether the
        target can be placed and builds the state its logs need after the setpoint went out.

        Every control step (twice: the sample's instant and the predicted one), so in scalars:
        the mean and only the trace of the predicted position covariance (trace(Fp P Fp') +
        trace(Q_pos), Fp the position rows of F), not the whole of P."""
        p = self.p
        off = self.off
        post = self.latest()
        if off is None or post is None:
            return "no live target yet"
        ts = t - off + p.latency_s  # to_sender(t)
        age = ts - post.t_fix
        if age > p.max_age_s:
            return f"live target stale ({age:.2f} s since its last position)"
        T = ts - post.t
        x = post.x
        if T > 0.0:
            cw, sw, s, c, ds, dc = _turn_terms(x[6], T)
            var = _position_variance(x, post.Ph, post.Pv, T, s, c, ds, dc)
            var += self.q_pos * T**3 / 3.0
            x = _mean(x, T, cw, sw, s, c)
        else:
            var = post.Ph[0] + post.Ph[5] + post.Pv[0]
            if T < 0.0:
                x = transition_mean(x, T)
        sig = math.sqrt(max(0.0, var)) + 0.5 * p.manoeuvre_accel_m_s2 * max(0.0, age) ** 2
        if sig > p.max_position_sigma_m:
            return (
                f"live target stale (position uncertainty {sig:.2f} m > "
                f"{p.max_position_sigma_m:g} m, {age:.2f} s since its last position)"
            )
        att = self.att
        if att is not None and ts - att[0] <= p.attitude_timeout_s:
            yaw = att[1] + x[6] * (ts - att[0])  # the target's own yaw, turned at the turn rate
        else:
            yaw = _course(x, post.yaw)
        return (*x, yaw)

    @staticmethod
    def build(t: float, placed: tuple[float, ...]) -> TargetState:
        """The state at control time t (s) of what :meth:`place` gave for t: position,
        velocity, acceleration w [-ve, vn, 0], omega [0, 0, w], omega_dot 0, R = rot_z(yaw),
        its arrays built when first read (the law reads its floats)."""
        n, e, d, vn, ve, vd, w, yaw = placed
        cy, sy = math.cos(yaw), math.sin(yaw)
        return target_state_of_floats(
            t, (cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0, n, e, d, vn, ve, vd,
                -w * ve, w * vn, 0.0, 0.0, 0.0, w, 0.0, 0.0, 0.0),
        )  # fmt: skip


__all__ = ["Report", "TargetEstimator", "TargetFilterParams", "chi2_quantile"]
