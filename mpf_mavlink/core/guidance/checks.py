"""Checks run before anything flies: Assumption 1, the theorem's gain condition and region of
attraction, and feasibility of the path and target motion for the vehicle. Pure functions."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from mpf_mavlink.constants import FT_TO_M, GRAVITY_M_S2
from mpf_mavlink.core.adapter import bank_and_load_factor
from mpf_mavlink.core.guidance.law import Gains
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetMotion, state_floats
from mpf_mavlink.core.vec3 import Mat3, Vec3, cross, dot, mat_T_vec


@dataclass(frozen=True)
class CheckResult:
    """One check: ``status`` is "pass", "warn" (outside the guarantee but flyable) or "fail"."""

    name: str
    status: str
    summary: str
    figures: dict[str, float | bool | None] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status != "fail"


def _times(horizon: float, dt: float) -> np.ndarray:
    n = max(2, int(math.ceil(horizon / dt)) + 1)
    return np.linspace(0.0, horizon, n)


def assumption1(
    path: TabulatedPath,
    target: TargetMotion,
    v_w_min: float,
    horizon_s: float,
    wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gust_max_m_s: float = 0.0,
    margin_m_s: float = 0.0,
    dt_s: float = 0.5,
) -> CheckResult:
    """Assumption 1: v_w > |v_t t1 + v_d - eta| for every path point over the horizon.

    The wind enters because the vehicle's airspeed must out-run the path point relative to the
    air; gusts add their peak magnitude (worst case). Samples s every ~1 m and t every dt_s.
    """
    n_s = int(min(4000, max(200, path.length)))
    ss = np.linspace(0.0, path.length, n_s, endpoint=not path.closed)
    P = np.array([path.eval(float(s))[0] for s in ss])  # (n, 3) in {T}
    eta = np.asarray(wind_ned, float)
    worst, t_worst, s_worst = 0.0, 0.0, 0.0
    for t in _times(horizon_s, dt_s):
        st = target.state(float(t))
        pdI = P @ st.R_T_I.T
        wI = st.R_T_I @ st.omega_T
        u = st.velocity[None, :] + np.cross(wI[None, :], pdI) - eta[None, :]
        sp = np.linalg.norm(u, axis=1) + gust_max_m_s
        i = int(np.argmax(sp))
        if sp[i] > worst:
            worst, t_worst, s_worst = float(sp[i]), float(t), float(ss[i])
    margin = v_w_min - worst
    ok = margin > margin_m_s
    return CheckResult(
        "assumption_1",
        "pass" if ok else "fail",
        f"max |v_t t1 + v_d - eta| = {worst:.2f} m/s at t = {t_worst:.1f} s, s = {s_worst:.1f} m; "
        f"v_w,min = {v_w_min:.2f} m/s, margin {margin:.2f} m/s",
        {"max_path_point_speed_m_s": worst, "margin_m_s": margin, "t_worst_s": t_worst},
    )


def gain_condition(
    gains: Gains,
    v_w_min: float,
    v_w_max: float,
    c1: float,
    c2: float,
    pt0: float | None = None,
    psi0: float | None = None,
) -> CheckResult:
    """The theorem's condition [conditionsGainAndK] and its region of attraction.

    K = min(K_p, v_min / sqrt(alpha^2 + c1^2)); needs K K_R > v_max^2 / (c1^2 (1 - 2 c2)^2).
    lambda_MPF = lambda_min(W) / lambda_max(M2) with k1 = 1/(4 c1^2),
    W = [[2 k1 K, -2 k1 v_max/(1-2c2)], [., K_R/2]], M2 = diag(k1, 1/(1-c2)).
    Region: |pt(0)| <= c1 and Psi(0) <= c2 (< 1/2). Outside it the law usually still converges
    (the estimate is conservative), so an initial state outside is a warning, not a failure.
    """
    K = min(gains.K_p, v_w_min / math.sqrt(gains.alpha**2 + c1**2))
    K_R_needed = v_w_max**2 / (c1**2 * (1.0 - 2.0 * c2) ** 2 * K)
    k1 = 1.0 / (4.0 * c1**2)
    off = -2.0 * k1 * v_w_max / (1.0 - 2.0 * c2)
    W = np.array([[2.0 * k1 * K, off], [off, gains.K_R / 2.0]])
    lam_W = float(np.linalg.eigvalsh(W)[0])
    lam_M2 = max(k1, 1.0 / (1.0 - c2))
    lam = lam_W / lam_M2
    ok = gains.K_R > K_R_needed
    figs: dict[str, float | bool | None] = {
        "K": K,
        "K_R": gains.K_R,
        "K_R_needed": K_R_needed,
        "lambda_mpf": lam,
        "c1_m": c1,
        "c2": c2,
    }
    text = (
        f"K = {K:.4g}, K_R = {gains.K_R:.4g} vs needed > {K_R_needed:.4g}, "
        f"lambda_MPF = {lam:.4g} 1/s (c1 = {c1:.3g} m, c2 = {c2:.3g})"
    )
    status = "pass" if ok else "fail"
    if pt0 is not None and psi0 is not None:
        inside = pt0 <= c1 and psi0 <= c2
        figs.update({"pt0_m": pt0, "psi0": psi0, "initial_inside_region": inside})
        text += f"; initial |pt| = {pt0:.2f} m, Psi = {psi0:.3f}: "
        text += "inside the region of attraction" if inside else "outside the guaranteed region"
        if ok and not inside:
            status = "warn"
    return CheckResult("gain_condition", status, text, figs)


def demanded_directions(
    path: TabulatedPath,
    target: TargetMotion,
    v_w: float,
    horizon_s: float,
    s0: float = 0.0,
    wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
    dt_s: float = 0.05,
    with_positions: bool = False,
) -> Any:
    """(t (s), wd1 (n, 3)): the air-relative direction flying the moving path exactly demands
    at airspeed v_w over the horizon (see :func:`feasibility`); with_positions: also the path
    point flown (NED m, (n, 3))."""
    e0, e1, e2 = (float(x) for x in wind_ned)
    ts = _times(horizon_s, dt_s)
    tl = ts.tolist()
    s = s0
    # A sequential integration (s follows sdot), so a loop, in scalar arithmetic: on 3-vectors
    # numpy's per-call cost would be most of the work (vec3's module docstring).
    W1: list[tuple[float, float, float]] = []
    P: list[tuple[float, float, float]] = []
    for k, t in enumerate(tl):
        f = state_floats(target.state(t))
        # R_T^I's rows as the columns of mat_T_vec's matrix: mat_T_vec(rows, x) = R_T^I x
        R = cast(Mat3, (f[0:3], f[3:6], f[6:9]))
        (p0, p1, p2), (v0, v1, v2) = f[9:12], f[12:15]
        pd, f1, f2, f3 = path.eval(s)[:4]
        pdI, f1I, f2I, f3I = mat_T_vec(R, pd), mat_T_vec(R, f1), mat_T_vec(R, f2), mat_T_vec(R, f3)
        P.append((p0 + pdI[0], p1 + pdI[1], p2 + pdI[2]))
        c = cross(mat_T_vec(R, cast(Vec3, f[18:21])), pdI)
        u = (v0 + c[0] - e0, v1 + c[1] - e1, v2 + c[2] - e2)
        a21, a31 = dot(u, f2I) / v_w, dot(u, f3I) / v_w
        a11 = math.sqrt(max(1e-12, 1.0 - a21 * a21 - a31 * a31))
        W1.append((a11 * f1I[0] + a21 * f2I[0] + a31 * f3I[0],
                   a11 * f1I[1] + a21 * f2I[1] + a31 * f3I[1],
                   a11 * f1I[2] + a21 * f2I[2] + a31 * f3I[2]))  # fmt: skip
        sdot = v_w * a11 - dot(u, f1I)
        if k + 1 < len(tl):
            s += sdot * (tl[k + 1] - t)
    W1a, Pa = np.array(W1).reshape(-1, 3), np.array(P).reshape(-1, 3)
    return (ts, W1a, Pa) if with_positions else (ts, W1a)


# MIL-F-8785C Fig. 7: sigma (ft/s) of medium/high-altitude turbulence at 500, 1750, 3750 and
# 7500 ft for the probability-of-exceedance rows the SIL's levels use (light 10^-2, moderate
# 10^-3, severe 10^-5), and the low-altitude W20 (ft/s) of sim/plant/atmosphere.TURBULENCE_LEVELS
_POE_ALT_FT = (500.0, 1750.0, 3750.0, 7500.0)
_POE_SIGMA_FPS = {
    "light": (6.6, 6.9, 7.4, 6.7),
    "moderate": (8.6, 9.6, 10.6, 10.1),
    "severe": (15.6, 17.6, 23.0, 23.6),
}
_W20_FPS = {"light": 25.0, "moderate": 50.0, "severe": 75.0}


def vertical_gust_scale(level: str, h_m: float) -> tuple[float, float]:
    """(sigma_w m/s, L_w m) of MIL-F-8785C Dryden turbulence at height h_m, as JSBSim's Milspec
    model computes them (with h the altitude above sea level, as it passes): below 1000 ft
    sigma_w = 0.1 W20, L_w = h; above 2000 ft the tabulated sigma and L = 1750 ft; linear
    between. ``none``: (0, 0)."""
    if level not in _W20_FPS:
        return 0.0, 0.0
    h = max(h_m / FT_TO_M, 10.0)
    s_low = 0.1 * _W20_FPS[level]
    s_tab = float(np.interp(h, _POE_ALT_FT, _POE_SIGMA_FPS[level]))
    if h <= 1000.0:
        sig, L = s_low, h
    elif h <= 2000.0:
        f = (h - 1000.0) / 1000.0
        sig, L = s_low + f * (s_tab - s_low), 1000.0 + f * 750.0
    else:
        sig, L = s_tab, 1750.0
    return sig * FT_TO_M, L * FT_TO_M


def vertical_gusts(
    level: str, heights_asl_m: np.ndarray, v_w: float, n_sigma: float = 2.0
) -> tuple[np.ndarray, np.ndarray]:
    """(w, T) per sample for :func:`climb_feasibility`: n_sigma sigma_w sustained over the
    turbulence's time scale L_w / v_w at each height (m above sea level)."""
    sc = [vertical_gust_scale(level, float(h)) for h in heights_asl_m]
    return (
        np.array([n_sigma * s for s, _ in sc]),
        np.array([L / max(v_w, 1.0) for _, L in sc]),
    )


