"""The target estimator exactly as it was before its scalar rewrite (main 5d64e11: numpy linear
algebra per fix), frozen.

tests/test_target_filter_equivalence.py compares the rewritten filter against this copy on
long report streams (in order, late, gated, re-initialised, malformed). Not used by the package.
"""
# ruff: noqa
# mypy: ignore-errors

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core import so3
from mpf_mavlink.core.target import TargetState

#: Upward leak of the clock-offset minimum (s per s): follows a sender clock drifting by up to
#: 100 ppm (crystal clocks: 20-50 ppm) while a single fast report does not fix it for ever.
CLOCK_DRIFT = 1e-4
#: Below this horizontal speed (m/s) the course does not define the frame's yaw.
MIN_COURSE_SPEED_M_S = 0.5
#: Initial 1-sigma of what the first report does not carry.
INIT_VEL_SIGMA_M_S = 5.0
INIT_TURN_SIGMA_RAD_S = 0.05

N = 7  # state size
_POS = slice(0, 3)
_VEL = slice(3, 6)
_EYE = np.eye(N)
_EYE.setflags(write=False)


@dataclass(frozen=True)
class TargetFilterParams:
    """Tuning and limits of :class:`TargetEstimator` (SI units; noise terms are 1-sigma, the
    process terms square roots of white-noise spectral densities)."""

    accel_noise_m_s2: float = 0.15  # horizontal acceleration, m/s^2/sqrt(Hz)
    vertical_accel_noise_m_s2: float = 0.05  # m/s^2/sqrt(Hz)
    turn_accel_noise_rad_s2: float = 0.003  # turn-rate random walk, rad/s/sqrt(s)
    position_noise_m: float = 2.0  # horizontal, per axis, when the report carries none
    vertical_noise_m: float = 3.0
    velocity_noise_m_s: float = 0.3  # per axis
    turn_rate_noise_rad_s: float = 0.01  # attitude-derived turn rate
    gate_probability: float = 0.9999
    reinit_after: int = 3
    max_position_sigma_m: float = 4.0  # stale beyond (predicted, radial, see position_sigma)
    manoeuvre_accel_m_s2: float = 0.3  # what the target may do unseen (staleness only)
    max_age_s: float = 10.0  # stale beyond, whatever the uncertainty
    latency_s: float = 0.0  # known smallest transport delay of the reports
    history_s: float = 10.0  # reports kept for re-ordering late ones
    attitude_timeout_s: float = 1.0  # a reported attitude older than this no longer sets {T}


@dataclass(frozen=True)
class Report:
    """One report of the target. ``t``: the sender's timestamp (s). position / velocity: NED (m,
    m/s) or None; pos_var: variances (m^2, n/e/d) or None for the configured noise; turn_rate:
    rad/s about down or None; yaw: rad or None (only used to hold the frame at low speed)."""

    t: float
    position: NDArray[np.float64] | None = None
    velocity: NDArray[np.float64] | None = None
    turn_rate: float | None = None
    yaw: float | None = None
    pos_var: NDArray[np.float64] | None = None
    attitude: bool = False  # yaw is the target's measured attitude (not a heading hint)


@dataclass(frozen=True)
class _Post:
    """The posterior after a report: time (sender clock), mean, covariance, gated reports in a
    row, the yaw held for low speeds, and the time of the newest fused position (what places
    the target: the staleness counts from it, not from attitude-only or gated reports)."""

    t: float
    x: NDArray[np.float64]
    P: NDArray[np.float64]
    nrej: int
    yaw: float
    t_fix: float


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


