"""Replay of tlogs: the real ArduPlane QuadPlane SITL recording (not ours), bridge runs recorded
against the scripted autopilot of tests/mav_peer.py replayed to identical commands, tampered,
truncated and corrupted copies, the command line.

The bridge recordings take ~4 s each (1 s pre-stream, 1.5 s tracking, hand-back); the real
tlog replays in < 1 s without plots.
"""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from mav_peer import MavPeer, PeerOptions  # noqa: E402

from mpf_mavlink.bridge.base import BridgeOptions, BridgeResult  # noqa: E402
from mpf_mavlink.bridge.controller import origin_texts, parse_marker  # noqa: E402
from mpf_mavlink.bridge.live import run_bridge  # noqa: E402
from mpf_mavlink.bridge.replay import TOLERANCE, replay  # noqa: E402
from mpf_mavlink.cli.main import main  # noqa: E402
from mpf_mavlink.config import bridge as bridge_config  # noqa: E402,F401
from mpf_mavlink.config.schema import Config, load_config  # noqa: E402
from mpf_mavlink.core.frames import geodetic_to_ned, ned_to_geodetic  # noqa: E402
from mpf_mavlink.mavlink import dialect as mavlink  # noqa: E402
from mpf_mavlink.mavlink import read_tlog  # noqa: E402

# a lifecycle flight of seconds has no steady window: it ends NOT JUDGED (exit 6), not PASS
from mpf_mavlink.runs.verdict import EXIT_NOT_JUDGED as NOT_JUDGED  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# A real ArduPlane SITL recording kept in the repository (provenance: tests/data/README.md).
SHARED_TLOG = Path(__file__).resolve().parent / "data" / "arduplane-quadplane-sitl-vtol.tlog"
REPLAY_CFG = ROOT / "configs" / "replay_arduplane_sitl.yaml"
FAST = ["mavlink.plots=false", "mavlink.heartbeat_timeout_s=3", "mavlink.mode_timeout_s=0.6",
        "mavlink.request_streams=false", "mavlink.set_fallback=false"]  # fmt: skip
RUN_FILES = (
    "timeseries.csv",
    "setpoints.csv",
    "path_T.csv",
    "metrics.json",
    "trajectory_3d.png",
    "planar.png",
    "target_relative.png",
    "errors.png",
    "sdot_rates.png",
    "setpoints.png",
)


# ----------------------------------------------------------------------------- helpers
def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def bridge_cfg(flavour: str, *overrides: str) -> Config:
    name = "bridge_px4.yaml" if flavour == "px4" else "bridge_arduplane.yaml"
    return load_config(ROOT / "configs" / name, [*FAST, *overrides])


class SlowHandbackPeer(MavPeer):
    """Ignores the first request for the hold mode, as a busy autopilot may: the bridge keeps
    streaming wings-level setpoints until its retry (after mavlink.mode_timeout_s) is accepted."""

    def __init__(self, *a: Any, **k: Any) -> None:
        super().__init__(*a, **k)
        self.ignored = 0

    def _set_mode(self, m: Any, now: float) -> None:
        hold = int(m.param2) == (4 if self.o.flavour == "px4" else 12)  # AUTO(.LOITER) / LOITER
        if hold and self.ignored == 0:
            self.ignored += 1
            return
        super()._set_mode(m, now)


def record_bridge_run(
    out: Path, flavour: str, telemetry_hz: float
) -> tuple[Config, BridgeResult, SlowHandbackPeer]:
    """Fly the bridge for 1.5 s against the scripted autopilot; the tlog is out/mavlink.tlog."""
    cfg = bridge_cfg(flavour)
    port = free_port()
    peer = SlowHandbackPeer(
        # the scripted plane flies the config's airspeed (ArduPlane's: 22 m/s, the bundle's cruise)
        PeerOptions(flavour=flavour, telemetry_hz=telemetry_hz, airspeed=cfg.vehicle.airspeed_m_s),
        port=port,
    ).start()
    try:
        res = run_bridge(
            cfg,
            BridgeOptions(url=f"udpin:127.0.0.1:{port}", out_dir=out, duration_s=1.5),
            log=lambda s: None,
        )
    finally:
        peer.stop()
    assert (res.state_reached, res.exit_code, res.handback_confirmed) == (
        "TRACKING",
        NOT_JUDGED,
        True,
    ), res.exit_reason
    return cfg, res, peer