def windowed_gust(sigma_w: float, L_w: float, v: float, T: float) -> tuple[float, float]:
    """(sigma_T m/s, nu_0 1/s) of the vertical gust averaged over a window of T s, flown at v m/s
    through MIL-F-8785C Dryden turbulence of intensity sigma_w (m/s) and scale L_w (m).

    The Dryden vertical spectrum in time (one-sided, integrating to sigma_w^2):
    Phi(w) = sigma_w^2 L / (pi v) (1 + 3 (L w / v)^2) / (1 + (L w / v)^2)^2; a T-s mean passes
    it through |H(w)|^2 = sinc^2(w T / 2). sigma_T^2 = m0 = int Phi |H|^2 dw, and Rice's
    up-crossing rate of the mean through zero is nu_0 = sqrt(m2 / m0) / (2 pi), m2 = int w^2
    Phi |H|^2 dw (finite: |H|^2 Phi falls as w^-4). Both by quadrature on a log grid."""
    if not (sigma_w > 0.0 and L_w > 0.0 and v > 0.0 and T > 0.0):
        return 0.0, 0.0
    tau = L_w / v
    w = np.logspace(-4.0, 3.0, 4000) / tau
    x2 = (tau * w) ** 2
    phi = sigma_w * sigma_w * tau / math.pi * (1.0 + 3.0 * x2) / (1.0 + x2) ** 2
    h2 = np.sinc(w * T / (2.0 * math.pi)) ** 2
    m0 = float(np.trapezoid(phi * h2, w))
    m2 = float(np.trapezoid(w * w * phi * h2, w))
    return math.sqrt(m0), math.sqrt(m2 / m0) / (2.0 * math.pi)


