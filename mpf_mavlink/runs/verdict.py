"""A flight's verdict: did it fail, why, or could it not be judged, in one line.

A run that ends its mission is not yet a flight that worked. :func:`assess` looks at the flown
time series (the plant's truth in ``sim``; the bridge's telemetry and the thrust it sent in
``run``) against the bounds of the ``metrics`` section and the vehicle's limits. Each failure is
one clause of a class, so that the verdict tells an energy problem from a tracking one:

- ``safety``: loss of control (|bank| > 90 deg or |pitch| > 60 deg at any instant: no
  fixed-wing mission flies there); altitude below ``metrics.altitude_floor_m`` above home.
- ``attitude``: |bank| beyond the vehicle's bank limit (the smaller of ``vehicle.max_bank_rad``
  and ``vehicle.autopilot_bank_limit_rad``) + ``metrics.bank_tolerance_rad`` (5 deg), or |pitch|
  beyond ``metrics.pitch_limit_rad``, for longer than ``metrics.limit_hold_s`` at a stretch; |bank|
  within ``checks.bank_margin_rad`` of the limit for more than ``metrics.limit_fraction`` of the
  steady window (the turn is saturated: the feedback has nothing left to correct with).
- ``energy``: airspeed outside [airspeed_min (1 - tol), airspeed_max (1 + tol)]
  (``metrics.airspeed_tolerance``) for longer than ``metrics.limit_hold_s``; the steady window's
  mean airspeed more than ``airspeed_tolerance`` from ``vehicle.airspeed_m_s`` (the law assumes
  that airspeed); thrust at its ceiling (``adapter.thrust_max``) for more than
  ``metrics.limit_fraction`` of the steady window (the airspeed is held, if at all, with no
  margin left).
- ``tracking``: |pt| above ``metrics.fail_pt_m`` at any time after ``metrics.steady_after_s``.

Why these tolerances (also docs/checks.md): ``bank_tolerance_rad`` 5 deg mirrors above the limit the
margin ``checks.bank_margin_rad`` keeps below it for the feedback and gusts (the autopilot clips the
set-point; the roll loop overshoots it: the demo's capture reaches 47.6-47.9 deg); the time beyond
the limit itself is reported (:func:`limits_line`). ``limit_hold_s`` 1 s is ~3 time constants of an
autopilot's roll loop (PX4 FW_R_TC 0.4 s, ArduPlane ~0.3-0.5 s, the X8's 0.19 s roll mode): a gust
that rolls the aircraft past its limit is corrected within it, a bank held longer is demanded.
``airspeed_tolerance`` 15 % is the light-turbulence allowance of the checks (2 m/s, about 2 sigma at
100 m) at the X8's 14 m/s minimum. ``limit_fraction`` 20 %: a path that passes the feasibility check
needs no bank in the margin band at all, and the level flight the checks assume needs trim thrust
(0.22 on the X8), far from the ceiling; a fifth of the steady window there is no longer a gust.

A flight whose steady window (``t >= steady_after_s``) is shorter than ``metrics.min_steady_s``
and that broke no limit is NOT JUDGED (exit :data:`EXIT_NOT_JUDGED`): its tracking figures are
n/a and "PASS" would be unexamined.

Pure: arrays in, a :class:`Verdict` out. The CLI prints :meth:`Verdict.line` last.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mpf_mavlink.config.schema import Config, MetricsConfig, VehicleConfig, bank_limit_rad

#: exit code of a flight that ran to its end but failed its verdict (3: refused by the checks,
#: 4: a safety exit of the bridge)
EXIT_VERDICT = 5
#: exit code of a flight that ran to its end but was too short to judge (no steady window)
EXIT_NOT_JUDGED = 6

LOSS_OF_CONTROL_BANK_RAD = math.pi / 2
LOSS_OF_CONTROL_PITCH_RAD = math.pi / 3

#: the order in which the classes are named (the first is what to look at first)
CLASSES = ("safety", "energy", "attitude", "tracking")
#: thrust within this of its ceiling counts as at the ceiling (the adapter clips to it exactly;
#: the SIL plant's throttle is the commanded one, rounded)
THRUST_CEILING_EPS = 0.005


def _longest_run(mask: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """(longest duration s, its start time s) of consecutive True samples of ``mask``."""
    best, start = 0.0, math.nan
    i, n = 0, len(mask)
    while i < n:
        if not mask[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and mask[j + 1]:
            j += 1
        # a sample stands for the time to the next one (the last: to itself)
        end = t[j + 1] if j + 1 < n else t[j]
        if end - t[i] > best:
            best, start = float(end - t[i]), float(t[i])
        i = j + 1
    return best, start


def _time_fraction(mask: np.ndarray, t: np.ndarray) -> tuple[float, float, float]:
    """(fraction of the time, seconds, first time s) that ``mask`` holds; each sample stands for
    the time to the next one."""
    if len(t) < 2:
        return (float(mask.mean()) if len(mask) else 0.0), 0.0, math.nan
    dt = np.diff(t, append=t[-1])
    total = float(t[-1] - t[0])
    secs = float(np.sum(dt[mask]))
    first = float(t[int(np.argmax(mask))]) if mask.any() else math.nan
    return (secs / total if total > 0 else float(mask.mean())), secs, first


def thrust_ceiling(cfg: Config) -> float:
    """The adapter's thrust ceiling (0..1): ``adapter.thrust_max``."""
    return cfg.adapter.thrust_max