def record_offsets(data: bytes) -> list[tuple[int, int]]:
    """(offset, length) of every record of a clean tlog, framed from the packet headers."""
    out, i = [], 0
    while i < len(data):
        stx, plen = data[i + 8], data[i + 9]
        n = 8 + (6 + plen + 2 if stx == 0xFE else 10 + plen + 2 + (13 if data[i + 10] & 1 else 0))
        out.append((i, n))
        i += n
    return out


def records_of(data: bytes, mtype: str, src: tuple[int, int] | None = None) -> list[int]:
    """Indices of the records of one message type (and source), in file order."""
    mav = mavlink.MAVLink(None)
    out = []
    for k, (o, n) in enumerate(record_offsets(data)):
        m = mav.decode(bytearray(data[o + 8 : o + n]))
        if m.get_type() == mtype and (
            src is None or (m.get_srcSystem(), m.get_srcComponent()) == src
        ):
            out.append(k)
    return out


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def real_replay(tmp_path_factory):
    out = tmp_path_factory.mktemp("real") / "run"
    res = replay(SHARED_TLOG, load_config(REPLAY_CFG), out_dir=out, plots=True)
    print(res.summary())
    return res, out


@pytest.fixture(scope="module")
def px4_run(tmp_path_factory):
    # 12.5 Hz telemetry: the bridge re-sends its last setpoint to keep >= 20 Hz
    out = tmp_path_factory.mktemp("px4")
    cfg, res, peer = record_bridge_run(out, "px4", 12.5)
    return cfg, res, peer, out


@pytest.fixture(scope="module")
def arduplane_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("arduplane")
    cfg, res, peer = record_bridge_run(out, "ardupilot", 50.0)
    return cfg, res, peer, out


# ----------------------------------------------------------------------------- the real tlog
def test_real_tlog_replays_with_a_complete_run_directory(real_replay):
    res, out = real_replay
    assert (res.records, res.skipped_regions, res.skipped_bytes) == (23894, 0, 0)
    assert res.flavour == "ardupilot" and res.duration_s == pytest.approx(207.6, abs=0.1)
    # the modes the recording is described with (QuadPlane QLOITER/QLAND around them)
    assert [name for _, _, name in res.modes] == ["QLOITER", "CIRCLE", "GUIDED", "QLAND"]
    guided = next((a, b) for a, b, name in res.modes if name == "GUIDED")
    assert guided == pytest.approx((85.0, 123.4), abs=0.1)
    # ~4 Hz: 888 ATTITUDE records, 4 of them before the first HEARTBEAT (dropped, as the bridge
    # does while it waits for the vehicle) and a few that the link's clock gate drops (this log's
    # receive times come in bursts: the autopilot clock jumps against them, 7 here); all but
    # those without a fresh position give a control step
    assert 870 <= res.attitude_samples <= 884 and res.link_rejected["time"] >= 5
    assert res.steps >= 850
    assert set(res.skipped_steps) <= {"position stale"}
    assert res.origin.startswith("first complete state") and res.check.sent == 0
    for f in RUN_FILES:
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    ts = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    assert len(ts) == res.recorded == res.steps and np.all(np.diff(ts["t"]) > 0)
    for k in ("pt_norm", "psi", "sdot", "w2_cmd", "w3_cmd", "p_n", "p_e", "p_d"):
        assert np.all(np.isfinite(ts[k])), k
    assert np.all((ts["psi"] >= 0) & (ts["psi"] <= 1))
    # guidance.rate_limit_rad_s, per axis (guidance.rate_limit_mode's default)
    assert np.max(np.maximum(np.abs(ts["w2_cmd"]), np.abs(ts["w3_cmd"]))) <= 0.5 + 1e-9
    sp = np.genfromtxt(out / "setpoints.csv", delimiter=",", names=True)
    assert len(sp) == len(ts) and np.all(np.abs(sp["bank"]) <= 0.8 + 1e-9)  # vehicle.max_bank_rad
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["replay"]["steps"] == res.steps and metrics["replay"]["commands"]["sent"] == 0


