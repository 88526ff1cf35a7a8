"""The certificate of a mission (``certificate.json``) and its one-page report (``report.md``
with ``ecdf.png`` and ``conditions.png``), from the rows of ``flights.csv``."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

from mpf_mavlink.certify.conditions import Conditions, describe
from mpf_mavlink.certify.model_error import model_error
from mpf_mavlink.certify.stats import clopper_pearson, flights_needed, quantile_interval

NOT_MODELLED = [
    "the airframe: the SIL flies its JSBSim model (aircraft.model), not the real aircraft; the "
    "profile carries only the autopilot's part (estimator errors, attitude loops and lags, turn "
    "per bank), the thrust ceiling is the model's own",
    "wind gusts, shear and thermals beyond the stated steady wind and turbulence",
    "sensor failures, GPS glitches, EKF resets and lane switches",
    "the real link's losses, bursts and reordering (only its latency and rates)",
    "take-off, climb and the hand-over: flights start at the stated start, in cruise",
    "conditions outside the stated ranges: the bound holds only inside them, drawn uniformly",
]


def _num(x: Any) -> float | None:
    if x in ("", None):
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def certificate(
    rows: list[dict[str, Any]], cond: Conditions, mission: dict[str, Any]
) -> dict[str, Any]:
    """The certificate (module docstring) of the flights ``rows``."""
    q, conf = cond.quantile, cond.confidence
    status: dict[str, int] = {}
    for r in rows:
        status[str(r["status"])] = status.get(str(r["status"]), 0) + 1
    flew = [r for r in rows if r["status"] in ("ok", "failed")]
    fail = [r for r in flew if r.get("verdict_status") == "FAIL" or r["status"] == "failed"]
    cert: dict[str, Any] = {
        "mission": mission,
        "conditions": {**asdict(cond), "source": cond.source},
        "flights": {
            "needed": flights_needed(q, conf),
            "needed_reason": f"smallest n with 1 - {q:g}^n >= {conf:g}: the largest of n flights "
            f"is a one-sided {100 * q:g} % bound with {100 * conf:g} % confidence",
            "in_table": len(rows),
            "judged": len(flew),
            "status": status,
        },
        "quantile": q,
        "confidence": conf,
    }
    me = model_error(str(mission.get("profile", "")))
    cert["model_error"] = me
    for key in ("steady_rms_m", "steady_max_m"):
        vals = [v for v in (_num(r.get(key)) for r in flew) if v is not None]
        med = quantile_interval(vals, 0.5, conf)
        top = quantile_interval(vals, q, conf)
        cert[key] = {
            "median": med["estimate"],
            "median_interval": [med["low"], med["high"]],
            f"p{round(100 * q)}": top["estimate"],
            f"p{round(100 * q)}_interval": [top["low"], top["high"]],
            "upper_bound": top["upper_bound"],
            "upper_bound_rank": top["upper_bound_rank"],
            # the bound a real flight is judged against: the SIL's, times its measured error
            "bound_with_model_error": (
                top["upper_bound"] * float(me["factor"])
                if me is not None and top["upper_bound"] is not None
                else top["upper_bound"]
            ),
            "max": max(vals) if vals else None,
            "n": len(vals),
        }
    k, n = len(fail), len(flew)
    lo, hi = clopper_pearson(k, n, conf) if n else (None, None)
    cert["p_fail"] = {"failed": k, "of": n, "estimate": (k / n) if n else None,
                      "interval": [lo, hi], "method": "Clopper-Pearson"}  # fmt: skip
    margins = [(v, r) for r in flew if (v := _num(r.get("altitude_margin_m"))) is not None]
    banks = [(v, r) for r in flew if (v := _num(r.get("max_bank_rad"))) is not None]
    if margins:
        v, r = min(margins, key=lambda x: x[0])
        cert["worst_altitude_margin_m"] = {"value": v, "flight": int(r["flight"])}
    if banks:
        v, r = max(banks, key=lambda x: x[0])
        cert["worst_bank_rad"] = {
            "value": v, "deg": math.degrees(v), "flight": int(r["flight"]),
            "limit_rad": _num(r.get("bank_limit_rad")),
        }  # fmt: skip
    cert["failing"] = [
        {"flight": int(r["flight"]), "status": r["status"], "error": r.get("error", ""),
         "conditions": json.loads(r["conditions"]) if r.get("conditions") else {}}
        for r in rows if r["status"] != "ok" or r.get("verdict_status") == "FAIL"
    ]  # fmt: skip
    cert["not_modelled"] = list(NOT_MODELLED)
    if me is not None:
        cert["not_modelled"].append(
            f"the SIL's own error beyond its calibration: the bound a real flight is judged "
            f"against is the SIL's x {float(me['factor']):.2f} (the worst real/SIL RMS ratio, "
            f"{me['worst_mission']}, of {me['source']}, floored at 1; max |pt| takes the same)"
        )
    cpu = [v for v in (_num(r.get("cpu_s")) for r in rows) if v is not None]
    cert["cpu_s_per_flight"] = sum(cpu) / len(cpu) if cpu else None
    return cert


def _f(x: Any, nd: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}"


def summary_lines(cert: dict[str, Any]) -> list[str]:
    """The certificate in a few lines (the terminal's and the report's head)."""
    q = round(100 * cert["quantile"])
    c = round(100 * cert["confidence"])
    fl = cert["flights"]
    out = [
        f"certificate: {cert['mission']['name']} on {cert['mission']['autopilot']} "
        f"({cert['mission']['profile']}), {fl['judged']} judged of {fl['in_table']} flights "
        f"(a {q} % bound at {c} % needs {fl['needed']}); status {fl['status']}",
    ]
    for key, what in (("steady_rms_m", "steady RMS |pt|"), ("steady_max_m", "steady max |pt|")):
        s = cert[key]
        lo, hi = s[f"p{q}_interval"]
        mlo, mhi = s["median_interval"]
        out.append(
            f"  {what}: median {_f(s['median'])} m [{_f(mlo)}, {_f(mhi)}], p{q} "
            f"{_f(s[f'p{q}'])} m [{_f(lo)}, {_f(hi)}] ({c} % CI), one-sided {c} % bound "
            f"{_f(s['upper_bound'])} m"
            + (
                f", with the model's error {_f(s['bound_with_model_error'])} m"
                if s.get("bound_with_model_error") not in (None, s["upper_bound"])
                else ""
            )
        )
    pf = cert["p_fail"]
    lo, hi = pf["interval"]
    out.append(f"  P(FAIL): {pf['failed']}/{pf['of']} = {_f(pf['estimate'])} "
               f"[{_f(lo)}, {_f(hi)}] (Clopper-Pearson {c} %)")  # fmt: skip
    am, wb = cert.get("worst_altitude_margin_m"), cert.get("worst_bank_rad")
    if am:
        out.append(f"  worst altitude margin {am['value']:.1f} m above the floor "
                   f"(flight {am['flight']})")  # fmt: skip
    if wb:
        out.append(
            f"  worst bank {wb['deg']:.1f} deg (flight {wb['flight']}"
            + (f", limit {math.degrees(wb['limit_rad']):.1f})" if wb["limit_rad"] else ")")
        )
    return out


def write_report(out: Path, cert: dict[str, Any], rows: list[dict[str, Any]]) -> list[Path]:
    """certificate.json, report.md, ecdf.png and conditions.png in ``out``."""
    (out / "certificate.json").write_text(json.dumps(cert, indent=2) + "\n")
    figs = _figures(out, cert, rows)
    q = round(100 * cert["quantile"])
    lines = ["# Certificate: " + cert["mission"]["name"], "", "```", *summary_lines(cert), "```",
             "", f"Command: `{cert['mission'].get('command', '')}`", ""]  # fmt: skip
    lines += [f"![ECDF of the steady figures]({figs[0].name})", "",
              f"![the figures against the conditions]({figs[1].name})", ""]  # fmt: skip
    lines += ["## Conditions", "", "```json",
              json.dumps(cert["conditions"], indent=1), "```", ""]  # fmt: skip
    lines += ["## Flights that did not pass", ""]
    if cert["failing"]:
        lines += ["| flight | status | conditions | why |", "|---|---|---|---|"]
        for f in cert["failing"]:
            lines.append(f"| {f['flight']} | {f['status']} | {describe(f['conditions'])} | "
                         f"{f['error']} |")  # fmt: skip
    else:
        lines.append("none")
    lines += ["", "## Not modelled", "", *[f"- {x}" for x in cert["not_modelled"]], "",
              f"The {q} % bound is distribution-free (order statistics); P(FAIL)'s interval is "
              "Clopper-Pearson's exact binomial interval.", ""]  # fmt: skip
    (out / "report.md").write_text("\n".join(lines))
    return [out / "certificate.json", out / "report.md", *figs]


def _figures(out: Path, cert: dict[str, Any], rows: list[dict[str, Any]]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    q = round(100 * cert["quantile"])
    flew = [r for r in rows if r["status"] in ("ok", "failed")]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    panels = (("steady_rms_m", "steady RMS |pt| (m)"), ("steady_max_m", "steady max |pt| (m)"))
    for ax, (key, what) in zip(axes, panels, strict=True):
        v = np.sort([x for x in (_num(r.get(key)) for r in flew) if x is not None])
        if len(v):
            ax.step(v, np.arange(1, len(v) + 1) / len(v), where="post")
        s = cert[key]
        for val, lab, st in ((s["median"], "median", "--"), (s[f"p{q}"], f"p{q}", ":"),
                             (s["upper_bound"], f"{q} % bound", "-.")):  # fmt: skip
            if val is not None:
                ax.axvline(val, ls=st, color="k", lw=0.8, label=f"{lab} {val:.3f}")
        ax.set_xlabel(what)
        ax.set_ylabel("fraction of flights")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{cert['mission']['name']}: {len(flew)} calibrated-SIL flights", fontsize=9)
    fig.tight_layout()
    p1 = out / "ecdf.png"
    fig.savefig(p1, dpi=110)
    plt.close(fig)
    keys = sorted({k for r in flew for k, v in json.loads(r["conditions"] or "{}").items()
                   if isinstance(v, float)})  # fmt: skip
    keys = [k for k in keys if len({json.loads(r["conditions"]).get(k) for r in flew}) > 1][:6]
    ncol = max(1, len(keys))
    fig, axes = plt.subplots(1, ncol, figsize=(3.0 * ncol, 3.0), squeeze=False)
    for ax, k in zip(axes[0], keys, strict=False):
        x = [json.loads(r["conditions"])[k] for r in flew]
        y = [_num(r.get("steady_rms_m")) or float("nan") for r in flew]
        ax.scatter(x, y, s=8)
        ax.set_xlabel(k, fontsize=8)
        ax.set_ylabel("steady RMS |pt| (m)", fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    p2 = out / "conditions.png"
    fig.savefig(p2, dpi=110)
    plt.close(fig)
    return [p1, p2]
