"""One flight of a campaign, run where a Dask worker puts it.

- kinematic plant: in-process (the paper's closed loop of ``sim/plant/kinematic.py``), ended early
  once |pt| has stayed below the convergence threshold for ``stop_after_converged_s`` (the
  rest of the flight would only repeat it), and bounded by the flight's wall-clock timeout;
- SIL plant: ``mpf-mavlink sim`` in a subprocess of its own (its own UDP ports, picked free by
  the SIL, and its own temporary run directory), killed at the timeout: a hang or a crash of
  the flight is a row with its error, never a lost worker. Flights whose run directory is not
  kept fly with ``mavlink.recording: lean``; the truth's figures then take the virtual point's
  ``s`` interpolated between the bridge's 10 Hz rows instead of read at every 50 Hz frame
  (docs/campaigns.md); the worst flights kept are flown again in full.

Every flight returns a flat row: the sample, the metrics kept, ``status`` (``ok``, ``failed``:
the flight's verdict failed it, ``refused``: the pre-flight gate did, ``error``, ``timeout``),
``error`` (one line), ``wall_s`` and ``cpu_s``: the CPU seconds the flight cost (user + system,
of the worker's process and of every process the flight started and waited for: the SIL's
simulator, vehicle and bridge), the figure that says what a campaign costs on a loaded machine,
where wall time says only how busy the machine was.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from mpf_mavlink.errors import MpfError


def fly(
    base: str,
    sets: list[str],
    plant: str,
    metrics: list[str],
    timeout_s: float,
    stop_after_converged_s: float | None = None,
    force: bool = False,
    out_dir: str | None = None,
) -> dict[str, Any]:
    """Fly one configuration (``base`` + ``sets``); never raises for a flight's own failure."""
    t0 = time.perf_counter()
    c0 = _cpu_s()
    row: dict[str, Any] = {"status": "error", "error": ""}
    try:
        if plant == "kinematic":
            m, status, err = _kinematic(base, sets, timeout_s, stop_after_converged_s, out_dir)
        else:
            m, status, err = _sil(base, sets, timeout_s, force, out_dir)
        row.update({k: _scalar(m.get(k)) for k in metrics})
        row["status"], row["error"] = status, err
        for k in ("initial_pt_m", "initial_psi"):
            if k in m and k not in row:
                row[k] = _scalar(m[k])
        row["sim_time_s"] = _scalar(m.get("sim_time_s"))
    except MpfError as e:
        row["error"] = str(e).splitlines()[0]
    except Exception as e:  # noqa: BLE001 - one flight's bug is that flight's row
        row["error"] = f"{type(e).__name__}: {e}".splitlines()[0]
    row["wall_s"] = round(time.perf_counter() - t0, 3)
    row["cpu_s"] = round(_cpu_s() - c0, 3)
    row["worker_pid"] = os.getpid()
    return row


def _cpu_s() -> float:
    """User + system CPU seconds of this process and its waited-for children (and theirs).

    A Dask worker runs one flight at a time (one thread per worker), so the difference over a
    flight is that flight's cost; the worker's own communication threads add a few ms.
    """
    me = resource.getrusage(resource.RUSAGE_SELF)
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + ch.ru_utime + ch.ru_stime


def _scalar(x: Any) -> Any:
    if isinstance(x, bool) or x is None or isinstance(x, str | int):
        return x
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, list | tuple | dict):
        return json.dumps(x)
    return str(x)