# Window lengths (s) over which the gust judgement averages the turbulence: a gust shorter than
# ~2 s is carried by the airframe's own speed and pitch response, one longer than a minute is the
# steady deficit's; between them a factor 1.5 apart (sigma_T changes by < 10 % from one to the next)
GUST_WINDOWS_S = (2.0, 3.0, 4.5, 7.0, 10.0, 15.0, 23.0, 35.0, 52.0)
# refuse when a gust beyond the reserve is more likely than not over the horizon, warn above 10 %
GUST_REFUSE_P, GUST_WARN_P = 0.5, 0.1
# height (m) a gust may cost beyond the reserve before it counts: less is a tracking error the
# law takes out within seconds (the X8's steady RMS is ~0.1 m), not an energy failure
GUST_TOLERANCE_M = 1.0


@dataclass(frozen=True)
class GustOdds:
    """The likeliest way a gust exhausts the reserve (:func:`gust_odds`): probability over the
    horizon, the window (s), where it is likeliest (s), the mean gust there (m/s) and its sigma."""

    p: float
    window_s: float
    t_s: float
    gust_m_s: float
    sigma_m_s: float


def gust_odds(
    ts: np.ndarray,
    need: np.ndarray,
    reserve: np.ndarray,
    level: str,
    heights_asl_m: np.ndarray,
    v_w: float,
    windows_s: tuple[float, ...] = GUST_WINDOWS_S,
    tolerance_m: float = GUST_TOLERANCE_M,
) -> GustOdds:
    """Probability that a vertical gust averaged over some window exhausts the energy reserve.

    A window of T s from t_k against the capability: the steady part of the demand beyond it,
    ``need`` (m/s: climb - max_climb for downdrafts, -climb - max_sink for updrafts), averaged
    over the window, n_k; the reserve R_k (m, ``reserve``). A mean gust above
    u_k = (R_k + tolerance_m) / T - n_k over that window costs more height than the reserve
    holds, by more than ``tolerance_m``. By Rice's
    formula the expected number of such gusts is N_T = sum_k dt nu_0 exp(-u_k^2 / (2 sigma_T^2))
    (sigma_T, nu_0: :func:`windowed_gust` at the sample's height; the level is crossed from
    below, counted once per crossing, only where u_k > 0: a deficit without a gust is the
    steady check's), and the chance of at least one is 1 - exp(-N_T) (Poisson). Windows of
    neighbouring lengths see the same gusts, so the largest over ``windows_s`` is reported
    (a lower bound of their union). One sign of gust per call."""
    best = GustOdds(0.0, 0.0, float(ts[0]), 0.0, 0.0)
    if len(ts) < 2:
        return best
    dts = np.diff(ts, prepend=ts[0])
    cum = np.concatenate([[0.0], np.cumsum(need * dts)])
    # the turbulence's scale changes slowly with height: evaluate it on 10 m steps
    hq = np.round(np.asarray(heights_asl_m, float) / 10.0) * 10.0
    for T in windows_s:
        j = np.minimum(np.searchsorted(ts, ts + T), len(ts) - 1)
        span = ts[j] - ts
        ok = span >= 0.5 * T  # the horizon's last windows are shorter than T: not this window
        if not np.any(ok):
            continue
        k = np.arange(len(ts))
        mean_n = np.where(ok, (cum[j + 1] - cum[k + 1]) / np.maximum(span, 1e-9), 0.0)
        u = (np.asarray(reserve, float) + tolerance_m) / T - mean_n
        sig = np.zeros(len(ts))
        nu = np.zeros(len(ts))
        for h in np.unique(hq):
            s_w, L_w = vertical_gust_scale(level, float(h))
            st, n0 = windowed_gust(s_w, L_w, v_w, T)
            sig[hq == h], nu[hq == h] = st, n0
        live = ok & (sig > 0.0)
        rate = np.zeros(len(ts))
        z = np.where(live, np.maximum(u, 0.0) / np.where(live, sig, 1.0), 0.0)
        rate[live] = nu[live] * np.exp(-0.5 * z[live] ** 2)
        n_exp = float(np.sum(rate * dts))
        p = 1.0 - math.exp(-n_exp)
        if p > best.p:
            kk = int(np.argmax(rate))
            best = GustOdds(p, T, float(ts[kk]), float(max(u[kk], 0.0)), float(sig[kk]))
    return best


