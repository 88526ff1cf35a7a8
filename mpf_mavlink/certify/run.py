"""``certify``: fly the mission on the calibrated SIL under drawn conditions, on dask.distributed.

Every flight is a task (the campaign's workers: a LocalCluster of single-threaded processes or
an existing scheduler) and a row of ``DIR/flights.csv`` the moment it lands, so a stopped run
keeps every finished flight and the same command flies only the missing ones. Flight ``i``'s
conditions depend on (seed, i) only: asking for more flights later adds flights, it never
changes the old ones.
"""

from __future__ import annotations

import hashlib
import json
import resource
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpf_mavlink.certify.conditions import Conditions, draw, flight_sets
from mpf_mavlink.errors import MpfError

FLAVOURS = {"px4": "px4", "arduplane": "ardupilot"}
FIGURES = ("steady_rms_m", "steady_max_m", "altitude_margin_m", "max_bank_rad", "verdict_status")
COLUMNS = ["flight", *FIGURES, "bank_limit_rad", "min_altitude_m", "status", "error",
           "conditions", "wall_s", "cpu_s", "sim_time_s"]  # fmt: skip
DONE = ("ok", "failed", "refused")  # a re-run does not fly these again


@dataclass
class Mission:
    """What every flight shares: the config file, the fixed overrides, the profile's words."""

    config: str
    sets: list[str]
    autopilot: str
    profile: str
    duration_s: float
    steady_after_s: float


def mission(config: Path, overrides: list[str], autopilot: str, cond: Conditions) -> Mission:
    """Load and check the mission once (a bad key fails here, before any flight)."""
    from mpf_mavlink.config import load_config
    from mpf_mavlink.config.autopilot_profile import calibrated_sets

    if autopilot not in FLAVOURS:
        raise MpfError(f"--autopilot {autopilot}: one of {', '.join(FLAVOURS)}")
    sets = [*overrides, *cond.set, "sil.link=udp", f"sil.flavour={FLAVOURS[autopilot]}"]
    if cond.duration_s is not None:
        sets.append(f"sim.duration_s={cond.duration_s:g}")
    if cond.steady_after_s is not None:
        sets.append(f"metrics.steady_after_s={cond.steady_after_s:g}")
    cfg = load_config(config, sets)
    extra, label = calibrated_sets(cfg)
    sets += extra
    cfg = load_config(config, sets)
    # an airframe trimmed at the mission's airspeed (the rig's SIL leg does the same)
    sets.append(f"aircraft.trim_airspeed_m_s={cfg.vehicle.airspeed_m_s:g}")
    cfg = load_config(config, sets)
    for i in (0, 1):  # two draws through the schema: the ranges' keys apply to this config
        load_config(config, [*sets, *flight_sets(cfg, draw(cond, i))])
    return Mission(
        str(Path(config).resolve()), sets, autopilot, label, cfg.sim.duration_s,
        cfg.metrics.steady_after_s,
    )  # fmt: skip


def fingerprint(m: Mission, cond: Conditions) -> str:
    """What the flights depend on: a directory with another is refused, not mixed."""
    text = json.dumps([m.sets, m.autopilot, cond.source and Path(cond.source).read_text()])
    text += Path(m.config).read_text()
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def fly_one(config: str, sets: list[str], timeout_s: float) -> dict[str, Any]:
    """One flight (``mpf-mavlink sim`` in a subprocess, as a campaign's): its row's figures."""
    from mpf_mavlink.campaign.flight import _sil

    t0 = time.perf_counter()
    c0 = _cpu_s()
    row: dict[str, Any] = {"status": "error", "error": ""}
    try:
        m, status, err = _sil(config, sets, timeout_s, False, None)
        vf = m.get("verdict_figures") or {}
        alt, floor = vf.get("min_altitude_m"), vf.get("altitude_floor_m")
        row.update(
            steady_rms_m=m.get("steady_rms_m"),
            steady_max_m=m.get("steady_max_m"),
            min_altitude_m=alt,
            altitude_margin_m=(alt - floor) if alt is not None and floor is not None else None,
            max_bank_rad=vf.get("max_bank_rad"),
            bank_limit_rad=vf.get("bank_limit_rad"),
            verdict_status=m.get("verdict_status"),
            sim_time_s=m.get("sim_time_s"),
            status=status,
            error=err,
        )
    except Exception as e:  # noqa: BLE001 - one flight's bug is that flight's row
        row["error"] = f"{type(e).__name__}: {e}".splitlines()[0]
    row["wall_s"] = round(time.perf_counter() - t0, 3)
    row["cpu_s"] = round(_cpu_s() - c0, 3)
    return row


