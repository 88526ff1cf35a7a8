"""``scripts/sitl px4|arduplane [CONFIG] --certificate DIR/certificate.json --flights N --out
OUT``: fly N real-firmware flights with conditions drawn from the certificate's distribution
and print, flight by flight, where each lands against the certificate (inside / outside its
one-sided 95 % bound of steady RMS and max |pt|), then the real median against the predicted
one. ``--record`` writes the table, with the command that wrote it, to
docs/results/validation-<certificate name>.md.

The rig draws what it can impose on the firmware: the steady wind and SIM_WIND_TURB
(ArduPlane; PX4 v1.16 SIH has none) and the target's speed, turn and climb (the mission's
``--set``). The link's latency is the real link's own and the start is where the take-off's
loiter puts the aircraft: the table says so. Draws come from the streams (seed + 7919, j), so
they are other draws than the certificate's flights, from the same distribution.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from mpf_mavlink.certify.conditions import Conditions, describe, draw
from mpf_mavlink.certify.report import NOT_MODELLED  # noqa: F401 - the words the docs quote

ROOT = Path(__file__).resolve().parents[2]
VALIDATION_SEED_OFFSET = 7919  # another stream than the certificate's own flights


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="scripts/sitl AUTOPILOT [CONFIG] --certificate FILE",
        description="fly real-firmware flights drawn from a certificate's conditions",
    )
    ap.add_argument("autopilot", choices=("px4", "arduplane"))
    ap.add_argument("config", nargs="?", help="the mission (default: the certificate's)")
    ap.add_argument("--certificate", required=True, type=Path)
    ap.add_argument("--flights", type=int, default=3)
    ap.add_argument("--out", required=True, type=Path, help="new or empty directory")
    ap.add_argument("--speedup", type=float, default=None)
    ap.add_argument("--record", action="store_true", help="write docs/results/validation-*.md")
    ap.add_argument(
        "--rejudge",
        action="store_true",
        help="fly nothing: judge the flights already in --out against --certificate",
    )
    return ap


def rig_args(
    autopilot: str, config: str, cert: dict[str, Any], d: dict[str, Any], out: Path
) -> list[str]:
    """The rig's arguments of one drawn flight (the certificate's mission and duration)."""
    m = cert["mission"]
    args = [autopilot, "--config", config, "--out", str(out), "--duration", f"{m['duration_s']:g}"]
    for s in cert["conditions"].get("set", []):
        args += ["--set", s]
    for k in ("speed_m_s", "turn_rate_rad_s", "climb_rate_m_s"):
        if f"target.{k}" in d:
            args += ["--set", f"target.{k}={d[f'target.{k}']:.5f}"]
    if m.get("steady_after_s") is not None:
        args += ["--set", f"metrics.steady_after_s={m['steady_after_s']:g}"]
    if autopilot == "arduplane":
        spd = d.get("wind.speed_m_s", 0.0)
        if spd > 0.0:
            args += ["--wind", f"{spd:.3f},{math.degrees(d.get('wind.from_rad', 0.0)) % 360:.1f}"]
        if d.get("turbulence.sitl_m_s", 0.0) > 0.0:
            args += ["--turbulence", f"{d['turbulence.sitl_m_s']:.3f}"]
    return args


def _bound(cert: dict[str, Any], key: str) -> float | None:
    """The certificate's one-sided bound of ``key`` (its p95 estimate if too few flights)."""
    s = cert.get(key, {})
    q = round(100 * float(cert.get("quantile", 0.95)))
    # a certificate that carries its model's error is judged by it (mpf_mavlink.certify.model_error)
    b = s.get("bound_with_model_error", s.get("upper_bound"))
    return float(b) if b is not None else (s.get(f"p{q}") if s.get(f"p{q}") is not None else None)