def test_real_tlog_guided_loiter_is_the_configured_path(real_replay):
    # In GUIDED (100-123 s) the plane loiters on the circle the config was fitted to (2.8 m RMS
    # residual horizontally, altitude within ~3 m): |pt| is a few metres there, and the virtual
    # point keeps up with the plane (sdot ~ its ground speed ~ 24 m/s +- wind).
    res, out = real_replay
    ts = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    t0 = res.t0_boot_s
    meta = json.loads((out / "metrics.json").read_text())["replay"]
    assert meta["t0_boot_s"] == t0
    # rows whose ATTITUDE falls in the loiter: boot time of the log at 100..123 s of record time
    boot = boot_times_at(100.0, 123.0)
    loiter = (ts["t"] + t0 >= boot[0]) & (ts["t"] + t0 <= boot[1])
    assert loiter.sum() >= 60
    assert np.median(ts["pt_norm"][loiter]) < 5.0
    assert np.median(ts["sdot"][loiter]) == pytest.approx(24.0, abs=4.0)


def boot_times_at(a: float, b: float) -> tuple[float, float]:
    """Autopilot boot times (s) of the first and last ATTITUDE recorded in [a, b] s of the log."""
    r = read_tlog(SHARED_TLOG, types=["ATTITUDE"])
    tb = [m.time_boot_ms * 1e-3 for t, m in r if a <= t - r.t_first_s <= b]
    return tb[0], tb[-1]


def test_real_tlog_rebuilt_positions_match_simstate_truth(real_replay):
    """The positions the estimator rebuilt against the simulator's truth (SIMSTATE).

    SIMSTATE carries lat/lon only (no altitude, no time stamp). ArduPilot sends it in the same
    stream group right after ATTITUDE, so the truth of a control step is the first SIMSTATE after
    that step's ATTITUDE record (same scheduler pass). The rebuilt positions are
    LOCAL_POSITION_NED about the EKF origin, which is not HOME here (HOME_POSITION only arrives at
    176 s); the origin is the point that maps the first GLOBAL_POSITION_INT onto the
    LOCAL_POSITION_NED of the same time_boot_ms: one constant, then 176 s are compared.
    After the landing (176.5 s, "Throttle disarmed") the EKF resets its origin: excluded.
    Tolerance 1.5 m: SITL's EKF lags its simulated GPS (up to ~0.9 m here at 24 m/s), plus the
    extrapolation of the position sample to the ATTITUDE time.
    """
    res, out = real_replay
    r = read_tlog(
        SHARED_TLOG, types=["SIMSTATE", "ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"]
    )
    glob = {m.time_boot_ms: m for _, m in r if m.get_type() == "GLOBAL_POSITION_INT"}
    loc = next(m for _, m in r if m.get_type() == "LOCAL_POSITION_NED" and m.time_boot_ms in glob)
    g = glob[loc.time_boot_ms]
    lat0, lon0, alt0 = ned_to_geodetic(
        (-loc.x, -loc.y, -loc.z), g.lat * 1e-7, g.lon * 1e-7, g.alt * 1e-3
    )
    truth: dict[int, tuple[float, Any]] = {}
    att = None
    for t, m in r:
        if m.get_type() == "ATTITUDE":
            att = m
        elif m.get_type() == "SIMSTATE" and att is not None:
            truth[att.time_boot_ms] = (t - r.t_first_s, m)
            att = None
    ts = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    err = []
    for row in ts:
        tb = int(round((row["t"] + res.t0_boot_s) * 1000.0))
        if tb in truth and truth[tb][0] < 176.0:
            s = truth[tb][1]
            n, e, _ = geodetic_to_ned(s.lat * 1e-7, s.lng * 1e-7, alt0, lat0, lon0, alt0)
            err.append(math.hypot(row["p_n"] - n, row["p_e"] - e))
    err_a = np.array(err)
    print(
        f"horizontal |rebuilt - SIMSTATE|: {len(err_a)} steps, median {np.median(err_a):.2f} m, "
        f"max {err_a.max():.2f} m"
    )
    assert len(err_a) >= 700
    assert np.max(err_a) < 1.5 and np.median(err_a) < 1.0