def _cpu_s() -> float:
    me = resource.getrusage(resource.RUSAGE_SELF)
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + ch.ru_utime + ch.ru_stime


@dataclass
class Flown:
    rows: list[dict[str, Any]]
    flown: int
    kept: int
    wall_s: float
    workers: int


def fly_all(
    m: Mission,
    cond: Conditions,
    n: int,
    out: Path,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    log: Callable[[str], None] = lambda s: print(s, file=sys.stderr, flush=True),
) -> Flown:
    """Fly flights 0..n-1 that have no finished row in ``out/flights.csv``."""
    from mpf_mavlink.campaign.run import _client, read_table
    from mpf_mavlink.config import load_config

    table = out / "flights.csv"
    meta = out / "certify.json"
    fp = fingerprint(m, cond)
    if meta.is_file() and json.loads(meta.read_text()).get("fingerprint") != fp:
        raise MpfError(
            f"{out}: holds the flights of another mission or conditions; choose another --out"
        )
    rows = read_table(table, COLUMNS, "flight", "not a certify flights table")
    todo = [i for i in range(n) if rows.get(i, {}).get("status") not in DONE]
    client, cluster, nw = _client(workers, scheduler) if todo else (None, None, 0)
    out.mkdir(parents=True, exist_ok=True)
    meta.write_text(json.dumps({"fingerprint": fp, "config": m.config}, indent=2) + "\n")
    t0 = time.perf_counter()
    flown = 0
    if todo:
        cfg = load_config(m.config, m.sets)
        log(f"certify {cond.name}: {len(todo)} flights to fly ({n - len(todo)} already in "
            f"{table}), calibrated SIL ({m.profile}), {nw} worker(s)")  # fmt: skip
        flown = _submit((client, cluster), m, cond, cfg, todo, table, rows, progress, log, t0)
    wall = time.perf_counter() - t0
    return Flown([rows[i] for i in sorted(rows) if i < n], flown, n - len(todo), wall, nw)


def _submit(
    pool: tuple[Any, Any],
    m: Mission,
    cond: Conditions,
    cfg: Any,
    todo: list[int],
    table: Path,
    rows: dict[int, dict[str, Any]],
    progress: bool,
    log: Callable[[str], None],
    t0: float,
) -> int:
    from mpf_mavlink.campaign.run import fly_table

    draws = {i: draw(cond, i) for i in todo}
    jobs = {i: (fly_one, m.config, [*m.sets, *flight_sets(cfg, d)], cond.timeout_s)
            for i, d in draws.items()}  # fmt: skip
    fails = [0]

    def finish(i: int, row: dict[str, Any]) -> dict[str, Any]:
        row = {**row, "flight": i, "conditions": json.dumps(draws[i], sort_keys=True)}
        return {c: ("" if row.get(c) is None else row.get(c)) for c in COLUMNS}

    def on_row(k: int, row: dict[str, Any]) -> None:
        fails[0] += row["status"] != "ok"
        if progress:
            el = time.perf_counter() - t0
            rms = row.get("steady_rms_m")
            log(f"  [{k}/{len(todo)}] flight {row['flight']}: {row['status']}"
                + (f", steady RMS {float(rms):.3f} m" if rms not in ("", None) else "")
                + f" ({fails[0]} not ok; {60.0 * k / el:.1f} flights/min, "
                f"{(len(todo) - k) * el / k / 60.0:.1f} min left)")  # fmt: skip

    return fly_table(pool, jobs, table, COLUMNS, rows, finish, on_row)
