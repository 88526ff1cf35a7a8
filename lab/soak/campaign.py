"""The reliability and security campaign (``scripts/soak``): faults, bad links, bad input.

Every mission scenario is a real software-in-the-loop flight over real loopback UDP:

    python -m lab.soak vehicle ...  (SimVehicle, JSBSim X8, realtime clock, its own process)
        <-> lab.soak.relay.UdpRelay (this process: impairments, injection, a tap of all traffic)
        <-> mpf-mavlink run CONFIG --connect udpin:... (the real bridge CLI, its own process)

The judge of each scenario is the traffic the relay saw (what the vehicle really received and
really reported), the bridge's exit code and run directory, and the vehicle's own report.

``python -m lab.soak [--only NAME[,NAME]] [--quick] [--seed N] [--list]`` prints one JSON
object: ``{"scenarios": [row, ...], "wall_s": ..., "all_pass": ...}``; exit status 0 when all
rows pass. ``--quick`` shortens the missions (the fast test subset uses it).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lab.soak.checks import Limits
from lab.soak.inputs import scenario_bad_input, scenario_output_dir, scenario_spoof
from lab.soak.missions import (
    scenario_baseline,
    scenario_blackout_link,
    scenario_blackout_link_reengage,
    scenario_blackout_telemetry,
    scenario_corrupt_dup_reorder,
    scenario_fuzz,
    scenario_loss_jitter,
    scenario_pilot,
    scenario_reboot,
    scenario_reboot_fast,
    scenario_sigkill,
    scenario_target_loss,
)
from lab.soak.rig import Opts, Row, vehicle_main

SCENARIOS: dict[str, Callable[..., Row]] = {
    "baseline": scenario_baseline,
    "fuzz": scenario_fuzz,
    "loss20_jitter50": scenario_loss_jitter,
    "corrupt5_dup5_reorder5": scenario_corrupt_dup_reorder,
    "blackout_link_2s": scenario_blackout_link,
    "blackout_link_2s_reengage": scenario_blackout_link_reengage,
    "blackout_telemetry_2s": scenario_blackout_telemetry,
    "target_feed_loss": scenario_target_loss,
    "pilot_mode_change": scenario_pilot,
    "vehicle_reboot": scenario_reboot,
    "vehicle_reboot_fast": scenario_reboot_fast,
    "bridge_sigkill": scenario_sigkill,
    "spoofing_signing": scenario_spoof,
    "bad_config_and_cli": scenario_bad_input,
    "output_dir_unwritable_or_full": scenario_output_dir,
}


_PROBE = """
import sys, time
while True:
    t = time.monotonic(); time.sleep(0.01); d = time.monotonic() - t - 0.01
    if d > 0.05:
        print(f"{t:.3f} {d:.3f}", flush=True)
"""


class StallProbe:
    """A process that sleeps 10 ms at a time and reports each oversleep > 50 ms with its start
    on CLOCK_MONOTONIC (system-wide on Linux): the MACHINE stalling (a shared 2-core box), which
    a 0.5 s telemetry timeout cannot tell from a fault of the code under test."""

    def __init__(self) -> None:
        self.stalls: list[tuple[float, float]] = []
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _PROBE], stdout=subprocess.PIPE, text=True
        )
        self._th = threading.Thread(target=self._read, daemon=True)
        self._th.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with contextlib.suppress(ValueError):
                t, d = (float(x) for x in line.split())
                self.stalls.append((t, d))

    def worst(self, t0: float, t1: float) -> float:
        return max((d for t, d in list(self.stalls) if t0 <= t <= t1), default=0.0)

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


STALL_RETRY_S = 0.25  # a failed row is re-run once if the machine stalled this long meanwhile


def run_campaign(
    names: list[str], o: Opts, log: Callable[[str], None] = lambda s: None
) -> dict[str, Any]:
    t0 = time.monotonic()
    rows = []
    probe = StallProbe()
    try:
        for name in names:
            log(f"[soak] {name} ...")
            row = run_row(name, o, probe, log)
            log(
                f"[soak] {name}: "
                f"{'pass' if not row.failures else 'FAIL ' + '; '.join(row.failures)} "
                f"({row.wall_s:.1f} s)"
            )
            rows.append(row.as_dict())
    finally:
        probe.close()
    return {
        "scenarios": rows,
        "wall_s": round(time.monotonic() - t0, 1),
        "all_pass": all(r["pass"] for r in rows),
        "quick": o.quick,
        "seed": o.seed,
    }


def run_row(
    name: str, o: Opts, probe: StallProbe, log: Callable[[str], None] = lambda s: None, **kw: Any
) -> Row:
    """One scenario; re-run once (and say so in the row) only when it failed while the machine
    stalled for ``STALL_RETRY_S`` or more."""
    row = _run_row(name, o, probe, **kw)
    stall = row.figures.get("machine_stall_max_s", 0.0)
    if row.failures and stall >= STALL_RETRY_S:
        log(f"[soak] {name}: failed while the machine stalled {stall:.2f} s; running it again")
        first = {"failures": row.failures, "machine_stall_max_s": stall}
        row = _run_row(name, dataclasses.replace(o, workdir=o.workdir / "retry"), probe, **kw)
        row.figures["retried_after"] = first
    return row


def _run_row(name: str, o: Opts, probe: StallProbe | None = None, **kw: Any) -> Row:
    t = time.monotonic()
    try:
        row = SCENARIOS[name](o, **kw)
    except Exception as e:  # noqa: BLE001 - a harness error is a failed row, not a lost table
        row = Row(name, failures=[f"harness error: {type(e).__name__}: {e}"])
    row.wall_s = time.monotonic() - t
    if probe is not None:
        row.figures["machine_stall_max_s"] = round(probe.worst(t, time.monotonic()), 3)
    return row


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["vehicle"]:
        return vehicle_main(argv[1:])
    ap = argparse.ArgumentParser(
        prog="scripts/soak",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument(
        "--only",
        default=None,
        help=f"comma-separated scenarios (default: all): {', '.join(SCENARIOS)}",
    )
    ap.add_argument("--quick", action="store_true", help="shorter missions (the fast test subset)")
    ap.add_argument(
        "--seed", type=int, default=1, help="seed of the relay's and the fuzzer's random generators"
    )
    ap.add_argument(
        "--keep", action="store_true", help="keep the work directory (runs, tlogs, vehicle logs)"
    )
    ap.add_argument("--list", action="store_true", help="list the scenarios and exit")
    a = ap.parse_args(argv)
    if a.list:
        print("\n".join(SCENARIOS))
        return 0
    names = (
        list(SCENARIOS) if a.only is None else [n.strip() for n in a.only.split(",") if n.strip()]
    )
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        print(
            f"scripts/soak: error: unknown scenario {', '.join(unknown)} "
            f"(known: {', '.join(SCENARIOS)})",
            file=sys.stderr,
        )
        return 2
    work = Path(tempfile.mkdtemp(prefix="mpf-soak-"))
    try:
        table = run_campaign(
            names, Opts(a.quick, a.seed, work), log=lambda s: print(s, file=sys.stderr, flush=True)
        )
        if a.keep:
            table["workdir"] = str(work)
        print(json.dumps(table, indent=1))
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0 if table["all_pass"] else 1


__all__ = ["SCENARIOS", "Limits", "Opts", "Row", "StallProbe", "main", "run_campaign", "run_row"]


if __name__ == "__main__":
    raise SystemExit(main())