def test_truncated_and_corrupted_copies_of_the_real_tlog(tmp_path, real_replay):
    full, _ = real_replay
    data = SHARED_TLOG.read_bytes()
    offs = record_offsets(data)
    half = offs[12000][1] // 2
    cut = offs[12000][0] + half  # record 12000 loses its tail: ~half of the flight is readable
    (tmp_path / "cut.tlog").write_bytes(data[:cut])
    res = replay(tmp_path / "cut.tlog", load_config(REPLAY_CFG))
    assert res.records == 12000 and res.truncated_tail_bytes == half and res.skipped_regions == 1
    assert 0.4 * full.steps < res.steps < 0.6 * full.steps
    assert (
        f"1 corrupt stretches skipped ({half} bytes, {half} of them a cut-off tail)"
        in res.summary()
    )
    # three ATTITUDE records corrupted (a payload byte): exactly those samples are lost
    atts = records_of(data, "ATTITUDE")
    bad = bytearray(data)
    for k in (atts[100], atts[400], atts[700]):
        o, _ = offs[k]
        bad[o + 8 + 8] ^= 0x5A
    (tmp_path / "bad.tlog").write_bytes(bytes(bad))
    res = replay(tmp_path / "bad.tlog", load_config(REPLAY_CFG))
    assert (res.records, res.skipped_regions) == (23894 - 3, 3)
    assert res.attitude_samples == full.attitude_samples - 3
    assert full.steps - 3 <= res.steps <= full.steps
    assert "3 corrupt stretches skipped" in res.summary()


# ----------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("run", ["px4_run", "arduplane_run"])
def test_bridge_tlog_replays_to_identical_commands(run, request, tmp_path):
    cfg, res, peer, out = request.getfixturevalue(run)
    rp = replay(out / "mavlink.tlog", cfg, out_dir=tmp_path / "replay", plots=False)
    print(rp.summary())
    c = rp.check
    n = res.counters
    assert c.markers and rp.origin == "MPF markers of the bridge"
    # every setpoint the bridge sent is in the tlog and is explained
    assert c.sent == n["setpoints_sent"] == len(peer.setpoints)
    assert c.compared + c.resent + c.safe == c.sent
    assert c.compared == n["law_evals"]  # one command per control step
    # the bridge counts a hand-back setpoint both as safe and as re-sent (it goes out on the
    # re-send timer): the replay tells them apart
    assert c.safe == n["safe_setpoints"] >= 3 and c.resent == n["setpoints_resent"] - c.safe
    assert c.differing == c.unexplained == c.unsent_steps == 0 and c.identical
    assert c.max_diff <= TOLERANCE
    print(f"round trip ({run}): {c.compared} commands, max |diff| {c.max_diff!r}")
    # what was recorded during TRACKING is what the replay computed at the same instants
    ts_b = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    ts_r = np.genfromtxt(tmp_path / "replay" / "timeseries.csv", delimiter=",", names=True)
    rows = np.searchsorted(ts_r["t"], ts_b["t"])
    assert np.array_equal(ts_r["t"][rows], ts_b["t"])
    for k in ("s", "sdot", "pt_norm", "psi", "w2_cmd", "w3_cmd"):
        np.testing.assert_allclose(ts_r[k][rows], ts_b[k], rtol=0, atol=1e-7, err_msg=k)
    # and the commands clipped at a limit (the envelope monitor's word): the same steps
    assert np.array_equal(ts_r["saturated"][rows], ts_b["saturated"])


