"""``mpf-mavlink replay LOG.tlog --config CONFIG``: re-run the guidance on recorded telemetry.

Thin: parse, load the config, call :func:`mpf_mavlink.bridge.replay.replay`, print the summary.
Known failures (missing or unreadable file, not a tlog, bad window, bad config) are MpfError:
one line, exit 2. Exit 1 when the tlog was recorded by this bridge and a replayed command
differs from what it sent (the summary says which first).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from mpf_mavlink.cli.common import add_output_flags, add_overrides, default_out, printer, seconds

REPLAY_DESCRIPTION = """\
Replay a tlog (this project's, MAVProxy's, QGroundControl's, an autopilot SITL's; MAVLink 1 or
2; corrupt records are skipped and counted) through the same estimator, target, law and adapter
as `mpf-mavlink run`, open loop: what the law saw and would have commanded at every ATTITUDE.

Writes a run directory (timeseries.csv with errors, Psi, sdot and commanded rates,
setpoints.csv, metrics.json, the paper's figures with the recorded path against the moving
desired path) and prints a summary: duration, message counts, modes flown, telemetry gaps,
tracking figures over the window.

A tlog recorded by `mpf-mavlink run` (or the SIL) carries the bridge's t0/s0 markers: every
SET_ATTITUDE_TARGET it sent is then recomputed and compared (tolerance 1e-6 per field), and
the first differing message is named. Ids, staleness limits and the flavour come from the
config's mavlink section (vehicle_sysid, source_system/source_component, target_sysid).

exit codes: 0 replayed (and identical, when there was something to compare); 1 a replayed
command differs from the recorded one; 2 missing/unreadable file, not a tlog, bad window or
configuration.
"""


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


def add_replay_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``replay`` sub-command (with ``func``) to an argparse sub-parsers object."""
    r: argparse.ArgumentParser = subparsers.add_parser(
        "replay",
        help="re-run the guidance on a recorded tlog (open loop) and check recorded commands",
        description=REPLAY_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    r.add_argument(
        "tlog",
        metavar="LOG.tlog",
        help="telemetry log: 8-byte big-endian microseconds + one MAVLink packet per record",
    )
    r.add_argument(
        "--config",
        required=True,
        metavar="CONFIG",
        help="scenario YAML (path, target, gains, mavlink ids and limits); see "
        "configs/replay_arduplane_sitl.yaml",
    )
    r.add_argument(
        "--out", type=Path, metavar="DIR", help="run directory (default: runs/<time>-replay-<name>)"
    )
    r.add_argument(
        "--from",
        dest="t_from",
        type=seconds,
        metavar="SECONDS",
        help="start of the window, s since the first record (default 0)",
    )
    r.add_argument(
        "--to",
        dest="t_to",
        type=seconds,
        metavar="SECONDS",
        help="end of the window, s since the first record (default: the end)",
    )
    add_overrides(r, "--set guidance.K_R=1.5")
    add_output_flags(r, plots_help="skip the PNG figures", quiet_help="print only the summary")
    r.set_defaults(func=cmd_replay)
    return r
