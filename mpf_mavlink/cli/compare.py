"""``mpf-mavlink compare CONFIG --laws mpf,npfg,...``: the same mission flown by each guidance law.

Thin: for each law the config is the same but ``guidance.law`` (so the same seeds of turbulence
and wind, the same start, the same adapter); the kinematic plant runs in-process, ``--plant
sil`` flies the full SIL (JSBSim vehicle + the bridge over MAVLink, figures from the plant's
truth). Table and overlay plots: :mod:`mpf_mavlink.runs.compare`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, cast

from mpf_mavlink.errors import MpfError

if TYPE_CHECKING:
    from mpf_mavlink.config.schema import Config, LawName

LAWS_ALL = ("mpf", "npfg", "npfg_static", "l1_loiter", "pursuit")


def parse_laws(text: str) -> list[str]:
    laws = [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in laws if x not in LAWS_ALL]
    if bad or not laws:
        raise MpfError(
            f"--laws {text}: unknown law {', '.join(bad) or '(none)'} "
            f"(one of {', '.join(LAWS_ALL)})"
        )
    return laws


class _Flown(NamedTuple):
    """One law's flight: its time series, exit code and reason, the plant's roll over the
    bridge's time series (SIL; None otherwise), whether it was flown again, and the SIL run's
    metrics (with its verdict; None for the kinematic plant, judged here)."""

    cols: dict[str, Any]
    code: int
    exit_reason: str
    roll: Any
    retried: bool
    metrics: dict[str, Any] | None


def _fly_sil(c: Config, law: str, out: Path, progress: bool, plots: bool, log: Any) -> _Flown:
    from sim.sil import run_sil

    retried = False
    res = run_sil(c, out / law, progress=progress, plots=plots, log=lambda s: None)
    if str(res.exit_reason).startswith("telemetry lost"):
        # a realtime-clock SIL on a CPU-starved shared machine can trip the bridge's
        # wall-clock watchdog (no property of the law); fly once more and say so
        log(
            f"      {law}: {res.exit_reason} after {res.metrics.get('sim_time_s')} s; "
            "flying it again"
        )
        res = run_sil(c, out / law, progress=progress, plots=plots, log=lambda s: None)
        retried = True
    roll = None
    tv = res.t_vehicle
    tr = res.truth
    if len(tv) and "euler" in tr:
        sel = (tr["t"] >= tv[0]) & (tr["t"] <= tv[-1])
        roll = tr["euler"][sel, 0]
    return _Flown(res.cols, res.exit_code, res.exit_reason, roll, retried, res.metrics)


def _fly_kinematic(c: Config, law: str, out: Path, progress: bool, plots: bool) -> _Flown:
    from mpf_mavlink.runs.write import write_run
    from sim.runner import run_kinematic

    kres = run_kinematic(c, progress=progress)
    if plots:
        write_run(out / law, kres.cols, kres.metrics, kres.path_T, plots=False)
    return _Flown(kres.cols, 0, "duration reached", None, False, None)


def run_compare(
    cfg: Config,
    laws: list[str],
    plant: str,
    out: Path,
    duration_s: float | None = None,
    progress: bool = True,
    plots: bool = True,
    log: Any = print,
) -> tuple[list[Any], str]:
    """Fly every law; returns (rows, markdown table). Raises MpfError for an unusable law."""
    from mpf_mavlink.config.scenario import build_path
    from mpf_mavlink.runs.compare import LawRow, law_figures, markdown_table, write_compare
    from mpf_mavlink.runs.verdict import assess

    if "l1_loiter" in laws and cfg.path.type not in ("circle", "helix"):
        raise MpfError(
            f"{cfg.source}: l1_loiter flies a loiter circle; path.type {cfg.path.type} is not one "
            "(drop it from --laws)"
        )
    path = build_path(cfg.path)
    nodes = path.positions()
    closed = bool(getattr(path, "closed", False))
    if duration_s is not None:
        cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, duration_s=duration_s))
    rows: list[Any] = []
    runs: dict[str, Any] = {}
    parse_laws(",".join(laws))  # the names' check, for callers other than the command line
    for i, law in enumerate(laws):
        name = cast("LawName", law)
        c = dataclasses.replace(cfg, guidance=dataclasses.replace(cfg.guidance, law=name))
        log(f"[{i + 1}/{len(laws)}] {law}: {plant}, {c.sim.duration_s:g} s ...")
        w0 = time.perf_counter()
        if plant == "sil":
            flown = _fly_sil(c, law, out, progress, plots, log)
        else:
            flown = _fly_kinematic(c, law, out, progress, plots)
        cols, code, exit_reason, roll, retried, metrics = flown
        if len(cols["t"]) < 2:
            raise MpfError(f"{law}: the run recorded no flight (exit {code})")
        fig = law_figures(
            cols, nodes, closed, c.vehicle.airspeed_m_s, c.metrics.steady_after_s,
            c.metrics.converge_threshold_m, roll,
        )  # fmt: skip
        if metrics is not None:
            status = str(metrics.get("verdict_status") or "n/a")
            classes = metrics.get("verdict_classes") or []
            vline = str(metrics.get("verdict") or "verdict: n/a (not judged: no flight)")
        else:  # the kinematic plant has no attitude, airspeed or thrust: tracking alone
            vd = assess(c, cols["t"], cols["pt_norm"])
            status, classes, vline = vd.status, vd.classes, vd.line()
            code = vd.exit_code(code)
        fig["verdict"] = status + (f" ({', '.join(classes)})" if classes else "")
        fig["verdict_line"] = vline
        fig["exit_code"] = code
        fig["exit_reason"] = exit_reason
        fig["retried_after_telemetry_loss"] = retried
        fig["tracked_s"] = float(cols["t"][-1])
        fig["wall_s"] = time.perf_counter() - w0
        rows.append(LawRow(law, fig))
        runs[law] = cols
        xt = fig["steady_rms_xt_m"]
        xt_txt = (
            f"{xt:.3f} m"
            if xt is not None
            else "n/a (no steady window: the flight ended before "
            f"t = {c.metrics.steady_after_s:g} s)"
        )
        log(f"      RMS cross-track {xt_txt}; {vline} ({fig['wall_s']:.0f} s wall)")
    wind = cfg.sil.wind_ned_m_s if plant == "sil" else cfg.kinematic.wind.steady_ned_m_s
    header = (
        f"{cfg.name}: {plant} plant, {cfg.sim.duration_s:g} s, steady from t >= "
        f"{cfg.metrics.steady_after_s:g} s, wind {tuple(wind)} m/s NED; "
        "xt = distance from the moving path"
    )
    write_compare(out, rows, runs, nodes, closed, header, plots)
    return rows, header + "\n\n" + markdown_table(rows)


def cmd_compare(args: argparse.Namespace) -> int:
    from mpf_mavlink.config.schema import load_config
    from mpf_mavlink.runs.compare import FLOWN_EXIT_CODES
    from mpf_mavlink.runs.rundir import prepare_out_dir

    cfg = load_config(args.config, args.overrides)
    if args.plant == "sil":
        from mpf_mavlink.config.autopilot_profile import calibrated_sets

        # the calibrated SIL unless the config names a profile (none included)
        extra, label = calibrated_sets(cfg)
        cfg = load_config(args.config, [*args.overrides, *extra]) if extra else cfg
        print(f"compare: SIL autopilot profile {label}", file=sys.stderr, flush=True)
    laws = parse_laws(args.laws)
    out = args.out or Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-compare-{cfg.name}"
    out = prepare_out_dir(out)
    rows, table = run_compare(
        cfg, laws, args.plant, out, args.duration, progress=not args.quiet,
        plots=not args.no_plots, log=lambda s: print(s, file=sys.stderr, flush=True),
    )  # fmt: skip
    print(table)
    print(f"\nrun directory: {out}  (compare.md, compare.json, compare_*.png, one run per law)")
    # a failed or unjudged verdict is a result (the table's verdict column); only a flight
    # that could not run to its end (a safety exit, telemetry lost) is an error
    bad = [r for r in rows if r.figures.get("exit_code") not in FLOWN_EXIT_CODES]
    if bad:
        why = [
            f"{r.law} (exit {r.figures.get('exit_code')}: {r.figures.get('exit_reason')})"
            for r in bad
        ]
        raise MpfError(
            f"compare: the flight of {', '.join(why)} could not run to its end (see its run "
            "directory)"
        )
    return 0


__all__ = ["cmd_compare", "parse_laws", "run_compare"]
