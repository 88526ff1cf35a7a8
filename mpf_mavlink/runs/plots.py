"""The paper's figures for any run directory (``sim``, ``run``, ``replay``): 3D and planar views
of the vehicle's (recorded) path against the moving desired path, the target-relative path,
|pt|, Psi, sdot, w2 and w3 (commanded and achieved), and the setpoints sent (when the run has a
``setpoints.csv``).

Works from the files alone, so older run directories (without the target-attitude columns or
without setpoints) still plot; lines are broken across gaps in time (a replay of a log with
telemetry gaps) instead of joining them with straight segments.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.errors import MpfError


def _gapped(t: NDArray[np.float64], *ys: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Insert NaN after every step longer than 5 median steps, so lines break at gaps."""
    if len(t) < 3:
        return [t, *ys]
    dt = np.diff(t)
    cut = np.nonzero(dt > 5.0 * max(float(np.median(dt)), 1e-9))[0] + 1
    if len(cut) == 0:
        return [t, *ys]
    return [np.insert(np.asarray(a, float), cut, np.nan) for a in (t, *ys)]


def _rot_zyx(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _paths_ned(
    cols: dict[str, Any], path_T: NDArray[np.float64] | None
) -> list[tuple[float, NDArray[np.float64]]]:
    """The path in NED where the target carried it: at the start, the middle and the end of the
    run (one of them for a target that does not move). Empty without the target attitude."""
    need = ("tgt_n", "tgt_e", "tgt_d", "tgt_roll", "tgt_pitch", "tgt_yaw")
    if path_T is None or len(path_T) == 0 or not all(k in cols for k in need):
        return []
    n = len(cols["t"])
    out: list[tuple[float, NDArray[np.float64]]] = []
    for k in sorted({0, n // 2, n - 1}):
        R = _rot_zyx(cols["tgt_roll"][k], cols["tgt_pitch"][k], cols["tgt_yaw"][k])
        p = np.array([cols["tgt_n"][k], cols["tgt_e"][k], cols["tgt_d"][k]])
        P = path_T @ R.T + p
        if out and np.max(np.abs(P - out[-1][1])) < 1e-6:
            continue  # the target did not move: one drawing is enough
        out.append((float(cols["t"][k]), P))
    return out


def _read_columns(f: Path, min_rows: int = 1) -> dict[str, NDArray[np.float64]] | None:
    """The columns of a CSV file with a header line, by name; None when the file is missing,
    unreadable, ragged or has fewer than ``min_rows`` rows."""
    if not f.is_file():
        return None
    try:
        header = f.open().readline().strip().split(",")
        A = np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError):
        return None
    if A.size == 0 or A.shape[1] != len(header) or A.shape[0] < min_rows:
        return None
    return {c: A[:, i] for i, c in enumerate(header)}


def _read_setpoints(d: Path) -> dict[str, NDArray[np.float64]] | None:
    return _read_columns(d / "setpoints.csv")


def _steady_after(metrics: dict[str, Any]) -> float | None:
    """The start of the steady window (s since engagement) the run was judged with."""
    vf = metrics.get("verdict_figures") or {}
    v = vf.get("steady_after_s", metrics.get("steady_after_s"))
    return float(v) if isinstance(v, int | float) else None


def _mark_window(ax: Any, t: NDArray[np.float64], steady_after: float | None) -> None:
    """Engagement (t = 0) as a line, the steady window (t >= steady_after_s) shaded."""
    if len(t) == 0:
        return
    if t[0] <= 0.0 <= t[-1]:
        ax.axvline(0.0, color="k", lw=0.8, ls=":", label="engaged")
    if steady_after is not None and steady_after < t[-1]:
        ax.axvspan(steady_after, t[-1], color="tab:green", alpha=0.08, label="steady window")


def _smooth(t: NDArray[np.float64], y: NDArray[np.float64], window_s: float) -> NDArray[np.float64]:
    """Centred moving mean over ``window_s`` (NaNs, e.g. the gaps, kept out of the mean)."""
    y = np.asarray(y, float)
    if len(t) < 3:
        return y
    dt = float(np.nanmedian(np.diff(t)))
    k = int(round(window_s / dt)) if dt > 0 else 1
    if k < 2:
        return y
    ok = np.isfinite(y)
    ker = np.ones(k)
    num = np.convolve(np.where(ok, y, 0.0), ker, mode="same")
    den = np.convolve(ok.astype(float), ker, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok & (den > 0), num / np.maximum(den, 1e-12), np.nan)


def _zoom(ax: Any, y: NDArray[np.float64]) -> None:
    """Limit the y axis to the commanded signal's range (+30 %): the achieved one's spikes
    must not squash it."""
    y = np.asarray(y, float)
    y = y[np.isfinite(y)]
    if len(y) == 0:
        return
    lo, hi = float(np.percentile(y, 0.5)), float(np.percentile(y, 99.5))
    pad = max(0.3 * (hi - lo), 0.02)
    ax.set_ylim(lo - pad, hi + pad)


def _up_range(
    t: NDArray[np.float64], *ups: NDArray[np.float64], steady_after: float | None = None
) -> tuple[float, float]:
    """The altitude range (m) of the given series, after the capture when the run has a steady
    window, padded by 20 % and at least 1 m each way."""
    sel = (
        t >= steady_after if steady_after is not None and np.any(t >= steady_after) else slice(None)
    )
    vals = np.concatenate([np.asarray(u, float)[sel] for u in ups])
    vals = vals[np.isfinite(vals)]
    if len(vals) == 0:
        return 0.0, 1.0
    lo, hi = float(np.min(vals)), float(np.max(vals))
    pad = max(0.2 * (hi - lo), 1.0)
    return lo - pad, hi + pad


def _read_limits(d: Path) -> dict[str, NDArray[np.float64]] | None:
    return _read_columns(d / "limits.csv", min_rows=2)


def _hlines(ax: Any, vals: list[float], style: str, color: str, label: str) -> None:
    """Horizontal lines at vals, labelled once."""
    for i, v in enumerate(vals):
        ax.axhline(v, ls=style, color=color, lw=0.9, label=label if i == 0 else None)


def _limits_bank(ax: Any, tt: NDArray[np.float64], roll: NDArray[np.float64], vf: Any) -> None:
    ax.plot(tt, np.degrees(roll), lw=0.8, color="tab:blue", label="bank")
    bl = vf.get("bank_limit_rad")
    if bl is not None:
        b = math.degrees(bl)
        _hlines(ax, [b, -b], "-", "tab:red", f"limit {b:.1f} deg")
        tol = math.degrees(float(vf.get("bank_tolerance_rad") or 0.0))
        if tol > 0:
            hold = vf.get("limit_hold_s", 1)
            _hlines(ax, [b + tol, -b - tol], ":", "tab:red",
                    f"+{tol:.0f} deg: fails held > {hold:g} s")  # fmt: skip
        band = vf.get("bank_band_rad")
        if band is not None:
            _hlines(ax, [math.degrees(band), -math.degrees(band)], "--", "tab:orange",
                    f"limit less the margin ({math.degrees(band):.0f} deg)")  # fmt: skip
    ax.set_ylabel("bank [deg]")


def _limits_pitch(ax: Any, tt: NDArray[np.float64], pitch: NDArray[np.float64], vf: Any) -> None:
    ax.plot(tt, np.degrees(pitch), lw=0.8, color="tab:blue", label="pitch")
    pl = vf.get("pitch_limit_rad")
    if pl is not None:
        lim_deg = math.degrees(pl)
        _hlines(ax, [lim_deg, -lim_deg], "-", "tab:red", f"limit {lim_deg:.0f} deg")
    ax.set_ylabel("pitch [deg]")


def _limits_airspeed(ax: Any, tt: NDArray[np.float64], vas: NDArray[np.float64], vf: Any) -> None:
    ax.plot(tt, vas, lw=0.8, color="tab:blue", label="airspeed")
    band_v = vf.get("airspeed_band_m_s")
    if band_v:
        _hlines(ax, list(band_v), "-", "tab:red", f"limits {band_v[0]:.1f} / {band_v[1]:.1f} m/s")
    if vf.get("airspeed_m_s") is not None:
        v = vf["airspeed_m_s"]
        _hlines(ax, [float(v)], "--", "tab:green", f"law's airspeed {v:g} m/s")
    ax.set_ylabel("airspeed [m/s]")


def _limits_altitude(
    ax: Any,
    tt: NDArray[np.float64],
    alt: NDArray[np.float64],
    lim: dict[str, NDArray[np.float64]],
    cols: dict[str, Any],
    floor: Any,
) -> None:
    ax.plot(tt, alt, lw=0.8, color="tab:blue", label="altitude")
    if "pf_d" in cols and len(cols["t"]):
        _, pfu = _gapped(cols["t"], -cols["pf_d"])
        ax.plot(_gapped(cols["t"], cols["t"])[0], pfu, lw=0.8, color="tab:green", alpha=0.8,
                label="desired point")  # fmt: skip
    if floor is not None:
        _hlines(ax, [float(floor)], "-", "tab:red", f"floor {floor:g} m")
    lo, hi = _up_range(lim["t"], lim["altitude"], steady_after=None)
    ax.set_ylim(lo, hi)
    ax.set_ylabel("altitude [m]")


def _limits_thrust(ax: Any, tt: NDArray[np.float64], thr: NDArray[np.float64], vf: Any) -> None:
    ax.plot(tt, thr, lw=0.8, color="tab:blue", label="thrust")
    if vf.get("thrust_max") is not None:
        _hlines(ax, [float(vf["thrust_max"])], "-", "tab:red", f"ceiling {vf['thrust_max']:g}")
    ax.set_ylabel("thrust [0..1]")
    ax.set_ylim(-0.05, 1.08)
    ax.set_xlabel("t [s since engagement]")


def _limits_title(metrics: dict[str, Any], vf: Any) -> str:
    """The figure's title: the source of the figures and the verdict's head (its clauses are in
    metrics.json and the command's last line)."""
    src = {"truth": "the plant's truth (SIL)", "telemetry": "telemetry (thrust: as sent)"}.get(
        str(vf.get("source")), "recorded"
    )
    verdict = str(metrics.get("verdict") or "").split(": ", 1)[-1]
    head = verdict if verdict.startswith(("PASS", "NOT JUDGED")) else verdict.split("):")[0] + ")"
    head = head if len(head) < 100 else head[:97] + "..."
    title = f"Against the limits: {src}"
    return title + (f"\nverdict: {head}" if verdict else "")


def _plot_limits(
    plt: Any,
    d: Path,
    lim: dict[str, NDArray[np.float64]],
    metrics: dict[str, Any],
    cols: dict[str, Any],
    steady_after: float | None,
) -> Path:
    """limits.png: bank, pitch, airspeed, altitude, thrust against time and their limits."""
    vf = metrics.get("verdict_figures") or {}
    t = lim["t"]
    fig, axs = plt.subplots(5, 1, figsize=(11, 11), sharex=True)
    tt, roll, pitch, vas, alt, thr = _gapped(
        t, lim["roll"], lim["pitch"], lim["airspeed"], lim["altitude"], lim["thrust"]
    )
    _limits_bank(axs[0], tt, roll, vf)
    _limits_pitch(axs[1], tt, pitch, vf)
    _limits_airspeed(axs[2], tt, vas, vf)
    floor = metrics.get("altitude_floor_m") or vf.get("altitude_floor_m")
    _limits_altitude(axs[3], tt, alt, lim, cols, floor)
    _limits_thrust(axs[4], tt, thr, vf)
    t_end = float(vf.get("tracked_s") or t[-1])
    for ax in axs:
        ax.grid(alpha=0.3)
        _mark_window(ax, np.array([t[0], t_end]), steady_after)
        if t_end < t[-1] - 1.0:
            ax.axvline(t_end, color="k", lw=0.8, ls="--", label="handed back")
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.suptitle(_limits_title(metrics, vf), fontsize=10)
    fig.subplots_adjust(left=0.08, right=0.74, bottom=0.05, top=0.91, hspace=0.1)
    p = d / "limits.png"
    fig.savefig(p, dpi=100)
    plt.close(fig)
    return p


class _Figures:
    """The figures of one run directory: the columns read, what every figure shares (the path
    where the target carried it, the steady window, the source of the figures) and the PNG
    files written so far."""

    def __init__(
        self,
        plt: Any,
        d: Path,
        cols: dict[str, Any],
        path_T: NDArray[np.float64] | None,
        metrics: dict[str, Any],
    ) -> None:
        self.plt, self.d, self.cols, self.path_T, self.metrics = plt, d, cols, path_T, metrics
        self.t: NDArray[np.float64] = cols["t"]
        self.out: list[Path] = []
        self.paths = _paths_ned(cols, path_T)
        self.steady_after = _steady_after(metrics)
        vf = metrics.get("verdict_figures") or {}
        self.src = {"truth": " (plant truth)", "telemetry": " (telemetry)"}.get(
            str(vf.get("source")), ""
        )
        col = self.col
        self.stationary = bool(
            np.all(
                np.ptp(np.column_stack([col("tgt_n"), col("tgt_e"), col("tgt_d")]), axis=0) < 1e-6
            )
        )

    def col(self, name: str) -> NDArray[np.float64]:
        """A column, or NaN where the run directory has none (an older layout)."""
        return self.cols[name] if name in self.cols else np.full(len(self.t), np.nan)

    def save(self, fig: Any, name: str, **margins: float) -> None:
        # Fixed margins instead of tight_layout, which draws every figure twice (a third of
        # the plotting time of a replay)
        fig.subplots_adjust(**{"left": 0.09, "right": 0.97, "bottom": 0.1, "top": 0.93, **margins})
        p = self.d / name
        fig.savefig(p, dpi=110)
        self.plt.close(fig)
        self.out.append(p)

    def trajectory_3d(self) -> None:
        """3D view (north, east, up) of the vehicle, the target, the desired point and the path."""
        t, cols, col, paths = self.t, self.cols, self.col, self.paths
        fig = self.plt.figure(figsize=(7, 6))
        ax = fig.add_subplot(projection="3d")
        _, pn, pe, pd = _gapped(t, cols["p_n"], cols["p_e"], cols["p_d"])
        ax.plot(pe, pn, -pd, lw=1.0, label="vehicle")
        for i, (tk, P) in enumerate(paths):
            alpha = 0.25 + 0.5 * (i + 1) / len(paths)
            ax.plot(P[:, 1], P[:, 0], -P[:, 2], "r-", lw=1.5, alpha=alpha,
                    label=f"desired path at t = {tk:.0f} s")  # fmt: skip
        if self.stationary:
            ax.plot(col("tgt_e")[:1], col("tgt_n")[:1], -col("tgt_d")[:1], "k^", label="target")
        else:
            ax.plot(col("tgt_e"), col("tgt_n"), -col("tgt_d"), "k--", lw=1.0, label="target")
        _, fn, fe, fd = _gapped(t, col("pf_n"), col("pf_e"), col("pf_d"))
        ax.plot(fe, fn, -fd, lw=0.6, alpha=0.6, label="desired point p_f")
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.set_zlabel("up [m]")
        ax.legend(loc="upper left", fontsize=8)
        ax.set_title(f"Moving path following (3D){self.src}")
        self.save(fig, "trajectory_3d.png", left=0.0, right=1.0, bottom=0.02, top=0.95)

    def _planar_view(self, ax: Any, view: tuple[Any, ...]) -> None:
        """One planar view: axes a, b (columns p_*, labels, signs, indices into the path)."""
        t, cols, col = self.t, self.cols, self.col
        a, b, la, lb, sa, sb, ia, ib = view
        ta, tb = "tgt_" + a[2:], "tgt_" + b[2:]
        for i, (tk, P) in enumerate(self.paths):
            alpha = 0.25 + 0.5 * (i + 1) / len(self.paths)
            ax.plot(sa * P[:, ia], sb * P[:, ib], "r-", lw=1.5, alpha=alpha,
                    label=f"desired path at t = {tk:.0f} s")  # fmt: skip
        _, xa, xb = _gapped(t, cols[a], cols[b])
        ax.plot(sa * xa, sb * xb, lw=1.0, color="tab:blue", label="vehicle")
        _, fa, fb = _gapped(t, col("pf_" + a[2:]), col("pf_" + b[2:]))
        ax.plot(sa * fa, sb * fb, lw=0.8, ls="--", color="tab:orange", zorder=3,
                label="desired point p_f")  # fmt: skip
        if self.stationary:
            ax.plot(sa * col(ta)[:1], sb * col(tb)[:1], "k^", label="target")
        else:
            ax.plot(sa * col(ta), sb * col(tb), "k--", lw=1.0, label="target")
        ax.set_xlabel(f"{la} [m]")
        ax.set_ylabel(f"{lb} [m]")
        ax.grid(alpha=0.3)

    def planar(self) -> None:
        """Planar views: the vehicle's path against the moving desired path."""
        t, col = self.t, self.col
        fig, axs = self.plt.subplots(1, 3, figsize=(14, 4.5))
        views = [
            ("p_e", "p_n", "east", "north", 1, 1, 1, 0),
            ("p_n", "p_d", "north", "up", 1, -1, 0, 2),
            ("p_e", "p_d", "east", "up", 1, -1, 1, 2),
        ]
        for ax, view in zip(axs, views, strict=True):
            self._planar_view(ax, view)
        axs[0].set_aspect("equal", adjustable="datalim")
        axs[0].legend(fontsize=8)
        # side views: the height scale of the vehicle and its desired point (after the capture
        # when there is a steady window), so that a height error of a metre is visible; the
        # target (on the ground under a path 100 m up) is off this scale and said so
        lo, hi = _up_range(t, -self.cols["p_d"], -col("pf_d"), steady_after=self.steady_after)
        for ax in axs[1:]:
            ax.set_ylim(lo, hi)
        tgt_up = -col("tgt_d")
        if np.all(np.isfinite(tgt_up)) and (np.max(tgt_up) < lo or np.min(tgt_up) > hi):
            axs[1].set_title(
                "side views scaled to the vehicle "
                f"(target at {np.median(tgt_up):.0f} m up, off scale)",
                fontsize=9,
            )
        fig.suptitle(
            f"Planar views: vehicle against the moving desired path{self.src}", fontsize=11
        )
        self.save(fig, "planar.png", left=0.06, right=0.99, bottom=0.12, top=0.88, wspace=0.25)

    def target_relative(self) -> None:
        """Target-relative path: where the vehicle flew in {T}, against the path."""
        cols, path_T = self.cols, self.path_T
        fig, ax = self.plt.subplots(figsize=(6, 6))
        if path_T is not None and len(path_T):
            ax.plot(path_T[:, 1], path_T[:, 0], "r-", lw=2, alpha=0.5, label="path p_d (in {T})")
        if "rel_x" in cols and "rel_y" in cols:
            _, rx, ry = _gapped(self.t, cols["rel_x"], cols["rel_y"])
            ax.plot(ry, rx, lw=0.8, label="vehicle relative to target")
            ax.plot(cols["rel_y"][:1], cols["rel_x"][:1], "go", label="start")
        ax.set_xlabel("y_T (right) [m]")
        ax.set_ylabel("x_T (forward) [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"Path in the target frame {{T}}{self.src}", fontsize=10)
        self.save(fig, "target_relative.png", left=0.13, bottom=0.09)

    def errors(self) -> None:
        """Errors: |pt| (log scale like the paper's zoom) and Psi."""
        t, metrics = self.t, self.metrics
        fig, axs = self.plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        tt, e, psi = _gapped(t, np.maximum(self.cols["pt_norm"], 1e-6), self.col("psi"))
        axs[0].semilogy(tt, e)
        axs[0].set_ylabel("|p~| [m]")
        axs[0].grid(alpha=0.3, which="both")
        rms = metrics.get("steady_rms_m")
        conv = metrics.get("convergence_time_s")
        conv_txt = "never" if conv is None else f"{conv:.3g} s"
        rms_txt = "n/a (no steady window)" if rms is None else f"{rms:.3g} m"
        axs[0].set_title(
            f"Tracking errors{self.src}: steady RMS |p~| {rms_txt}, convergence {conv_txt}",
            fontsize=10,
        )
        for ax in axs:
            _mark_window(ax, t, self.steady_after)
        axs[1].plot(tt, psi)
        axs[1].set_ylabel("Psi(R~)")
        axs[1].set_xlabel("t [s]")
        axs[1].grid(alpha=0.3)
        if axs[0].get_legend_handles_labels()[0]:  # the window or the engagement is drawn
            axs[0].legend(fontsize=8, loc="upper right")
        self.save(fig, "errors.png", left=0.12, hspace=0.08)

    def sdot_rates(self) -> None:
        """sdot, w2 and w3 (commanded against achieved)."""
        t, col = self.t, self.col
        fig, axs = self.plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        tt, sd, w2c, w3c, w2, w3 = _gapped(
            t, col("sdot"), col("w2_cmd"), col("w3_cmd"), col("w2"), col("w3")
        )
        axs[0].plot(tt, sd)
        axs[0].set_ylabel("sdot [m/s]")
        axs[0].set_title(
            f"Virtual-point speed and wind-frame rates{self.src}\ncommanded (dark, on top) "
            "against achieved (light: 1 s mean of the attitude difference)", fontsize=10,
        )  # fmt: skip
        for ax, k, cmd, ach in ((axs[1], "w2", w2c, w2), (axs[2], "w3", w3c, w3)):
            # the achieved rate is a difference of attitudes at the telemetry rate: its raw
            # noise (turbulence, quantisation) hides the command, so it is drawn filtered and
            # under it
            ax.plot(tt, _smooth(tt, ach, 1.0), lw=1.6, color="tab:orange", alpha=0.6, zorder=2,
                    label=f"{k} achieved (1 s mean)")  # fmt: skip
            ax.plot(tt, cmd, lw=0.8, color="tab:blue", zorder=3, label=f"{k} commanded")
            ax.set_ylabel(f"{k} [rad/s]")
            _zoom(ax, cmd)
            ax.legend(fontsize=8, loc="upper right")
        for ax in axs:
            ax.grid(alpha=0.3)
            _mark_window(ax, t, self.steady_after)
        axs[-1].set_xlabel("t [s]")
        self.save(fig, "sdot_rates.png", left=0.12, bottom=0.07, top=0.92, hspace=0.08)

    def setpoints(self, sp: dict[str, NDArray[np.float64]]) -> None:
        """The setpoints sent (bridge) or that would have been sent (replay)."""
        fig, axs = self.plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        ts, bank, pitch, thr, p, q, r = _gapped(
            sp["t"], sp["bank"], sp["pitch"], sp["thrust"], sp["p"], sp["q"], sp["r"]
        )
        axs[0].plot(ts, np.degrees(bank), label="bank")
        axs[0].plot(ts, np.degrees(pitch), label="pitch")
        axs[0].set_ylabel("set-point [deg]")
        axs[0].legend(fontsize=8)
        for name, v in (("p", p), ("q", q), ("r", r)):
            axs[1].plot(ts, v, lw=0.8, label=name)
        axs[1].set_ylabel("body rates [rad/s]")
        axs[1].legend(fontsize=8)
        axs[2].plot(ts, thr)
        axs[2].set_ylabel("thrust [0..1]")
        axs[2].set_xlabel("t [s]")
        axs[0].set_title(
            "Set-points sent to the autopilot (bank, pitch, body rates, thrust)", fontsize=10
        )
        for ax in axs:
            ax.grid(alpha=0.3)
        self.save(fig, "setpoints.png", left=0.12, bottom=0.07, top=0.95, hspace=0.08)


def plot_run(d: str | Path) -> list[Path]:
    """Draw every figure of the run directory d as PNG files; return their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mpf_mavlink.runs.rundir import read_run

    d = Path(d)
    cols, path_T, metrics = read_run(d)
    need = ("t", "p_n", "p_e", "p_d", "pt_norm")
    missing = [c for c in need if c not in cols]
    if missing:
        raise MpfError(f"{d / 'timeseries.csv'}: not a run time series (no column {missing[0]!r})")
    if len(cols["t"]) == 0:
        return []
    figs = _Figures(plt, d, cols, path_T, metrics)
    figs.trajectory_3d()
    figs.planar()
    figs.target_relative()
    figs.errors()
    figs.sdot_rates()
    sp = _read_setpoints(d)
    if sp is not None and {"t", "bank", "pitch", "thrust", "p", "q", "r"} <= set(sp):
        figs.setpoints(sp)
    # What the verdict judged against the limits (limits.csv): bank, pitch, airspeed, altitude
    # and thrust against time, with the limits, the engagement and the steady window.
    lim = _read_limits(d)
    if lim is not None:
        figs.out.append(_plot_limits(plt, d, lim, metrics, cols, figs.steady_after))
    return figs.out
