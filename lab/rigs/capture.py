"""The capture matrix on real firmware: ``scripts/capture-figures --out DIR [--record]``.

Both autopilots x {the shipped circle, a closed 3D spline over a moving target} x {300 m from
the path flying away, 30 m below it, 30 m above it}: 12 flights of the rig
(``scripts/sitl AUTOPILOT --start-offset X,Y,D``, :mod:`lab.rigs.common`), each as long as its
capture bound plus ~30 s of tracking, then ``--before``'s rows with the capture guards off
(``guidance.capture_guards=false``) to show what they fix. Per row (from the bridge's run
record: ``bridge/timeseries.csv``, ``bridge/limits.csv``, ``bridge/metrics.json``):

- start: |pt| when the bridge engaged (m);
- captured: the bridge's convergence time, |pt| < 5 m (``metrics.converge_threshold_m`` of the
  shipped configs) from then to the end of the flight;
- bound: d0 / (v_a - v_t) + 2 pi R / v_a + 20 s (:func:`capture_bound_s`);
- lowest altitude against the moving path's lowest point less 10 m (above home), or, from a
  start below that (30 m under a circle), against the start altitude less 1 m: no descent;
- time with |bank| beyond the autopilot's limit + 2 deg (at most 1 s) and the largest bank;
- verdict: PASS when captured within the bound, never below the floor, and beyond the bank
  limit + 2 deg for at most 1 s.

``--render DIR`` writes the table of flights already flown again; ``--record`` writes
``docs/results/capture.md`` with the command that wrote it.
"""

from __future__ import annotations

import argparse
import csv
import datetime as _dt
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from lab.rigs.bundles import ROOT
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.constants import GRAVITY_M_S2

RESULT = ROOT / "docs" / "results" / "capture.md"
CONFIGS = {
    ("arduplane", "circle"): "configs/bridge_arduplane.yaml",
    ("arduplane", "spline"): "configs/bridge_arduplane_spline.yaml",
    ("px4", "circle"): "configs/bridge_px4.yaml",
    ("px4", "spline"): "configs/bridge_px4_spline.yaml",
}
#: the starts (X along the aircraft's track, Y right, D down; m from the placed path)
STARTS = {"away": (300.0, 0.0, 0.0), "below": (0.0, 0.0, 30.0), "above": (0.0, 0.0, -30.0)}
#: the "before" rows: the same starts with the guards off
BEFORE = (("arduplane", "spline", "away"), ("px4", "spline", "away"))
FLOOR_MARGIN_M = 10.0  # the acceptance: never below the path's lowest point less this
START_TOLERANCE_M = 1.0  # ... or, starting below that, below the start (its altitude noise)
BANK_OVER_DEG = 2.0  # ... nor beyond the autopilot's bank limit + this for more than 1 s
BANK_OVER_MAX_S = 1.0
SETTLE_S = 20.0  # the law's settling once near the path (bound), see capture_bound_s
STEADY_S = 30.0  # tracking flown after the bound
#: the start 30 m below sits at the edge of checks.max_start_below_m (30 m): raised for the
#: matrix so that the engagement altitude's noise does not refuse it
SETS = ("checks.max_start_below_m=45",)


def capture_bound_s(cfg: Any, d0_m: float) -> float:
    """The capture time (s) a row must meet from |pt(0)| = d0_m: d0 / (v_a - v_t), flown
    straight back against the target's motion, plus one full turn at the guarded bank (the
    reversal and the turn onto the path) 2 pi R / v_a with R = v_a^2 / (g k tan(B - margin)),
    plus SETTLE_S for the law's own convergence from the path's neighbourhood."""
    v = cfg.vehicle
    va = v.airspeed_m_s
    vt = float(getattr(cfg.target, "speed_m_s", 0.0) or 0.0)
    lim = (
        v.max_bank_rad
        if v.autopilot_bank_limit_rad is None
        else min(v.max_bank_rad, v.autopilot_bank_limit_rad)
    )
    bank = lim - cfg.guidance.capture_bank_margin_rad
    radius = va * va / (GRAVITY_M_S2 * v.turn_gain * math.tan(bank))
    return float(d0_m / max(va - vt, 1.0) + 2.0 * math.pi * radius / va + SETTLE_S)


