"""A fleet in our SIL: ``scripts/sil_fleet CONFIG --n 3 --out DIR`` (docs/fleet.md).

N ``mpf-mavlink sim`` processes (each a JSBSim vehicle and its own bridge) fly CONFIG's mission
together on the realtime clock: the coordination and the target's common epoch are on the
wall clock, so N lockstep simulations, each as fast as it can go, would not share a time. They
start ``--gap`` s apart (the last slot first, as the firmware rig's bridges engage one after
another) from loiters ``--spread`` m apart, with the slots 360/N apart over a direct UDP mesh
on loopback and the same target epoch. Figures as the firmware rig's (lab/rigs/fleet.py), all
of them our own SIL's: per aircraft the plant truth's steady RMS and max of |pt| and the sim's
verdict; for the fleet the spacing error between neighbours against their slots (with
``fleet.spacing: time`` judged in time from the records alone: :func:`time_spacing_series`),
the time to converge after the last engagement, and the RMS and max from ``--judge-after`` s
on (the verdict's window). ``--seeds 1,2,3`` is the campaign row: one fleet flight per seed
(every aircraft's turbulence seeded apart), a row each and the aggregate, DIR/campaign.json.
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

import numpy as np

from lab.rigs.fleet import (
    _free_udp_ports,
    fleet_sets,
    read_fleet_csv,
    spacing_figures,
    spacing_series,
)

ROOT = Path(__file__).resolve().parents[2]


def _member_sets(
    a: argparse.Namespace, k: int, seed: int, ports: list[int], epoch: float, duration: float
) -> list[str]:
    """The ``--set`` overrides of member k: the realtime clock, its start loiter, its own
    turbulence seed, the fleet's slots, links and epoch, its duration (s)."""
    offset = (k - (a.n - 1) / 2.0) * a.spread
    return [
        "sil.clock=realtime",
        f"sil.seed={seed * 100 + k}",
        f"sil.initial_position_ned_m=[{a.start[0]},{a.start[1] + offset},{a.start[2]}]",
        f"sim.duration_s={duration}",
        *[s for s in fleet_sets(a.n, k, ports, ports, epoch) if not s.startswith("mavlink.")],
        *a.set,
    ]


def fly(a: argparse.Namespace, out: Path, seed: int) -> dict[str, Any]:
    """One fleet flight into ``out``: the N sims, then the figures (also out/fleet.json)."""
    out.mkdir(parents=True, exist_ok=False)
    ports = _free_udp_ports(a.n)
    epoch = time.time() + 10.0  # every bridge up and placing its target before t = 0
    procs: list[Any] = [None] * a.n
    print(f"seed {seed}: {a.n} SIL aircraft flying {a.duration:g} s (realtime), started "
          f"{a.gap:g} s apart, into {out}", flush=True)  # fmt: skip
    # the last slot first: each one engages a gap after the one ahead of it, as the firmware
    # rig's bridges do, so the fleet starts spread about the lap rather than bunched
    for rank, k in enumerate(reversed(range(a.n))):
        if rank:
            time.sleep(a.gap)
        cmd = [sys.executable, "-m", "mpf_mavlink.cli", "sim", str(a.config), "--no-plots", "-q",
               "--out", str(out / f"member{k}")]  # fmt: skip
        for s in _member_sets(a, k, seed, ports, epoch, a.duration + (a.n - 1 - rank) * a.gap):
            cmd += ["--set", s]
        (out / f"member{k}.cmd").write_text(" ".join(cmd) + "\n")
        log = open(out / f"member{k}.log", "w")  # noqa: SIM115 - the child's lifetime
        procs[k] = (subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT), log)
    t0 = time.time()
    try:
        while any(p.poll() is None for p, _ in procs):
            time.sleep(2.0)
            if a.progress and int(time.time() - t0) % 30 < 2:
                print(f"  {time.time() - t0:.0f} s", flush=True)
    finally:
        for p, log in procs:
            if p.poll() is None:
                p.terminate()
                p.wait(20)
            log.close()
    return judge(a, out, [p.returncode for p, _ in procs], seed)


