"""A flight's verdict: did it fail, and why, in one line (issue 13, "honest verdicts").

A run that ends its mission is not yet a flight that worked. :func:`judge` looks at the flown
time series (the plant's truth in ``sim``; the bridge's estimates in ``run``) against bounds of
the ``metrics`` section and the vehicle's limits:

- tracking: |pt| above ``metrics.fail_pt_m`` at any time after ``metrics.steady_after_s``
  (the capture is over by then; the demo converges in ~30-40 s of its 120);
- altitude: below ``metrics.altitude_floor_m`` above the local origin (home) at any time;
- airspeed: outside [airspeed_min (1 - tol), airspeed_max (1 + tol)] (``vehicle``,
  ``metrics.airspeed_tolerance``) for longer than ``metrics.limit_hold_s`` at a stretch
  (turbulence takes the demo's X8 2 m/s under its 14 m/s minimum for moments: not a failure);
- attitude: |bank| above ``vehicle.max_bank_rad`` + ``metrics.bank_tolerance_rad`` or |pitch|
  above ``metrics.pitch_limit_rad`` for longer than ``metrics.limit_hold_s``;
- loss of control: |bank| > 90 deg or |pitch| > 60 deg at any instant (no fixed-wing mission
  flies there).

Pure: arrays in, clauses out. The CLI prints :func:`verdict_line` last and exits
:data:`EXIT_VERDICT` when a flight that otherwise ended normally failed its verdict.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: exit code of a flight that ran to its end but failed its verdict (3: refused by the checks,
#: 4: a safety exit of the bridge)
EXIT_VERDICT = 5

LOSS_OF_CONTROL_BANK_RAD = math.pi / 2
LOSS_OF_CONTROL_PITCH_RAD = math.pi / 3


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


def judge(
    cfg: Any,
    t: np.ndarray,
    pt_norm: np.ndarray,
    altitude: np.ndarray | None = None,
    airspeed: np.ndarray | None = None,
    roll: np.ndarray | None = None,
    pitch: np.ndarray | None = None,
) -> list[str]:
    """The failures (one clause each, empty when the flight passed).

    t: s since engagement; pt_norm: |pt| (m); altitude: m above the local origin (up);
    airspeed: m/s; roll, pitch: rad. Arrays of the same length; None = not judged.
    """
    m, v = cfg.metrics, cfg.vehicle
    t = np.asarray(t, float)
    out: list[str] = []
    if len(t) == 0:
        return out
    if roll is not None and pitch is not None:
        r, p = np.abs(np.asarray(roll, float)), np.abs(np.asarray(pitch, float))
        lost = (r > LOSS_OF_CONTROL_BANK_RAD) | (p > LOSS_OF_CONTROL_PITCH_RAD)
        if lost.any():
            k = int(np.argmax(lost))
            out.append(
                f"loss of control at t = {t[k]:.1f} s (bank {math.degrees(r[k]):.0f} deg, "
                f"pitch {math.degrees(p[k]):.0f} deg)"
            )
    if altitude is not None:
        alt = np.asarray(altitude, float)
        k = int(np.argmin(alt))
        if alt[k] < m.altitude_floor_m:
            out.append(
                f"altitude {alt[k]:.1f} m at t = {t[k]:.1f} s, below the floor {m.altitude_floor_m:g} m"
            )
    hold = m.limit_hold_s
    if airspeed is not None:
        a = np.asarray(airspeed, float)
        lo, hi = v.v_min * (1.0 - m.airspeed_tolerance), v.v_max * (1.0 + m.airspeed_tolerance)
        dur, t_at = _longest_run((a < lo) | (a > hi), t)
        if dur > hold:
            out.append(
                f"airspeed outside [{lo:.1f}, {hi:.1f}] m/s for {dur:.1f} s from t = {t_at:.1f} s"
            )
    if roll is not None and pitch is not None:
        bank_lim = v.max_bank_rad + m.bank_tolerance_rad
        dur, t_at = _longest_run(np.abs(np.asarray(roll, float)) > bank_lim, t)
        if dur > hold:
            out.append(
                f"bank beyond {math.degrees(bank_lim):.0f} deg for {dur:.1f} s from t = {t_at:.1f} s"
            )
        dur, t_at = _longest_run(np.abs(np.asarray(pitch, float)) > m.pitch_limit_rad, t)
        if dur > hold:
            out.append(
                f"pitch beyond {math.degrees(m.pitch_limit_rad):.0f} deg for {dur:.1f} s from t = {t_at:.1f} s"
            )
    steady = t >= m.steady_after_s
    if steady.any():
        pts = np.asarray(pt_norm, float)[steady]
        k = int(np.argmax(pts))
        if not pts[k] <= m.fail_pt_m:  # NaN fails too
            out.append(
                f"|pt| {pts[k]:.1f} m at t = {t[steady][k]:.1f} s after convergence "
                f"(bound {m.fail_pt_m:g} m from t = {m.steady_after_s:g} s)"
            )
    return out


def verdict_line(failures: list[str]) -> str:
    """One line: ``verdict: PASS`` or ``verdict: FAIL: <clause>; <clause>``."""
    return "verdict: PASS" if not failures else "verdict: FAIL: " + "; ".join(failures)


__all__ = ["EXIT_VERDICT", "judge", "verdict_line"]