def bank_limit_deg(cfg: Any) -> float:
    v = cfg.vehicle
    lim = (
        v.max_bank_rad
        if v.autopilot_bank_limit_rad is None
        else min(v.max_bank_rad, v.autopilot_bank_limit_rad)
    )
    return math.degrees(lim)


def _read_csv(p: Path) -> dict[str, np.ndarray]:
    with open(p) as f:
        rows = list(csv.reader(f))
    head, data = rows[0], np.array([[float(x) for x in r] for r in rows[1:] if r], float)
    return {h: data[:, i] for i, h in enumerate(head)}


def _time_over(mask: np.ndarray, t: np.ndarray) -> float:
    """Seconds for which ``mask`` holds (each sample holding until the next)."""
    if len(t) < 2:
        return 0.0
    dt = np.diff(t, append=t[-1])
    return float(np.sum(dt[mask]))


def row_figures(flight_dir: Path, cfg: Any) -> dict[str, Any]:
    """The row's figures of one rig flight directory (see the module docstring)."""
    b = flight_dir / "bridge"
    m = json.loads((b / "metrics.json").read_text())
    ts = _read_csv(b / "timeseries.csv")
    lim = _read_csv(b / "limits.csv")
    sp = _read_csv(b / "setpoints.csv")
    nodes = _read_csv(b / "path_T.csv")
    zmax = float(np.max(nodes[list(nodes)[-1]]))  # {T} down of the path's lowest node
    # the path's lowest point (level targets: the target's down plus the lowest node's)
    lowest_alt = -(ts["tgt_d"] + zmax)
    alt = -ts["p_d"]
    t = ts["t"]
    d0 = float(m.get("initial_pt_m") or ts["pt_norm"][0])
    bound = capture_bound_s(cfg, d0)
    cap = m.get("convergence_time_s")
    lim_deg = bank_limit_deg(cfg)
    roll = np.degrees(np.abs(lim["roll"]))
    over_s = _time_over(roll > lim_deg + BANK_OVER_DEG, lim["t"])
    # the floor; a start below it (30 m under a circle) must not descend from where it engaged
    floor = np.minimum(lowest_alt - FLOOR_MARGIN_M, alt[0] - START_TOLERANCE_M)
    k = int(np.argmin(alt - floor))
    floor_ok = bool(np.all(alt >= floor))
    cap_ok = cap is not None and float(cap) <= bound
    exit_reason = str(m.get("exit_reason") or "")
    cut = "mission duration" not in exit_reason  # a safety exit of the bridge, not the end
    ok = cap_ok and floor_ok and over_s <= BANK_OVER_MAX_S and not cut
    why = [w for w, bad in ((f"bridge stopped: {exit_reason}", cut),
                            ("not captured in the bound", not cap_ok),
                            ("below the floor", not floor_ok),
                            ("over-banked", over_s > BANK_OVER_MAX_S)) if bad]  # fmt: skip
    return {
        "start_m": d0,
        "captured_s": None if cap is None else float(cap),
        "bound_s": bound,
        "lowest_alt_m": float(alt[k]),
        "path_lowest_alt_m": float(lowest_alt[k]),
        "floor_alt_m": float(floor[k]),
        "lowest_at_s": float(t[k]),
        "bank_over_s": over_s,
        "bank_limit_deg": lim_deg,
        "max_bank_deg": float(np.max(roll)),
        "tracked_s": float(t[-1]),
        "steady_rms_m": m.get("steady_rms_m"),
        "sdot_range_m_s": [float(ts["sdot"].min()), float(ts["sdot"].max())],
        "pitch_sp_range_deg": [
            float(np.degrees(sp["pitch"].min())),
            float(np.degrees(sp["pitch"].max())),
        ],  # fmt: skip
        "max_bank_sp_deg": float(np.degrees(np.abs(sp["bank"]).max())),
        "verdict": "PASS" if ok else "FAIL: " + ", ".join(why),
    }


def _flight(ap: str, path: str, start: str, before: bool) -> str:
    return f"{ap}-{path}-{start}" + ("-guards-off" if before else "")


