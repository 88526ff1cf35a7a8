"""``mpf-mavlink run CONFIG --connect URL``: fly the MPF law on a PX4 or ArduPlane autopilot.

Thin: parse, load the config, call :func:`mpf_mavlink.bridge.live.run_bridge`, print the summary,
return its exit code. Known failures (bad URL, no vehicle, bad config) are MpfError: one line.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from mpf_mavlink.cli.common import (
    add_output_flags,
    add_overrides,
    check_host,
    count,
    default_out,
    exit_codes_epilog,
    positive,
    printer,
)

RUN_DESCRIPTION = """\
Connect to a PX4 or ArduPlane autopilot, run the pre-flight checks, pre-stream setpoints,
take control in its offboard mode (PX4 OFFBOARD, ArduPlane GUIDED), fly the 3D moving-path-
following law and hand control back to the hold mode (PX4 AUTO.LOITER, ArduPlane LOITER).

It stops commanding at once if telemetry goes stale (> 0.5 s by default), the live target can
no longer be placed (target_estimator.max_position_sigma_m), or if
someone else changes the flight mode (it never fights the pilot). After a telemetry or target
loss it ends the run, or with --reengage N flies again (N times at most) once the stream is
back and the vehicle is in the hold mode. Ctrl-C, SIGTERM, the mission duration or an error
hand control back. Everything is recorded in the run directory:
mavlink.tlog (all traffic), timeseries.csv, setpoints.csv, limits.csv, metrics.json and plots.
The last line is the flight's verdict on telemetry (docs/checks.md, "Verdicts").
"""

CONNECT_HELP = (
    "MAVLink connection: udpin:HOST:PORT (listen; PX4 SITL offboard udpin:0.0.0.0:14540), "
    "udpout:HOST:PORT, tcp:HOST:PORT (ArduPilot SITL tcp:127.0.0.1:5760), tcpin:HOST:PORT, or a "
    "serial device /dev/ttyUSB0[:BAUD] (default 57600)"
)


def cmd_run(args: argparse.Namespace) -> int:
    from mpf_mavlink.bridge.base import BridgeOptions
    from mpf_mavlink.bridge.live import run_bridge
    from mpf_mavlink.config.schema import load_config
    from mpf_mavlink.runs.rundir import prepare_out_dir

    # the simulator's sections are not read: the bridge flies what the link says
    cfg = load_config(args.config, args.overrides, sim_sections=False)
    check_host(args.connect, "--connect")
    out = prepare_out_dir(args.out or default_out("run", cfg.name))
    opts = BridgeOptions(
        url=args.connect,
        out_dir=out,
        flavour=None if args.flavour is None else args.flavour,
        duration_s=args.duration,
        heartbeat_timeout_s=args.heartbeat_timeout,
        arm=True if args.arm else None,
        plots=False if args.no_plots else None,
        reengage=args.reengage,
        force=args.force,
    )
    res = run_bridge(cfg, opts, log=printer(args.quiet))
    print(res.summary(), flush=True)
    from mpf_mavlink.runs.verdict import limits_line

    lim = limits_line((res.metrics or {}).get("verdict_figures") or {})
    if lim:
        print(lim, flush=True)
    if res.verdict:
        print(res.verdict, flush=True)
    return res.exit_code


def add_run_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``run`` sub-command (with ``func``) to an argparse sub-parsers object."""
    r: argparse.ArgumentParser = subparsers.add_parser(
        "run",
        help="fly the MPF law on a PX4 / ArduPlane autopilot over MAVLink",
        description=RUN_DESCRIPTION,
        epilog=exit_codes_epilog("run"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    r.add_argument(
        "config",
        metavar="CONFIG",
        help="scenario YAML with mavlink and adapter sections (see configs/bridge_*.yaml)",
    )
    r.add_argument("--connect", required=True, metavar="URL", help=CONNECT_HELP)
    r.add_argument(
        "--flavour", choices=["px4", "ardupilot", "auto"], default=None,
        help="autopilot family; auto (the default, or mavlink.flavour) reads it from the "
        "HEARTBEAT. A value that contradicts the HEARTBEAT is an error",
    )  # fmt: skip
    r.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="run directory (default: runs/<time>-run-<name>); checked writable before connecting",
    )
    r.add_argument(
        "--duration",
        type=positive,
        metavar="S",
        help="seconds of TRACKING before handing back (default: mavlink.mission_duration_s)",
    )
    r.add_argument(
        "--heartbeat-timeout", type=positive, metavar="S",
        help="give up with one line and exit 2 when no autopilot HEARTBEAT (or no usable "
        "telemetry) arrives within S seconds (default: mavlink.heartbeat_timeout_s)",
    )  # fmt: skip
    r.add_argument(
        "--arm",
        action="store_true",
        help="arm the vehicle after pre-streaming if it is disarmed (off by default: arm it "
        "yourself)",
    )
    r.add_argument(
        "--reengage", type=count, metavar="N",
        help="after telemetry or the live target is lost and control handed back, fly again up "
        "to N times when it is back (mavlink.reengage_wait_s, reengage_settle_s) and the vehicle "
        "is in the hold mode; 0 ends the run at the first loss (default: mavlink.reengage_max, 0)",
    )  # fmt: skip
    add_overrides(r, "--set mavlink.vehicle_sysid=2 or --set guidance.K_R=1.5")
    add_output_flags(
        r, plots_help="skip the PNG figures in the run directory",
        quiet_help="print only the final summary",
    )  # fmt: skip
    r.add_argument(
        "--force", action="store_true",
        help="engage even when a pre-flight check fails (the flight's verdict still judges it)",
    )  # fmt: skip
    r.set_defaults(func=cmd_run)
    return r