def judge(a: argparse.Namespace, out: Path, codes: list[int | None], seed: int) -> dict[str, Any]:
    """The per-aircraft and fleet figures of a finished flight directory."""
    from mpf_mavlink.config.scenario import build_path
    from mpf_mavlink.config.schema import load_config

    cfg = load_config(a.config)
    L = float(build_path(cfg.path).length)
    dirs = [out / f"member{k}" / "bridge" for k in range(a.n)]
    tracks = [read_fleet_csv(d / "fleet.csv") for d in dirs]
    aircraft = []
    for k in range(a.n):
        try:
            m = json.loads((out / f"member{k}" / "metrics.json").read_text())
        except (OSError, ValueError):
            m = {}
        aircraft.append({
            "steady_rms_m": m.get("steady_rms_m"), "steady_max_m": m.get("steady_max_m"),
            "cross_track_rms_m": m.get("steady_rms_cross_track_m"),
            "verdict": m.get("verdict_status", "NO RUN"), "exit_code": codes[k],
        })  # fmt: skip
    s: dict[str, Any] = {"seed": seed, "config": str(a.config), "n": a.n, "aircraft": aircraft,
                         "length_m": L}  # fmt: skip
    if any(tr is None for tr in tracks):
        s["fleet"] = {"converged": False, "why": "a member wrote no fleet.csv"}
    else:
        t_all = max(float(tr["t_unix_s"][0]) for tr in tracks if tr is not None)
        slots = [j / a.n for j in range(a.n)]
        if cfg.section("fleet").spacing == "time":
            ser = time_spacing_series([tr for tr in tracks if tr is not None], slots, L)
        else:
            ser = spacing_series(tracks, slots, L, True)
        s["fleet"] = spacing_figures(ser, t_all, math.inf, a.converge_m, a.n)
        # and over a stated window: from --judge-after s after the last engagement to the end
        s["fleet"]["window"] = _window(ser, t_all + a.judge_after, a.n)
        s["fleet"]["window"]["from_s"] = a.judge_after
        np.savez(out / "spacing.npz", t_unix_s=ser["t_unix_s"], worst_m=ser["worst_m"],
                 n_alive=ser["n_alive"])  # fmt: skip
        try:
            from lab.rigs.fleet_figures import draw

            draw(out, a.n, ser, t_all, None, dirs)
        except Exception as e:  # noqa: BLE001 - figures never fail a flight
            s["figures_error"] = f"{type(e).__name__}: {e}"
    fl = s["fleet"]
    bad = [k for k, f in enumerate(aircraft) if f["verdict"] != "PASS"]
    if bad:
        s["verdict"] = f"FAIL: aircraft {bad} did not pass"
    elif "window" not in fl or fl["window"]["spacing_rms_m"] is None:
        s["verdict"] = f"FAIL: no spacing from {a.judge_after:g} s ({fl.get('why', '')})"
    elif fl["window"]["spacing_rms_m"] > a.spacing_bar:
        rms = fl["window"]["spacing_rms_m"]
        s["verdict"] = (f"FAIL: spacing RMS {rms:.2f} m > {a.spacing_bar:g} m from "
                        f"{a.judge_after:g} s")  # fmt: skip
    else:
        s["verdict"] = "PASS"
    (out / "fleet.json").write_text(json.dumps(s, indent=2, default=str) + "\n")
    return s


