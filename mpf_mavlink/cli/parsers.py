"""The argument definitions of the sub-commands (``run``'s is in :mod:`.run`): cheap to
build, each handler's module imported only when its command runs."""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mpf_mavlink.cli.common import (
    add_output_flags,
    add_overrides,
    exit_codes_epilog,
    positive,
    seconds,
)


def _lazy(module: str, name: str) -> Callable[[argparse.Namespace], int]:
    """The handler ``module.name``, imported when the command runs (its exit code)."""

    def handler(args: argparse.Namespace) -> int:
        return int(getattr(importlib.import_module(module), name)(args))

    return handler


SET_HELP = (
    "override one configuration key, e.g. --set guidance.K_R=3 or "
    "--set kinematic.autopilot_bandwidth_rad_s=2.5 (repeatable; validated like the file)"
)


def add_config(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", metavar="CONFIG", help="scenario YAML file (see configs/)")
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP
    )


def add_check_parser(sub: Any) -> None:
    c = sub.add_parser(
        "check",
        help="run the pre-flight checks (Assumption 1, gain condition, feasibility)",
        description="Run the pre-flight checks for a scenario; exit 3 when one fails.",
        epilog=exit_codes_epilog("check"),
    )
    add_config(c)
    c.add_argument("--json", action="store_true", help="also print the figures as JSON")
    c.set_defaults(func=_lazy("mpf_mavlink.cli.commands", "cmd_check"))


def add_sim_parser(sub: Any) -> None:
    s = sub.add_parser(
        "sim",
        help="simulate a scenario and write a run directory",
        description="Simulate a scenario and write a run directory: timeseries.csv, metrics.json "
        "and the paper's figures as PNG. With sil.link: none (the default) the paper's kinematic "
        "closed loop runs in-process; with sil.link: udp the simulated vehicle (JSBSim aircraft or "
        "kinematic plant behind a PX4 / ArduPlane MAVLink endpoint) and the bridge fly the mission "
        "as two processes over UDP loopback, the metrics come from the plant's truth and the "
        "bridge's tlog is kept (see configs/default.yaml).",
        epilog=exit_codes_epilog("sim"),
    )
    add_config(s)
    s.add_argument("--out", type=Path, help="run directory (default: runs/<time>-sim-<name>)")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    s.add_argument(
        "--force", action="store_true",
        help="fly even when a pre-flight check fails (mpf-mavlink check): the verdict still "
        "judges it",
    )  # fmt: skip
    s.set_defaults(func=_lazy("mpf_mavlink.cli.commands", "cmd_sim"))


def add_plot_parser(sub: Any) -> None:
    pl = sub.add_parser(
        "plot",
        help="re-draw the figures of a run directory",
        description="Re-draw the PNG figures of a run directory (sim, run or replay).",
        epilog=exit_codes_epilog("plot"),
    )
    pl.add_argument("run_dir", metavar="RUN_DIR", type=Path)
    pl.set_defaults(func=_lazy("mpf_mavlink.cli.commands", "cmd_plot"))


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
    r.set_defaults(func=_lazy("mpf_mavlink.cli.replay", "cmd_replay"))
    return r


VEHICLE_DESCRIPTION = """\
Run the simulated vehicle of a scenario alone, paced to the wall clock, so that MAVProxy, a
ground station (QGroundControl, Mission Planner) or your own pymavlink / MAVSDK code can connect
to it as to a real autopilot. What it simulates comes from the config: sil.plant (the JSBSim
aircraft of the aircraft section, by default the Skywalker X8, or the kinematic plant),
sil.flavour (PX4: OFFBOARD after >= 1 s of SET_ATTITUDE_TARGET, Hold after 1 s without;
ArduPlane: GUIDED, attitude quaternion only), wind, turbulence, gusts, telemetry rates and
latencies. It starts armed, in trimmed level flight, loitering (PX4 AUTO.LOITER, ArduPlane
LOITER) at kinematic.initial_position_ned_m (or sil.initial_position_ned_m) about the home
sil.home_*. The config's scripted target is published as its own MAVLink system
(sil.target_system, FOLLOW_TARGET and GLOBAL_POSITION_INT), as a live target for the bridge.

Connections (--serve):
  udpout:127.0.0.1:14550   send to a ground station listening on 14550 (QGroundControl's and
                           MAVProxy's default; this is what PX4 SITL does)
  udpin:0.0.0.0:14540      listen; answer whoever sends first (the bridge: mpf-mavlink run
                           CONFIG --connect udpout:127.0.0.1:14540)
  tcpin:0.0.0.0:5760       listen for one TCP client (as ArduPilot SITL does)

Identity: system 1, component 1 (the target: system 2). Ctrl-C (or SIGTERM) stops it cleanly.
A ground station gets what it asks of an autopilot, per flavour (sim/vehicle/gcs_services.py): the
parameter list with the firmware's names (setting them changes the run), the mission protocol,
AUTOPILOT_VERSION, GPS_RAW_INT; MAVLink FTP is refused (NAK) and unknown commands are answered
UNSUPPORTED. Messages a peer sends not addressed to the vehicle reach its other UDP peers (a
ground station beside the bridge sees the bridge's MPF_* values and texts).

example:
  mpf-mavlink vehicle configs/default.yaml --serve udpin:127.0.0.1:14540 &
  mpf-mavlink run configs/default.yaml --connect udpout:127.0.0.1:14540
"""