def verdict_row(
    cert: dict[str, Any], j: int, d: dict[str, Any], fig: dict[str, Any]
) -> dict[str, Any]:
    """Where one real flight lands against the certificate."""
    # the link's latency is the real link's own on the rig: not a drawn condition there
    out: dict[str, Any] = {"flight": j, "conditions": describe(_rig_drawn(d))}
    out["verdict"] = verdict = str(fig.get("verdict", "?"))
    # a flight that ended before its steady window (a safety exit, a lost link) says nothing
    # of the mission's tracking: not judged against the bound, not in the medians
    out["judged"] = judged = verdict.startswith(("PASS", "FAIL"))
    for key in ("steady_rms_m", "steady_max_m"):
        v, b = fig.get(key), _bound(cert, key)
        out[key] = v if judged else None
        out[f"{key}_bound"] = b
        out[f"{key}_inside"] = None if v is None or b is None or not judged else bool(v <= b)
    return out


def _f(x: Any) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def table(cert: dict[str, Any], rows: list[dict[str, Any]], command: str) -> str:
    """The validation table (markdown) with the medians' ratio and the command."""
    q = round(100 * float(cert.get("quantile", 0.95)))
    m = cert["mission"]
    lines = [
        f"# Validation of the certificate {m['name']} ({m['autopilot']}, {m['profile']})",
        "",
        f"Written by `{command}` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).",
        f"Real firmware (../shared/sitl), {m['duration_s']:g} s missions, steady from t >= "
        f"{m.get('steady_after_s', 0):g} s; the certificate: "
        f"{cert['flights']['judged']} calibrated-SIL flights. Drawn on the rig: wind, "
        "SIM_WIND_TURB (ArduPlane), the target's motion; not drawn: latency and start "
        "(the real link's and the take-off's).",
        "",
        f"| flight | conditions | steady RMS (m) | {q} % bound | inside | max pt (m) | "
        f"{q} % bound | inside | verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ins = [
            {True: "inside", False: "OUTSIDE", None: "n/a"}[r[f"{k}_inside"]]
            for k in ("steady_rms_m", "steady_max_m")
        ]
        lines.append(
            f"| {r['flight']} | {r['conditions']} | {_f(r['steady_rms_m'])} | "
            f"{_f(r['steady_rms_m_bound'])} | {ins[0]} | {_f(r['steady_max_m'])} | "
            f"{_f(r['steady_max_m_bound'])} | {ins[1]} | {r['verdict']} |"
        )
    lines.append("")
    lines += summary(cert, rows)
    return "\n".join(lines) + "\n"


def summary(cert: dict[str, Any], rows: list[dict[str, Any]]) -> list[str]:
    """Outside count and the real median over the certificate's median."""
    import statistics

    out = []
    n_out = sum(1 for r in rows if r["steady_rms_m_inside"] is False or
                r["steady_max_m_inside"] is False)  # fmt: skip
    judged = [r for r in rows if r.get("judged", True)]
    line = f"Outside the bound: {n_out} of {len(judged)} judged flights"
    if len(judged) < len(rows):
        line += f" ({len(rows) - len(judged)} of {len(rows)} NOT JUDGED: see the verdict column)"
    out.append(line + ".")
    for key, what in (("steady_rms_m", "steady RMS"), ("steady_max_m", "max |pt|")):
        vals = [r[key] for r in rows if r[key] is not None]
        pm = cert.get(key, {}).get("median")
        if vals and pm:
            rm = statistics.median(vals)
            ratio = rm / pm
            ok = "within" if 0.67 <= ratio <= 1.5 else "OUTSIDE"
            out.append(f"{what}: real median {rm:.3f} m, certificate median {pm:.3f} m, "
                       f"real / predicted {ratio:.2f} ({ok} [0.67, 1.5]).")  # fmt: skip
    return out


