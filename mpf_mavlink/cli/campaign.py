"""``mpf-mavlink campaign CAMPAIGN.yaml --out DIR``: Monte-Carlo flights on dask.distributed."""

from __future__ import annotations

import argparse
import json
import sys


def cmd_campaign(args: argparse.Namespace) -> int:
    from mpf_mavlink.campaign.design import load_campaign
    from mpf_mavlink.campaign.report import format_summary, plots, reflown_dirs, summarise
    from mpf_mavlink.campaign.run import run_campaign
    from mpf_mavlink.errors import MpfError

    if args.workers is not None and args.workers < 1:
        raise MpfError(f"--workers {args.workers}: must be at least 1")
    spec = load_campaign(args.campaign)
    res = run_campaign(
        spec, args.out, workers=args.workers, scheduler=args.scheduler,
        progress=not args.quiet, retry_errors=args.retry_errors,
    )  # fmt: skip
    summary = summarise(spec, res.rows)
    summary.update(wall_s=res.wall_s, flown=res.flown, skipped=res.skipped, workers=res.workers)
    if res.flown and res.wall_s > 0:
        summary["flights_per_min"] = 60.0 * res.flown / res.wall_s
    if not args.no_report:
        files = plots(spec, res.rows, args.out)
        kept = reflown_dirs(spec, res.rows, args.out)
        summary["figures"] = [str(p) for p in files]
        summary["worst_run_dirs"] = [str(p) for p in kept]
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(format_summary(summary))
    if "flights_per_min" in summary:
        print(f"flown now: {res.flown} in {res.wall_s:.1f} s on {res.workers} worker(s) "
              f"({summary['flights_per_min']:.1f} flights/min); "
              f"results: {args.out / 'results.csv'}")  # fmt: skip
    for d in summary.get("worst_run_dirs", []):
        print(f"worst flight kept: {d}  (mpf-mavlink plot {d})")
    bad = summary["status"].get("error", 0) + summary["status"].get("timeout", 0)
    if bad:
        print(f"mpf-mavlink: {bad} flight(s) did not run to their end (see the error column)",
              file=sys.stderr)  # fmt: skip
        return 1
    return 0