@dataclass
class _Deficits:
    """The largest height deficits (m) of :func:`climb_feasibility` beyond the climb (up) and
    the sink (dn) capability, the times they peak (s), the climb / sink needed at the worst
    instant (m/s, gusts included) and the gust that set the climb's."""

    worst_up: float
    t_up: float
    worst_dn: float
    t_dn: float
    need_up: float
    need_dn: float
    gust_note: str = ""

    def refusal(
        self, res_up: float, res_dn: float, v_w: float, v_min: float, v_max: float
    ) -> str | None:
        """Why the path is refused (a deficit beyond its reserve, m), or None."""
        if self.worst_up > res_up:
            return (
                f"the path climbs faster than the aircraft can for long: {self.worst_up:.1f} m "
                f"of height beyond its climb by t = {self.t_up:.1f} s{self.gust_note}, more than "
                f"the {res_up:.1f} m that slowing from {v_w:g} to {v_min:.1f} m/s buys; "
            )
        if self.worst_dn > res_dn:
            return (
                f"the path descends faster than the aircraft can at idle: {self.worst_dn:.1f} m "
                f"beyond its sink by t = {self.t_dn:.1f} s (updrafts included), more than the "
                f"{res_dn:.1f} m that speeding up to {v_max:.1f} m/s absorbs; "
            )
        return None


