"""``mpf-mavlink replay LOG.tlog --config CONFIG``: re-run the guidance on recorded telemetry.

Thin: parse, load the config, call :func:`mpf_mavlink.bridge.replay.replay`, print the summary.
Known failures (missing or unreadable file, not a tlog, bad window, bad config) are MpfError:
one line, exit 2. Exit 1 when the tlog was recorded by this bridge and a replayed command
differs from what it sent (the summary says which first).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mpf_mavlink.cli.common import default_out, printer


def cmd_replay(args: argparse.Namespace) -> int:
    from mpf_mavlink.bridge.replay import replay
    from mpf_mavlink.config.schema import load_config

    cfg = load_config(args.config, args.overrides)
    out = args.out or default_out("replay", cfg.name)
    res = replay(
        args.tlog,
        cfg,
        out_dir=out,
        t_from=args.t_from,
        t_to=args.t_to,
        plots=not args.no_plots,
        log=printer(args.quiet),
    )
    print(res.summary(), flush=True)
    hint = _config_hint(Path(args.tlog), Path(args.config), res.notes)
    if hint:
        print(hint, flush=True)
    c = res.check
    return 1 if (c.markers and not c.identical and c.sent) else 0


def _config_hint(tlog: Path, config: Path, notes: list[str]) -> str | None:
    """A pointer to the run's own config when the replay disagrees with the bridge's markers and
    the tlog sits in a run directory (mpf-mavlink run / sim write config.yaml beside it): a SIL
    run's bridge flies the scenario with the SIL's overrides, not the YAML it was started with."""
    if not any("disagree" in n for n in notes):
        return None
    own = tlog.parent / "config.yaml"
    try:
        if not own.is_file() or own.resolve() == config.resolve():
            return None
    except OSError:
        return None
    return f"hint              the run's own config is {own}: replay with --config {own}"
