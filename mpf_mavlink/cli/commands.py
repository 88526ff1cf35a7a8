"""The handlers of ``mpf-mavlink check``, ``sim`` and ``plot`` (imported when one runs)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mpf_mavlink.cli.common import default_out, figure_lines
from mpf_mavlink.errors import CheckFailed

if TYPE_CHECKING:
    from mpf_mavlink.config.schema import Config


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
