"""A campaign on dask.distributed: every sample a task, every result a row as soon as it lands.

The results table (``results.csv`` in the output directory) is appended and flushed row by row,
so a campaign stopped by anything (Ctrl-C, a dead laptop) keeps every finished flight, and the
same command run again flies only the samples without a row. A worker that dies mid-flight is
the scheduler's to handle: its tasks go to the other workers (``distributed`` reschedules them);
a flight that kills workers again and again ends as a row with the error, as does a flight that
raised, timed out or was refused by the pre-flight gate.

With ``--scheduler tcp://HOST:PORT`` the same campaign runs on an existing cluster (``dask
scheduler`` and ``dask worker`` processes started from this project's environment); without
it a LocalCluster of one single-threaded worker process per core (``--workers N``) is started
for the run and closed after it.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mpf_mavlink.campaign.design import overrides_for, samples
from mpf_mavlink.campaign.flight import fly
from mpf_mavlink.campaign.spec import CampaignSpec
from mpf_mavlink.config import load_config
from mpf_mavlink.config.schema import Config
from mpf_mavlink.errors import MpfError

FINISHED = ("ok", "failed", "refused")  # a re-run does not fly these again
RETRYABLE = ("error", "timeout")  # ... nor these, unless asked to (--retry-errors)


@dataclass
class CampaignResult:
    out: Path
    rows: list[dict[str, Any]]
    flown: int  # flights flown by this invocation
    skipped: int  # samples already in the results table
    wall_s: float
    workers: int
    summary: dict[str, Any] = field(default_factory=dict)


def columns(spec: CampaignSpec) -> list[str]:
    """The results table's header: fixed for a campaign file, checked on resume."""
    keep = [m for m in spec.metrics if m not in ("initial_pt_m", "initial_psi")]
    return ["sample", *[v.key for v in spec.vary], "initial_pt_m", "initial_psi", *keep,
            "status", "error", "wall_s", "cpu_s", "sim_time_s", "worker_pid"]  # fmt: skip


def _fingerprint(spec: CampaignSpec) -> str:
    text = Path(spec.source).read_bytes() + spec.base_path.read_bytes()
    return hashlib.sha256(text).hexdigest()[:16]


def read_table(path: Path, header: list[str], key: str, other: str) -> dict[int, dict[str, Any]]:
    """The rows of an existing results table by their integer ``key`` column, the last row of
    a key winning; ``other``: what a table with other columns is, for the error."""
    if not path.is_file():
        return {}
    with path.open(newline="") as f:
        r = csv.DictReader(f)
        if r.fieldnames != header:
            raise MpfError(f"{path}: {other}; choose another --out")
        return {int(row[key]): row for row in r}


def fly_table(
    pool: tuple[Any, Any],
    jobs: dict[int, tuple[Any, ...]],
    table: Path,
    header: list[str],
    rows: dict[int, dict[str, Any]],
    finish: Callable[[int, dict[str, Any]], dict[str, Any]],
    on_row: Callable[[int, dict[str, Any]], None],
) -> int:
    """Run each job ``i: (function, *args)`` on the ``pool`` (client, cluster: closed after) and
    append ``finish(i, row)`` to ``table`` (its header written when it is new) the moment it
    lands, flushed, into ``rows`` too; a job that raised is an error row. ``on_row(k, row)``
    after the k-th. Returns how many ran."""
    from distributed import as_completed

    client, cluster = pool
    new_file = not table.is_file()
    try:
        with table.open("a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=header, extrasaction="ignore")
            if new_file:
                w.writeheader()
                fh.flush()
            futs = {
                client.submit(*job, key=f"mpf-{table.stem}-{i}-{time.time_ns()}", pure=False): i
                for i, job in jobs.items()
            }
            for k, f in enumerate(as_completed(list(futs)), start=1):
                i = futs[f]
                try:
                    row = f.result()
                except Exception as e:  # noqa: BLE001 - KilledWorker, a lost scheduler...: a row
                    row = {"status": "error", "error": f"{type(e).__name__}: {e}".splitlines()[0]}
                rows[i] = row = finish(i, row)
                w.writerow(row)
                fh.flush()
                on_row(k, row)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return len(futs)


def _client(workers: int | None, scheduler: str | None) -> tuple[Any, Any, int]:
    from distributed import Client, LocalCluster

    if scheduler is not None:
        if not scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://", "ws://", "wss://")):
            raise MpfError(
                f"--scheduler {scheduler}: not a dask scheduler address (tcp://HOST:PORT)"
            )
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as e:
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise MpfError(f"--scheduler {scheduler}: no dask scheduler answered ({msg})") from None
        n = len(client.scheduler_info().get("workers", {}))
        return client, None, n
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
        silence_logs=40,  # logging.ERROR: the progress bar is the campaign's output
    )  # fmt: skip
    return Client(cluster), cluster, n