def time_spacing_series(
    tracks: list[dict[str, np.ndarray]], slots: list[float], length_m: float, hz: float = 2.0
) -> dict[str, Any]:
    """Spacing in time judged from the records alone (each member's s against the common clock,
    no lap-clock model): for each neighbour pair (a, b ahead by the slot difference dsigma) at
    time t, the gap since b was where a is now, against dsigma times a's own last lap (the time
    since a was there one lap ago); the error in metres at the lap's mean along-path speed
    (L / lap). Where a has not flown a lap yet, the pair is not judged."""
    L = length_m
    hist = []
    for tr in tracks:
        t, sm = tr["t_unix_s"], np.maximum.accumulate(tr["s_m"])  # s flown, for interpolation
        hist.append((t, sm))
    t0 = max(h[0][0] for h in hist)
    t1 = min(h[0][-1] for h in hist)
    grid = np.arange(t0, t1, 1.0 / hz)
    order = sorted(range(len(tracks)), key=lambda k: slots[k] % 1.0)
    worst = np.full(len(grid), np.nan)
    n_alive = np.zeros(len(grid), int)
    pairs: list[list[float]] = []

    def when(k: int, s_val: float) -> float:
        t, sm = hist[k]
        if s_val < sm[0]:
            return math.nan
        return float(np.interp(s_val, sm, t))

    for gi, t in enumerate(grid):
        errs = []
        for i, a in enumerate(order):
            b = order[(i + 1) % len(order)]
            sa = float(np.interp(t, *hist[a]))
            sb = float(np.interp(t, *hist[b]))
            lap = t - when(a, sa - L)
            tb = when(b, sb - ((sb - sa) % L))  # b's latest time at a's place
            if not (math.isfinite(lap) and math.isfinite(tb)):
                continue
            dsig = (slots[b] - slots[a]) % 1.0
            errs.append(((t - tb) - dsig * lap) * L / lap)
        n_alive[gi] = len(tracks) if len(errs) == len(order) else 0
        pairs.append(errs if n_alive[gi] else [])
        if errs and n_alive[gi]:
            worst[gi] = max(abs(e) for e in errs)
    return {"t_unix_s": grid, "worst_m": worst, "n_alive": n_alive, "pairs": pairs}


def _window(ser: dict[str, Any], t_from: float, n: int) -> dict[str, Any]:
    """RMS and max (m) of every neighbour pair's spacing error from ``t_from`` (Unix s) on,
    while all n members report."""
    t, na = ser["t_unix_s"], ser["n_alive"]
    errs = [e for i in np.flatnonzero((t >= t_from) & (na == n)) for e in ser["pairs"][i]]
    if not errs:
        return {"spacing_rms_m": None, "spacing_max_m": None, "judged_s": 0.0}
    x = np.abs(np.array(errs))
    judged = float(t[(t >= t_from) & (na == n)][-1] - t_from)
    return {"spacing_rms_m": float(np.sqrt(np.mean(x**2))), "spacing_max_m": float(x.max()),
            "judged_s": judged}  # fmt: skip


def _f(x: Any, spec: str = ".3g") -> str:
    return "-" if x is None else format(float(x), spec)


def print_flight(s: dict[str, Any]) -> None:
    print(f"seed {s['seed']}: {s['n']} aircraft on {s['config']} (our SIL, JSBSim X8, realtime)")
    print(f"{'aircraft':>8} {'steady RMS m':>12} {'max m':>7} {'xtrack RMS':>10}  verdict")
    for k, f in enumerate(s["aircraft"]):
        print(f"{k:>8} {_f(f['steady_rms_m']):>12} {_f(f['steady_max_m']):>7} "
              f"{_f(f['cross_track_rms_m']):>10}  {f['verdict']}")  # fmt: skip
    fl = s["fleet"]
    if fl.get("converged"):
        print(f"fleet: start spread {_f(fl['start_spread_worst_m'])} m; converged (all pairs "
              f"within {s.get('converge_m')} m) {_f(fl['converge_s'])} s after the last "
              f"engagement; "
              f"spacing RMS {_f(fl['spacing_rms_m'])} m, max {_f(fl['spacing_max_m'])} m over "
              f"{_f(fl['judged_s'])} s")  # fmt: skip
    else:
        print(f"fleet: not converged within {s.get('converge_m')} m for good: {fl}")
    w = fl.get("window")
    if w:
        print(f"fleet: from {w['from_s']:g} s after the last engagement: spacing RMS "
              f"{_f(w['spacing_rms_m'])} m, max {_f(w['spacing_max_m'])} m over "
              f"{_f(w['judged_s'])} s")  # fmt: skip
    print(f"verdict: {s['verdict']}", flush=True)


