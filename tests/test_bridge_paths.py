"""Bridge paths beyond the basic life cycle, against the scripted autopilot of tests/mav_peer.py
on real loopback UDP: arming, a live target sent as GLOBAL_POSITION_INT + ATTITUDE, telemetry
as ATTITUDE_QUATERNION, GLOBAL_POSITION_INT-only position and the bridge's own wind estimate.

Missions are short (0.5 - 1 s of TRACKING); each run takes about 3 s.
"""

from __future__ import annotations

import math
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from mav_peer import MavPeer, PeerOptions  # noqa: E402

from mpf_mavlink.bridge.base import BridgeOptions, BridgeResult  # noqa: E402
from mpf_mavlink.bridge.live import run_bridge  # noqa: E402
from mpf_mavlink.config import bridge as bridge_config  # noqa: E402,F401
from mpf_mavlink.config.schema import Config, load_config  # noqa: E402
from mpf_mavlink.core.frames import ned_to_geodetic  # noqa: E402
from mpf_mavlink.mavlink import dialect as mavlink  # noqa: E402
from mpf_mavlink.mavlink import mavutil  # noqa: E402

# a lifecycle flight of seconds has no steady window: it ends NOT JUDGED (exit 6), not PASS
from mpf_mavlink.runs.verdict import EXIT_NOT_JUDGED as NOT_JUDGED  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FAST = ["mavlink.plots=false", "mavlink.heartbeat_timeout_s=3", "mavlink.mode_timeout_s=0.6",
        "mavlink.request_streams=false", "mavlink.set_fallback=false"]  # fmt: skip
ARM, SET_MODE = 400, 176


# ----------------------------------------------------------------------------- helpers
def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def cfg_for(flavour: str, *overrides: str) -> Config:
    name = "bridge_px4.yaml" if flavour == "px4" else "bridge_arduplane.yaml"
    return load_config(ROOT / "configs" / name, [*FAST, *overrides])


def fly(
    cfg: Config, port: int, out: Path, duration: float, during: Any = None, **opts: Any
) -> tuple[BridgeResult, list[str]]:
    """run_bridge in this (main) thread against udpin:127.0.0.1:port; ``during`` runs in a
    daemon thread meanwhile. Returns the result and the bridge's log lines."""
    if during is not None:
        threading.Thread(target=during, daemon=True).start()
    log: list[str] = []
    url = f"udpin:127.0.0.1:{port}"
    bopts = BridgeOptions(url=url, out_dir=out, duration_s=duration, **opts)
    return run_bridge(cfg, bopts, log=log.append), log


def commands(peer: MavPeer, cmd: int) -> list[Any]:
    return [c for c in peer.commands if c.msg.command == cmd]


def read_tlog(path: Path) -> list[Any]:
    tl = mavutil.mavlink_connection(str(path))
    out = []
    while (m := tl.recv_match()) is not None:
        out.append(m)
    return out


def table(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True)