def run_campaign(
    spec: CampaignSpec,
    out: Path,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    retry_errors: bool = False,
    log: Callable[[str], None] = lambda s: print(s, file=sys.stderr),
) -> CampaignResult:
    """Fly every sample without a finished row; returns all rows (old and new)."""

    header = columns(spec)
    table = out / "results.csv"
    fp = _fingerprint(spec)
    meta = out / "campaign.json"
    if meta.is_file() and table.is_file():
        old = json.loads(meta.read_text()).get("fingerprint")
        if old != fp:
            raise MpfError(
                f"{out}: holds the results of another version of the campaign or its base "
                "configuration; choose another --out"
            )
    rows = read_table(table, header, "sample", "written by another campaign (its columns differ)")
    redo = FINISHED if retry_errors else (*FINISHED, *RETRYABLE)
    done = {i for i, r in rows.items() if r.get("status") in redo}
    base = load_config(spec.base_path, spec.set)
    if spec.plant == "sil":
        from mpf_mavlink.config.autopilot_profile import calibrated_sets

        # the calibrated SIL unless the campaign or its base names a profile (none included)
        extra, label = calibrated_sets(base)
        if extra:
            spec = dataclasses.replace(spec, set=[*spec.set, *extra])
            base = load_config(spec.base_path, spec.set)
        log(f"campaign {spec.name}: SIL autopilot profile {label}")
    all_samples = samples(spec)
    todo = [i for i in range(spec.samples) if i not in done]
    # the workers first: a scheduler that does not answer leaves no directory behind
    client, cluster, n = _client(workers, scheduler) if todo else (None, None, 0)
    out.mkdir(parents=True, exist_ok=True)
    info = {"name": spec.name, "source": spec.source, "base": str(spec.base_path),
            "fingerprint": fp}  # fmt: skip
    meta.write_text(json.dumps(info, indent=2) + "\n")
    t0 = time.perf_counter()
    result = CampaignResult(out, [], 0, len(done), 0.0, 0)
    if todo:
        result.workers = n
        log(f"campaign {spec.name}: {len(todo)} flights to fly ({len(done)} already in "
            f"{table}), {spec.plant} plant, {n} worker(s)")  # fmt: skip
        result.flown = _fly_all((client, cluster), spec, base, all_samples, todo, table, rows,
                                progress)  # fmt: skip
    result.wall_s = time.perf_counter() - t0
    result.rows = [rows[i] for i in sorted(rows)]
    return result


def _fly_all(
    pool: tuple[Any, Any],
    spec: CampaignSpec,
    base: Config,
    all_samples: list[dict[str, Any]],
    todo: list[int],
    table: Path,
    rows: dict[int, dict[str, Any]],
    progress: bool,
) -> int:
    from tqdm import tqdm

    jobs = {
        i: (fly, str(spec.base_path), [*spec.set, *overrides_for(base, all_samples[i])],
            spec.plant, spec.metrics, spec.timeout_s, spec.stop_after_converged_s, spec.force)
        for i in todo
    }  # fmt: skip
    bar = tqdm(total=len(todo), desc=f"campaign {spec.name}", unit="flight", disable=not progress,
               file=sys.stderr, mininterval=0.5, dynamic_ncols=True)  # fmt: skip
    failures = [0]

    def finish(i: int, row: dict[str, Any]) -> dict[str, Any]:
        row = {**row, "sample": i, **all_samples[i]}
        return {k: ("" if v is None else v) for k, v in row.items()}

    def on_row(_: int, row: dict[str, Any]) -> None:
        failures[0] += row.get("status") != "ok"
        bar.set_postfix(failures=failures[0], refresh=False)
        bar.update(1)

    try:
        return fly_table(pool, jobs, table, columns(spec), rows, finish, on_row)
    finally:
        bar.close()
