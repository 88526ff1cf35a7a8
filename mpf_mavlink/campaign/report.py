"""What a person looks at after a campaign: the summary (success rate, percentiles), the ECDFs,
each metric against each varied parameter, the worst flights re-flown into run directories for
``mpf-mavlink plot``, and the empirical region of attraction against the certified one.

The certified region is what the theorem's gain condition certifies for the campaign's gains
(:func:`mpf_mavlink.core.guidance.checks.gain_condition`, the condition ``check`` prints): a
start (|pt(0)|, Psi(0)) is certified when some c1 >= |pt(0)| satisfies the condition with
c2 = Psi(0) (< 1/2). It is computed on the plot's grid, never drawn from a formula of ours.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.campaign.spec import CampaignSpec

NUMERIC = ("first_within_s", "convergence_time_s", "steady_rms_m", "steady_max_m",
           "steady_psi_max", "max_rate_cmd_rad_s", "final_pt_m", "initial_pt_m", "initial_psi",
           "wall_s", "cpu_s", "sim_time_s")  # fmt: skip


def _num(x: Any) -> float | None:
    if x is None or x == "":
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def converged(row: dict[str, Any]) -> bool:
    """|pt| below the threshold and staying there by the flight's end."""
    return row.get("status") in ("ok", "failed") and _num(row.get("convergence_time_s")) is not None


def success(spec: CampaignSpec, row: dict[str, Any]) -> bool:
    if row.get("status") != "ok" or not converged(row):
        return False
    if spec.success_rms_m is not None:
        rms = _num(row.get("steady_rms_m"))
        return rms is not None and rms <= spec.success_rms_m
    return True


def summarise(spec: CampaignSpec, rows: list[dict[str, Any]]) -> dict[str, Any]:
    n = len(rows)
    status: dict[str, int] = {}
    for r in rows:
        status[str(r.get("status"))] = status.get(str(r.get("status")), 0) + 1
    out: dict[str, Any] = {
        "flights": n,
        "status": status,
        "success_rate": (sum(success(spec, r) for r in rows) / n) if n else None,
        "converged_rate": (sum(converged(r) for r in rows) / n) if n else None,
        "percentiles": {},
    }
    for k in (*spec.metrics, "wall_s", "cpu_s"):
        vals = [v for r in rows if (v := _num(r.get(k))) is not None]
        if not vals or k == "verdict":
            continue
        a = np.asarray(vals)
        out["percentiles"][k] = {
            "n": len(vals),
            **{f"p{q}": float(np.percentile(a, q)) for q in (5, 50, 95)},
            "max": float(a.max()),
        }
    return out


def format_summary(s: dict[str, Any]) -> str:
    lines = [
        f"flights: {s['flights']}  status: "
        + ", ".join(f"{k} {v}" for k, v in sorted(s["status"].items())),
        f"success rate: {_pct(s['success_rate'])}  converged: {_pct(s['converged_rate'])}",
        f"{'metric':<22}{'n':>6}{'p5':>11}{'p50':>11}{'p95':>11}{'max':>11}",
    ]
    for k, p in s["percentiles"].items():
        lines.append(
            f"{k:<22}{p['n']:>6}" + "".join(f"{p[q]:>11.4g}" for q in ("p5", "p50", "p95", "max"))
        )
    return "\n".join(lines)


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.1f} %"


