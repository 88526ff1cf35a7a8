"""``mpf-mavlink certify CONFIG --autopilot px4|arduplane --conditions FILE --out DIR``: a
distribution-free bound on how a mission flies on the calibrated SIL in stated conditions."""

from __future__ import annotations

import argparse
import shlex
import sys
import time


def cmd_certify(args: argparse.Namespace) -> int:
    from mpf_mavlink.certify.conditions import parse_conditions
    from mpf_mavlink.certify.report import certificate, summary_lines, write_report
    from mpf_mavlink.certify.run import fly_all, mission
    from mpf_mavlink.certify.stats import flights_needed
    from mpf_mavlink.errors import MpfError

    if args.workers is not None and args.workers < 1:
        raise MpfError(f"--workers {args.workers}: must be at least 1")
    if args.flights is not None and args.flights < 1:
        raise MpfError(f"--flights {args.flights}: must be at least 1")
    if not args.config.is_file():
        raise MpfError(f"{args.config}: no such configuration")
    cond = parse_conditions(args.conditions)
    m = mission(args.config, args.overrides, args.autopilot, cond)
    need = flights_needed(cond.quantile, cond.confidence)
    n = args.flights if args.flights is not None else need
    if n < need:
        print(f"certify: {n} flights are fewer than the {need} a one-sided "
              f"{100 * cond.quantile:g} % bound at {100 * cond.confidence:g} % needs: the "
              "certificate's bound will be n/a", file=sys.stderr)  # fmt: skip
    res = fly_all(m, cond, n, args.out, args.workers, args.scheduler, progress=not args.quiet)
    cmd = "mpf-mavlink certify " + " ".join(shlex.quote(x) for x in sys.argv[2:])
    info = {"name": cond.name, "config": m.config, "sets": m.sets, "autopilot": m.autopilot,
            "profile": m.profile, "duration_s": m.duration_s,
            "steady_after_s": m.steady_after_s, "command": cmd,
            "written": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}  # fmt: skip
    cert = certificate(res.rows, cond, info)
    if res.flown and res.wall_s > 0:
        cert["speed"] = {"flown": res.flown, "wall_s": res.wall_s, "workers": res.workers,
                         "flights_per_min": 60.0 * res.flown / res.wall_s}  # fmt: skip
    write_report(args.out, cert, res.rows)
    print("\n".join(summary_lines(cert)))
    if "speed" in cert:
        s = cert["speed"]
        print(f"flown now: {s['flown']} in {s['wall_s']:.1f} s on {s['workers']} worker(s) "
              f"({s['flights_per_min']:.2f} flights/min; {cert['cpu_s_per_flight']:.1f} CPU-s "
              "per flight)")  # fmt: skip
    print(f"kept from before: {res.kept}; certificate: {args.out / 'certificate.json'}, "
          f"report: {args.out / 'report.md'}")  # fmt: skip
    bad = sum(1 for r in res.rows if r["status"] in ("error", "timeout"))
    if bad:
        print(f"mpf-mavlink: {bad} flight(s) did not run to their end (see flights.csv)",
              file=sys.stderr)  # fmt: skip
        return 1
    return 0