def _steady_deficits(
    ts: np.ndarray,
    c: np.ndarray,
    dts: np.ndarray,
    max_climb: float,
    max_sink: float,
    up: float,
    dn: float,
) -> _Deficits:
    """D(t) = max(0, D + (c - max_climb) dt) (and likewise for the sink): its peak and when."""
    d_up = d_dn = 0.0
    worst_up = worst_dn = 0.0
    t_up = t_dn = float(ts[0])
    for k in range(len(ts)):
        d_up = max(0.0, d_up + (c[k] - max_climb) * dts[k])
        d_dn = max(0.0, d_dn + (-c[k] - max_sink) * dts[k])
        if d_up > worst_up:
            worst_up, t_up = d_up, float(ts[k])
        if d_dn > worst_dn:
            worst_dn, t_dn = d_dn, float(ts[k])
    return _Deficits(worst_up, t_up, worst_dn, t_dn, up, dn)


def _add_gust_deficits(
    dfc: _Deficits,
    ts: np.ndarray,
    c: np.ndarray,
    dts: np.ndarray,
    gusts: tuple[np.ndarray, np.ndarray],
    max_climb: float,
    max_sink: float,
) -> None:
    """A gust of w for T from each instant on top of the mean demand over that window: the
    excess beyond the capability is a deficit like the steady one (dfc updated in place)."""
    w, T = gusts
    cum = np.concatenate([[0.0], np.cumsum(c * dts)])
    for k in range(len(ts)):
        j = int(np.searchsorted(ts, ts[k] + T[k]))
        j = min(j, len(ts) - 1)
        span = float(ts[j] - ts[k])
        if span <= 0.0:
            continue
        mean_c = float(cum[j + 1] - cum[k + 1]) / span
        # the gust lasts T or until the horizon ends, whichever is first
        dfc.need_up = max(dfc.need_up, mean_c + w[k])
        dfc.need_dn = max(dfc.need_dn, -mean_c + w[k])
        gu = max(0.0, mean_c + w[k] - max_climb) * span
        gd = max(0.0, -mean_c + w[k] - max_sink) * span
        if gu > dfc.worst_up:
            dfc.worst_up, dfc.t_up = gu, float(ts[k])
            dfc.gust_note = f" (a {w[k]:.1f} m/s downdraft for {T[k]:.0f} s from t = {ts[k]:.0f} s)"
        if gd > dfc.worst_dn:
            dfc.worst_dn, dfc.t_dn = gd, float(ts[k])


def _demand(
    ts: np.ndarray, W1: np.ndarray, v_w: float, max_climb: float | None, max_sink: float | None
) -> tuple[np.ndarray, float, float, dict[str, float | bool | None], str]:
    """The air-relative climb c = -v_w wd1_z (m/s) per sample, its peak climb and sink (m/s, >= 0),
    the check's first figures and the sentence that heads its summary."""
    c = -v_w * W1[:, 2]
    k_up, k_dn = int(np.argmax(c)), int(np.argmin(c))
    up, dn = max(0.0, float(c[k_up])) + 0.0, max(0.0, float(-c[k_dn])) + 0.0
    figs: dict[str, float | bool | None] = {
        "peak_climb_m_s": up, "peak_sink_m_s": dn,
        "max_climb_m_s": max_climb, "max_sink_m_s": max_sink,
    }  # fmt: skip
    head = (
        f"the path demands up to {up:.2f} m/s of climb at t = {ts[k_up]:.1f} s and "
        f"{dn:.2f} m/s of sink at t = {ts[k_dn]:.1f} s"
    )
    return c, up, dn, figs, head