def align_to_truth(ts: np.ndarray, truth: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of timeseries.csv matched to the peer's telemetry ticks.

    Row times are ``time_boot_ms / 1000 - t0`` (the bridge's mission time); t0 is not
    recorded, so try every tick as the first row's and keep the offset that maps every row onto
    a tick with the smallest position error. Returns (truth positions, truth attitudes (roll,
    pitch, yaw), max position error) per row."""
    by_tb = {tb: (pos, rpy) for tb, pos, rpy in truth}
    t_ms = np.round(ts["t"] * 1000.0).astype(int)
    p = np.column_stack([ts["p_n"], ts["p_e"], ts["p_d"]])
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for tb0 in by_tb:
        off = tb0 - t_ms[0]
        hits = [by_tb.get(int(off + m)) for m in t_ms]
        if any(h is None for h in hits):
            continue
        P = np.array([h[0] for h in hits])
        err = float(np.max(np.linalg.norm(p - P, axis=1)))
        if best is None or err < best[0]:
            best = (err, P, np.array([h[1] for h in hits]))
    assert best is not None, "no alignment of the time series with the peer's ticks"
    return best[1], best[2], np.linalg.norm(p - best[1], axis=1)


# ----------------------------------------------------------------------------- arming
def test_cli_arm_arms_after_prestream_and_before_the_mode_request(tmp_path, capsys):
    from mpf_mavlink.cli.main import main

    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", start_armed=False), port=port).start()
    try:
        rc = main(
            ["run", str(ROOT / "configs/bridge_px4.yaml"), "--connect", f"udpin:127.0.0.1:{port}",
             "--out", str(tmp_path), "--duration", "0.5", "--arm", "--no-plots", "-q",
             *[a for kv in FAST for a in ("--set", kv)]]
        )  # fmt: skip
    finally:
        peer.stop()
    out = capsys.readouterr().out
    assert rc == NOT_JUDGED, out
    assert peer.armed
    # exactly: ARM (param1 = 1, not forced), OFFBOARD, then the hold mode
    cmds = [c.msg for c in peer.commands]
    assert [c.command for c in cmds] == [ARM, SET_MODE, SET_MODE]
    arm = cmds[0]
    assert (arm.param1, arm.param2, arm.target_system, arm.target_component) == (1.0, 0.0, 1, 1)
    assert [c.param2 for c in cmds[1:]] == [6.0, 4.0]
    # the ARM comes after >= 1 s of pre-streamed setpoints ...
    t_arm = peer.commands[0].t
    before = [s.t for s in peer.setpoints if s.t < t_arm]
    assert before and before[-1] - before[0] >= 1.0 - 0.01  # the bridge's clock: >= 1 s
    # ... and the mode request only after the vehicle's HEARTBEAT said "armed" (tlog order)
    kinds = []
    for m in read_tlog(tmp_path / "mavlink.tlog"):
        if m.get_type() == "COMMAND_LONG":
            kinds.append("arm" if m.command == ARM else "mode")
        elif (
            m.get_type() == "HEARTBEAT"
            and m.get_srcSystem() == 1
            and m.autopilot != mavlink.MAV_AUTOPILOT_INVALID
            and m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        ):
            kinds.append("armed")
    assert kinds.index("arm") < kinds.index("armed") < kinds.index("mode")


@pytest.mark.parametrize("arm_result", ["MAV_RESULT_DENIED", "MAV_RESULT_ACCEPTED"])
def test_vehicle_that_never_arms_is_refused_without_a_mode_request(tmp_path, arm_result):
    port = free_port()
    opts = PeerOptions(flavour="px4", start_armed=False, arm_result=getattr(mavlink, arm_result))
    peer = MavPeer(opts, port=port).start()
    try:
        cfg = cfg_for("px4", "mavlink.mode_timeout_s=0.3")  # waits mode_timeout * retries
        res, log = fly(cfg, port, tmp_path, 1.0, arm=True)
        n = len(peer.setpoints)
        time.sleep(0.3)
        assert len(peer.setpoints) == n, "still streaming after giving up"
    finally:
        peer.stop()
    assert res.exit_code == 4 and "did not arm" in res.exit_reason, log
    assert res.state_reached == "PRESTREAM" and not res.engaged
    assert len(commands(peer, ARM)) == 1 and commands(peer, SET_MODE) == []
    assert not res.handback_requested  # never took control: nothing to hand back
    assert not peer.armed and peer.mode_is("POSCTL")
    waited = max(s.t for s in peer.setpoints) - commands(peer, ARM)[0].t
    if arm_result == "MAV_RESULT_DENIED":
        # a refusal ends the wait at once and names the autopilot's answer
        assert "ARM refused (MAV_RESULT_DENIED)" in res.exit_reason, res.exit_reason
        assert waited <= 0.3
    else:
        # accepted but never armed: it waited for the armed HEARTBEAT as configured (3 x 0.3 s)
        assert "no armed HEARTBEAT" in res.exit_reason, res.exit_reason
        assert 0.9 - 0.1 <= waited <= 0.9 + 0.15


def test_no_arming_by_default(tmp_path):
    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", start_armed=False), port=port).start()
    try:
        res, log = fly(cfg_for("px4"), port, tmp_path, 0.5)
    finally:
        peer.stop()
    assert commands(peer, ARM) == [] and not peer.armed
    # arming is the operator's business: the life cycle runs as usual without it
    assert (res.exit_code, res.state_reached) == (NOT_JUDGED, "TRACKING"), log
    assert [c.msg.param2 for c in commands(peer, SET_MODE)] == [6.0, 4.0]


# ----------------------------------------------------------------------------- live target
TARGET_SYSID = 42
TARGET_START = (60.0, -40.0, -100.0)  # NED about home (m)
TARGET_VEL = (0.0, 3.0, 0.0)  # moving East at 3 m/s ...
TARGET_YAW = 1.2  # ... while its ATTITUDE says yaw 1.2 rad (68.8 deg): crabbing


def _target_sender(
    peer: MavPeer,
    stop: threading.Event,
    sent: list[float],
    stop_after: Any = None,
    att_until: Any = None,
):
    """The target as its own system: ATTITUDE then GLOBAL_POSITION_INT at 20 Hz, its own clock.
    ``stop_after()`` true: fall silent; ``att_until()`` false: GLOBAL_POSITION_INT only."""

    def run() -> None:
        t0 = time.monotonic()
        while not stop.is_set():
            if stop_after is not None and stop_after():
                return
            t = time.monotonic() - t0
            ned = [TARGET_START[i] + TARGET_VEL[i] * t for i in range(3)]
            lat, lon, alt = ned_to_geodetic(ned, *peer.o.home)
            tb = int(t * 1000) + 5000
            if att_until is None or att_until():
                peer.send_as(
                    TARGET_SYSID,
                    mavlink.MAVLink_attitude_message(tb, 0.0, 0.0, TARGET_YAW, 0.0, 0.0, 0.0),
                )
            peer.send_as(TARGET_SYSID, mavlink.MAVLink_global_position_int_message(
                tb, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
                int(round(-ned[2] * 1000)), 0, 300, 0, 9000))  # fmt: skip
            sent.append(time.monotonic())
            time.sleep(0.05)

    return run


def _after_offboard(peer: MavPeer, delay_s: float) -> Any:
    """A predicate: true until ``delay_s`` after the peer first reports its offboard mode."""
    t_off: list[float] = []

    def before() -> bool:
        if not t_off and peer.in_offboard():
            t_off.append(time.monotonic() + delay_s)
        return not t_off or time.monotonic() <= t_off[0]

    return before


def _rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_live_target_from_global_position_int_and_attitude(tmp_path):
    """The target sends ATTITUDE + GLOBAL_POSITION_INT, then (0.3 s after OFFBOARD) only
    GLOBAL_POSITION_INT: the path frame follows its ATTITUDE while that is fresh
    (target_timeout_s = 1 s), then its velocity heading."""
    port = free_port()
    # send_global: the vehicle's HOME_POSITION gives the geodetic origin for the target
    peer = MavPeer(PeerOptions(flavour="px4", send_global=True), port=port).start()
    stop, sent = threading.Event(), []
    sender = _target_sender(peer, stop, sent, att_until=_after_offboard(peer, 0.3))
    try:
        cfg = cfg_for("px4", "target.type=mavlink", f"mavlink.target_sysid={TARGET_SYSID}")
        res, log = fly(cfg, port, tmp_path, 2.0, sender)
    finally:
        stop.set()
        peer.stop()
    assert (res.exit_code, res.state_reached, res.handback_confirmed) == (
        NOT_JUDGED,
        "TRACKING",
        True,
    ), log
    assert res.counters["rejected_sysid"] == 0  # the target's system id is let in
    ts = table(tmp_path / "timeseries.csv")
    assert len(ts) >= 30
    # the target's position reached the law: North and Down fixed, East advancing at 3 m/s,
    # extrapolated between its 20 Hz samples (not a staircase) to each control time
    np.testing.assert_allclose(ts["tgt_n"], TARGET_START[0], atol=0.05)
    np.testing.assert_allclose(ts["tgt_d"], TARGET_START[2], atol=0.05)
    slope = np.polyfit(ts["t"], ts["tgt_e"], 1)[0]
    assert slope == pytest.approx(3.0, abs=0.15)
    rate = np.diff(ts["tgt_e"]) / np.diff(ts["t"])
    assert np.median(rate) == pytest.approx(3.0, abs=0.3)
    # the path frame: the target's ATTITUDE (yaw 1.2) first, then its velocity heading (pi/2)
    d = np.column_stack([ts["p_n"] - ts["tgt_n"], ts["p_e"] - ts["tgt_e"], ts["p_d"] - ts["tgt_d"]])
    rel = np.column_stack([ts["rel_x"], ts["rel_y"], ts["rel_z"]])
    by_att = np.linalg.norm(rel - d @ _rot_z(TARGET_YAW), axis=1) < 1e-3
    by_vel = np.linalg.norm(rel - d @ _rot_z(math.pi / 2), axis=1) < 1e-3
    assert np.all(by_att ^ by_vel)  # each row is exactly one of the two
    n_att = int(np.argmin(by_att)) if not by_att.all() else len(ts)
    assert n_att >= 20 and np.all(by_att[:n_att]) and np.all(by_vel[n_att:])
    assert len(ts) - n_att >= 15, "the stale target ATTITUDE was still used"


@pytest.mark.slow  # > 6 s of real-time flight: full suite (CI), not the quick loop
def test_stale_live_target_stops_the_mission_and_says_so(tmp_path):
    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", send_global=True), port=port).start()
    stop, sent = threading.Event(), []
    before = _after_offboard(peer, 0.3)  # the target falls silent 0.3 s after OFFBOARD
    sender = _target_sender(peer, stop, sent, stop_after=lambda: not before())
    try:
        cfg = cfg_for("px4", "target.type=mavlink", f"mavlink.target_sysid={TARGET_SYSID}")
        res, log = fly(cfg, port, tmp_path, 30.0, sender)
    finally:
        stop.set()
        peer.stop()
    assert res.exit_code == 4, log
    assert "live target stale" in res.exit_reason and "stopped commanding" in res.exit_reason
    assert res.state_reached == "TRACKING"
    # the hold mode is requested and confirmed after the stop
    assert [c.msg.param2 for c in commands(peer, SET_MODE)] == [6.0, 4.0]
    assert res.handback_requested and res.handback_confirmed and peer.mode_is("AUTO.LOITER")
    # timing: the target estimator refuses the target once its predicted uncertainty passes
    # max_position_sigma_m (4 m): sigma_0 + a tau^2 / 2 with a = manoeuvre_accel_m_s2 (0.3),
    # so no later than sqrt(2 x 4 / a) = 5.16 s whatever sigma_0, and not before
    # sqrt(2 (4 - 2) / a) = 3.65 s while sigma_0 of a target seen at 20 Hz stays below 2 m.
    # Commands went on until then and none outlived the staleness by more than
    # telemetry_timeout_s (0.5), give or take a scheduling stall of the test's own peer thread
    # (0.15 s seen on a loaded CI box)
    lo, hi = math.sqrt(2.0 * (4.0 - 2.0) / 0.3), math.sqrt(2.0 * 4.0 / 0.3)
    last_target = sent[-1]
    offboard_sp = [s.t for s in peer.setpoints if (s.mode >> 16) & 0xFF == 6]
    assert max(offboard_sp) >= last_target + lo
    assert max(s.t for s in peer.setpoints) <= last_target + hi + 0.5 + 0.3
    # and the vehicle's telemetry never stopped: it was the target that went stale
    assert peer.last_telemetry_t > max(s.t for s in peer.setpoints)


# ----------------------------------------------------------------------------- telemetry
def test_attitude_quaternion_telemetry_runs_the_full_lifecycle(tmp_path):
    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", attitude_quaternion=True), port=port).start()
    try:
        # without delay compensation the adapter acts on the attitude as received (with it, on
        # the attitude predicted to when the setpoint acts: tests/test_delay.py)
        res, log = fly(cfg_for("px4", "mavlink.delay_compensation=false"), port, tmp_path, 1.0)
    finally:
        peer.stop()
    assert (res.state_reached, res.exit_code, res.handback_confirmed) == (
        "TRACKING",
        NOT_JUDGED,
        True,
    ), log
    assert [c.msg.param2 for c in commands(peer, SET_MODE)] == [6.0, 4.0]
    assert res.tracked_s == pytest.approx(1.0, abs=0.05)
    types = [m.get_type() for m in read_tlog(tmp_path / "mavlink.tlog")]
    assert types.count("ATTITUDE_QUATERNION") >= 100 and types.count("ATTITUDE") == 0
    # one setpoint per ATTITUDE_QUATERNION sample (50 Hz) while tracking
    offboard = [s for s in peer.setpoints if (s.mode >> 16) & 0xFF == 6]
    assert len(offboard) >= 40
    # the attitude the bridge acted on is the peer's: the PX4 roll-rate command is
    # p = (bank_sp - roll) / tau_roll (- sin(pitch) chi_dot, < 0.005 rad here) when unclipped
    ts, sp = table(tmp_path / "timeseries.csv"), table(tmp_path / "setpoints.csv")
    assert len(ts) == len(sp) >= 40
    _, rpy, pos_err = align_to_truth(ts, peer.truth)
    assert np.max(pos_err) < 1e-3
    free = np.abs(sp["p"]) < 1.2217 - 1e-3
    assert np.sum(free) >= 20
    roll_seen = sp["bank"] - 0.5 * sp["p"]
    np.testing.assert_allclose(roll_seen[free], rpy[free, 0], atol=0.01)


def test_global_position_int_only_about_home_position(tmp_path):
    port = free_port()
    peer = MavPeer(
        PeerOptions(flavour="px4", send_local=False, send_global=True), port=port
    ).start()
    try:
        res, log = fly(cfg_for("px4"), port, tmp_path, 1.0)
    finally:
        peer.stop()
    assert (res.state_reached, res.exit_code, res.handback_confirmed) == (
        "TRACKING",
        NOT_JUDGED,
        True,
    ), log
    types = {m.get_type() for m in read_tlog(tmp_path / "mavlink.tlog")}
    assert "LOCAL_POSITION_NED" not in types and {"GLOBAL_POSITION_INT", "HOME_POSITION"} <= types
    # every control step saw the peer's position of that instant: GLOBAL_POSITION_INT comes at
    # 25 Hz, ATTITUDE at 50 Hz, so every other step is extrapolated by 20 ms (0.3 m at 15 m/s
    # if it were not); degE7 and mm quantisation are ~1 cm. The max allows for a stall of the
    # peer's thread between its samples (5 cm seen on a loaded CI box); the median cannot hide
    # a missing extrapolation
    ts = table(tmp_path / "timeseries.csv")
    assert len(ts) >= 40
    _, _, err = align_to_truth(ts, peer.truth)
    assert np.median(err) < 0.03 and np.max(err) < 0.15


def test_own_wind_estimate_without_wind_messages(tmp_path):
    wind = (4.0, -3.0, 0.0)
    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", wind_ned=wind, send_wind=False), port=port).start()
    try:
        res, log = fly(cfg_for("px4", "guidance.wind_compensation=true"), port, tmp_path, 1.0)
    finally:
        peer.stop()
    assert (res.state_reached, res.exit_code, res.handback_confirmed) == (
        "TRACKING",
        NOT_JUDGED,
        True,
    ), log
    types = {m.get_type() for m in read_tlog(tmp_path / "mavlink.tlog")}
    assert not types & {"WIND", "WIND_COV"}
    # what the law saw: the estimate from ground velocity - airspeed * body x (zero sideslip;
    # the peer's 0.02 rad pitch costs 15 (1 - cos 0.02) = 0.003 m/s), from the first row on
    ts = table(tmp_path / "timeseries.csv")
    assert len(ts) >= 40
    np.testing.assert_allclose(ts["wind_n"], wind[0], atol=0.1)
    np.testing.assert_allclose(ts["wind_e"], wind[1], atol=0.1)
    np.testing.assert_allclose(ts["wind_d"], 0.0, atol=1e-9)
    _, _, err = align_to_truth(ts, peer.truth)
    assert np.max(err) < 1e-3