def main(argv: list[str]) -> int:
    a = parser().parse_args(argv)
    if not a.certificate.is_file():
        print(f"sitl: --certificate {a.certificate}: no such file", file=sys.stderr)
        return 2
    try:
        cert = json.loads(a.certificate.read_text())
        cond_raw = dict(cert["conditions"])
    except (ValueError, KeyError) as e:
        print(f"sitl: --certificate {a.certificate}: not a certificate ({e})", file=sys.stderr)
        return 2
    if cert["mission"]["autopilot"] != a.autopilot:
        print(f"sitl: --certificate {a.certificate}: certifies {cert['mission']['autopilot']}, "
              f"not {a.autopilot}", file=sys.stderr)  # fmt: skip
        return 2
    if a.flights < 1:
        print(f"sitl: --flights {a.flights}: must be at least 1", file=sys.stderr)
        return 2
    out = a.out.resolve()
    if a.rejudge and not out.is_dir():
        print(f"sitl: --rejudge: --out {a.out}: no such directory", file=sys.stderr)
        return 2
    if not a.rejudge and out.exists() and (not out.is_dir() or any(out.iterdir())):
        print(f"sitl: --out {a.out}: exists and is not an empty directory", file=sys.stderr)
        return 2
    config = a.config or cert["mission"]["config"]
    cond = _conditions(cond_raw)
    command = "scripts/sitl " + " ".join(shlex.quote(x) for x in argv)
    out.mkdir(parents=True, exist_ok=a.rejudge)
    rows: list[dict[str, Any]] = []
    for j in range(a.flights):
        d = draw(cond, j)
        fdir = out / f"flight-{j}"
        args = rig_args(a.autopilot, config, cert, d, fdir)
        if a.speedup:
            args += ["--speedup", f"{a.speedup:g}"]
        print(f"[{j + 1}/{a.flights}] {describe(_rig_drawn(d))}", flush=True)
        if not a.rejudge:
            with open(out / f"flight-{j}.log", "w") as f:
                subprocess.run([sys.executable, "-m", "lab.rigs", *args], cwd=ROOT, stdout=f,
                               stderr=subprocess.STDOUT, check=False)  # fmt: skip
        s = _read(fdir / "summary.json")
        fig = dict(s.get("figures", {}))
        fig["verdict"] = str(s.get("verdict", "not flown"))[:40]
        r = verdict_row(cert, j, d, fig)
        rows.append(r)
        print(f"    steady RMS {_f(r['steady_rms_m'])} m (bound {_f(r['steady_rms_m_bound'])}: "
              f"{r['steady_rms_m_inside']}), max |pt| {_f(r['steady_max_m'])} m (bound "
              f"{_f(r['steady_max_m_bound'])}: {r['steady_max_m_inside']}), "
              f"{fig['verdict']}", flush=True)  # fmt: skip
    text = table(cert, rows, command)
    (out / "validation.md").write_text(text)
    (out / "validation.json").write_text(json.dumps(rows, indent=1) + "\n")
    print("\n" + text)
    if a.record:
        dest = ROOT / "docs" / "results" / f"validation-{cert['mission']['name']}.md"
        dest.write_text(text)
        print(f"recorded: {dest}")
    unjudged = [r["flight"] for r in rows if not r["judged"]]
    if unjudged:
        print(
            f"sitl: flights {unjudged} could not be judged (their verdicts above)", file=sys.stderr
        )
        return 1
    return 0


def _conditions(raw: dict[str, Any]) -> Conditions:
    """The certificate's conditions with the validation's own seed stream."""
    from mpf_mavlink.config.build import _build

    raw = {k: v for k, v in raw.items() if k != "source"}
    raw["seed"] = int(raw.get("seed", 0)) + VALIDATION_SEED_OFFSET
    return _build(Conditions, raw, "<certificate>", "")


def _rig_drawn(d: dict[str, Any]) -> dict[str, Any]:
    """The drawn conditions the rig imposes (not the link's, not the start's)."""
    return {k: v for k, v in d.items() if not k.startswith(("link.", "start."))}


def _read(p: Path) -> dict[str, Any]:
    try:
        return dict(json.loads(p.read_text()))
    except (OSError, ValueError):
        return {}