@dataclass
class Verdict:
    """The judgement of one flight: failures (``(class, clause)``), or why it was not judged,
    and the figures it was judged on (``figures``: max bank, time at the limits, ...)."""

    failures: list[tuple[str, str]] = field(default_factory=list)
    not_judged: str | None = None
    figures: dict[str, Any] = field(default_factory=dict)
    # what the line names besides its judgement (the bridge's envelope episodes: a limit the
    # law could not get is said, whether or not it failed the flight)
    notes: list[str] = field(default_factory=list)

    @property
    def status(self) -> str:
        """``PASS``, ``FAIL`` or ``NOT JUDGED``."""
        if self.failures:
            return "FAIL"
        return "NOT JUDGED" if self.not_judged else "PASS"

    @property
    def classes(self) -> list[str]:
        """The failed classes in :data:`CLASSES` order."""
        seen = {c for c, _ in self.failures}
        return [c for c in CLASSES if c in seen]

    @property
    def clauses(self) -> list[str]:
        """``class: clause`` for each failure, the most basic class first."""
        order = {c: i for i, c in enumerate(CLASSES)}
        return [f"{c}: {s}" for c, s in sorted(self.failures, key=lambda x: order[x[0]])]

    def line(self) -> str:
        """One line: ``verdict: PASS``, ``verdict: FAIL (energy, tracking): energy: ...; ...``
        or ``verdict: NOT JUDGED: <why>``."""
        note = "".join(f" [{n}]" for n in self.notes)
        if self.failures:
            return f"verdict: FAIL ({', '.join(self.classes)}): " + "; ".join(self.clauses) + note
        if self.not_judged:
            return f"verdict: NOT JUDGED: {self.not_judged}" + note
        return "verdict: PASS" + note

    def exit_code(self, code: int = 0) -> int:
        """The run's exit code: ``code`` when the run ended otherwise than normally (refused,
        a safety exit, ...), else 0, :data:`EXIT_VERDICT` or :data:`EXIT_NOT_JUDGED`."""
        if code not in (0, EXIT_VERDICT, EXIT_NOT_JUDGED):
            return code
        if self.failures:
            return EXIT_VERDICT
        return EXIT_NOT_JUDGED if self.not_judged else 0

    def record(self, metrics: dict[str, Any]) -> None:
        """Into a run's metrics: ``verdict`` (the line), ``verdict_status``,
        ``verdict_classes``, ``verdict_failures``, ``verdict_figures``."""
        metrics["verdict"] = self.line()
        metrics["verdict_status"] = self.status
        metrics["verdict_classes"] = self.classes
        metrics["verdict_failures"] = self.clauses
        metrics["verdict_figures"] = self.figures
        metrics["verdict_notes"] = self.notes