def _turbulence_odds(
    ts: np.ndarray, c: np.ndarray, caps: tuple[float, float], v_w: float,
    turbulence: tuple[str, np.ndarray, np.ndarray, np.ndarray],
    figs: dict[str, float | bool | None],
) -> tuple[GustOdds, str]:  # fmt: skip
    """The likelier of a downdraft and an updraft exhausting its reserve (:func:`gust_odds`
    against the climb and sink capability ``caps``, m/s), and the sentence that says so; the
    two probabilities go into ``figs``."""
    level, hts, r_up, r_dn = turbulence
    o_up = gust_odds(ts, c - caps[0], r_up, level, hts, v_w)
    o_dn = gust_odds(ts, -c - caps[1], r_dn, level, hts, v_w)
    figs.update(gust_p_down=o_up.p, gust_p_up=o_dn.p)
    worst, what = (o_up, "downdraft") if o_up.p >= o_dn.p else (o_dn, "updraft")
    r_at = float(np.interp(worst.t_s, ts, r_up if what == "downdraft" else r_dn))
    odds = (
        f"a {worst.window_s:g} s {what} of {worst.gust_m_s:.1f} m/s "
        f"({worst.gust_m_s / max(worst.sigma_m_s, 1e-9):.1f} sigma of {level} turbulence's "
        f"{worst.window_s:g} s mean, {worst.sigma_m_s:.2f} m/s) near t = {worst.t_s:.0f} s "
        f"exhausts the {r_at:.1f} m energy reserve: {100.0 * worst.p:.0f} % likely over the "
        f"{ts[-1] - ts[0]:.0f} s"
    )
    return worst, odds


def _marginal(
    up: float, dn: float, dfc: _Deficits, caps: tuple[float, float],
    reserves: tuple[float, float], marginal: float, gust_marg: bool, with_gusts: bool,
) -> tuple[bool, str]:  # fmt: skip
    """Whether the demand is marginal (the steady peak above ``marginal`` x the capability
    ``caps`` (m/s), a gust's above the capability itself, or half a reserve (m) spent), and the
    words that say how close it is."""
    (max_climb, max_sink), (res_up, res_dn) = caps, reserves
    marg = (
        gust_marg
        or up > marginal * max_climb or dn > marginal * max_sink
        or dfc.need_up > max_climb or dfc.need_dn > max_sink
        or dfc.worst_up > 0.5 * res_up or dfc.worst_dn > 0.5 * res_dn
    )  # fmt: skip
    why = (
        f": marginal: climb up to {dfc.need_up:.2f} and sink up to {dfc.need_dn:.2f} m/s needed"
        + (" with the turbulence's 2-sigma gusts" if with_gusts else "")
        + f" (warn above the capability, {marginal:g} x without gusts), deficits "
        f"{dfc.worst_up:.1f} / {dfc.worst_dn:.1f} m of the {res_up:.1f} / {res_dn:.1f} m "
        "reserves (warn above half)"
    )
    return marg, why