def fly_row(out: Path, ap: str, path: str, start: str, before: bool) -> Path:
    """One rig flight; returns its directory (the rig's exit code is the bridge verdict's,
    which judges the steady window: the matrix judges the capture itself)."""
    cfg_path = CONFIGS[(ap, path)]
    cfg = load_config(ROOT / cfg_path)
    off = STARTS[start]
    d_plan = math.hypot(*off) * (1.2 if off[0] else 1.0)
    duration = max(90.0, capture_bound_s(cfg, d_plan) + STEADY_S)
    d = out / _flight(ap, path, start, before)
    sets = [*SETS, *(["guidance.capture_guards=false"] if before else [])]
    cmd = [sys.executable, "-m", "lab.rigs", ap, "--out", str(d), "--config", cfg_path,
           "--start-offset", ",".join(f"{x:g}" for x in off), "--duration", f"{duration:.0f}",
           *[x for s in sets for x in ("--set", s)]]  # fmt: skip
    print("capture: " + " ".join(cmd[2:]), flush=True)
    with open(out / f"{d.name}.log", "w") as log:
        subprocess.run(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, check=False)
    return d


def _rng(x: Any) -> str:
    return "n/a" if x is None else f"{x[0]:.1f}..{x[1]:.1f}"


def fly_sil(out: Path, guards: bool) -> Path:
    """Our SIL (JSBSim X8 with ArduPlane's rules behind MAVLink, the real bridge over UDP) on
    the ArduPlane spline from 300 m beyond its southern point, flying south: the same start
    with the guards on and off, run to run repeatable where the firmware's loiter is not."""
    d = out / f"sil-arduplane-spline-away-guards-{'on' if guards else 'off'}"
    cmd = [sys.executable, "-m", "mpf_mavlink.cli", "sim", CONFIGS[("arduplane", "spline")],
           "--out", str(d), "--set", "sil.link=udp", "--set", "sim.duration_s=100",
           "--set", "kinematic.initial_position_ned_m=[-520,0,-100]",
           "--set", "kinematic.initial_attitude_rpy_rad=[0,0,3.14159]",
           "--set", f"guidance.capture_guards={'true' if guards else 'false'}"]  # fmt: skip
    print("capture: " + " ".join(cmd[2:]), flush=True)
    with open(out / f"{d.name}.log", "w") as log:
        subprocess.run(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, check=False)
    return d


def _fmt(x: Any, spec: str = ".1f") -> str:
    return "n/a" if x is None else format(x, spec)


