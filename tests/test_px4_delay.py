"""The loop delay against a peer that behaves as PX4 v1.16 does in body-rate OFFBOARD: its
ATTITUDE_TARGET carries our body rates but the stamp of an attitude set-point from before
OFFBOARD, frozen; it answers TIMESYNC with its boot clock. And the attitude source chosen once
per flight (controller.py, estimator.py, boot_clock.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpf_mavlink.bridge.controller import Controller, ControlSetup
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.core.frames import euler_to_matrix
from mpf_mavlink.mavlink.boot_clock import BootClockGate
from mpf_mavlink.mavlink.codec import (
    AttitudeSample,
    AttitudeTargetSample,
    LocalPositionSample,
    TimesyncSample,
    VfrHudSample,
)

DEMO = Path(__file__).resolve().parents[1] / "configs" / "default.yaml"

# The peer's clock: PX4 boot time = our clock - BOOT (s). Latencies (s): telemetry down, the
# bridge's compute, the setpoint up; the loop delay is their sum.
BOOT = 1_700_000_000.0
DOWN, COMPUTE, UP = 0.004, 0.0015, 0.006
FROZEN_S = 3.2  # the stamp of the last attitude set-point before OFFBOARD


def _fly_px4_like(
    ctl: Controller, seconds: float, timesync: bool = True, rate: float = 1.0
) -> list[float]:
    """50 Hz ATTITUDE + LOCAL_POSITION_NED + VFR_HUD from the peer, one step per ATTITUDE, its
    setpoint 'sent' COMPUTE after receipt (note_sent with that time, as the bridge does with
    the tlog record time), a frozen-stamp ATTITUDE_TARGET echoing the rates sent, and a
    TIMESYNC answer every 0.5 s (the request leaves at our time ts, PX4 stamps it UP later on
    its clock, the answer arrives DOWN after that). ``rate``: PX4's clock runs that fast against
    ours (a lockstep SITL on a loaded host runs slow). Returns the delays in use, step by step."""
    R = euler_to_matrix(0.0, 0.0, 0.0)
    used: list[float] = []

    def ours(tb: float) -> float:  # our clock when PX4's reads tb
        return BOOT + 10.0 + (tb - 10.0) / rate

    def px4(t: float) -> float:  # PX4's clock when ours reads t
        return 10.0 + (t - BOOT - 10.0) * rate

    for k in range(round(seconds * 50)):
        tb = 10.0 + 0.02 * k  # PX4 boot time of the samples
        rx = ours(tb) + DOWN
        if timesync and k % 25 == 0:
            ts = rx - 0.01
            tc1 = px4(ts + UP)
            ctl.feed_vehicle(TimesyncSample(round(tc1 * 1e9), round(ts * 1e9)), ts + UP + DOWN)
        ctl.feed_vehicle(VfrHudSample(16.0, 16.0, 0.5, 0.0, 100.0, 0.0), rx)
        pos = np.array([0.32 * k, 0.0, -100.0])
        ctl.feed_vehicle(LocalPositionSample(tb, pos, np.array([16.0, 0.0, 0.0])), rx)
        if not ctl.feed_vehicle(AttitudeSample(tb, R, np.zeros(3)), rx):
            continue
        if ctl.t0 is None:
            ctl.set_origin()
            ctl.init_s()
        st = ctl.step()
        if st is None:
            continue
        ctl.delay.note_sent(rx + COMPUTE)
        ctl.delay.note_sent(rx + COMPUTE + 0.05)  # a re-send of the same setpoint measures nothing
        used.append(ctl.delay.delay_s)
        p, q, r = (float(np.float32(v)) for v in st.setpoint.body_rates_frd)
        ctl.feed_vehicle(AttitudeTargetSample(FROZEN_S, (p, q, r), 0.5, 128), rx + 0.008)
    return used


def test_frozen_echo_stamps_never_measure_and_timesync_does():
    """The echo's stamp never moves: every echo after the first is counted frozen and none is
    a measurement. The delay from TIMESYNC is the telemetry's age when received (DOWN), the
    bridge's time (COMPUTE) and the uplink (UP), exactly, on an asymmetric link too: the offset
    assumes half the round trip each way, and the one-way latency added back is that same half,
    so their sum is tc1 - ts1, the request's own uplink latency plus the clocks' offset."""
    ctl = Controller(ControlSetup.of(load_config(DEMO, ["mavlink.known_delay_s=0.1"])))
    used = _fly_px4_like(ctl, 4.0)
    assert not ctl.delay.delays and ctl.delay.echoes_frozen == len(used) - 1
    assert ctl.delay.delay_source() == "timesync"
    want = DOWN + COMPUTE + UP
    # float64 of times ~1.7e9 s resolve 0.24 us
    assert ctl.delay.delay_s == pytest.approx(want, abs=1e-6)
    # measured from the first step on (an answer came before it): the configured 0.1 s never used
    assert used[0] == pytest.approx(want, abs=1e-6)


def test_a_drifting_px4_clock_is_followed():
    """PX4 SITL's lockstep clock ran 1.1 % slow against the wall clock on a loaded host: the
    offset moves 11 ms per second. The fitted offset keeps the delay at the true one, on PX4's
    clock rate (DOWN + COMPUTE + UP) x rate, within 0.2 ms; the offset of the oldest answer
    kept (8 s back) would be ~90 ms off."""
    rate = 0.989
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    used = _fly_px4_like(ctl, 20.0, rate=rate)
    assert ctl.delay.delay_source() == "timesync"
    want = rate * (DOWN + COMPUTE + UP)
    assert max(abs(d - want) for d in used[-100:]) < 2e-4


def test_without_timesync_the_configured_delay_stays_and_says_so():
    ctl = Controller(ControlSetup.of(load_config(DEMO, ["mavlink.known_delay_s=0.03"])))
    used = _fly_px4_like(ctl, 1.0, timesync=False)
    assert used and all(d == 0.03 for d in used)
    assert ctl.delay.delay_source() == "mavlink.known_delay_s" and ctl.delay.echoes_frozen > 0


def test_a_moving_echo_stamp_is_preferred_over_timesync():
    """An autopilot that stamps the echo on receipt (PX4 with attitude set-points, our SIL):
    the echo measures everything, TIMESYNC is not used."""
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    _fly_px4_like(ctl, 0.5)
    ctl.est.t0 = 0.0
    ctl.delay.sent.clear()
    for k in range(9):
        ctl.delay.sent.append((50.0 + 0.02 * k, (0.1 + 0.01 * k, 0.0, 0.0)))
        rates = (float(np.float32(0.1 + 0.01 * k)), 0.0, 0.0)
        ctl.feed_vehicle(AttitudeTargetSample(50.0 + 0.02 * k + 0.013, rates, 0.5, 128), None)
    assert ctl.delay.delay_source() == "echo"
    assert ctl.delay.delay_s == pytest.approx(0.013, abs=1e-9)


def test_answers_to_other_requests_are_ignored():
    """A TIMESYNC answer whose ts1 is not a recent time of ours (another client's request, or
    PX4's own) gives a round trip outside [0, 1] s and is not used."""
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    ctl.feed_vehicle(TimesyncSample(5_000_000_000, 123_456_789), BOOT)
    ctl.feed_vehicle(TimesyncSample(5_000_000_000, round((BOOT + 5.0) * 1e9)), BOOT)
    assert not ctl.delay.timesync


def test_the_clock_gate_accepts_old_setpoint_stamps_and_counts_nothing():
    """ATTITUDE_TARGET's time is its set-point's: PX4's frozen stamp, minutes old, is consistent
    (not 'time'), never 'stale' against the previous echo, and moves nothing; a stamp ahead of
    the clock is still refused, and so is one before any clock exists."""
    g = BootClockGate()
    assert g.check("ATTITUDE_TARGET", 3.2, 1000.0) == "settling"
    for k in range(10):
        g.check("ATTITUDE", 100.0 + 0.02 * k, 1000.0 + 0.02 * k)
    assert g.off is not None
    off = g.off
    for k in range(5):
        assert g.check("ATTITUDE_TARGET", 3.2, 1000.3 + 0.02 * k) is None
    assert g.check("ATTITUDE_TARGET", 100.3, 1000.3) is None
    assert g.check("ATTITUDE_TARGET", 200.0, 1000.4) == "time"  # 100 s in the future
    assert g.off == off and g.check("ATTITUDE", 100.5, 1000.5) is None


def test_attitude_source_is_one_per_flight_whatever_the_boot_order():
    """PX4 streaming ATTITUDE and ATTITUDE_QUATERNION at 50 Hz each, on their own schedules
    (10 ms apart): the control instants are the ATTITUDE ones (50 Hz), whichever stream came
    first; with ATTITUDE_QUATERNION alone, it is the source, and stays so after the origin."""
    R = euler_to_matrix(0.0, 0.0, 0.3)
    for quat_first in (True, False):
        ctl = Controller(ControlSetup.of(load_config(DEMO)))
        steps = 0
        for k in range(100):  # 1 s
            tb = 5.0 + 0.02 * k
            pair = [("ATTITUDE_QUATERNION", tb + 0.01), ("ATTITUDE", tb)]
            if not quat_first:
                pair.reverse()
            for src, t in pair:
                steps += ctl.feed_vehicle(AttitudeSample(t, R, np.zeros(3), src), 100.0 + t)
            if k == 10:
                ctl.est.lock_attitude_source()
        assert ctl.est.att_source == "ATTITUDE"
        # the first quaternion (before any ATTITUDE) may count once; the rest never
        assert steps in (100, 101) and ctl.est.att_ignored >= 99
        assert ctl.instants.att_period_s == pytest.approx(0.02, rel=1e-6)
    ctl = Controller(ControlSetup.of(load_config(DEMO)))
    for k in range(10):
        ctl.feed_vehicle(AttitudeSample(5.0 + 0.02 * k, R, np.zeros(3), "ATTITUDE_QUATERNION"), 1.0)
    assert ctl.est.lock_attitude_source() == "ATTITUDE_QUATERNION"
    assert not ctl.feed_vehicle(AttitudeSample(6.0, R, np.zeros(3), "ATTITUDE"), 1.0)
    assert ctl.feed_vehicle(AttitudeSample(6.01, R, np.zeros(3), "ATTITUDE_QUATERNION"), 1.0)


# ----------------------------------------------------------------------------- over UDP
def test_bridge_against_a_px4_like_peer_measures_by_timesync_and_sets_a_hold(tmp_path):
    """The live bridge against tests/mav_peer.py acting as PX4 v1.16: ATTITUDE_TARGET every
    tick with a frozen stamp, TIMESYNC answered, stock COM_OBL_RC_ACT = 0 (Position) sent
    bytewise. The echoes pass the clock gate (no rejected_time) but never measure; the delay
    comes from TIMESYNC and is the loopback's (well under 50 ms on a loaded 2-core host, above
    0: the telemetry is older than its receipt); the fallback is made Hold with read-back and
    its loiter point set to the path's centre, and the summary says so."""
    import json
    import struct
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from mav_peer import MavPeer, PeerOptions
    from test_bridge import cfg_for, fly, free_port

    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", send_global=True, frozen_echo_ms=3200), port=port)
    peer.start()
    try:
        res = fly(cfg_for("px4", "mavlink.set_fallback=true"), f"udpin:127.0.0.1:{port}",
                  tmp_path, 3.0)  # fmt: skip
    finally:
        peer.stop()
    # a 3 s lifecycle flight has no steady window: NOT JUDGED (exit 6) is its right ending
    assert (res.state_reached, res.exit_code) == ("TRACKING", 6), res.exit_reason
    m = json.loads((tmp_path / "metrics.json").read_text())
    dc = m["delay_compensation"]
    assert m["counters"]["rejected_time"] == 0
    assert dc["echoes_frozen"] > 50 and dc["echoes_in_median"] == 0
    assert dc["loop_delay_source"] == "timesync" and dc["timesync_delays_in_median"] == 9
    assert 0.0 < dc["loop_delay_s"] < 0.05
    # the Hold: PARAM_SET of 5 as an INT32, bytewise, and the peer's read-back of it
    sets = [r.msg for r in peer.param_sets]
    assert [s.param_id for s in sets] == ["COM_OBL_RC_ACT"] and sets[0].param_type == 6
    assert struct.unpack("<i", struct.pack("<f", sets[0].param_value))[0] == 5
    assert peer.params["COM_OBL_RC_ACT"][0] == 5.0
    fd = m["fallback_detail"]
    assert fd["is_hold"] and fd["com_obl_rc_act_set_from"] == 0.0 and fd["loiter_centre"]
    assert "Hold (AUTO.LOITER)" in m["fallback"] and "the path's centre" in m["fallback"]
    assert "80 m CW (NAV_LOITER_RAD)" in m["fallback"] and "NAV_RCL_ACT = 2" in m["fallback"]
    assert [c.msg.command for c in peer.commands if c.msg.command == 192] == [192]
    # the delays come from the tlog (TIMESYNC answers, the setpoints' record times): a replay
    # recomputes every command bit for bit
    from mpf_mavlink.bridge.replay import replay

    cfg = cfg_for("px4", "mavlink.set_fallback=true")
    c = replay(tmp_path / "mavlink.tlog", cfg, plots=False).check
    assert c.compared == m["counters"]["law_evals"] and c.identical


def test_bridge_refuses_to_engage_when_the_hold_is_not_confirmed(tmp_path):
    """A PX4 that does not answer the parameters: the fallback cannot be made a hold, so the
    bridge never asks for OFFBOARD (exit 3, one line naming COM_OBL_RC_ACT)."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from mav_peer import MavPeer, PeerOptions
    from test_bridge import cfg_for, fly, free_port, mode_requests

    port = free_port()
    peer = MavPeer(PeerOptions(flavour="px4", px4_params=False), port=port).start()
    try:
        res = fly(cfg_for("px4", "mavlink.set_fallback=true"), f"udpin:127.0.0.1:{port}",
                  tmp_path, 3.0)  # fmt: skip
    finally:
        peer.stop()
    assert res.exit_code == 3 and "COM_OBL_RC_ACT" in res.exit_reason
    assert not mode_requests(peer) and not peer.setpoints


def test_the_fallback_line_says_what_px4_will_do():
    """px4_fallback.describe: the stock Position fallback is called what it is on a fixed-wing
    (straight on, not a hold); Hold names its radius, direction, centre and the RC-loss action;
    the RC exemptions are said when set."""
    from mpf_mavlink.bridge.px4_fallback import describe, detail

    stock = {"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 0.0, "NAV_RCL_ACT": 2.0}
    line = describe(stock)
    assert "Position mode" in line and "NOT a hold" in line and "loiter" not in line
    hold = {**stock, "COM_OBL_RC_ACT": 5.0, "NAV_LOITER_RAD": -120.0}
    line = describe(hold, set_from=0.0, centre="the path's centre X")
    assert "Hold (AUTO.LOITER)" in line and "120 m CCW" in line and "the path's centre X" in line
    assert "set by the bridge (was 0)" in line and "Return (NAV_RCL_ACT = 2)" in line
    assert "ignored in Hold" in describe({**hold, "COM_RCL_EXCEPT": 2.0})
    assert "no RC input" in describe({**hold, "COM_RC_IN_MODE": 4.0})
    assert "unknown" in describe({"COM_OF_LOSS_T": 1.0})
    d = detail(hold, 0.0, None)
    assert d["is_hold"] and not detail(stock, None, None)["is_hold"]