def transition(x: NDArray[np.float64], T: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(x', F): the coordinated-turn mean over T (s) and its Jacobian."""
    n, e, d, vn, ve, vd, w = x.tolist()
    cw, sw, s, c, ds, dc = _turn_terms(w, T)
    xp = np.array(
        (n + s * vn - c * ve, e + c * vn + s * ve, d + T * vd,
         cw * vn - sw * ve, sw * vn + cw * ve, vd, w)
    )  # fmt: skip
    F = np.eye(N)
    F[0, 3], F[0, 4], F[1, 3], F[1, 4] = s, -c, c, s
    F[2, 5] = T
    F[3, 3], F[3, 4], F[4, 3], F[4, 4] = cw, -sw, sw, cw
    F[0, 6] = ds * vn - dc * ve
    F[1, 6] = dc * vn + ds * ve
    F[3, 6] = -T * (sw * vn + cw * ve)
    F[4, 6] = T * (cw * vn - sw * ve)
    return xp, F


def transition_mean(x: list[float], T: float) -> tuple[float, ...]:
    """The coordinated-turn mean over T (s) of x (as a list): :func:`transition`'s x',
    the same expressions (so the same floats), without the Jacobian."""
    n, e, d, vn, ve, vd, w = x
    cw, sw, s, c, _, _ = _turn_terms(w, T)
    return (n + s * vn - c * ve, e + c * vn + s * ve, d + T * vd,
            cw * vn - sw * ve, sw * vn + cw * ve, vd, w)  # fmt: skip


def position_variance(x: list[float], P: list[list[float]], T: float) -> float:
    """trace(Fp P Fp'), Fp the position rows of :func:`transition`'s Jacobian at x over T (s):
    the predicted position variance before the process noise, in scalars (Fp is sparse: rows
    [1 0 0 s -c 0 F06], [0 1 0 c s 0 F16], [0 0 1 0 0 T 0])."""
    vn, ve, w = x[3], x[4], x[6]
    _, _, s, c, ds, dc = _turn_terms(w, T)
    f06 = ds * vn - dc * ve
    f16 = dc * vn + ds * ve
    var = P[2][2] + 2.0 * T * P[2][5] + T * T * P[5][5]  # row [0 0 1 0 0 T 0]
    P3, P4, P6 = P[3], P[4], P[6]
    for i, a, b, f in ((0, s, -c, f06), (1, c, s, f16)):  # rows at i, 3, 4, 6
        Pi = P[i]
        var += (
            (Pi[i] + a * Pi[3] + b * Pi[4] + f * Pi[6])
            + a * (P3[i] + a * P3[3] + b * P3[4] + f * P3[6])
            + b * (P4[i] + a * P4[3] + b * P4[4] + f * P4[6])
            + f * (P6[i] + a * P6[3] + b * P6[4] + f * P6[6])
        )
    return var


def process_noise(p: TargetFilterParams, T: float) -> NDArray[np.float64]:
    """Q over T (s): white acceleration per axis, random-walk turn rate."""
    Q = np.zeros((N, N))
    for i, q in ((0, p.accel_noise_m_s2**2), (1, p.accel_noise_m_s2**2),
                 (2, p.vertical_accel_noise_m_s2**2)):  # fmt: skip
        Q[i, i] = q * T**3 / 3.0
        Q[i, i + 3] = Q[i + 3, i] = q * T**2 / 2.0
        Q[i + 3, i + 3] = q * T
    Q[6, 6] = p.turn_accel_noise_rad_s2**2 * T
    return Q


def predict(
    p: TargetFilterParams, x: NDArray[np.float64], P: NDArray[np.float64], T: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    if T == 0.0:
        return x, P
    if T < 0.0:  # backwards (a control time before the posterior): the mean only
        return transition(x, T)[0], P
    xp, F = transition(x, T)
    Pp = F @ P @ F.T + process_noise(p, T)
    return xp, 0.5 * (Pp + Pp.T)


class TargetEstimator:
    """The EKF with its report history and clock offset (see the module docstring).

    ``add(report, t_rx)`` with the receive time in the control base (s); ``state(t)`` at a
    control time t (s) gives a :class:`TargetState` or the reason why none.
    """

    def __init__(self, params: TargetFilterParams) -> None:
        self.p = params
        self.gates = [0.0] + [chi2_quantile(params.gate_probability, k) for k in range(1, 8)]
        self.hist: list[Report] = []
        self.times: list[float] = []  # hist's report times, for bisect
        self.posts: list[_Post | None] = []
        self.anchor: _Post | None = None  # the posterior before hist[0]
        self.off: float | None = None  # clock offset + smallest delay (control - sender, s)
        self.rx_last = 0.0
        self.t_last = -math.inf  # newest report time (sender clock)
        self.att: tuple[float, float] | None = None  # newest reported attitude: (t, yaw)
        self._cache: tuple[_Post, list[float], list[list[float]]] | None = None  # _lists
        self._sel: dict[
            tuple[int, ...],
            tuple[NDArray[np.float64], NDArray[np.intp], tuple[NDArray[np.intp], ...]],
        ] = {}  # _selection
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
            post, what = self._fuse(prev, hist[i])
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

    def _init(self, r: Report, nrej: int = 0) -> _Post:
        assert r.position is not None
        pv = self._pos_var(r)
        x = np.zeros(N)
        x[_POS] = r.position
        P = np.zeros((N, N))
        P[_POS, _POS] = np.diag(pv)
        if r.velocity is not None:
            x[_VEL] = r.velocity
            P[_VEL, _VEL] = np.eye(3) * self.p.velocity_noise_m_s**2
        else:
            P[_VEL, _VEL] = np.eye(3) * INIT_VEL_SIGMA_M_S**2
        if r.turn_rate is not None:
            x[6] = r.turn_rate
            P[6, 6] = self.p.turn_rate_noise_rad_s**2
        else:
            P[6, 6] = INIT_TURN_SIGMA_RAD_S**2
        yaw = r.yaw if r.yaw is not None else 0.0
        return _Post(r.t, x, P, nrej, self._course(x, yaw), r.t)

    def _pos_var(self, r: Report) -> NDArray[np.float64]:
        if r.pos_var is not None:
            return np.asarray(r.pos_var, float)
        h, v = self.p.position_noise_m**2, self.p.vertical_noise_m**2
        return np.array((h, h, v))

    @staticmethod
    def _course(x: Sequence[float] | NDArray[np.float64], held: float) -> float:
        vn, ve = float(x[3]), float(x[4])
        if vn * vn + ve * ve > MIN_COURSE_SPEED_M_S**2:
            return math.atan2(ve, vn)
        return held

    def _fuse(self, prev: _Post | None, r: Report) -> tuple[_Post | None, str]:
        if prev is None:
            if r.position is None:
                return None, "waiting"
            return self._init(r), "fused"
        x, P = predict(self.p, prev.x, prev.P, r.t - prev.t)
        rows: list[int] = []
        z: list[float] = []
        rv: list[float] = []
        if r.position is not None:
            rows += [0, 1, 2]
            z += r.position.tolist()
            rv += self._pos_var(r).tolist()
        if r.velocity is not None:
            rows += [3, 4, 5]
            z += r.velocity.tolist()
            rv += [self.p.velocity_noise_m_s**2] * 3
        if r.turn_rate is not None:
            rows.append(6)
            z.append(float(r.turn_rate))
            rv.append(self.p.turn_rate_noise_rad_s**2)
        held = r.yaw if r.yaw is not None else prev.yaw
        if not rows:
            return _Post(r.t, x, P, prev.nrej, self._course(x, held), prev.t_fix), "fused"
        H, idx, block = self._selection(tuple(rows))
        nu = np.asarray(z) - x[idx]
        S = P[block] + np.diag(rv)
        d2 = float(nu @ np.linalg.solve(S, nu))
        if not math.isfinite(d2) or d2 > self.gates[len(rows)]:
            nrej = prev.nrej + 1
            if nrej >= self.p.reinit_after and r.position is not None:
                return self._init(r), "reinit"
            return _Post(prev.t, prev.x, prev.P, nrej, prev.yaw, prev.t_fix), "gated"
        K = np.linalg.solve(S, H @ P).T  # P H' S^-1 (S symmetric)
        x = x + K @ nu
        IKH = _EYE - K @ H
        P = IKH @ P @ IKH.T + K @ np.diag(rv) @ K.T  # Joseph form: stays symmetric positive
        t_fix = r.t if r.position is not None else prev.t_fix
        return _Post(r.t, x, 0.5 * (P + P.T), 0, self._course(x, held), t_fix), "fused"

    def _selection(
        self, rows: tuple[int, ...]
    ) -> tuple[NDArray[np.float64], NDArray[np.intp], tuple[NDArray[np.intp], ...]]:
        """(H, the rows as an index array, np.ix_ of them) of a measurement of those state rows:
        a handful of patterns, built once each."""
        sel = self._sel.get(rows)
        if sel is None:
            H = np.zeros((len(rows), N))
            H[range(len(rows)), rows] = 1.0
            sel = self._sel[rows] = (H, np.array(rows, np.intp), np.ix_(rows, rows))
        return sel

    # -- output ----------------------------------------------------------------------------
    def latest(self) -> _Post | None:
        for post in reversed(self.posts):
            if post is not None:
                return post
        return self.anchor

    def predicted(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float] | None:
        """(mean, covariance, held yaw) at control time t (s), or None without a state."""
        ts = self.to_sender(t)
        post = self.latest()
        if ts is None or post is None:
            return None
        x, P = predict(self.p, post.x, post.P, ts - post.t)
        return x, P, post.yaw

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
        sig = math.sqrt(max(0.0, float(np.trace(P[_POS, _POS]))))
        return sig + 0.5 * self.p.manoeuvre_accel_m_s2 * tau * tau

    def state(self, t: float) -> TargetState | str:
        """The target at control time t (s), or why it cannot be placed."""
        ts = self.to_sender(t)
        post = self.latest()
        if ts is None or post is None:
            return "no live target yet"
        age = ts - post.t_fix
        if age > self.p.max_age_s:
            return f"live target stale ({age:.2f} s since its last position)"
        # every control step: the mean and only the trace of the predicted position covariance
        # (trace(Fp P Fp') + trace(Q_pos), Fp the position rows of F), not the whole of P, in
        # scalars: numpy's per-call cost is most of it at this size
        T = ts - post.t
        xl, Pl = self._lists(post)
        x: tuple[float, ...] | list[float]
        if T > 0.0:
            x = transition_mean(xl, T)
            q = 2.0 * self.p.accel_noise_m_s2**2 + self.p.vertical_accel_noise_m_s2**2
            var = position_variance(xl, Pl, T) + q * T**3 / 3.0
        else:
            x = transition_mean(xl, T) if T < 0.0 else xl
            var = Pl[0][0] + Pl[1][1] + Pl[2][2]
        held = post.yaw
        sig = math.sqrt(max(0.0, var)) + 0.5 * self.p.manoeuvre_accel_m_s2 * max(0.0, age) ** 2
        if sig > self.p.max_position_sigma_m:
            return (
                f"live target stale (position uncertainty {sig:.2f} m > "
                f"{self.p.max_position_sigma_m:g} m, {age:.2f} s since its last position)"
            )
        vn, ve, w = x[3], x[4], x[6]
        att = self.att
        if att is not None and ts - att[0] <= self.p.attitude_timeout_s:
            yaw = att[1] + w * (ts - att[0])  # the target's own yaw, turned on at the turn rate
        else:
            yaw = self._course(x, held)
        return TargetState(
            t, np.array(x[0:3]), np.array(x[3:6]), np.array((-w * ve, w * vn, 0.0)),
            so3.rot_z(yaw), np.array((0.0, 0.0, w)), np.zeros(3),
        )  # fmt: skip

    def _lists(self, post: _Post) -> tuple[list[float], list[list[float]]]:
        """The posterior's mean and covariance as lists (kept for the latest posterior: the
        control steps between two reports all start from it)."""
        c = self._cache
        if c is None or c[0] is not post:
            c = self._cache = (post, post.x.tolist(), post.P.tolist())
        return c[1], c[2]


__all__ = ["Report", "TargetEstimator", "TargetFilterParams", "chi2_quantile"]