def _kinematic(
    base: str, sets: list[str], timeout_s: float, stop_after: float | None, out_dir: str | None
) -> tuple[dict[str, Any], str, str]:
    from mpf_mavlink.bridge.preflight import initial_errors
    from mpf_mavlink.config import load_config
    from mpf_mavlink.runs.rundir import RunTable, compute_metrics
    from mpf_mavlink.runs.verdict import assess
    from sim.plant.kinematic import record
    from sim.runner import kinematic_loop, record_sample

    cfg = load_config(base, sets)
    loop, x = kinematic_loop(cfg)
    pt0, psi0, _ = initial_errors(cfg, loop.path, loop.target)  # the path built once a flight
    dt = cfg.kinematic.dt_s
    n = int(round(cfg.sim.duration_s / dt))
    every = cfg.sim.record_every
    thr = cfg.metrics.converge_threshold_m
    table = RunTable()
    wall_end = time.perf_counter() + timeout_s
    inside_since: float | None = None
    status, err = "ok", ""

    def rec(smp: Any) -> None:
        record_sample(table, smp)

    for i in range(n):
        x = loop.step(x, dt)
        last = loop.last
        assert last is not None
        if i % every == 0:
            rec(last)
        e = float(last.diag.pt_norm)
        if not math.isfinite(e):
            status, err = "failed", f"non-finite |pt| at t = {last.t:.2f} s"
            break
        if e < thr:
            inside_since = last.t if inside_since is None else inside_since
            if stop_after is not None and last.t - inside_since >= stop_after:
                break
        else:
            inside_since = None
        if i % 256 == 255 and time.perf_counter() > wall_end:
            status, err = "timeout", f"flight timeout {timeout_s:g} s at t = {last.t:.1f} s"
            break
    rec(record(loop, x))
    cols = table.arrays()
    m = compute_metrics(cols, cfg.metrics.steady_after_s, thr)
    m.update(initial_pt_m=pt0, initial_psi=psi0, sim_time_s=float(cols["t"][-1]),
             final_pt_m=float(cols["pt_norm"][-1]))  # fmt: skip
    if status == "ok":
        # a flight stopped early once converged has no steady window: NOT JUDGED, still "ok"
        # (its convergence is the campaign's figure)
        vd = assess(cfg, cols["t"], cols["pt_norm"])
        m["verdict"] = vd.line()
        if vd.failures:
            status, err = "failed", vd.line()
    if out_dir is not None:
        from mpf_mavlink.runs.write import write_run

        write_run(Path(out_dir), cols, m, loop.path.positions(), plots=True)
    return m, status, err


def _last_pt(path: Path) -> float | None:
    """|pt| (m) of the last row of a run's timeseries.csv (the plant's truth in the SIL)."""
    lines = path.read_text().splitlines()
    if len(lines) < 2:
        return None
    col = lines[0].split(",").index("pt_norm")
    return float(lines[-1].split(",")[col])


def _sil(
    base: str, sets: list[str], timeout_s: float, force: bool, out_dir: str | None
) -> tuple[dict[str, Any], str, str]:
    deadline = time.monotonic() + timeout_s
    m, status, err = _sil_once(base, sets, timeout_s, force, out_dir)
    if status == "error" and err.startswith("exit 4: telemetry lost"):
        # in lockstep the bridge's watchdog counts vehicle time (mavlink.lockstep), but a SIL on
        # the realtime clock on a CPU-starved shared host can still trip it (no property of the
        # law). Fly the same sample once more, as `compare` does, and say so in the row; a
        # second loss stays an error.
        first = err
        left = deadline - time.monotonic()
        if left > 0:
            m, status, err = _sil_once(base, sets, left, force, out_dir)
            note = f"flown twice, first: {first}"
            err = f"{err} ({note})" if err else note
    return m, status, err


def _sil_once(
    base: str, sets: list[str], timeout_s: float, force: bool, out_dir: str | None
) -> tuple[dict[str, Any], str, str]:
    with tempfile.TemporaryDirectory(prefix="mpf-campaign-") as tmp:
        out = Path(out_dir) if out_dir is not None else Path(tmp) / "run"
        cmd = [sys.executable, "-m", "mpf_mavlink.cli", "sim", base, "--out", str(out), "-q"]
        if out_dir is None:
            # a flight whose records are not kept: no figures, and the bridge's lean recording
            # (no tlog, a row in five; the same setpoints, so the same flight), unless the
            # campaign's own sets say otherwise (they come later and win)
            cmd += ["--no-plots", "--set", "mavlink.recording=lean"]
        if force:
            cmd.append("--force")
        for s in sets:
            cmd += ["--set", s]
        root = Path(__file__).resolve().parents[2]
        try:
            p = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return {}, "timeout", f"flight timeout {timeout_s:g} s"
        mpath = out / "metrics.json"
        m = json.loads(mpath.read_text()) if mpath.is_file() else {}
        ts = out / "timeseries.csv"
        if "final_pt_m" not in m and ts.is_file():
            m["final_pt_m"] = _last_pt(ts)
        # -q keeps stderr quiet on a flight's own ending: the bridge's exit reason names it
        last = (p.stderr.strip().splitlines() or [""])[-1] or str(m.get("bridge_exit_reason") or "")
        if p.returncode == 0:
            return m, "ok", ""
        if p.returncode == 6:  # ran to its end, too short to judge: its figures stand
            return m, "ok", str(m.get("verdict") or last)
        if p.returncode == 3:
            return m, "refused", last
        if p.returncode == 5:
            return m, "failed", str(m.get("verdict") or last)
        return m, "error", f"exit {p.returncode}: {last}"
