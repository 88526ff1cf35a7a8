"""The bridge against a scripted ArduPlane peer that reports a strong wind (issue 40): the
pre-engage checks refuse with the measured wind; ``--force`` flies, the envelope monitor tells
the ground station (STATUSTEXT, WARNING) and its hold policy hands back (exit 4), records kept."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from mav_peer import MavPeer, PeerOptions  # noqa: E402
from test_bridge import AP_CRUISE_M_S, cfg_for, free_port  # noqa: E402

from mpf_mavlink.bridge.base import BridgeOptions  # noqa: E402
from mpf_mavlink.bridge.live import run_bridge  # noqa: E402
from mpf_mavlink.mavlink import dialect, read_tlog  # noqa: E402

# 7.7 m/s blowing south (from the north), the peer's kinematics carried by it as well; the
# target held still at the circle's centre 150 m east of the peer's start (-200, 0, -100)
WIND = (-7.7, 0.0, 0.0)
STILL = ["target.speed_m_s=0", "target.position_ned_m=[-200.0,150.0,-100.0]"]


def _peer(port: int) -> MavPeer:
    opts = PeerOptions(flavour="ardupilot", send_wind=True, wind_ned=WIND,
                       airspeed=AP_CRUISE_M_S)  # fmt: skip
    return MavPeer(opts, port=port).start()


def _fly(cfg, port: int, out: Path, duration: float, force: bool):
    return run_bridge(
        cfg,
        BridgeOptions(
            url=f"udpin:127.0.0.1:{port}", out_dir=out, duration_s=duration, force=force
        ),  # fmt: skip
        log=lambda s: None,
    )


def test_the_measured_wind_refuses_what_the_configs_calm_accepts(tmp_path):
    port = free_port()
    peer = _peer(port)
    try:
        # the checks look ahead over the mission (60 s: the downwind side of the circle)
        res = _fly(cfg_for("ardupilot", *STILL), port, tmp_path, 60.0, force=False)
        time.sleep(0.2)
    finally:
        peer.stop()
    assert res.exit_code == 3 and res.state_reached == "CHECKS"
    # the peer's WIND carries 7.7 m/s from 0 deg: the one line names it, the bank and the limit
    # (0.61 rad = 34.95 deg less the 5 deg margin)
    assert "feasibility (peak bank " in res.exit_reason
    assert "needed with the measured wind 7.7 m/s from 0 deg (WIND), limit 29.9 deg" in (
        res.exit_reason
    )
    assert "--force flies it anyway" in res.exit_reason
    assert peer.commands == [] and peer.setpoints == []  # never asked for GUIDED


@pytest.mark.slow
def test_forced_flight_reports_the_envelope_and_the_hold_policy_hands_back(tmp_path):
    # the circle's centre 300 m east of the peer (150 m off the circle): the capture turns at
    # psi_turn's 0.5 rad/s, atan(0.5 22 / 9.81 / turn gain) > 48 deg against the 35 deg limit,
    # for seconds; armed at once with a 1 s limit the policy hands back 1 s into that episode
    far = ["target.speed_m_s=0", "target.position_ned_m=[-200.0,300.0,-100.0]"]
    cfg = cfg_for("ardupilot", *far, "envelope.armed_after_s=0", "envelope.exceeded_for_s=1")
    port = free_port()
    peer = _peer(port)
    try:
        res = _fly(cfg, port, tmp_path, 20.0, force=True)
        time.sleep(0.2)
    finally:
        peer.stop()
    assert res.exit_code == 4, res.exit_reason
    assert res.exit_reason.startswith("envelope exceeded: bank beyond its limit for 1.0 s")
    assert res.handback_requested and res.handback_confirmed and peer.mode_is("LOITER")
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["forced"] == ["feasibility"] and m["checks_measured"]["wind_source"] == "WIND"
    env = m["envelope"]
    assert env["handed_back"] == res.exit_reason and env["kinds"]["bank"]["episodes"] >= 1
    # the hand-back came within one 50 Hz step of 1 s of the episode's start
    ep = next(e for e in env["episodes"] if e["kind"] == "bank")
    assert 1.0 <= ep["duration_s"] <= 1.0 + 0.05
    assert "[envelope: bank at its limit" in m["verdict"]
    # once per episode, at severity WARNING, in the tlog the run kept
    texts = [
        (msg.severity, msg.text)
        for _, msg in read_tlog(tmp_path / "mavlink.tlog", types=["STATUSTEXT"]).messages
        if msg.text.startswith("MPF envelope")
    ]
    assert any(
        msg.text == "MPF FORCED despite failed feasibility"
        for _, msg in read_tlog(tmp_path / "mavlink.tlog", types=["STATUSTEXT"]).messages
    )
    bank = [t for t in texts if t[1].startswith("MPF envelope: bank ")]
    assert bank and all(s == dialect.MAV_SEVERITY_WARNING for s, _ in texts)
    assert len([t for t in bank if "hold" not in t[1]]) == env["kinds"]["bank"]["episodes"]
    assert bank[-1][1] == "MPF envelope: bank 1s, hold"