def climb_feasibility(
    ts: np.ndarray,
    W1: np.ndarray,
    v_w: float,
    v_min: float,
    v_max: float,
    max_climb_m_s: float | None,
    max_sink_m_s: float | None,
    marginal: float = 0.8,
    g: float = GRAVITY_M_S2,
    gusts: tuple[np.ndarray, np.ndarray] | None = None,
    turbulence: tuple[str, np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> CheckResult:
    """The climb and descent the path demands (air-relative: path slope, target climb, vertical
    wind; c = -v_w wd1_z) against the aircraft's steady capability at v_w.

    A climb beyond max_climb for a while is paid from kinetic energy: the speed may fall from
    v_w to v_min, a reserve of (v_w^2 - v_min^2) / (2 g) m of height (a descent beyond max_sink
    fills v_max likewise). The deficit D(t) = max(0, D + (c - max_climb) dt) is the largest
    integral of the excess over any interval: D above the reserve is refused (the airspeed
    cannot be held), a peak demand above ``marginal`` x the capability or D above half the
    reserve warns. Unknown capability (None): a warning when the path climbs or sinks at all.
    v_min, v_max: the airspeeds the flight may reach (the verdict's window).
    gusts: (w (m/s), T (s)) per sample: a vertical gust of w sustained for T (turbulence: 2
    sigma_w over the Dryden time scale L_w / V, :func:`vertical_gusts`). A downdraft adds w to the
    climb, an updraft to the sink, for T from each instant: the excess over that window beyond
    the capability is a deficit like the steady one.
    turbulence: (level, heights above sea level (m), climb reserve (m), sink reserve (m)) per
    sample: the odds that a gust averaged over any of :data:`GUST_WINDOWS_S` exhausts that
    reserve (:func:`gust_odds`, downdrafts and updrafts): at least GUST_REFUSE_P over the
    horizon is refused, GUST_WARN_P warns. The reserves are the adapter's (from the airspeed it
    flies to the airspeed where it gives the path up), not the verdict's window.
    """
    c, up, dn, figs, head = _demand(ts, W1, v_w, max_climb_m_s, max_sink_m_s)
    if max_climb_m_s is None or max_sink_m_s is None:
        st = "warn" if max(up, dn) > 0.5 else "pass"
        return CheckResult(
            "climb", st, head + " (capability unknown: set vehicle.max_climb_rate_m_s and "
            "vehicle.max_sink_rate_m_s)", figs,
        )  # fmt: skip
    caps = (max_climb_m_s, max_sink_m_s)
    res_up = max(v_w * v_w - v_min * v_min, 0.0) / (2.0 * g)
    res_dn = max(v_max * v_max - v_w * v_w, 0.0) / (2.0 * g)
    dts = np.diff(ts, prepend=ts[0])
    dfc = _steady_deficits(ts, c, dts, max_climb_m_s, max_sink_m_s, up, dn)
    if gusts is not None:
        _add_gust_deficits(dfc, ts, c, dts, gusts, max_climb_m_s, max_sink_m_s)
    figs.update(deficit_climb_m=dfc.worst_up, deficit_sink_m=dfc.worst_dn, reserve_climb_m=res_up,
                reserve_sink_m=res_dn)  # fmt: skip
    cap = f" (capability at {v_w:g} m/s: climb {max_climb_m_s:g}, sink {max_sink_m_s:g} m/s)"
    refused = dfc.refusal(res_up, res_dn, v_w, v_min, v_max)
    if refused is not None:
        return CheckResult("climb", "fail", refused + head + cap, figs)
    odds, gust_marg = "", False
    if turbulence is not None:
        worst, odds = _turbulence_odds(ts, c, caps, v_w, turbulence, figs)
        if worst.p >= GUST_REFUSE_P:
            return CheckResult(
                "climb", "fail",
                f"turbulence beyond the aircraft's energy: {odds} (refused from "
                f"{100.0 * GUST_REFUSE_P:.0f} %); " + head + cap, figs,
            )  # fmt: skip
        gust_marg = worst.p >= GUST_WARN_P  # the likelier sign's odds
    figs.update(need_climb_m_s=dfc.need_up, need_sink_m_s=dfc.need_dn)
    marg, why = _marginal(
        up, dn, dfc, caps, (res_up, res_dn), marginal, gust_marg, gusts is not None
    )
    if gust_marg:
        why += f"; {odds} (warn from {100.0 * GUST_WARN_P:.0f} %)"
    return CheckResult(
        "climb", "warn" if marg else "pass", head + cap + (why if marg else ""), figs
    )


def feasibility(
    path: TabulatedPath,
    target: TargetMotion,
    v_w: float,
    horizon_s: float,
    max_bank_rad: float,
    max_turn_rate_rad_s: float | None = None,
    s0: float = 0.0,
    wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
    dt_s: float = 0.05,
    bank_margin_rad: float = 0.0,
    turn_gain: float = 1.0,
    demanded: tuple[Any, Any] | None = None,
) -> CheckResult:
    """Peak turn rate and bank that flying the moving path exactly demands at airspeed v_w.

    On the path (pt = 0) the air-relative direction is wd1 and the virtual point moves at
    sdot = v_w wd11 - (v_t t1 + v_d - eta) . f1. We integrate s over the horizon, difference
    wd1 in time for the turn rate |d wd1/dt| (rad/s) and get the bank from the acceleration
    v_w d wd1/dt with gravity (steady wind does not change the air-relative acceleration).
    The bank must stay ``bank_margin_rad`` below the limit (and the turn rate below the rate of
    that bank): a path flown at the limit leaves the feedback nothing to correct with.
    ``turn_gain`` is the turn the aircraft really flies per bank, as a fraction of the
    coordinated turn (the adapter's learned turn gain): it needs tan(bank) / turn_gain to turn
    as the path asks (an airframe that turns 25 % less needs 37.6 deg where the textbook says
    29.8), and its turn-rate limit is turn_gain g tan(limit) / v_w. ``demanded``: the (t, wd1)
    of :func:`demanded_directions` for these arguments, when the caller has them already.
    """
    if demanded is None:
        demanded = demanded_directions(path, target, v_w, horizon_s, s0, wind_ned, dt_s)
    ts, W1 = demanded
    dW = np.gradient(W1, ts, axis=0)
    rate = np.linalg.norm(dW, axis=1)
    banks = np.array(
        [abs(bank_and_load_factor(tuple(W1[k]), tuple(v_w * dW[k]))[0]) for k in range(len(ts))]
    )
    if turn_gain != 1.0:
        banks = np.arctan(np.tan(banks) / turn_gain)
    k_r, k_b = int(np.argmax(rate)), int(np.argmax(banks))
    bank_ok = max(max_bank_rad - bank_margin_rad, 0.0)
    limit_rate = (
        max_turn_rate_rad_s
        if max_turn_rate_rad_s is not None
        else turn_gain * GRAVITY_M_S2 * math.tan(bank_ok) / v_w
    )
    ok = banks[k_b] <= bank_ok and rate[k_r] <= limit_rate
    return CheckResult(
        "feasibility",
        "pass" if ok else "fail",
        f"peak turn rate {rate[k_r]:.3f} rad/s at t = {ts[k_r]:.1f} s (limit {limit_rate:.3f}); "
        f"peak bank {math.degrees(banks[k_b]):.1f} deg at t = {ts[k_b]:.1f} s "
        f"(limit {math.degrees(max_bank_rad):.1f}"
        + (f" - {math.degrees(bank_margin_rad):.1f} margin" if bank_margin_rad > 0 else "")
        + (f"; turn gain {turn_gain:g})" if turn_gain != 1.0 else ")"),
        {
            "peak_turn_rate_rad_s": float(rate[k_r]),
            "turn_rate_limit_rad_s": limit_rate,
            "peak_bank_rad": float(banks[k_b]),
            "bank_limit_rad": max_bank_rad,
            "bank_margin_rad": bank_margin_rad,
            "turn_gain": turn_gain,
        },
    )


def autopilot_profile_limits(
    label: str,
    airspeed_m_s: float,
    full_thrust_airspeed_m_s: float | None,
    turned: CheckResult,
    turn_gain: float,
) -> CheckResult:
    """What the SIL's autopilot profile can fly (``label`` names it): the law's airspeed
    (m/s) below the level airspeed the profile's full thrust flies (level flight at full
    thrust leaves nothing to climb or turn with), and the path's bank within the limit at the
    profile's turn per bank (``turned``: :func:`feasibility` at ``turn_gain``)."""
    fig: dict[str, float | bool | None] = {
        "airspeed_m_s": airspeed_m_s,
        "full_thrust_airspeed_m_s": full_thrust_airspeed_m_s,
        "turn_gain": turn_gain,
        "peak_bank_rad": turned.figures.get("peak_bank_rad"),
        "bank_limit_rad": turned.figures.get("bank_limit_rad"),
    }
    if full_thrust_airspeed_m_s is not None and airspeed_m_s >= full_thrust_airspeed_m_s:
        return CheckResult(
            "autopilot_profile", "fail",
            f"{label}: airspeed {airspeed_m_s:g} m/s needs more thrust than the profile's full "
            f"thrust flies (level {full_thrust_airspeed_m_s:g} m/s at thrust 1); fly slower or "
            "use sil.autopilot_profile: auto (the autopilot's part, the airframe's own thrust)",
            fig,
        )  # fmt: skip
    if not turned.ok:
        pb = math.degrees(float(turned.figures.get("peak_bank_rad") or 0.0))
        lim = math.degrees(float(turned.figures.get("bank_limit_rad") or 0.0))
        mg = math.degrees(float(turned.figures.get("bank_margin_rad") or 0.0))
        return CheckResult(
            "autopilot_profile", "fail",
            f"{label}: bank {pb:.1f} deg beyond the limit {lim:.1f} deg"
            + (f" - {mg:.1f} margin" if mg > 0 else "")
            + f" at the profile's turn gain {turn_gain:g} ({turned.summary})",
            fig,
        )  # fmt: skip
    words = f"{label}: turn gain {turn_gain:g}, {turned.summary}"
    if full_thrust_airspeed_m_s is not None:
        words += f"; full thrust flies {full_thrust_airspeed_m_s:g} m/s level"
    return CheckResult("autopilot_profile", "pass", words, fig)