@dataclass
class _Window:
    """What every clause of :func:`assess` judges against: the flight's times, its steady
    window, the hold and fraction limits, and where the failures and figures go."""

    m: MetricsConfig
    t: np.ndarray
    steady: np.ndarray
    steady_s: float
    judged_steady: bool
    out: list[tuple[str, str]]
    fig: dict[str, Any]

    @property
    def hold(self) -> float:
        return self.m.limit_hold_s

    @property
    def frac_lim(self) -> float:
        return self.m.limit_fraction


def _judge_loss_of_control(w: _Window, roll: np.ndarray, pitch: np.ndarray) -> None:
    r, p = np.abs(np.asarray(roll, float)), np.abs(np.asarray(pitch, float))
    lost = (r > LOSS_OF_CONTROL_BANK_RAD) | (p > LOSS_OF_CONTROL_PITCH_RAD)
    if lost.any():
        k = int(np.argmax(lost))
        w.out.append(("safety", f"loss of control at t = {w.t[k]:.1f} s (bank "
                      f"{math.degrees(r[k]):.0f} deg, pitch "
                      f"{math.degrees(p[k]):.0f} deg)"))  # fmt: skip


def _judge_altitude(w: _Window, altitude: np.ndarray) -> None:
    m = w.m
    alt = np.asarray(altitude, float)
    k = int(np.argmin(alt))
    w.fig["min_altitude_m"] = float(alt[k])
    w.fig["altitude_floor_m"] = m.altitude_floor_m
    if alt[k] < m.altitude_floor_m:
        w.out.append(("safety", f"altitude {alt[k]:.1f} m at t = {w.t[k]:.1f} s, below the "
                      f"floor {m.altitude_floor_m:g} m (metrics.altitude_floor_m)"))  # fmt: skip


def _judge_airspeed(w: _Window, v: VehicleConfig, airspeed: np.ndarray) -> None:
    m, t, hold = w.m, w.t, w.hold
    a = np.asarray(airspeed, float)
    lo, hi = v.v_min * (1.0 - m.airspeed_tolerance), v.v_max * (1.0 + m.airspeed_tolerance)
    w.fig.update(airspeed_band_m_s=[lo, hi], airspeed_m_s=v.airspeed_m_s,
                 min_airspeed_m_s=float(np.nanmin(a)),
                 max_airspeed_m_s=float(np.nanmax(a)))  # fmt: skip
    dur, t_at = _longest_run((a < lo) | (a > hi), t)
    if dur > hold:
        w.out.append(("energy", f"airspeed outside [{lo:.1f}, {hi:.1f}] m/s for {dur:.1f} s "
                      f"from t = {t_at:.1f} s (limit {hold:g} s)"))  # fmt: skip
    if w.judged_steady:
        mean = float(np.nanmean(a[w.steady]))
        w.fig["steady_mean_airspeed_m_s"] = mean
        dv = m.airspeed_tolerance * v.airspeed_m_s
        if not abs(mean - v.airspeed_m_s) <= dv:
            w.out.append(("energy", f"airspeed not held: mean {mean:.1f} m/s from t = "
                          f"{m.steady_after_s:g} s for {w.steady_s:.0f} s against the "
                          f"{v.airspeed_m_s:g} m/s the law assumes "
                          f"(limit +-{dv:.1f} m/s)"))  # fmt: skip


def _judge_thrust(w: _Window, ceil: float, thrust: np.ndarray) -> None:
    t, steady, frac_lim = w.t, w.steady, w.frac_lim
    thr = np.asarray(thrust, float)
    at = thr >= ceil - THRUST_CEILING_EPS
    w.fig["thrust_max"] = ceil
    w.fig["thrust_at_ceiling_fraction"] = _time_fraction(at, t)[0]
    if w.judged_steady:
        frac, secs, first = _time_fraction(at[steady], t[steady])
        w.fig["steady_thrust_at_ceiling_fraction"] = frac
        if frac > frac_lim:
            w.out.append(("energy", f"thrust at its ceiling {ceil:g} for {100 * frac:.0f} % "
                          f"of the steady window ({secs:.0f} of {w.steady_s:.0f} s, first at "
                          f"t = {first:.1f} s; limit {100 * frac_lim:.0f} %)"))  # fmt: skip