def worst(spec: CampaignSpec, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The ``keep_worst`` flights: errors and failures first, then the largest ``rank_by``."""

    def key(r: dict[str, Any]) -> tuple[int, float]:
        bad = 0 if r.get("status") in ("error", "timeout", "failed") else 1
        v = _num(r.get(spec.rank_by))
        return (bad, -(v if v is not None else math.inf))

    flown = [r for r in rows if r.get("status") != "refused"]
    return sorted(flown, key=key)[: spec.keep_worst]


def reflown_dirs(spec: CampaignSpec, rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """Fly the worst flights again (same sample, same seeds) into ``out/worst/<sample>``."""
    from mpf_mavlink.campaign.design import overrides_for
    from mpf_mavlink.campaign.flight import fly
    from mpf_mavlink.config import load_config

    base = load_config(spec.base_path, spec.set)
    dirs = []
    for r in worst(spec, rows):
        if r.get("status") in ("timeout",):
            continue
        sample = {v.key: _typed(r.get(v.key)) for v in spec.vary}
        d = out / "worst" / f"sample-{int(r['sample']):05d}"
        sets = [*spec.set, *overrides_for(base, sample)]
        fly(str(spec.base_path), sets, spec.plant, spec.metrics, spec.timeout_s,
            spec.stop_after_converged_s, spec.force, str(d))  # fmt: skip
        if (d / "metrics.json").is_file():
            dirs.append(d)
    return dirs


def _typed(x: Any) -> Any:
    if isinstance(x, str):
        import yaml

        return yaml.safe_load(x) if x else None
    return x


def certified_c1(spec: CampaignSpec, psi0: float, c1_max: float = 1e5) -> float | None:
    """The smallest c1 (m, 5 % grid from 1 mm) for which the gain condition holds with
    c2 = Psi(0), or None. K c1^2 grows with c1, so the condition holds for every larger c1:
    a start with this Psi(0) is certified whatever its |pt(0)| (c1 = max(|pt(0)|, this))."""
    from mpf_mavlink.config import load_config
    from mpf_mavlink.config.scenario import build_gains
    from mpf_mavlink.core.guidance.checks import gain_condition

    key = (spec.source, round(psi0, 12))
    if key in _c1_cache:
        return _c1_cache[key]
    cfg = _cfg_cache.get(spec.source)
    if cfg is None:
        cfg = _cfg_cache[spec.source] = load_config(spec.base_path, spec.set)
    found: float | None = None
    if psi0 < 0.5:
        g = build_gains(cfg)
        c1 = 1e-3
        while c1 <= c1_max:
            if gain_condition(g, cfg.vehicle.v_min, cfg.vehicle.v_max, c1, psi0).ok:
                found = c1
                break
            c1 *= 1.05
    _c1_cache[key] = found
    return found


def certified(spec: CampaignSpec, pt0: float, psi0: float) -> bool:
    """Whether the gain condition certifies the start (|pt(0)| m, Psi(0)) for these gains."""
    return certified_c1(spec, psi0) is not None


_c1_cache: dict[tuple[str, float], float | None] = {}
_cfg_cache: dict[str, Any] = {}


def plots(spec: CampaignSpec, rows: list[dict[str, Any]], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written: list[Path] = []
    flown = [r for r in rows if r.get("status") in ("ok", "failed")]
    # ECDFs of the tracking figures
    keys = [k for k in ("steady_rms_m", "steady_max_m", "convergence_time_s", "final_pt_m")
            if k in spec.metrics]  # fmt: skip
    if flown and keys:
        fig, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 3.6), squeeze=False)
        for ax, k in zip(axes[0], keys, strict=True):
            vals = np.sort([x for r in flown if (x := _num(r.get(k))) is not None])
            if len(vals):
                ax.step(vals, np.arange(1, len(vals) + 1) / len(vals), where="post")
            ax.set_xlabel(k)
            ax.set_ylabel("fraction of flights")
            ax.grid(alpha=0.3)
            ax.set_title(f"{len(vals)} of {len(flown)} flights")
        fig.suptitle(f"campaign {spec.name}: ECDF")
        fig.tight_layout()
        written.append(_save(fig, out / "ecdf.png"))
    # the ranking metric against each varied parameter
    if flown:
        vs = spec.vary
        fig, axes = plt.subplots(1, len(vs), figsize=(4.2 * len(vs), 3.6), squeeze=False)
        for ax, var in zip(axes[0], vs, strict=True):
            v = var
            xs = [_typed(r.get(v.key)) for r in flown]
            ys = [_num(r.get(spec.rank_by)) for r in flown]
            ok = [r.get("status") == "ok" for r in flown]
            cats = sorted({str(x) for x in xs}) if v.dist == "choice" else None
            for good, color in ((True, "tab:blue"), (False, "tab:red")):
                pts = [(cats.index(str(x)) if cats else x, y)
                       for x, y, o in zip(xs, ys, ok, strict=True)
                       if o == good and y is not None]  # fmt: skip
                if pts:
                    ax.scatter(*zip(*pts, strict=True), s=8, color=color,
                               label="ok" if good else "failed verdict")  # fmt: skip
            if cats:
                ax.set_xticks(range(len(cats)), cats)
            ax.set_xlabel(v.key)
            ax.set_ylabel(spec.rank_by)
            ax.grid(alpha=0.3)
        if axes[0][0].get_legend_handles_labels()[0]:
            axes[0][0].legend(fontsize=8)
        fig.tight_layout()
        written.append(_save(fig, out / "parameters.png"))
    roa = roa_plot(spec, rows, out)
    if roa is not None:
        written.append(roa)
    return written


def roa_plot(spec: CampaignSpec, rows: list[dict[str, Any]], out: Path) -> Path | None:
    """Converged / not against the start (|pt(0)|, Psi(0)), over the certified region."""
    import matplotlib.pyplot as plt

    raw = [(_num(r.get("initial_pt_m")), _num(r.get("initial_psi")), converged(r)) for r in rows
           if r.get("status") in ("ok", "failed")]  # fmt: skip
    pts = [(a, b, c) for a, b, c in raw if a is not None and b is not None]
    if len(pts) < 2 or not any(k.startswith("initial.") for k in (v.key for v in spec.vary)):
        return None
    P = np.array([(a, b) for a, b, _ in pts])
    conv = np.array([c for _, _, c in pts])
    xmax = float(P[:, 0].max()) * 1.05 + 1e-9
    gx = np.linspace(0.0, xmax, 60)
    gy = np.linspace(0.0, 1.0, 81)  # Psi = (1 - cos(angle to d1)) / 2 lies in [0, 1]
    cert = np.array([[certified(spec, float(x), float(y)) for x in gx] for y in gy], float)
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.contourf(gx, gy, cert, levels=[0.5, 1.5], colors=["tab:green"], alpha=0.18)
    ax.contour(gx, gy, cert, levels=[0.5], colors=["tab:green"], linewidths=1.5)
    ax.scatter(P[conv, 0], P[conv, 1], s=6, color="tab:blue", label=f"converged ({conv.sum()})")
    ax.scatter(P[~conv, 0], P[~conv, 1], s=10, marker="x", color="tab:red",
               label=f"not converged ({(~conv).sum()})")  # fmt: skip
    ax.plot([], [], color="tab:green", label="certified by the gain condition (Theorem 1)")
    ax.set_xlabel("|pt(0)| (m)")
    ax.set_ylabel("Psi(0)")
    ax.set_ylim(0.0, 1.0)
    command = f"mpf-mavlink campaign {_rel(spec.source)}"
    ax.set_title(f"campaign {spec.name}: empirical region of attraction\n({command})", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    inside = [c for (a, b, c) in pts if certified(spec, a, b)]
    outside = [c for (a, b, c) in pts if not certified(spec, a, b)]
    (out / "roa.json").write_text(json.dumps({
        "flights": len(pts), "converged": int(conv.sum()),
        "certified_starts": len(inside), "certified_converged": int(sum(inside)),
        "uncertified_starts": len(outside), "uncertified_converged": int(sum(outside)),
        "command": command,
    }, indent=2) + "\n")  # fmt: skip
    (out / "roa.md").write_text(roa_table(spec, pts, command))
    return _save(fig, out / "roa.png")


def _rel(path: str) -> str:
    """``path`` relative to the working directory when it is inside it (for a command line)."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def roa_table(spec: CampaignSpec, pts: list[tuple[Any, Any, bool]], command: str) -> str:
    """roa.md: converged flights / flights by the start's Psi(0) band and |pt(0)| band, and
    inside / outside the certified region (markdown, naming the command that wrote it)."""
    psi_edges = [0.0, 0.25, 0.5, 0.75, 1.0001]
    d_max = max(float(a) for a, _, _ in pts)
    d_edges = list(np.linspace(0.0, d_max * 1.0001, 4))
    head = "| Psi(0) \\ \\|pt(0)\\| (m) | " + " | ".join(
        f"{d_edges[i]:.0f}-{d_edges[i + 1]:.0f}" for i in range(3)) + " | all |"  # fmt: skip
    lines = [f"Written by `{command}` ({len(pts)} flights): converged / flown, by the start's",
             "Psi(0) and |pt(0)|; certified = inside the region the gain condition of Theorem 1",
             "certifies for these gains.", "", head, "|---|---|---|---|---|"]  # fmt: skip

    def cell(sel: list[bool]) -> str:
        return f"{sum(sel)} / {len(sel)}" if sel else "-"

    for i in range(4):
        lo, hi = psi_edges[i], psi_edges[i + 1]
        row = [c for a, b, c in pts if lo <= b < hi]
        cells = [cell([c for a, b, c in pts if lo <= b < hi and d_edges[j] <= a < d_edges[j + 1]])
                 for j in range(3)]  # fmt: skip
        lines.append(f"| {lo:.2f}-{min(hi, 1.0):.2f} | " + " | ".join(cells) + f" | {cell(row)} |")
    cert = [c for a, b, c in pts if certified(spec, a, b)]
    unc = [c for a, b, c in pts if not certified(spec, a, b)]
    lines += ["", f"certified starts: {cell(cert)} converged; uncertified: {cell(unc)}.", ""]
    return "\n".join(lines)


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
