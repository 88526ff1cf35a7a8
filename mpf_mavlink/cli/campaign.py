"""``mpf-mavlink campaign CAMPAIGN.yaml --out DIR``: Monte-Carlo flights on dask.distributed."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from mpf_mavlink.cli.common import exit_codes_epilog


def add_campaign_parser(sub: Any) -> None:
    c = sub.add_parser(
        "campaign",
        help="fly a Monte-Carlo campaign of a mission on dask (local cores or a cluster)",
        description=(
            "Fly every sample of a campaign file (a base configuration, distributions over its "
            "keys, a sample design; see configs/campaign_*.yaml) on dask.distributed, one flight "
            "per task. Each finished flight is a row of DIR/results.csv at once; running the same "
            "command again flies only the samples without a row. Then DIR gets summary.json, "
            "ecdf.png, parameters.png, roa.png (when the start is varied: the empirical region "
            "of attraction against the one the gain condition certifies) and worst/<sample>/ run "
            "directories of the worst flights for `mpf-mavlink plot`."
        ),
        epilog=exit_codes_epilog("campaign"),
    )
    c.add_argument("campaign", metavar="CAMPAIGN", type=Path, help="campaign YAML file")
    c.add_argument("--out", type=Path, required=True, help="output directory (resumable)")
    g = c.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: one per core)")  # fmt: skip
    g.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="an existing dask scheduler to run on instead of local "
                        "workers")  # fmt: skip
    c.add_argument("--retry-errors", action="store_true",
                   help="fly again the samples whose row is an error or a timeout")  # fmt: skip
    c.add_argument("--no-report", action="store_true",
                   help="only fly; skip the plots and the re-flown worst flights")  # fmt: skip
    c.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_campaign)


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