def _judge_attitude(
    w: _Window, roll: np.ndarray, pitch: np.ndarray, bank_lim: float, band: float
) -> None:
    m, t, hold, fig, steady, frac_lim = w.m, w.t, w.hold, w.fig, w.steady, w.frac_lim
    r, p = np.abs(np.asarray(roll, float)), np.abs(np.asarray(pitch, float))
    lim = bank_lim + m.bank_tolerance_rad
    over = r > lim
    # reported: the time beyond the limit itself; failed: beyond it + the tolerance, held
    fig.update(max_bank_rad=float(np.nanmax(r)), max_pitch_rad=float(np.nanmax(p)),
               bank_beyond_limit_s=_time_fraction(r > bank_lim, t)[1],
               bank_beyond_limit_longest_s=_longest_run(r > bank_lim, t)[0])  # fmt: skip
    dur, t_at = _longest_run(over, t)
    if dur > hold:
        w.out.append(("attitude", f"bank beyond {math.degrees(lim):.1f} deg for {dur:.1f} s "
                      f"from t = {t_at:.1f} s (max {math.degrees(fig['max_bank_rad']):.1f} deg; "
                      f"limit {hold:g} s)"))  # fmt: skip
    dur, t_at = _longest_run(p > m.pitch_limit_rad, t)
    if dur > hold:
        w.out.append(("attitude", f"pitch beyond {math.degrees(m.pitch_limit_rad):.0f} deg for "
                      f"{dur:.1f} s from t = {t_at:.1f} s (limit {hold:g} s)"))  # fmt: skip
    if w.judged_steady:
        frac, secs, first = _time_fraction(r[steady] >= band, t[steady])
        fig["steady_bank_at_limit_fraction"] = frac
        if frac > frac_lim:
            w.out.append(("attitude", f"bank at its limit (>= {math.degrees(band):.1f} of "
                          f"{math.degrees(bank_lim):.1f} deg) for {100 * frac:.0f} % of the "
                          f"steady window ({secs:.0f} of {w.steady_s:.0f} s, first at t = "
                          f"{first:.1f} s; limit {100 * frac_lim:.0f} %): "
                          "the turn is saturated"))  # fmt: skip


def _judge_tracking(w: _Window, pt_norm: np.ndarray) -> None:
    m, t, steady = w.m, w.t, w.steady
    pts = np.asarray(pt_norm, float)[steady]
    k = int(np.argmax(pts))
    if not pts[k] <= m.fail_pt_m:  # NaN fails too
        w.out.append(("tracking", f"|pt| {pts[k]:.1f} m at t = {t[steady][k]:.1f} s after "
                      f"convergence (bound {m.fail_pt_m:g} m from "
                      f"t = {m.steady_after_s:g} s)"))  # fmt: skip