SERVE_HELP = "MAVLink connection to serve: udpout:HOST:PORT, udpin:HOST:PORT or tcpin:HOST:PORT"


def add_vehicle_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``vehicle`` sub-command (with ``func``)."""
    p: argparse.ArgumentParser = subparsers.add_parser(
        "vehicle",
        help="serve the simulated vehicle alone (real time) for MAVProxy, a GCS or your own code",
        description=VEHICLE_DESCRIPTION,
        epilog=exit_codes_epilog("vehicle"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_config(p)
    p.add_argument("--serve", required=True, metavar="URL", help=SERVE_HELP)
    p.add_argument(
        "--clock", choices=["realtime", "lockstep"], default="realtime",
        help="realtime (default): paced to the wall clock; lockstep: advance as soon as the peer "
        "answers each telemetry frame with a SET_ATTITUDE_TARGET (real time while nobody "
        "commands it)",
    )  # fmt: skip
    p.add_argument(
        "--speed",
        type=positive,
        metavar="X",
        help="realtime clock at X times real time (default 1)",
    )
    p.add_argument(
        "--duration",
        type=positive,
        metavar="S",
        help="stop after S seconds of simulated flight (default: run until Ctrl-C)",
    )
    p.set_defaults(func=_lazy("mpf_mavlink.cli.sim", "cmd_vehicle"))
    return p


def _add_workers(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: one per core)")  # fmt: skip
    g.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="an existing dask scheduler instead of local workers")  # fmt: skip


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
    _add_workers(c)
    c.add_argument("--retry-errors", action="store_true",
                   help="fly again the samples whose row is an error or a timeout")  # fmt: skip
    c.add_argument("--no-report", action="store_true",
                   help="only fly; skip the plots and the re-flown worst flights")  # fmt: skip
    c.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=_lazy("mpf_mavlink.cli.campaign", "cmd_campaign"))


def add_certify_parser(sub: Any) -> None:
    c = sub.add_parser(
        "certify",
        help="bound a mission's tracking on the calibrated SIL over stated conditions",
        description=(
            "Fly the mission CONFIG on the calibrated SIL (the autopilot's identified profile, "
            "sil.autopilot_profile auto unless CONFIG names one) under conditions drawn from "
            "FILE (configs/certify/*.yaml; docs/certify.md), on dask.distributed as `campaign` "
            "does: as many flights as a one-sided bound of the quantile at the confidence needs "
            "(59 for 95 % at 95 %) or --flights N. Writes DIR/flights.csv (row by row; the "
            "same command again flies only the missing flights), DIR/certificate.json and "
            "DIR/report.md with ecdf.png and conditions.png."
        ),
        epilog=exit_codes_epilog("certify"),
    )
    c.add_argument("config", metavar="CONFIG", type=Path, help="the mission's configuration")
    c.add_argument("--autopilot", required=True, choices=("px4", "arduplane"))
    c.add_argument("--conditions", required=True, type=Path, metavar="FILE",
                   help="conditions YAML")  # fmt: skip
    c.add_argument("--out", required=True, type=Path, metavar="DIR",
                   help="output directory (resumable)")  # fmt: skip
    c.add_argument("--flights", type=int, default=None,
                   help="flights to fly (default: what the bound needs)")  # fmt: skip
    c.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a key of CONFIG (repeatable)")  # fmt: skip
    _add_workers(c)
    c.add_argument("-q", "--quiet", action="store_true", help="no per-flight progress")
    c.set_defaults(func=_lazy("mpf_mavlink.cli.certify", "cmd_certify"))


def add_compare_parser(subparsers: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = subparsers.add_parser(
        "compare",
        help="fly the same mission with MPF and the baseline guidance laws; one table",
        description="Fly the same mission (same seeds, start, adapter) with each guidance law "
        "(mpf; npfg = PX4 NPFG on the moving path with path-relative velocities; npfg_static = "
        "the same path re-sent as if it stood still; l1_loiter = ArduPlane's L1 loiter about the "
        "moving centre, circular paths only; pursuit = carrot chasing) and write a table "
        "(convergence, steady RMS / max of |pt| and of the cross-track distance, max bank, rate "
        "effort, time saturated, verdict) and overlay plots.",
        epilog=exit_codes_epilog("compare"),
    )
    add_config(p)
    p.add_argument(
        "--laws",
        default="mpf,npfg,npfg_static,pursuit",
        help="comma-separated laws (default: %(default)s)",
    )
    p.add_argument("--plant", choices=["kinematic", "sil"], default="kinematic",
                   help="kinematic (in-process, the paper's plant) or sil (JSBSim + bridge "
                        "over MAVLink)")  # fmt: skip
    p.add_argument(
        "--duration",
        type=positive,
        metavar="S",
        help="seconds of each flight (default sim.duration_s)",
    )
    p.add_argument("--out", type=Path, help="directory (default runs/<time>-compare-<name>)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_lazy("mpf_mavlink.cli.compare", "cmd_compare"))
    return p
