"""A lockstep SIL run seen through MAVLink's own log tools and a ground station's eyes: the tlog's
record times are the simulation's (mavflightmodes.py reports the true OFFBOARD duration), and the
bridge's guidance values (NAMED_VALUE_FLOAT) and state texts (STATUSTEXT) are in it, each batch
sent after the setpoint of the same control step.

Kinematic plant, no turbulence, 30 s of tracking: only time stamps and messages are tested.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
pytest.importorskip("pymavlink")

from pymavlink import mavutil  # noqa: E402

from mpf_mavlink.config.schema import load_config  # noqa: E402
from sim.sil import run_sil  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEMO = str(ROOT / "configs" / "default.yaml")
PX4_OFFBOARD = 6 << 16
TRACK_S = 120.0


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    cfg = load_config(
        DEMO,
        ["sil.plant=kinematic", "sil.turbulence=none", f"sim.duration_s={TRACK_S:g}",
         "metrics.steady_after_s=60"],
    )  # fmt: skip
    out = tmp_path_factory.mktemp("gcs") / "run"
    r = run_sil(cfg, out, progress=False, plots=False, log=lambda s: None)
    assert r.exit_code == 0, r.exit_reason
    return r


def offboard_truth_s(r) -> float:
    """OFFBOARD duration (s) in the plant's truth: frames in that mode x the frame period."""
    tb = r.truth["time_boot_s"][r.truth["mode"] == PX4_OFFBOARD]
    return float(tb[-1] - tb[0] + (tb[1] - tb[0]))


def tlog_messages(path: Path, types: list[str]) -> list:
    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while True:
        m = log.recv_match(type=types)
        if m is None:
            return out
        out.append(m)


def test_tlog_record_times_are_the_simulations(run):
    truth = offboard_truth_s(run)
    assert truth == pytest.approx(TRACK_S, abs=2.0)  # the mission plus engage / hand-back
    hbs = [m for m in tlog_messages(run.tlog, ["HEARTBEAT"]) if m.get_srcComponent() == 1]
    hbs = [m for m in hbs if m.get_srcSystem() == 1]
    off = [m._timestamp for m in hbs if m.custom_mode == PX4_OFFBOARD]
    after = [m._timestamp for m in hbs if m.custom_mode != PX4_OFFBOARD and m._timestamp > off[-1]]
    # first OFFBOARD heartbeat to the first one after it: the mode's span at 1 Hz heartbeats
    # (each end up to one period late, in the same direction: within 1 s of the truth)
    span = after[0] - off[0]
    assert abs(span - truth) <= 1.0, (span, truth)
    # the same from pymavlink's own tool: it prints h:mm:ss (whole seconds, truncated)
    tool = Path(sys.executable).with_name("mavflightmodes.py")
    if not tool.exists():
        pytest.skip("mavflightmodes.py is not installed next to this Python")
    text = subprocess.run([sys.executable, str(tool), str(run.tlog)], capture_output=True,
                          text=True, timeout=120).stdout  # fmt: skip
    hms = re.search(r"^OFFBOARD\s+(\d+):(\d\d):(\d\d)", text, re.M)
    assert hms is not None, text[-500:]
    reported = int(hms[1]) * 3600 + int(hms[2]) * 60 + int(hms[3])
    assert abs(reported - truth) <= 2.0, (reported, truth)  # + 1 s of truncation
    # record times never run backwards by more than a frame's untimed messages (20 ms)
    log = mavutil.mavlink_connection(str(run.tlog))
    ts = []
    while (m := log.recv_msg()) is not None:
        ts.append(m._timestamp)
    assert np.min(np.diff(ts)) > -0.021


def test_bridge_guidance_values_and_texts_reach_the_tlog_after_the_setpoint(run):
    msgs = tlog_messages(run.tlog, ["NAMED_VALUE_FLOAT", "STATUSTEXT", "SET_ATTITUDE_TARGET"])
    ours = [m for m in msgs if m.get_srcComponent() == 191]
    nvf = [m for m in ours if m.get_type() == "NAMED_VALUE_FLOAT"]
    names = {m.name for m in nvf}
    assert names == {"MPF_pt", "MPF_psi", "MPF_sdot", "MPF_state"}
    assert all(len(n) <= 10 for n in names)
    # 2 Hz of vehicle time while setpoints flow (prestream ~1.5 s, engage, tracking, hand-back)
    pt = [m for m in nvf if m.name == "MPF_pt"]
    dt = np.diff([m.time_boot_ms for m in pt]) * 1e-3
    assert np.min(dt) >= 0.5 - 0.02 - 1e-9  # never faster than 2 Hz (one 20 ms frame of grid)
    assert len(pt) >= 2.0 * TRACK_S * 0.95
    # each batch right after the setpoint answering the same ATTITUDE (same time_boot_ms)
    last_sp = None
    for m in ours:
        if m.get_type() == "SET_ATTITUDE_TARGET":
            last_sp = m.time_boot_ms
        elif m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "MPF_pt":
            assert last_sp == m.time_boot_ms
    texts = [m.text for m in ours if m.get_type() == "STATUSTEXT"]
    for s in ("MPF: PRESTREAM", "MPF: ENGAGE", "MPF: TRACKING", "MPF: HANDBACK", "MPF: DONE"):
        assert s in texts, texts
    assert any(t.startswith("MPF: stop: mission duration") for t in texts), texts