def assess(
    cfg: Config,
    t: np.ndarray,
    pt_norm: np.ndarray,
    altitude: np.ndarray | None = None,
    airspeed: np.ndarray | None = None,
    roll: np.ndarray | None = None,
    pitch: np.ndarray | None = None,
    thrust: np.ndarray | None = None,
    source: str = "truth",
) -> Verdict:
    """Judge a flight.

    t: s since engagement; pt_norm: |pt| (m); altitude: m above the local origin (up);
    airspeed: m/s; roll, pitch: rad; thrust: 0..1 (applied in SIL, commanded on a real
    flight). Arrays of the same length; None = not judged. ``source`` says what the arrays are
    (``truth`` or ``telemetry``) for the figures.
    """
    m = cfg.metrics
    t = np.asarray(t, float)
    vd = Verdict(figures={"source": source})
    fig = vd.figures
    if len(t) == 0:
        vd.not_judged = "no flight was recorded"
        return vd
    steady = t >= m.steady_after_s
    steady_s = float(t[-1] - m.steady_after_s) if steady.any() else 0.0
    judged_steady = steady_s >= m.min_steady_s and steady.sum() >= 2
    w = _Window(m, t, steady, steady_s, judged_steady, vd.failures, fig)
    fig.update(tracked_s=float(t[-1]), steady_after_s=m.steady_after_s, steady_s=steady_s)
    bank_lim = bank_limit_rad(cfg)
    band = max(bank_lim - cfg.checks.bank_margin_rad, 0.0)
    fig.update(bank_limit_rad=bank_lim, bank_tolerance_rad=m.bank_tolerance_rad,
               bank_band_rad=band, pitch_limit_rad=m.pitch_limit_rad,
               limit_hold_s=m.limit_hold_s, limit_fraction=m.limit_fraction)  # fmt: skip
    if roll is not None and pitch is not None:
        _judge_loss_of_control(w, roll, pitch)
    if altitude is not None:
        _judge_altitude(w, altitude)
    if airspeed is not None:
        _judge_airspeed(w, cfg.vehicle, airspeed)
    if thrust is not None:
        _judge_thrust(w, thrust_ceiling(cfg), thrust)
    if roll is not None and pitch is not None:
        _judge_attitude(w, roll, pitch, bank_lim, band)
    if judged_steady:
        _judge_tracking(w, pt_norm)
    else:
        vd.not_judged = (
            f"tracked {t[-1]:.1f} s, steady window {steady_s:.1f} s from t = "
            f"{m.steady_after_s:g} s (metrics.steady_after_s) is shorter than "
            f"metrics.min_steady_s = {m.min_steady_s:g} s: fly longer or lower steady_after_s"
        )
    return vd


def limits_line(figures: dict[str, Any]) -> str | None:
    """One line of what the verdict measured against the limits (so that a limit touched
    within its tolerance is said, not silent): max bank and the time beyond its limit, thrust
    at its ceiling, the steady mean airspeed. None without figures."""
    f = figures or {}
    parts = []
    if f.get("max_bank_rad") is not None and f.get("bank_limit_rad") is not None:
        parts.append(
            f"max bank {math.degrees(f['max_bank_rad']):.1f} deg (limit "
            f"{math.degrees(f['bank_limit_rad']):.1f}: {f.get('bank_beyond_limit_s', 0.0):.1f} s "
            f"beyond, longest {f.get('bank_beyond_limit_longest_s', 0.0):.1f} s; fails beyond "
            f"{math.degrees(f['bank_limit_rad'] + f.get('bank_tolerance_rad', 0.0)):.1f} for "
            f"{f.get('limit_hold_s', 0):g} s)"
        )
    if f.get("steady_thrust_at_ceiling_fraction") is not None:
        parts.append(
            f"thrust at its ceiling {100 * f['steady_thrust_at_ceiling_fraction']:.0f} % of the "
            f"steady window (limit {100 * f.get('limit_fraction', 0):.0f} %)"
        )
    elif f.get("thrust_at_ceiling_fraction") is not None:
        parts.append(
            f"thrust at its ceiling {100 * f['thrust_at_ceiling_fraction']:.0f} % of the flight"
        )
    if f.get("steady_mean_airspeed_m_s") is not None:
        parts.append(
            f"steady mean airspeed {f['steady_mean_airspeed_m_s']:.1f} m/s (law "
            f"{f.get('airspeed_m_s', 0):g})"
        )
    if not parts:
        return None
    return f"limits ({f.get('source', '?')}): " + "; ".join(parts)


def verdict_line(failures: list[str]) -> str:
    """One line for a list of ``class: clause`` failures: ``verdict: PASS`` or
    ``verdict: FAIL: <clause>; <clause>`` (a :class:`Verdict` says more: :meth:`Verdict.line`)."""
    return "verdict: PASS" if not failures else "verdict: FAIL: " + "; ".join(failures)
