"""A fleet in our SIL: N ``mpf-mavlink vehicle`` processes (JSBSim, real-time clock: the
coordination's common time is the wall clock) and N ``mpf-mavlink run`` bridges on one path,
each vehicle started on the path ``--spread-deg`` from the previous one (docs/fleet.md).

    python -m sim.fleet_sil --fleet 2 --duration 90 --out DIR [--config CFG] [--set K=V ...]

Prints and writes DIR/fleet.json: per aircraft the bridge's steady RMS and verdict, for the
fleet the spacing figures of :func:`sim.rigs.fleet.spacing_figures`. Circles only (the start
states are placed on the circle, clockwise).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from sim.rigs.bundles import die_with_parent
from sim.rigs.fleet import (
    _free_udp_ports,
    fleet_sets,
    read_fleet_csv,
    spacing_figures,
    spacing_series,
)

ROOT = Path(__file__).resolve().parents[1]


def fly(a: argparse.Namespace) -> dict[str, Any]:
    from mpf_mavlink.config.scenario import build_path
    from mpf_mavlink.config.schema import load_config

    cfg = load_config(Path(a.config), list(a.overrides))
    if cfg.path.type != "circle":
        raise SystemExit(f"fleet_sil: {a.config}: a circle is needed (path.type {cfg.path.type})")
    n, out = a.fleet, Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    r = float(cfg.path.radius_m)
    c = [
        float(x) + float(y)
        for x, y in zip(cfg.target.position_ned_m, cfg.path.center_m, strict=True)
    ]
    L = float(build_path(cfg.path).length)
    ports = _free_udp_ports(2 * n)
    vports, fports = ports[:n], ports[n:]
    epoch = time.time() + 8.0
    procs: list[subprocess.Popen[str]] = []
    py = [sys.executable, "-m", "mpf_mavlink.cli"]
    try:
        for k in range(n):
            th = math.pi - math.radians(a.spread_deg) * k  # clockwise: behind the previous one
            pos = [c[0] + r * math.cos(th), c[1] + r * math.sin(th), c[2]]
            sets = [
                *a.overrides,
                f"sil.initial_position_ned_m=[{pos[0]:.2f},{pos[1]:.2f},{pos[2]:.2f}]",
                f"sil.initial_heading_rad={th + math.pi / 2:.5f}",
                "sil.initial_mode=cruise",
                "sil.clock=realtime",
            ]
            serve = f"udpin:127.0.0.1:{vports[k]}"
            extra = [x for s in sets for x in ("--set", s)]
            cmd = [*py, "vehicle", a.config, "--serve", serve, "--duration",
                   f"{a.duration + 60:g}", *extra]  # fmt: skip
            with open(out / f"vehicle{k}.log", "w") as log:
                procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                              text=True, preexec_fn=die_with_parent))  # fmt: skip
        time.sleep(3.0)
        for k in range(n):
            sets = [*a.overrides, *fleet_sets(n, k, fports, fports, epoch), "mavlink.plots=false"]
            cmd = [*py, "run", a.config, "--connect", f"udpout:127.0.0.1:{vports[k]}",
                   "--duration", f"{a.duration:g}", "--out", str(out / f"bridge{k}"),
                   *[x for s in sets for x in ("--set", s)]]  # fmt: skip
            with open(out / f"bridge{k}.log", "w") as log:
                procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                              text=True, preexec_fn=die_with_parent))  # fmt: skip
        codes = [p.wait(timeout=a.duration + 180) for p in procs[n:]]
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
    aircraft = []
    for k in range(n):
        try:
            m = json.loads((out / f"bridge{k}" / "metrics.json").read_text())
        except (OSError, ValueError):
            m = {}
        aircraft.append({"steady_rms_m": m.get("steady_rms_m"), "verdict": m.get("verdict"),
                         "exit_code": codes[k]})  # fmt: skip
    tracks = [read_fleet_csv(out / f"bridge{k}" / "fleet.csv") for k in range(n)]
    fl: dict[str, Any] = {"converged": False, "why": "no fleet.csv"}
    if any(t is not None for t in tracks):
        firsts = [t["t_unix_s"][0] for t in tracks if t is not None]
        ser = spacing_series(tracks, [j / n for j in range(n)], L, True)
        fl = spacing_figures(ser, max(firsts), math.inf, a.converge_m, n)
    s = {"aircraft": aircraft, "fleet": fl, "n": n, "spread_deg": a.spread_deg}
    (out / "fleet.json").write_text(json.dumps(s, indent=2, default=str) + "\n")
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim.fleet_sil")
    ap.add_argument("--fleet", type=int, default=2)
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--config", default=str(ROOT / "configs" / "bridge_arduplane.yaml"))
    ap.add_argument("--spread-deg", type=float, default=150.0)
    ap.add_argument("--converge-m", type=float, default=10.0)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    a = ap.parse_args(argv)
    s = fly(a)
    for k, f in enumerate(s["aircraft"]):
        print(f"aircraft {k}: steady RMS {f['steady_rms_m']} m, {f['verdict']}")
    print(f"fleet: {s['fleet']}")
    return 0 if s["fleet"].get("converged") else 1


if __name__ == "__main__":
    sys.exit(main())
