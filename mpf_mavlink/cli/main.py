"""Command line: ``mpf-mavlink check|sim|plot`` (and the bridge commands as they land).

Library first, CLI thin: each command parses, calls a library function, reports. Known
errors (MpfError) print one line and exit non-zero; nothing else is caught.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mpf_mavlink import __version__
from mpf_mavlink.cli.common import default_out, exit_codes_epilog, figure_lines
from mpf_mavlink.errors import CheckFailed, MpfError

if TYPE_CHECKING:
    from mpf_mavlink.config.schema import Config

SET_HELP = (
    "override one configuration key, e.g. --set guidance.K_R=3 or "
    "--set kinematic.autopilot_bandwidth_rad_s=2.5 (repeatable; validated like the file)"
)


def _add_config(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", metavar="CONFIG", help="scenario YAML file (see configs/)")
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP
    )


def _load(args: argparse.Namespace) -> Any:
    from mpf_mavlink.config.schema import load_config

    return load_config(args.config, args.overrides)


def cmd_check(args: argparse.Namespace) -> int:
    from mpf_mavlink.bridge.preflight import format_checks, run_checks

    cfg = _load(args)
    results = run_checks(cfg)
    print(format_checks(results))
    if args.json:
        print(
            json.dumps(
                {r.name: {"status": r.status, **r.figures} for r in results},
                indent=2,
                default=float,
            )
        )
    failed = [r.name for r in results if not r.ok]
    if failed:
        raise CheckFailed(f"{cfg.source}: check failed: {', '.join(failed)}")
    return 0


def _summary(metrics: dict[str, Any], out: Path) -> str:
    keys = [
        ("first_within_s", "first within threshold", "s"),
        ("convergence_time_s", "stays within threshold", "s"),
        ("steady_rms_m", "steady RMS |pt|", "m"),
        ("steady_mean_vertical_m", "steady mean vertical", "m"),
        ("steady_mean_radial_m", "steady mean radial", "m"),
        ("steady_max_m", "steady max |pt|", "m"),
        ("steady_psi_max", "steady max Psi", ""),
        ("max_rate_cmd_rad_s", "peak rate command", "rad/s"),
        ("sim_time_s", "simulated time", "s"),
        ("wall_time_s", "wall time", "s"),
    ]
    lines = ["", f"{'figure':<22} {'value':>12}  unit", "-" * 42]
    lines += figure_lines(metrics, keys, 22, 12)
    lines.append("")
    lines.append(f"run directory: {out}  (timeseries.csv, metrics.json, *.png)")
    return "\n".join(lines)


def _gate(cfg: Config, force: bool) -> None:
    """The pre-flight gate of ``check``: a failed check refuses the flight unless forced."""
    from mpf_mavlink.bridge.preflight import format_checks, run_checks

    results = run_checks(cfg)
    failed = [r for r in results if not r.ok]
    warned = [r for r in results if r.status == "warn"]
    if warned and (force or not failed):  # flown: say what the checks expect to go wrong
        print(format_checks(warned), file=sys.stderr)
    if not failed:
        return
    if force:
        print(format_checks(failed), file=sys.stderr)
        names = ", ".join(r.name for r in failed)
        print(f"mpf-mavlink: --force: flying despite the failed check: {names}", file=sys.stderr)
        return
    raise CheckFailed(
        f"{cfg.source}: refused to fly: check failed: "
        + "; ".join(f"{r.name} ({r.summary})" for r in failed)
        + " (--force flies it anyway)"
    )


def cmd_sim(args: argparse.Namespace) -> int:
    from mpf_mavlink.runs.rundir import prepare_out_dir
    from mpf_mavlink.runs.write import write_run

    cfg = _load(args)
    _gate(cfg, args.force)
    if cfg.sil.link != "none":  # the SIL vehicle and the bridge over MAVLink
        from mpf_mavlink.cli.sim import cmd_sim_sil

        out = prepare_out_dir(args.out or default_out("sil", cfg.name))
        return cmd_sim_sil(cfg, out, args.quiet, args.no_plots, args.force)
    out = prepare_out_dir(args.out or default_out("sim", cfg.name))
    from sim.runner import run_kinematic

    res = run_kinematic(cfg, progress=not args.quiet)
    from mpf_mavlink.runs.verdict import assess

    # the paper's kinematic plant has no attitude, airspeed or thrust to judge: tracking only
    vd = assess(cfg, res.cols["t"], res.cols["pt_norm"])
    vd.record(res.metrics)
    write_run(out, res.cols, res.metrics, res.path_T, plots=not args.no_plots)
    print(_summary(res.metrics, out))
    print(vd.line())
    return vd.exit_code(0)


def cmd_plot(args: argparse.Namespace) -> int:
    from mpf_mavlink.runs.plots import plot_run

    files = plot_run(args.run_dir)
    for f in files:
        print(f)
    return 0


class _OneLineErrors(argparse.ArgumentParser):
    """Command-line errors as one line naming the culprit, like every other error of the CLI
    (argparse prints the whole usage first). Sub-commands inherit the class."""

    def error(self, message: str) -> Any:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _Version(argparse.Action):
    """--version: the version."""

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        print(f"{parser.prog} {__version__}")
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    p = _OneLineErrors(
        prog="mpf-mavlink",
        description="3D moving-path-following guidance for fixed-wing vehicles over MAVLink.",
    )
    p.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    c = sub.add_parser(
        "check",
        help="run the pre-flight checks (Assumption 1, gain condition, feasibility)",
        description="Run the pre-flight checks for a scenario; exit 3 when one fails.",
        epilog=exit_codes_epilog("check"),
    )
    _add_config(c)
    c.add_argument("--json", action="store_true", help="also print the figures as JSON")
    c.set_defaults(func=cmd_check)

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
    _add_config(s)
    s.add_argument("--out", type=Path, help="run directory (default: runs/<time>-sim-<name>)")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    s.add_argument(
        "--force", action="store_true",
        help="fly even when a pre-flight check fails (mpf-mavlink check): the verdict still "
        "judges it",
    )  # fmt: skip
    s.set_defaults(func=cmd_sim)

    pl = sub.add_parser(
        "plot",
        help="re-draw the figures of a run directory",
        description="Re-draw the PNG figures of a run directory (sim, run or replay).",
        epilog=exit_codes_epilog("plot"),
    )
    pl.add_argument("run_dir", metavar="RUN_DIR", type=Path)
    pl.set_defaults(func=cmd_plot)
    from mpf_mavlink.cli import parsers
    from mpf_mavlink.cli.run import add_run_parser

    add_run_parser(sub)
    parsers.add_replay_parser(sub)
    parsers.add_vehicle_parser(sub, _add_config)
    parsers.add_campaign_parser(sub)
    parsers.add_certify_parser(sub)
    parsers.add_compare_parser(sub, _add_config)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except MpfError as e:
        _leave_nothing_behind()
        print(f"mpf-mavlink: error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        _leave_nothing_behind()
        print("mpf-mavlink: interrupted", file=sys.stderr)
        return 130


def _leave_nothing_behind() -> None:
    """A failed command removes the run directories it created and left empty."""
    from mpf_mavlink.runs.rundir import remove_empty_created

    remove_empty_created()


if __name__ == "__main__":
    sys.exit(main())