def test_px4_low_rate_run_had_resends(px4_run):
    _, res, _, _ = px4_run
    # at 12.5 Hz telemetry the bridge fills the gaps to keep >= 20 Hz: the round trip above
    # therefore covers re-sends as well as commands and safe setpoints
    assert res.counters["setpoints_resent"] >= 20


def test_markers_are_exact_and_short():
    for t0, s0 in ((100.514, 471.23889772899196), (0.1 + 0.2, -1e-300), (123456789.123, 1.0 / 3.0)):
        texts = origin_texts(t0, s0)
        assert all(len(x) <= 50 for x in texts)
        assert [parse_marker(x) for x in texts] == [("t0", t0), ("s0", s0)]
    assert (
        parse_marker("MPF stream") == ("stream", None)
        and parse_marker("EKF2 IMU0 switching") is None
    )


def _tamper_sat(data: bytes, k_rec: int, thrust_delta: float) -> tuple[bytes, float]:
    """Re-pack the SET_ATTITUDE_TARGET of record k with a different thrust (valid CRC)."""
    o, n = record_offsets(data)[k_rec]
    mav = mavlink.MAVLink(None)
    m = mav.decode(bytearray(data[o + 8 : o + n]))
    packer = mavlink.MAVLink(None, srcSystem=m.get_srcSystem(), srcComponent=m.get_srcComponent())
    packer.seq = m.get_seq()
    m.thrust = float(m.thrust) + thrust_delta
    buf = bytes(m.pack(packer))
    new = mav.decode(bytearray(buf)).thrust
    return data[:o] + data[o : o + 8] + buf + data[o + n :], new