def campaign_row(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The aggregate of the seeds' flights: worst aircraft RMS, spacing RMS and convergence."""
    rms = [max((f["steady_rms_m"] or math.inf) for f in r["aircraft"]) for r in rows]
    sp = [(r["fleet"].get("window") or {}).get("spacing_rms_m") or math.inf for r in rows]
    cv = [r["fleet"].get("converge_s", math.inf) for r in rows]
    return {
        "flights": len(rows),
        "passed": sum(r["verdict"] == "PASS" for r in rows),
        "worst_aircraft_rms_m": {"mean": float(np.mean(rms)), "max": float(np.max(rms))},
        "spacing_rms_m_from_judge_after": {"mean": float(np.mean(sp)), "max": float(np.max(sp))},
        "converge_s": {"mean": float(np.mean(cv)), "max": float(np.max(cv))},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="scripts/sil_fleet",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
        epilog="Exit 0 when every flight's verdict is PASS, 1 otherwise, 2 for bad arguments.",
    )
    p.add_argument("config", type=Path, nargs="?", default=ROOT / "configs" / "fleet_demo.yaml",
                   help="mission YAML with a fleet section (default: configs/fleet_demo.yaml, "
                   "the demo's figure-eight spaced in time)")  # fmt: skip
    p.add_argument("--out", type=Path, required=True, help="run directory (new)")
    p.add_argument("--n", type=int, default=3, help="aircraft (default 3)")
    p.add_argument("--duration", type=float, default=300.0, help="s of tracking (default 300)")
    p.add_argument("--seeds", default="1", help="comma-separated seeds: one flight each")
    p.add_argument("--spread", type=float, default=30.0, help="m between start loiters")
    p.add_argument("--gap", type=float, default=18.0,
                   help="s between the members' starts (default 18: a third of the demo's "
                   "~53 s lap)")  # fmt: skip
    p.add_argument("--start", type=float, nargs=3, default=(-100.0, 0.0, -100.0),
                   metavar=("N", "E", "D"), help="the middle start loiter (m, NED)")  # fmt: skip
    p.add_argument("--converge-m", type=float, default=10.0, help="converged: pairs within")
    p.add_argument("--spacing-bar", type=float, default=5.0, help="spacing RMS bar (m)")
    p.add_argument(
        "--judge-after",
        type=float,
        default=150.0,
        help="the spacing is judged from this many s after the last engagement "
        "(default 150: the captures and the first laps)",
    )
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override for every member (repeatable)")  # fmt: skip
    p.add_argument("--no-progress", dest="progress", action="store_false")
    a = p.parse_args(argv)
    try:
        seeds = [int(x) for x in a.seeds.split(",") if x.strip()]
    except ValueError:
        p.error(f"--seeds {a.seeds!r}: expected integers separated by commas")
    if a.n < 2 or not a.config.is_file() or a.out.exists() and any(a.out.iterdir()):
        p.error("--n >= 2, an existing CONFIG and a new or empty --out are needed")
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in seeds:
        s = fly(a, a.out / f"seed{seed}", seed)
        s["converge_m"] = a.converge_m
        print_flight(s)
        rows.append(s)
    if len(rows) > 1:
        row = campaign_row(rows)
        (a.out / "campaign.json").write_text(json.dumps({"row": row, "flights": rows},
                                                        indent=2, default=str) + "\n")  # fmt: skip
        print(f"campaign row: {json.dumps(row)}")
    return 0 if all(r["verdict"] == "PASS" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
