"""``mpf-mavlink vehicle CONFIG --serve URL`` and the SIL half of ``mpf-mavlink sim``.

Thin: parse, load the config, call :mod:`sim.sil`, print. Known failures are MpfError (one line).
"""

from __future__ import annotations

import argparse
import math
import signal
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mpf_mavlink.cli.common import (
    check_host,
    figure_lines,
)
from mpf_mavlink.errors import MpfError

if TYPE_CHECKING:
    from mpf_mavlink.config.schema import Config


def _check_serve_url(url: str) -> None:
    from mpf_mavlink.mavlink.url import parse_url

    parsed = parse_url(url)  # MpfError (one line) for anything malformed
    if parsed.kind not in ("udpin", "udpout", "tcpin"):
        raise MpfError(
            f"--serve {url}: the vehicle serves udpin:, udpout: or tcpin: (got {parsed.kind})"
        )
    check_host(url, "--serve")


def cmd_vehicle(args: argparse.Namespace) -> int:
    from mpf_mavlink.config.schema import load_config

    cfg = load_config(args.config, args.overrides)
    _check_serve_url(args.serve)
    from sim.sil import build_vehicle

    over: dict[str, Any] = {}
    if args.speed is not None:
        over["realtime_speed"] = args.speed
    try:
        v = build_vehicle(cfg, args.serve, clock=args.clock, **over)
    except OSError as e:
        raise MpfError(f"--serve {args.serve}: cannot open ({e.strerror or e})") from None
    sil, ac = cfg.sil, cfg.aircraft
    what = f"JSBSim {ac.model}" if sil.plant == "jsbsim" else "kinematic plant"
    print(
        f"simulated {sil.flavour} vehicle ({what}, {args.clock} clock) on {args.serve}: system 1, "
        f"target as system {sil.target_system}; {v.mode_name}, {v.tun.cruise_airspeed:g} m/s. "
        "Ctrl-C to stop.",
        flush=True,
    )

    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    prev = signal.signal(signal.SIGTERM, on_term)
    seen = len(v.modes.changes)
    end = args.duration if args.duration is not None else math.inf
    try:
        while v.t < end:
            v.run(min(1.0, end - v.t))
            for t, name in v.modes.changes[seen:]:
                print(f"t = {t:8.2f} s  mode {name}", flush=True)
            seen = len(v.modes.changes)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, prev)
        v.close()
    print(
        f"stopped after {v.t:.1f} s of simulated flight ({v.link.rx_count} messages received)",
        flush=True,
    )
    return 0


# ----------------------------------------------------------------------------- sim (SIL)
def _plots_line(out: Path) -> str:
    """The summary's plots line: the figures this run drew (none with --no-plots)."""
    names = sorted(p.stem for p in out.glob("*.png"))
    if not names:
        return "plots:         none (--no-plots)"
    return f"plots:         {out}/*.png  ({', '.join(names)})"


def sil_summary(res: Any) -> str:
    """The table printed at the end of a SIL ``sim``: figures, then where everything is."""
    m = res.metrics
    rows = [
        ("first_within_s", "first within threshold", "s"),
        ("convergence_time_s", "stays within threshold", "s"),
        ("steady_rms_m", "steady RMS |pt|", "m"),
        ("steady_mean_vertical_m", "steady mean vertical", "m"),
        ("steady_mean_radial_m", "steady mean radial", "m"),
        ("steady_rms_cross_track_m", "steady RMS cross-track", "m"),
        ("bridge_thrust_saturated_fraction", "thrust at ceiling", "frac"),
        ("steady_max_m", "steady max |pt|", "m"),
        ("steady_psi_max", "steady max Psi", ""),
        ("max_rate_cmd_rad_s", "peak rate command", "rad/s"),
        ("sim_time_s", "tracked (simulated)", "s"),
        ("wall_time_s", "wall time", "s"),
        ("real_time_factor_tracking", "real-time factor", "x"),
    ]
    lines = [
        "",
        f"SIL: {m.get('plant')} plant, {m.get('flavour')} flavour, {m.get('clock')} clock; "
        "truth of the plant, "
        f"|pt| from t >= {m.get('steady_after_s', '?')} s after engagement",
        f"{'figure':<24} {'value':>10}  unit",
        "-" * 42,
    ]
    lines += figure_lines(m, rows, 24, 10)
    hb = "hand-back confirmed" if m.get("handback_confirmed") else "hand-back NOT confirmed"
    lines += [
        "",
        f"bridge: {m.get('bridge_exit_reason')} (exit {m.get('bridge_exit_code')}); {hb}",
        f"run directory: {res.out_dir}  (timeseries.csv and truth.csv from the plant, "
        "metrics.json)",
        _plots_line(Path(res.out_dir)),
        f"tlog:          {res.tlog}  (both directions; MAVProxy, QGC or mavlogdump.py read it)"
        if Path(res.tlog).is_file()
        else "tlog:          none (mavlink.recording: lean writes none)",
        f"bridge's view: {res.bridge_dir}  (what the law saw: timeseries.csv, setpoints.csv, "
        "metrics.json)",
    ]
    return "\n".join(lines)


def cmd_sim_sil(cfg: Config, out: Path, quiet: bool, no_plots: bool, force: bool = False) -> int:
    from sim.sil import run_sil

    res = run_sil(
        cfg, out, progress=not quiet, plots=not no_plots, log=lambda s: print(s, flush=True),
        force=force,
    )  # fmt: skip
    res.metrics.setdefault("steady_after_s", cfg.metrics.steady_after_s)
    print(sil_summary(res), flush=True)
    from mpf_mavlink.runs.verdict import limits_line

    lim = limits_line(res.metrics.get("verdict_figures") or {})
    if lim:
        print(lim, flush=True)
    # last line: the verdict on the plant's truth (exit 5 when the flight failed it)
    print(res.metrics.get("verdict") or "verdict: none (the bridge recorded no flight)", flush=True)
    return int(res.exit_code)


__all__ = ["cmd_sim_sil", "cmd_vehicle", "sil_summary"]