def test_a_tampered_tlog_names_the_first_differing_message(tmp_path, px4_run):
    cfg, _, _, out = px4_run
    data = (out / "mavlink.tlog").read_bytes()
    sats = records_of(data, "SET_ATTITUDE_TARGET", (1, 191))
    offs = record_offsets(data)
    mav = mavlink.MAVLink(None)
    tb = [mav.decode(bytearray(data[offs[j][0] + 8 : sum(offs[j])])).time_boot_ms for j in sats]
    # a command, not a re-send: the first SET_ATTITUDE_TARGET of the second half with a new time
    k = next(i for i in range(len(sats) // 2, len(sats)) if tb[i] != tb[i - 1])
    tampered, new_thrust = _tamper_sat(data, sats[k], 0.01)
    (tmp_path / "t.tlog").write_bytes(tampered)
    rp = replay(tmp_path / "t.tlog", cfg)
    c = rp.check
    assert not c.identical and c.differing == 1 and c.unexplained == 0
    first = c.first_difference or ""
    assert first.startswith(f"SET_ATTITUDE_TARGET #{k + 1} (tlog record {sats[k]},")
    assert f"thrust recorded {new_thrust!r}, replayed" in first
    # re-sends of that setpoint (if any) differ from the tampered copy: counted, not hidden
    assert "DIFFERENT" in rp.summary()


def test_a_different_config_names_the_first_differing_message(tmp_path, capsys, arduplane_run):
    cfg, _, _, out = arduplane_run
    cfg_file = ROOT / "configs" / "bridge_arduplane.yaml"
    rc = main(
        [
            "replay",
            str(out / "mavlink.tlog"),
            "--config",
            str(cfg_file),
            *sum((["--set", s] for s in FAST), []),
            "--set",
            "guidance.K_R=0.6",
            # a loaded machine can leave the short recorded flight far off the path with every
            # command at the rate limit, where K_R changes nothing: the limit changes those
            "--set",
            "guidance.rate_limit_rad_s=0.3",
            "--out",
            str(tmp_path / "r"),
            "--no-plots",
            "-q",
        ]
    )
    text = capsys.readouterr().out
    assert rc == 1, text
    line = next(x for x in text.splitlines() if x.startswith("commands"))
    assert (
        "DIFFERENT" in line
        and "first: SET_ATTITUDE_TARGET #" in line
        and "recorded" in line
        and "replayed" in line
    )
    # the same config replays identically through the command line (exit 0)
    rc = main(
        [
            "replay",
            str(out / "mavlink.tlog"),
            "--config",
            str(cfg_file),
            *sum((["--set", s] for s in FAST), []),
            "--out",
            str(tmp_path / "same"),
            "--no-plots",
            "-q",
        ]
    )
    assert rc == 0 and "identical:" in capsys.readouterr().out


def test_truncated_and_corrupted_copies_of_a_bridge_tlog(tmp_path, px4_run):
    cfg, _, _, out = px4_run
    data = (out / "mavlink.tlog").read_bytes()
    offs = record_offsets(data)
    full = replay(out / "mavlink.tlog", cfg).check
    # cut inside a record after ~60 % of the file: what is readable replays identically
    k = int(0.6 * len(offs))
    (tmp_path / "cut.tlog").write_bytes(data[: offs[k][0] + 5])
    rp = replay(tmp_path / "cut.tlog", cfg)
    assert rp.truncated_tail_bytes == 5 and rp.records == k
    assert rp.check.identical and 0 < rp.check.compared < full.compared
    # a bridge killed there: its mapped tlog (tlog.MAP_BYTES) ends in zeros after the records
    (tmp_path / "killed.tlog").write_bytes(data[: offs[k][0]] + bytes(40_000))
    rp = replay(tmp_path / "killed.tlog", cfg)
    assert (rp.records, rp.skipped_regions, rp.skipped_bytes, rp.zero_tail_bytes) == (
        k,
        0,
        0,
        40_000,
    )
    assert rp.check.identical and 0 < rp.check.compared < full.compared
    assert "then 40000 zero bytes: the writer was killed" in rp.summary()
    # our own HEARTBEATs corrupted: skipped, counted, nothing else changes
    hbs = records_of(data, "HEARTBEAT", (1, 191))[:2]
    bad = bytearray(data)
    for j in hbs:
        bad[offs[j][0] + 8 + 11] ^= 0xFF
    (tmp_path / "hb.tlog").write_bytes(bytes(bad))
    rp = replay(tmp_path / "hb.tlog", cfg)
    assert rp.skipped_regions == 2 and rp.check.identical and rp.check.compared == full.compared


def test_a_lost_command_record_is_reported(tmp_path, arduplane_run):
    # 50 Hz telemetry: no re-sends while tracking, so a lost command is not covered by a copy
    cfg, _, _, out = arduplane_run
    data = (out / "mavlink.tlog").read_bytes()
    offs = record_offsets(data)
    sats = records_of(data, "SET_ATTITUDE_TARGET", (1, 191))
    bad = bytearray(data)
    bad[offs[sats[40]][0] + 8 + 12] ^= 0xFF  # a payload byte: the CRC fails, the record is lost
    (tmp_path / "sat.tlog").write_bytes(bytes(bad))
    rp = replay(tmp_path / "sat.tlog", cfg)
    assert rp.skipped_regions == 1 and not rp.check.identical and rp.check.unsent_steps == 1
    first = rp.check.first_difference or ""
    assert (
        first.startswith("before SET_ATTITUDE_TARGET #41 (tlog record")
        and "1 replayed control step(s) were never sent" in first
    )


# ----------------------------------------------------------------------------- command line
def test_cli_errors_are_one_line_and_nonzero(tmp_path, capsys):
    cases = [
        ([str(tmp_path / "missing.tlog")], "no such tlog file"),
        ([str(REPLAY_CFG)], "not a tlog"),  # a YAML file is no tlog
        ([str(SHARED_TLOG), "--from", "50", "--to", "40"], "bad window"),
        ([str(SHARED_TLOG), "--from", "500"], "bad window"),
    ]
    for args, want in cases:
        rc = main(
            ["replay", *args, "--config", str(REPLAY_CFG), "--out", str(tmp_path / "o"), "-q"]
        )
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and want in err[0], (args, err)
        assert not (tmp_path / "o").exists()  # no empty run directory left behind
    with pytest.raises(SystemExit) as e:
        main(["replay", str(SHARED_TLOG), "--config", str(REPLAY_CFG), "--from", "-3"])
    assert e.value.code == 2


@pytest.mark.slow  # among the longest of the quick loop (CPU or real time): full suite (CI) only
def test_cli_window_and_plot_of_any_run(tmp_path, arduplane_run):
    _, _, _, bridge_out = arduplane_run
    out = tmp_path / "w"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "mpf_mavlink.cli",
            "replay",
            str(SHARED_TLOG),
            "--config",
            str(REPLAY_CFG),
            "--from",
            "85",
            "--to",
            "123",
            "--out",
            str(out),
            "--no-plots",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=dict(os.environ),
    )
    assert r.returncode == 0, r.stderr
    for want in (
        "duration          207.61 s; window 85.00 .. 123.00 s",
        "GUIDED 85.0-123.4 s",
        "telemetry gaps",
        "ATTITUDE",
        "median |pt|",
        "commands          no SET_ATTITUDE_TARGET",
    ):
        assert want in r.stdout, want
    ts = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    assert 120 <= len(ts) <= 160  # ~38 s of ~4 Hz samples
    # `plot` re-draws a replay directory and a bridge run directory alike
    for d in (out, bridge_out):
        assert main(["plot", str(d)]) == 0
        for f in (
            "trajectory_3d.png",
            "planar.png",
            "errors.png",
            "sdot_rates.png",
            "setpoints.png",
        ):
            assert (d / f).is_file(), (d, f)


def test_markers_in_a_bridge_tlog(px4_run):
    _, _, _, out = px4_run
    r = read_tlog(out / "mavlink.tlog", types=["STATUSTEXT"])
    texts = [m.text for _, m in r if (m.get_srcSystem(), m.get_srcComponent()) == (1, 191)]
    marks = [parse_marker(x) for x in texts]
    assert [mk[0] for mk in marks if mk is not None] == ["t0", "s0", "stream"]
    # the rest is what an operator's ground station shows (bridge/operator.py), never a marker
    assert all(x.startswith("MPF: ") for x, mk in zip(texts, marks, strict=True) if mk is None)


def test_live_target_round_trip_is_bit_identical(tmp_path):
    """A live FOLLOW_TARGET: its samples are stamped with the receive times (the tlog's record
    times, in us), re-stamped at the origin and extrapolated to each control time. Any
    difference between the receive time the bridge used and the record time would move the
    target and show in the commands: they are equal to the last bit."""
    import threading
    import time

    cfg = bridge_cfg("px4", "target.type=mavlink", "mavlink.target_sysid=42")
    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", send_global=True), port=port).start()
    stop = threading.Event()

    def target() -> None:
        t0 = time.monotonic()
        while not stop.is_set():
            t = time.monotonic() - t0
            lat, lon, alt = ned_to_geodetic((0.0, 3.0 * t, -100.0), *peer.o.home)
            peer.send_as(42, mavlink.MAVLink_follow_target_message(
                int(t * 1000), 3, int(lat * 1e7), int(lon * 1e7), alt, [0.0, 3.0, 0.0], [0.0] * 3,
                [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3, 0))  # fmt: skip
            time.sleep(0.05)

    threading.Thread(target=target, daemon=True).start()
    try:
        res = run_bridge(
            cfg,
            BridgeOptions(url=f"udpin:127.0.0.1:{port}", out_dir=tmp_path, duration_s=1.0),
            log=lambda s: None,
        )
    finally:
        stop.set()
        peer.stop()
    assert res.exit_code == NOT_JUDGED, res.exit_reason
    rp = replay(tmp_path / "mavlink.tlog", cfg)
    c = rp.check
    assert c.identical and c.compared == res.counters["law_evals"] >= 40
    assert c.max_diff == 0.0
    assert rp.counts["FOLLOW_TARGET"] >= 20


def test_noisy_late_out_of_order_target_replays_bit_identically(tmp_path):
    """A live target as a radio delivers it: 5 Hz fixes with 2 m noise, FOLLOW_TARGET and
    GLOBAL_POSITION_INT of each fix, every third pair held back behind the next one (out of
    order), a 100 s offset between the target's clock and ours. The estimator re-orders,
    de-duplicates and fuses them from the reports' own stamps and the tlog's receive times;
    the replay, fed the same records, re-runs it to the same commands, bit for bit."""
    import threading
    import time

    cfg = bridge_cfg(
        "px4", "target.type=mavlink", "mavlink.target_sysid=42", "target_estimator.latency_s=0.05"
    )
    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", send_global=True), port=port).start()
    stop = threading.Event()
    rng = np.random.default_rng(11)

    def frames(t: float) -> list[Any]:
        n, e = rng.normal(0.0, 2.0, 2)
        lat, lon, alt = ned_to_geodetic((n, 3.0 * t + e, -100.0), *peer.o.home)
        ms = int((t + 100.0) * 1000)
        return [
            mavlink.MAVLink_follow_target_message(
                ms, 3, int(lat * 1e7), int(lon * 1e7), alt, [0.0, 3.0, 0.0], [0.0] * 3,
                [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3, 0),
            mavlink.MAVLink_global_position_int_message(
                ms, int(lat * 1e7), int(lon * 1e7), int(alt * 1000), int(alt * 1000), 0, 300, 0,
                65535),
        ]  # fmt: skip

    def target() -> None:
        t0 = time.monotonic()
        held: list[Any] = []
        k = 0
        while not stop.is_set():
            out = frames(time.monotonic() - t0)
            if k % 3 == 0:
                held = out  # sent after the next fix
            else:
                for m in out + held:
                    peer.send_as(42, m)
                held = []
            k += 1
            time.sleep(0.2)

    threading.Thread(target=target, daemon=True).start()
    try:
        res = run_bridge(
            cfg,
            BridgeOptions(url=f"udpin:127.0.0.1:{port}", out_dir=tmp_path, duration_s=1.5),
            log=lambda s: None,
        )
    finally:
        stop.set()
        peer.stop()
    assert res.exit_code == NOT_JUDGED, res.exit_reason
    rp = replay(tmp_path / "mavlink.tlog", cfg)
    c = rp.check
    assert c.identical and c.compared == res.counters["law_evals"] >= 40
    assert c.max_diff == 0.0
    te = rp.metrics["replay"]["target_estimator"]
    # every fix twice (one a duplicate), some of them late: the filter saw all three cases
    assert te["fused"] >= 5 and te["duplicate"] >= 5 and te["out_of_order"] >= 1, te


def test_replay_points_to_the_runs_own_config_when_the_markers_disagree(tmp_path: Path) -> None:
    # a SIL run's bridge flies with the SIL's overrides, so its tlog replayed with the YAML the
    # run started from disagrees at the s0 marker; the run directory holds the config it flew
    from mpf_mavlink.cli.replay import _config_hint

    tlog, own = tmp_path / "mavlink.tlog", tmp_path / "config.yaml"
    tlog.write_bytes(b"")
    other = tmp_path / "other.yaml"
    disagree = [
        "the bridge took s0 = 1.0 m, this config gives 2.0 m: the tlog and the code/config disagree"
    ]
    assert _config_hint(tlog, other, disagree) is None  # no config beside the tlog
    own.write_text("name: x\n")
    hint = _config_hint(tlog, other, disagree)
    assert hint is not None and str(own) in hint
    assert _config_hint(tlog, own, disagree) is None  # already replayed with it
    assert _config_hint(tlog, other, []) is None  # nothing disagreed


def test_a_tlog_without_the_configured_vehicle_says_nothing_was_replayed() -> None:
    # the real tlog's autopilot is system 1: told to expect system 7, the replay never sees its
    # HEARTBEAT, steps nothing and says which key to check
    cfg = load_config(REPLAY_CFG, ["mavlink.vehicle_sysid=7"])
    res = replay(SHARED_TLOG, cfg)
    assert res.steps == 0
    assert any("no autopilot HEARTBEAT from system 7" in n for n in res.notes), res.notes