def table(out: Path, command: str) -> str:
    """docs/results/capture.md's text from the flights in ``out``."""
    lines = [
        "# Capture from far: the matrix on real firmware (written by `scripts/capture-figures`; "
        "do not edit by hand)",
        "",
        f"Command: `{command}`",
        "",
        "Stock firmware from ../shared/sitl (`scripts/sitl AUTOPILOT --start-offset X,Y,D`, "
        "docs/sitl.md), configs as shipped plus `--set "
        + " ".join(SETS)
        + "` (the 30 m-below start is at checks.max_start_below_m's edge). Start: |pt| at "
        "engagement. Captured: |pt| < 5 m from then to the end. Bound: d0 / (v_a - v_t) + "
        "2 pi R / v_a + 20 s, R = v_a^2 / (g k tan(bank limit - 5 deg)): flown straight back "
        "against the target, one full turn at the guarded bank, the law's settling. Lowest: "
        "the aircraft's lowest altitude above home, against the floor: the moving path's lowest "
        f"point - {FLOOR_MARGIN_M:g} m, or from a start below that the start altitude - "
        f"{START_TOLERANCE_M:g} m (no descent). Bank: time beyond the autopilot's limit + "
        f"{BANK_OVER_DEG:g} deg (at most {BANK_OVER_MAX_S:g} s) and the largest bank (the "
        "aircraft's own loiter bank at engagement included). sdot: the virtual point's "
        "progression, its range; set-points: the pitch range and the largest bank sent. "
        "Guards off: `--set guidance.capture_guards=false`. The sil-arduplane rows are our SIL "
        "(`mpf-mavlink sim --set sil.link=udp`: JSBSim X8, ArduPlane rules, the real bridge) "
        "from 300 m beyond the spline's southern point flying south, with the guards on and "
        "off: the same start each time, where the firmware's loiter gives another start per "
        "flight.",
        "",
        "| autopilot | path | start | guards | start (m) | captured (s) | bound (s) | lowest / "
        "floor (m) | bank > limit + 2 (s) | max bank / limit (deg) | steady RMS (m) | sdot "
        "(m/s) | pitch, max bank set-point (deg) | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    flown: list[dict[str, Any]] = []
    keys = [(a, p, s, False) for a in ("arduplane", "px4") for p in ("circle", "spline")
            for s in STARTS] + [(a, p, s, True) for a, p, s in BEFORE]  # fmt: skip
    keys += [("sil-arduplane", "spline", "away", b) for b in (False, True)]
    for ap, path, start, before in keys:
        d = out / _flight(ap, path, start, before)
        if ap.startswith("sil"):
            d = out / f"{ap}-{path}-{start}-guards-{'off' if before else 'on'}"
        cfg = load_config(ROOT / CONFIGS[(ap.removeprefix("sil-"), path)])
        try:
            f = row_figures(d, cfg)
        except (OSError, ValueError, KeyError, IndexError) as e:
            f = {"verdict": f"NOT FLOWN ({type(e).__name__})"}
        f.update(autopilot=ap, path=path, start=start, guards=not before)
        flown.append(f)
        lines.append(
            f"| {ap} | {path} ({CONFIGS[(ap.removeprefix('sil-'), path)]}) | "
            f"{start} {STARTS[start]} | "
            f"{'off' if before else 'on'} | {_fmt(f.get('start_m'), '.0f')} | "
            f"{_fmt(f.get('captured_s'))} | {_fmt(f.get('bound_s'), '.0f')} | "
            f"{_fmt(f.get('lowest_alt_m'))} / {_fmt(f.get('floor_alt_m'))} | "
            f"{_fmt(f.get('bank_over_s'))} | {_fmt(f.get('max_bank_deg'))} / "
            f"{_fmt(f.get('bank_limit_deg'))} | {_fmt(f.get('steady_rms_m'), '.2f')} | "
            f"{_rng(f.get('sdot_range_m_s'))} | {_rng(f.get('pitch_sp_range_deg'))}, "
            f"{_fmt(f.get('max_bank_sp_deg'))} | {f['verdict']} |"
        )
    (out / "capture.json").write_text(json.dumps(flown, indent=2) + "\n")
    date = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    lines += ["", f"Written {date} from {out.name}/ (commit {_commit()})."]
    return "\n".join(lines) + "\n"


def _commit() -> str:
    r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                       text=True, check=False)  # fmt: skip
    return r.stdout.strip() or "unknown"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="scripts/capture-figures", description=__doc__)
    ap.add_argument("--out", required=True, help="directory of the flights (kept, reused)")
    ap.add_argument("--only", choices=("arduplane", "px4"), help="one autopilot's rows")
    ap.add_argument("--path", choices=("circle", "spline"), help="one path's rows")
    ap.add_argument("--start", choices=tuple(STARTS), help="one start's rows")
    ap.add_argument("--before", action="store_true", help="also the guards-off rows")
    ap.add_argument("--no-matrix", action="store_true", help="only the guards-off rows")
    ap.add_argument("--sil", action="store_true", help="also our SIL's rows (guards on, off)")
    ap.add_argument("--render", action="store_true", help="fly nothing: the table of --out")
    ap.add_argument("--record", action="store_true", help="write docs/results/capture.md")
    a = ap.parse_args(argv)
    out = Path(a.out).expanduser().resolve()
    out.mkdir(parents=True, exist_ok=True)
    if not a.render:
        todo = [] if a.no_matrix else [(p_, q, s, False) for p_ in ("arduplane", "px4")
                                       for q in ("circle", "spline") for s in STARTS]  # fmt: skip
        if a.before or a.no_matrix:
            todo += [(p_, q, s, True) for p_, q, s in BEFORE]
        for p_, q, s, before in todo:
            if (a.only and p_ != a.only) or (a.path and q != a.path) or (a.start and s != a.start):
                continue
            if (out / _flight(p_, q, s, before) / "summary.json").is_file():
                continue  # flown already (the directory is reused, never overwritten)
            fly_row(out, p_, q, s, before)
    if a.sil and not a.render:
        for guards in (True, False):
            if not (out / f"sil-arduplane-spline-away-guards-{'on' if guards else 'off'}"
                    / "metrics.json").is_file():  # fmt: skip
                fly_sil(out, guards)
    command = "scripts/capture-figures " + " ".join(sys.argv[1:] if argv is None else argv)
    text = table(out, command)
    (out / "capture.md").write_text(text)
    print(text)
    if a.record:
        RESULT.write_text(text)
        print(f"written {RESULT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
