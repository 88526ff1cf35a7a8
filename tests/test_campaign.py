"""Monte-Carlo campaigns: the campaign file's validation, the sample designs, resumable results,
and a real dask scheduler with two real workers, one of them killed mid-campaign."""

from __future__ import annotations

import csv
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mpf_mavlink.campaign.design import load_campaign, samples, unit_points
from mpf_mavlink.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "configs" / "paper_lemniscate.yaml"
DEMO = ROOT / "configs" / "default.yaml"


def _write(tmp_path: Path, text: str, name: str = "c.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


KIN = f"""
name: t
base: {PAPER}
plant: kinematic
samples: 8
design: lhs
seed: 3
set: [sim.duration_s=30, kinematic.dt_s=0.04, metrics.steady_after_s=20]
vary:
  - {{key: initial.distance_m, dist: uniform, low: 0.0, high: 60.0}}
  - {{key: initial.heading_rad, dist: uniform, low: -3.0, high: 3.0}}
  - {{key: guidance.K_p, dist: loguniform, low: 1.0, high: 8.0}}
metrics: [convergence_time_s, final_pt_m, verdict]
rank_by: final_pt_m
stop_after_converged_s: 3
keep_worst: 1
"""


@pytest.mark.parametrize(
    "edit, culprit",
    [
        (("samples: 8", "samples: 8\nbogus: 1"), "bogus"),
        (
            ("guidance.K_p, dist: loguniform", "guidance.K_q, dist: loguniform"),
            "guidance.K_q",
        ),
        (("low: 1.0, high: 8.0", "low: 0.0, high: 8.0"), "vary[2].low"),
        (("low: 1.0, high: 8.0", "low: 1.0, high: 8.0, sd: 2"), "vary[2].sd"),
        (("design: lhs", "design: grid"), "design"),
        (("low: 1.0, high: 8.0", "low: 1.0, high: -8.0"), "vary[2].high"),
        (("rank_by: final_pt_m", "rank_by: steady_rms_m"), "rank_by"),
    ],
)  # fmt: skip
def test_a_bad_campaign_file_is_one_line_naming_the_key(tmp_path, edit, culprit):
    p = _write(tmp_path, KIN.replace(*edit))
    with pytest.raises(ConfigError) as e:
        load_campaign(p)
    msg = str(e.value)
    assert culprit in msg and "\n" not in msg and str(p) in msg


def test_a_key_out_of_the_base_configs_range_is_refused_before_flying(tmp_path):
    # K_p must be > 0 in the config: a normal distribution centred at 0 probes it at its mean
    normal = KIN.replace(
        "dist: loguniform, low: 1.0, high: 8.0", "dist: normal, mean: 0.0, sd: 1.0"
    )
    p = _write(tmp_path, normal)
    with pytest.raises(ConfigError, match="guidance.K_p"):
        load_campaign(p)


def test_overrides_read_back_as_the_same_numbers():
    # Python's repr writes 1e-05 without a dot, which YAML (PyYAML) reads as a STRING: the
    # flight's config was refused ("must be a number"). Every override must load back exactly.
    import math

    from mpf_mavlink.campaign.design import initial_overrides, overrides_for
    from mpf_mavlink.config.schema import load_config

    src = str(Path(__file__).resolve().parents[1] / "configs" / "default.yaml")
    base = load_config(src)
    sample = {"mavlink.known_delay_s": 1e-05, "sil.wind_ned_m_s[0]": np.float64(2e-06)}
    cfg = load_config(src, overrides_for(base, sample))
    assert cfg.section("mavlink").known_delay_s == 1e-05
    assert cfg.section("sil").wind_ned_m_s[0] == 2e-06
    for b in (0.0, math.pi / 2, math.pi):  # sin(pi) = 1.2e-16: such components too
        ov = initial_overrides(base, {"initial.bearing_rad": b, "initial.distance_m": 50.0})
        got = load_config(src, ov).kinematic.initial_position_ned_m
        want = [float(x) for x in ov[0].partition("=[")[2].rstrip("]").split(", ")]
        assert list(got) == want


def test_designs_are_seeded_and_latin_hypercube_fills_every_stratum(tmp_path):
    spec = load_campaign(_write(tmp_path, KIN))
    a, b = unit_points(spec), unit_points(spec)
    assert np.array_equal(a, b)
    # Latin hypercube: in each dimension exactly one of the n points falls in each 1/n stratum
    n = spec.samples
    for j in range(a.shape[1]):
        assert sorted(np.floor(a[:, j] * n).astype(int).tolist()) == list(range(n))
    s = samples(spec)
    assert all(1.0 <= x["guidance.K_p"] <= 8.0 for x in s)
    # log-uniform: log K_p is uniform, so the LHS strata of log K_p are equally wide
    logs = np.sort(np.log([x["guidance.K_p"] for x in s]))
    edges = np.log(1.0) + np.arange(n + 1) * (np.log(8.0) - np.log(1.0)) / n
    assert all(edges[i] <= logs[i] <= edges[i + 1] for i in range(n))


def _cli(*args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mpf_mavlink.cli", *args],
        cwd=ROOT, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow  # > 8 s of real-time flight: full suite (CI), not the quick loop
def test_local_campaign_is_resumable_and_the_rerun_flies_the_same_numbers(tmp_path):
    p = _write(tmp_path, KIN)
    out = tmp_path / "out"
    r = _cli("campaign", str(p), "--out", str(out), "--workers", "1", "-q")
    assert r.returncode == 0, r.stderr
    rows = _rows(out)
    assert sorted(int(x["sample"]) for x in rows) == list(range(8))
    assert all(x["status"] == "ok" for x in rows)
    # one flight at a time on a one-thread worker: its CPU time is positive and cannot exceed
    # its wall time but for the worker's idle communication threads (a few ms)
    assert all(0.0 < float(x["cpu_s"]) <= float(x["wall_s"]) + 0.05 for x in rows), rows
    assert "flights: 8" in r.stdout and (out / "roa.png").is_file() and (out / "ecdf.png").is_file()
    assert (out / "worst").is_dir() and any((out / "worst").iterdir())
    # lose the last three rows (a campaign killed mid-way): the re-run flies exactly those
    keep, lost = rows[:5], rows[5:]
    with (out / "results.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(keep)
    r2 = _cli("campaign", str(p), "--out", str(out), "--workers", "1", "-q", "--no-report")
    assert r2.returncode == 0, r2.stderr
    assert "flown now: 3 in" in r2.stdout
    again = {x["sample"]: x for x in _rows(out)}
    assert len(again) == 8
    for x in lost:
        # the kinematic plant is deterministic: the same sample flies to the same figures
        y = again[x["sample"]]
        assert (y["convergence_time_s"], y["final_pt_m"]) == (
            x["convergence_time_s"],
            x["final_pt_m"],
        )
    # another campaign into the same directory is refused, not mixed in
    r3 = _cli("campaign", str(_write(tmp_path, KIN.replace("seed: 3", "seed: 4"), "d.yaml")),
              "--out", str(out), "--workers", "1", "-q")  # fmt: skip
    assert r3.returncode != 0 and "another" in r3.stderr


def _free_tcp_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _dask(*args: str) -> subprocess.Popen[bytes]:
    exe = Path(sys.executable).parent / "dask"
    cmd = [str(exe)] if exe.is_file() else [sys.executable, "-m", "dask"]
    return subprocess.Popen([*cmd, *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)  # fmt: skip


@pytest.mark.slow
def test_real_scheduler_and_two_workers_survive_a_killed_worker(tmp_path):
    # 4 SIL flights (the demo: JSBSim X8 + PX4 endpoint + bridge over UDP, 15 s each) and 4
    # kinematic ones on a `dask scheduler` with two `dask worker`s; one worker is SIGKILLed as
    # soon as the first row lands, while the other flights are in the air
    port = _free_tcp_port()
    addr = f"tcp://127.0.0.1:{port}"
    procs = [_dask("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard")]
    time.sleep(2.0)
    for _ in range(2):
        procs.append(_dask("worker", addr, "--nthreads", "1", "--no-nanny", "--no-dashboard"))
    sil = _write(tmp_path, f"""
name: sil
base: {DEMO}
plant: sil
samples: 4
design: random
seed: 1
set: [sim.duration_s=15, metrics.steady_after_s=10]
vary:
  - {{key: sil.command_latency_s, dist: uniform, low: 0.0, high: 0.04}}
metrics: [first_within_s, convergence_time_s, steady_rms_m, final_pt_m, verdict]
rank_by: final_pt_m
timeout_s: 300
keep_worst: 0
""", "sil.yaml")  # fmt: skip
    kin = _write(
        tmp_path, KIN.replace("samples: 8", "samples: 4").replace("keep_worst: 1", "keep_worst: 0")
    )
    try:
        deadline = time.monotonic() + 60
        from distributed import Client

        with Client(addr, timeout="20s") as c:
            while len(c.scheduler_info()["workers"]) < 2:
                assert time.monotonic() < deadline, "the two dask workers never registered"
                time.sleep(0.5)
        victim = procs[1]
        outs = {}
        for name, spec in (("sil", sil), ("kin", kin)):
            out = tmp_path / name
            cli = subprocess.Popen(
                [sys.executable, "-m", "mpf_mavlink.cli", "campaign", str(spec), "--out", str(out),
                 "--scheduler", addr, "-q", "--no-report"],
                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            )  # fmt: skip
            if name == "sil":
                while not ((out / "results.csv").is_file() and len(_rows(out)) >= 1):
                    assert cli.poll() is None, cli.communicate()
                    assert time.monotonic() < deadline + 200, "no SIL flight finished"
                    time.sleep(0.2)
                n_at_kill = len(_rows(out))
                os.killpg(victim.pid, signal.SIGKILL)
                victim.wait(10)
            stdout, stderr = cli.communicate(timeout=400)
            assert cli.returncode == 0, stdout + stderr
            outs[name] = _rows(out)
        assert n_at_kill < 4
        # every sample has its row, every flight ran to its end on whichever worker was left
        # ("failed" is a flight flown to its end whose verdict failed it: 15 s of the demo end
        # before it converges, and its |pt| of 8-9 m from t = 10 s is near the verdict's 10 m
        # bound, which a machine loaded to 20 crossed in 2 of 4 flights; the tracking asked of
        # these flights is the line below, not the verdict)
        for name, rows in outs.items():
            assert sorted(int(x["sample"]) for x in rows) == [0, 1, 2, 3], name
            ran = ("ok", "failed") if name == "sil" else ("ok",)
            assert all(x["status"] in ran for x in rows), [x["error"] for x in rows]
        # tracking, not just ending: each capture brought the vehicle within the demo's
        # converge_threshold_m (3 m) of the moving path. |pt| at 15 s is no measure of that: the
        # demo's capture swings 1 -> 20 -> 1 m on the figure-eight's tight lobe for ~20 s, and the
        # start is not one state: the hand-over runs on wall-clock timers and PX4's 1 Hz
        # HEARTBEAT confirms it, so identical flights on an idle machine started 20 or 34 m off
        # and ended 10.7 or 8.8 m off at 15 s. From 20-34 m at 16 m/s the straight-line closure
        # takes 1.3-2.1 s (measured: first within 3 m at 1.3-2.2 s), well inside the flight.
        assert all(x["first_within_s"] not in ("", None) for x in outs["sil"]), [
            {k: x[k] for k in ("sample", "initial_pt_m", "first_within_s", "final_pt_m", "status")}
            for x in outs["sil"]
        ]
        # a SIL flight's cost is its subprocesses' (the worker only waits on them, a few ms):
        # counted, it is at least the vehicle's ~290 us of CPU per 20 ms frame (scripts/bench
        # mavlink_framing_us) over 15 s = 750 frames, 0.22 s, before the bridge and JSBSim's load
        sil_cpu = [float(x["cpu_s"]) for x in outs["sil"]]
        assert all(c > 0.2 for c in sil_cpu), sil_cpu
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)


def test_a_sil_flight_whose_bridge_lost_telemetry_is_flown_once_more(monkeypatch):
    # a realtime-clock SIL on a CPU-starved host can trip the bridge's wall-clock watchdog.
    # The same sample is flown once more and the row says so; any other error is not retried.
    from mpf_mavlink.campaign import flight

    lost = (
        {"bridge_exit_reason": "telemetry lost"},
        "error",
        "exit 4: telemetry lost: no ATTITUDE",
    )
    calls: list[float] = []

    def scripted(outcomes):
        it = iter(outcomes)

        def once(base, sets, timeout_s, force, out_dir):
            calls.append(timeout_s)
            return next(it)

        return once

    monkeypatch.setattr(flight, "_sil_once", scripted([lost, ({"steady_rms_m": 0.2}, "ok", "")]))
    row = flight.fly("default.yaml", [], "sil", ["steady_rms_m"], timeout_s=100.0)
    assert row["status"] == "ok" and row["steady_rms_m"] == 0.2
    assert row["error"].startswith("flown twice, first: exit 4: telemetry lost")
    assert len(calls) == 2 and calls[1] <= 100.0  # the retry shares the flight's timeout

    calls.clear()
    monkeypatch.setattr(flight, "_sil_once", scripted([lost, lost]))
    row = flight.fly("default.yaml", [], "sil", ["steady_rms_m"], timeout_s=100.0)
    assert row["status"] == "error" and "flown twice" in row["error"] and len(calls) == 2

    calls.clear()
    other = ({}, "error", "exit 1: bad config")
    monkeypatch.setattr(flight, "_sil_once", scripted([other]))
    row = flight.fly("default.yaml", [], "sil", ["steady_rms_m"], timeout_s=100.0)
    assert row["error"] == "exit 1: bad config" and len(calls) == 1


def test_sil_flights_not_kept_fly_the_lean_recording_kept_ones_the_full(monkeypatch, tmp_path):
    """A campaign flight whose run directory is thrown away pays for no tlog and one row in
    five (mavlink.recording: lean, the same setpoints); a sample's own sets still win, and the
    worst flights flown again into a kept directory get the full recording and plots."""
    from mpf_mavlink.campaign import flight

    cmds: list[list[str]] = []

    def run(cmd, **kw):
        cmds.append(list(cmd))
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(flight.subprocess, "run", run)
    flight._sil_once("default.yaml", ["sil.seed=3", "mavlink.recording=full"], 10.0, False, None)
    flight._sil_once("default.yaml", ["sil.seed=3"], 10.0, False, str(tmp_path / "kept"))
    thrown, kept = cmds
    assert "--no-plots" in thrown and "--no-plots" not in kept
    sets = [thrown[i + 1] for i, a in enumerate(thrown) if a == "--set"]
    assert sets == ["mavlink.recording=lean", "sil.seed=3", "mavlink.recording=full"]
    assert not any("recording" in a for a in kept)
