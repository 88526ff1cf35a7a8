"""The SIL vehicle's pieces alone (sim/vehicle/, sim/autopilot/): framing (pymavlink's, with
MAVLink.send's sequence bookkeeping), the lockstep bookkeeping, the setpoint and mode rules, the
step clock, the config and the truth record. No sockets, no plant: each piece is driven by hand."""

from __future__ import annotations

import math
import os
import time
from types import SimpleNamespace

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: E402

from mpf_mavlink.mavlink.modes import px4_custom_mode  # noqa: E402
from sim.autopilot.modes import GUIDED, LOITER, OFFBOARD, Modes, Tunables  # noqa: E402
from sim.autopilot.setpoints import PX4_OFFBOARD_MIN_STREAM_S, Setpoints  # noqa: E402
from sim.vehicle.clock import LockstepClock, StepClock  # noqa: E402
from sim.vehicle.config import TelemetryRates, VehicleConfig, stock_rates  # noqa: E402
from sim.vehicle.link import Framer, _ignored  # noqa: E402
from sim.vehicle.lockstep import Lockstep, is_mode_request  # noqa: E402
from sim.vehicle.truth import TruthRecorder  # noqa: E402


class _Sink:
    def write(self, buf: bytes) -> None:
        pass


# ------------------------------------------------------------------------------ framing
FRAMES = [
    (M.MAVLink_attitude_message, (1234, 0.1, -0.2, 3.0, 0.01, 0.0, -0.5)),
    (M.MAVLink_local_position_ned_message, (1234, 1.5, -2.0, -100.0, 16.0, 0.5, 0.0)),
    (
        M.MAVLink_global_position_int_message,
        (20, 473977420, 85455940, 588000, 100000, 1600, -5, 0, 9000),
    ),
    (M.MAVLink_heartbeat_message, (1, 12, 217, 0x03040000, 4, 3)),
    (
        M.MAVLink_follow_target_message,
        (
            1234,
            15,
            473977420,
            85455940,
            500.0,
            [1.0, 2.0, 0.0],
            [0.1, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.1],
            [0.0, 0.0, 0.0],
            7,
        ),
    ),
    (
        M.MAVLink_home_position_message,
        (
            473977420,
            85455940,
            488000,
            0.0,
            0.0,
            0.0,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            123456789,
        ),
    ),
    (M.MAVLink_attitude_target_message, (1000, 128, [1.0, 0.5, 0.0, 0.0], 0.1, 0.2, 0.3, 0.5)),
    (M.MAVLink_sys_status_message, (1, 1, 1, 100, 12600, 500, 90, 0, 0, 0, 0, 0, 0, 0, 0, 0)),
    (M.MAVLink_statustext_message, (6, b"pymavlink encodes text", 0, 0)),
    (M.MAVLink_vfr_hud_message, (0.0, 0.0, 0, 0, 0.0, 0.0)),  # all zero: one payload byte kept
]


@pytest.mark.parametrize("cls,args", FRAMES, ids=[c.msgname for c, _ in FRAMES])
def test_framer_writes_pymavlinks_bytes(cls, args):
    """The framer's bytes are pymavlink's ``MAVLink.send``'s, sequence numbers and counters
    included: a peer cannot tell the two apart."""
    for ids in ((1, 1), (2, 191)):  # the vehicle's and the target's system
        ours, ref = M.MAVLink(_Sink(), *ids), M.MAVLink(_Sink(), *ids)
        framer = Framer(ours)
        for seq in range(3):
            buf = framer.pack(cls, *args)
            assert buf == bytes(cls(*args).pack(ref)), (ids, seq)
            ref.seq = (ref.seq + 1) & 0xFF
        assert ours.seq == 3 and ours.total_packets_sent == 3


def test_datagrams_of_dropped_messages_are_counted_unparsed_and_the_rest_parsed():
    """What the vehicle drops on arrival (NAMED_VALUE_FLOAT, a HEARTBEAT) is counted frame by
    frame from the headers; a datagram with one wanted message in it, a MAVLink 1 frame, a
    fragment or trailing bytes go to pymavlink whole (0)."""
    mav = M.MAVLink(_Sink(), 255, 190)
    nvf = bytes(M.MAVLink_named_value_float_message(5, b"MPF_pt", 1.5).pack(mav))
    hb = bytes(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(mav))
    cmd = bytes(
        M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0).pack(
            mav
        )
    )
    wanted = frozenset((M.MAVLINK_MSG_ID_COMMAND_LONG, M.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET))
    assert _ignored(nvf, wanted) == 1
    assert _ignored(nvf + hb + nvf, wanted) == 3
    assert _ignored(nvf + cmd, wanted) == 0
    assert _ignored(cmd, wanted) == 0
    assert _ignored(nvf[:-1], wanted) == 0  # a fragment: pymavlink keeps its bytes
    assert _ignored(nvf + b"\x00", wanted) == 0
    assert _ignored(b"\xfe" + nvf[1:], wanted) == 0  # not MAVLink 2: pymavlink's to read
    signed = bytearray(nvf)
    signed[2] = 1  # MAVLINK_IFLAG_SIGNED: 13 bytes of signature follow, missing here
    assert _ignored(bytes(signed), wanted) == 0
    assert _ignored(bytes(signed) + bytes(13), wanted) == 1


# ------------------------------------------------------------------------------ lockstep
def test_lockstep_awaits_the_latest_attitude_that_acts_within_the_next_frame():
    """20 ms frames, 20 ms command latency: the answer to the ATTITUDE written at the end of
    frame k acts at its end + 20 ms, i.e. at the end of frame k+1 - so at the end of frame k+1
    the vehicle awaits frame k's answer (written one frame earlier), not its own."""
    ls = Lockstep(frame_period=0.02, command_latency_s=0.02)
    ls.written(1000, -1, 1.00)
    ls.choose(1.00)
    assert ls.await_ms == -1  # nothing old enough yet: the first frame is not held up
    ls.written(1020, -1, 1.02)
    ls.choose(1.02)
    assert ls.await_ms == 1000
    assert not ls.answered
    assert ls.on_answer(1000) == pytest.approx(1.00)  # its latency runs from there
    assert ls.answered and ls.answers == 1
    assert ls.on_answer(990) is None  # an answer to a frame never written: no time known
    assert ls.answer_ms == 1000  # a late answer does not move the mark back


def test_lockstep_without_overlap_awaits_the_last_attitude_whatever_the_latency():
    ls = Lockstep(frame_period=0.02, command_latency_s=0.02, overlap=False)
    for k, ms in enumerate((1000, 1020, 1040)):
        ls.written(ms, -1, 1.0 + 0.02 * k)
        ls.choose(1.0 + 0.02 * k)
        assert ls.await_ms == ms  # its own frame's answer, not an earlier one's
    assert ls.overlapped == 0
    on = Lockstep(frame_period=0.02, command_latency_s=0.02)
    for k, ms in enumerate((1000, 1020, 1040)):
        on.written(ms, -1, 1.0 + 0.02 * k)
        on.choose(1.0 + 0.02 * k)
    assert on.await_ms == 1020 and on.overlapped == 2


def test_lockstep_unstamped_peer_and_multirate_positions():
    ls = Lockstep(frame_period=0.02, command_latency_s=0.0)
    ls.written(1000, -1, 1.0)
    ls.choose(1.0)
    assert not ls.answered
    ls.on_answer(0)  # a peer that does not stamp: any answer counts
    assert ls.answered
    # a position-only frame is remembered, not awaited, until the peer answers one
    ls.written(-1, 1010, 1.01)
    ls.choose(1.01)
    assert ls.await_ms == 1000 and not ls.answers_positions
    assert ls.on_answer(1010) == pytest.approx(1.01)
    assert ls.answers_positions
    ls.written(-1, 1030, 1.03)
    ls.choose(1.03)
    assert ls.await_ms == 1030


def test_a_mode_request_ends_the_waits_until_it_is_applied():
    """The hand-back: the bridge asks for the hold mode instead of answering; the frames until
    the request is applied do not wait for answers that will not come."""
    mav = M.MAVLink(None, 255, 190)
    do_set_mode = mav.command_long_encode(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 3, 0, 0, 0, 0)
    set_mode = mav.set_mode_encode(0, 1, 12)  # target 0: any system, as the dispatcher takes it
    other = mav.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, 33, 0, 0, 0, 0, 0, 0)
    elsewhere = mav.command_long_encode(7, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 3, 0, 0, 0, 0)
    assert is_mode_request(do_set_mode, "COMMAND_LONG", 1)
    assert is_mode_request(set_mode, "SET_MODE", 1)
    assert not is_mode_request(other, "COMMAND_LONG", 1)  # not a mode change: still waits
    assert not is_mode_request(elsewhere, "COMMAND_LONG", 1)  # another vehicle's
    ls = Lockstep(frame_period=0.02, command_latency_s=0.02)
    for k, ms in enumerate((1000, 1020)):
        ls.written(ms, -1, 1.0 + 0.02 * k)
        ls.choose(1.0 + 0.02 * k)
    assert not ls.answered
    ls.on_mode_request()
    ls.on_mode_request()
    assert ls.answered
    ls.mode_request_applied()
    assert ls.answered  # one of the two still pending
    ls.mode_request_applied()
    assert not ls.answered  # both applied: the frame awaits its answer again
    ls.mode_request_applied()  # one dispatched without being read here (a test, a replay)
    assert ls.modes_pending == 0 and not ls.answered


def test_lockstep_clock_waits_long_for_an_answering_peer_and_short_after_a_timeout():
    """The first frame and every frame after an answered one wait up to answered_timeout_s;
    a frame after a timeout waits answer_timeout_s: the poll is asked for that long."""
    clock = LockstepClock(answer_timeout_s=0.01, answered_timeout_s=0.2)
    asked: list[float] = []
    answers = iter([False, False, True, False])  # the first poll of each frame

    def poll(timeout: float) -> bool:
        if timeout > 0.0:
            asked.append(timeout)
            if next(answers):
                return True
        time.sleep(timeout)  # the whole wait passes unanswered
        return False

    for k in range(4):
        clock.wait(1.0 + 0.02 * k, poll, lambda: True)
    # the bounds are the timeouts themselves: poll is asked for what is left of each
    assert 0.1 < asked[0] <= 0.2  # first frame: the peer is taken to be answering
    assert asked[1] <= 0.01  # after a timeout
    assert asked[2] <= 0.01  # still after a timeout (it answers this one)
    assert 0.1 < asked[3] <= 0.2  # after an answered frame
    assert clock.timeouts == 3 and clock.answered_frames == 1
    assert LockstepClock(answer_timeout_s=0.0).answered_timeout_s == 0.0  # free-running stays
    assert LockstepClock(answer_timeout_s=30.0).answered_timeout_s == 30.0  # never shorter


def test_lockstep_spin_ends_the_wait_on_the_answer_and_rests_after_a_run_of_misses():
    """The spin polls without a timeout until the answer (no sleeping poll is asked for then);
    SPIN_MISSES_MAX spins in a row that end without it make the next SPIN_REST_FRAMES frames
    sleep at once; a frame after a timeout never spins (the peer is not answering)."""
    clock = LockstepClock(answer_timeout_s=0.01, answered_timeout_s=0.2, spin_s=0.002)
    sleeping: list[float] = []
    spins = [0]
    answer_after = [3]  # polls without a timeout before the answer comes (None: never)

    def poll(timeout: float) -> bool:
        if timeout > 0.0:
            sleeping.append(timeout)
            return True  # the sleeping wait always gets its answer here
        spins[0] += 1
        n = answer_after[0]
        if n is not None and spins[0] >= n:
            spins[0] = 0
            return True
        return False

    # a spin long enough that a descheduled test process cannot end it before the answer; then
    # the short one, whose spins below miss whatever the host does (the answer never comes)
    clock.spin_s = 60.0
    clock.wait(1.0, poll, lambda: True)
    assert sleeping == [] and clock.spun == 1 and clock.answered_frames == 1
    clock.spin_s = 0.002
    answer_after[0] = None  # from now on the answer comes only to the sleeping wait
    for k in range(LockstepClock.SPIN_MISSES_MAX):
        clock.wait(1.02 + 0.02 * k, poll, lambda: True)
    assert len(sleeping) == LockstepClock.SPIN_MISSES_MAX and clock.spun == 1
    spins[0] = 0
    for k in range(LockstepClock.SPIN_REST_FRAMES):  # resting: not one poll without a timeout
        clock.wait(2.0 + 0.02 * k, poll, lambda: True)
    assert spins[0] == 0
    assert len(sleeping) == LockstepClock.SPIN_MISSES_MAX + LockstepClock.SPIN_REST_FRAMES
    clock.wait(9.0, poll, lambda: True)  # rested: it spins again
    assert spins[0] > 0
    assert clock.spin_cpu_s >= 0.0 and clock.timeouts == 0
    with pytest.raises(ValueError, match="spin_s"):
        LockstepClock(spin_s=-1.0)


# ------------------------------------------------------------------------------ setpoints
def _sat(mask: int, q=(1.0, 0.0, 0.0, 0.0), rates=(0.1, 0.2, 0.3), thrust: float = 0.6):
    return SimpleNamespace(
        type_mask=mask,
        q=list(q),
        body_roll_rate=rates[0],
        body_pitch_rate=rates[1],
        body_yaw_rate=rates[2],
        thrust=thrust,
    )


def test_px4_offboard_setpoints_and_their_stream_rule():
    sp = Setpoints()
    sp.take_px4(_sat(128 | 2), t=10.0, ms=10000, require_thrust=False)  # pitch rate ignored
    assert sp.sp == ("rates", (0.1, 0.0, 0.3), pytest.approx(0.6))
    assert sp.echo is not None and sp.echo[0] == 10000
    assert not sp.offboard_available(10.5)  # streaming, but not for a second yet
    for k in range(1, 11):  # 10 Hz for a second
        sp.take_px4(_sat(128), t=10.0 + 0.1 * k, ms=0, require_thrust=False)
    assert 11.0 - 10.0 >= PX4_OFFBOARD_MIN_STREAM_S and sp.offboard_available(11.0)
    assert not sp.offboard_available(11.6)  # a gap over 0.5 s ends the stream
    sp.take_px4(_sat(128 | 64, thrust=math.nan), t=12.0, ms=0, require_thrust=False)
    assert sp.sp is not None and sp.sp[2] == 0.0  # throttle ignore: zero thrust, NaN unused
    sp.take_px4(_sat(128, rates=(math.nan, 0.0, 0.0)), t=12.1, ms=0, require_thrust=False)
    sp.take_px4(_sat(128 | 7), t=12.2, ms=0, require_thrust=False)
    assert sp.dropped["nonfinite"] == 1 and sp.dropped["no_axes"] == 1
    sp.take_px4(_sat(0, q=(math.cos(0.1), math.sin(0.1), 0.0, 0.0)), 13.0, 0, False)
    kind, (roll, pitch), _ = sp.sp
    assert kind == "att" and roll == pytest.approx(0.2) and pitch == pytest.approx(0.0)


def test_px4_all_rates_setpoint_takes_every_rule():
    """type_mask 128 (every rate and the thrust, what the bridge streams) has a path of its
    own: the thrust clipped to 0..1, the echo raw, a NaN in any used field dropped and not
    counted as signal, the stream rule kept."""
    sp = Setpoints()
    sp.take_px4(_sat(128, rates=(0.1, -0.2, 0.3), thrust=1.7), t=20.0, ms=20000,
                require_thrust=True)  # fmt: skip
    assert sp.sp == ("rates", (0.1, -0.2, 0.3), 1.0)
    assert sp.echo == (20000, 128, (1.0, 0.0, 0.0, 0.0), (0.1, -0.2, 0.3), 1.7)
    assert sp.stream_start == 20.0 and sp.sp_last == 20.0
    for i, bad in enumerate(((math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, -math.inf))):
        sp.take_px4(_sat(128, rates=bad), t=20.1 + i, ms=0, require_thrust=False)
    sp.take_px4(_sat(128, thrust=math.nan), t=24.0, ms=0, require_thrust=False)
    assert sp.dropped["nonfinite"] == 4 and sp.sp_last == 20.0
    sp.take_px4(_sat(128, thrust=-0.5), t=25.0, ms=0, require_thrust=False)
    assert sp.sp == ("rates", (0.1, 0.2, 0.3), 0.0)
    assert sp.stream_start == 25.0  # after a gap over 0.5 s: a new stream


def test_ardupilot_guided_forced_axes():
    """ArduPlane's inverted mask: type_mask 134 (0b10000110) forces roll alone."""
    sp = Setpoints()
    half = 0.5 * math.radians(30.0)
    sp.take_ardupilot(_sat(134, q=(math.cos(half), math.sin(half), 0.0, 0.0)), t=5.0)
    assert sp.forced_t == [5.0, None, None, 5.0]  # thrust used: bit 64 clear
    assert sp.forced[0] == pytest.approx(math.radians(30.0))
    sp.reset_forced()
    sp.take_ardupilot(_sat(0, thrust=math.nan), t=6.0)
    assert sp.dropped["nonfinite"] == 1 and sp.forced_t == [None] * 4


# ------------------------------------------------------------------------------ modes
def _modes(px4: bool) -> tuple[Modes, list[str]]:
    said: list[str] = []
    st = SimpleNamespace(
        position_ned=np.array([10.0, 20.0, -100.0]), velocity_ned=np.array([0.0, 16.0, 0.0])
    )
    clock = SimpleNamespace(boot_s=30.0, t=18.0)
    return Modes(px4, Tunables(loiter_radius=80.0), clock, lambda: st, said.append), said


def test_px4_mode_requests():
    modes, said = _modes(px4=True)
    modes.hold(announce=False)
    assert modes.behaviour == LOITER and modes.name == "AUTO.LOITER"
    assert modes.custom_mode == px4_custom_mode(4, 3) and said == []
    assert modes.center == (10.0, 20.0) and modes.alt_sp == 100.0
    assert modes.course == pytest.approx(math.pi / 2)
    res, why = modes.request(1, 6, 0, offboard_ready=lambda: False)
    assert res == M.MAV_RESULT_TEMPORARILY_REJECTED and "offboard" in why
    res, why = modes.request(1, 6, 0, offboard_ready=lambda: True)
    assert res == M.MAV_RESULT_ACCEPTED and why is None and modes.behaviour == OFFBOARD
    assert said == ["Mode OFFBOARD"] and modes.changes[-1] == (18.0, "OFFBOARD")
    assert modes.request(1, 8, 0, lambda: True)[0] == M.MAV_RESULT_TEMPORARILY_REJECTED
    assert modes.request(0, 4, 3, lambda: True)[0] == M.MAV_RESULT_DENIED  # no custom flag
    modes.request(1, 4, 0, lambda: True)
    assert modes.name == "AUTO.MISSION"  # AUTO without a sub mode is MISSION


def test_ardupilot_modes_and_base_mode():
    modes, _ = _modes(px4=False)
    modes.hold(announce=False)
    assert modes.custom_mode == 12 and modes.name == "LOITER"
    flags = modes.base_mode()
    for bit in (
        M.MAV_MODE_FLAG_SAFETY_ARMED,
        M.MAV_MODE_FLAG_GUIDED_ENABLED,
        M.MAV_MODE_FLAG_AUTO_ENABLED,
        M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    ):
        assert flags & bit
    reset = []
    modes.on_guided = lambda: reset.append(True)
    assert modes.request(1, 15, 0, lambda: False)[0] == M.MAV_RESULT_ACCEPTED
    assert modes.behaviour == GUIDED and reset == [True]
    assert modes.request(1, 99, 0, lambda: False)[0] == M.MAV_RESULT_FAILED
    modes.armed = False
    assert not modes.base_mode() & M.MAV_MODE_FLAG_SAFETY_ARMED


# ------------------------------------------------------------------------------ clock, config
def test_step_clock():
    c = StepClock(0.01, 1200)  # a 12 s trim flight at 100 Hz
    c.k += 5
    assert c.boot_s == pytest.approx(12.05) and c.t == pytest.approx(0.05)
    assert c.ms() == 12050 and c.us() == 12050000 and c.ready_boot_s == pytest.approx(12.0)


def test_vehicle_config_checks_and_rates():
    with pytest.raises(ValueError, match="flavour"):
        VehicleConfig(flavour="inav")
    with pytest.raises(ValueError, match="initial_mode"):
        VehicleConfig(initial_mode="orbit")
    with pytest.raises(ValueError, match="plant"):
        VehicleConfig(plant="xplane")
    assert VehicleConfig("ardupilot").telemetry_rates() == stock_rates("ardupilot")
    r = VehicleConfig("px4", rates={"attitude": 50.0, "wind": None}).telemetry_rates()
    assert r.attitude == 50.0 and r.wind == stock_rates("px4").wind
    assert VehicleConfig(rates=TelemetryRates()).telemetry_rates() == TelemetryRates()
    with pytest.raises(ValueError, match="stream"):
        VehicleConfig(rates={"attitudes": 1.0}).telemetry_rates()


# ------------------------------------------------------------------------------ truth
def test_truth_rows_and_the_target_on_its_clock():
    rec = TruthRecorder()
    st = SimpleNamespace(
        position_ned=np.array([1.0, 2.0, -3.0]),
        velocity_ned=np.zeros(3),
        wind_ned=np.zeros(3),
        euler=(0.1, 0.2, 0.3),
        airspeed=16.0,
        throttle=0.4,
    )
    rec.record(0.0, 12.0, st, 7)
    rec.record(0.02, 12.02, st, 7)
    target = SimpleNamespace(
        state=lambda t: SimpleNamespace(position=(t, 0, 0), velocity=(1, 0, 0))
    )
    T = rec.truth(target, epoch_boot_s=12.0)
    assert T["position_ned"].shape == (2, 3) and T["mode"].tolist() == [7, 7]
    assert T["target_position"][:, 0] == pytest.approx([0.0, 0.02])
    rec.forget_target()  # a new epoch: the target's rows are recomputed on its clock
    T = rec.truth(target, epoch_boot_s=11.0)
    assert T["target_position"][:, 0] == pytest.approx([1.0, 1.02])
    assert T["target_t"] == pytest.approx([1.0, 1.02])
    off = TruthRecorder(enabled=False)
    off.record(0.0, 12.0, st, 7)
    assert off.truth(None, 0.0)["t"].shape == (0,)


# ------------------------------------------------------------------------------ target stream
@pytest.mark.parametrize("turn", [0.01, 0.0])
def test_target_positions_computed_ahead_are_the_bytes_computed_on_time(monkeypatch, turn):
    """The target's fixes are computed in bursts ahead of their due times (a pure function of
    the target's time): the packets are byte for byte those computed when due, across an
    epoch change (the times ahead then miss and are computed when they come)."""
    import sim.vehicle.target_stream as TS
    from mpf_mavlink.core.target import ConstantTurn
    from sim.plant.jsbsim_plant import LocalNED

    def fly(ahead: int) -> list[bytes]:
        monkeypatch.setattr(TS, "_AHEAD", ahead)
        out: list[bytes] = []
        clock = StepClock(0.01, 1234)
        link = SimpleNamespace(
            target_framer=Framer(M.MAVLink(_Sink(), 2, 1)), put=out.append, tmav=None
        )
        motion = ConstantTurn((10.0, -5.0, 0.0), 3.0, 0.3, turn, 0.1)
        ts = TS.TargetStream(motion, clock, link, LocalNED(41.185, -8.76, 0.0), 0.0, 10.0,
                             True, True, None)  # fmt: skip
        for i in range(700):  # 14 s of 20 ms frames
            clock.k += 2
            if i == 300:
                ts.epoch_boot_s = clock.boot_s - 0.37  # as take_epoch does
            ts.frame()
        return out

    got, want = fly(50), fly(1)
    assert len(want) == 14 * 10 * 2 + 14  # FOLLOW_TARGET + GLOBAL_POSITION_INT, HEARTBEAT
    assert got == want


def test_the_target_quaternion_of_rows_is_the_rotation_in_all_four_branches():
    """The one matrix -> quaternion conversion (:func:`mpf_mavlink.quaternion.quat_of_rows`,
    which the target stream sends and :func:`matrix_to_quat_wxyz` returns) gives, in all four
    of Shepperd's branches (rotations by ~pi about each axis reach the three non-trace ones), a
    unit quaternion with w >= 0 whose matrix is the rotation: a few roundings per element, so
    1e-14 (50 eps) bounds the error of the round trip."""
    from mpf_mavlink.core import so3
    from mpf_mavlink.core.frames import matrix_to_quat_wxyz, quat_wxyz_to_matrix
    from mpf_mavlink.quaternion import quat_of_rows

    rng = np.random.default_rng(5)
    branches = set()
    for i in range(4000):
        axis = rng.normal(size=3) if i % 2 else np.eye(3)[i // 2 % 3] + 0.05 * rng.normal(size=3)
        angle = rng.uniform(-math.pi, math.pi) if i % 4 < 2 else math.pi - rng.uniform(0, 0.3)
        R = so3.exp(angle * axis / np.linalg.norm(axis))
        q = quat_of_rows(R.ravel().tolist())
        assert q == matrix_to_quat_wxyz(R)
        assert q[0] >= 0.0 and abs(math.fsum(c * c for c in q) - 1.0) < 1e-14
        assert np.max(np.abs(quat_wxyz_to_matrix(q) - R)) < 1e-14
        tr = R[0, 0] + R[1, 1] + R[2, 2]
        branches.add(-1 if tr > 0 else int(np.argmax(np.diag(R))))
    assert branches == {-1, 0, 1, 2}


def test_target_fields_from_floats_equal_those_from_arrays():
    """A motion whose states carry floats and one whose states carry only arrays (the same
    numbers) give the target stream the same fields, to the bit."""
    import sim.vehicle.target_stream as TS
    from mpf_mavlink.core.target import ConstantTurn, TargetState
    from sim.plant.jsbsim_plant import LocalNED

    turn = ConstantTurn((10.0, -5.0, 0.0), 3.0, 0.3, 0.01, 0.1)

    class ArraysOnly:
        def state(self, t: float) -> TargetState:
            s = turn.state(t)
            return TargetState(t, np.array(s.position), np.array(s.velocity),
                               np.array(s.acceleration), np.array(s.R_T_I), np.array(s.omega_T),
                               np.array(s.omega_dot_T))  # fmt: skip

    def fields(motion: object) -> list[tuple[object, ...]]:
        ts = TS.TargetStream(motion, StepClock(0.01, 0), SimpleNamespace(), LocalNED(41.185,
                             -8.76, 0.0), 0.0, 10.0, True, True, None)  # fmt: skip
        return [ts._fields(0.1 * k + 0.013) for k in range(200)]

    assert turn.state(1.0).floats is not None and ArraysOnly().state(1.0).floats is None
    assert fields(turn) == fields(ArraysOnly())


def test_constant_turn_state_on_floats_is_the_float64_formula():
    """ConstantTurn.state computes on Python floats what ``position + [dn, de, -climb t]``
    gives in float64 arrays, to the bit, and gives Python floats whatever type t has."""
    from mpf_mavlink.core.target import ConstantTurn

    rng = np.random.default_rng(11)
    for k in range(300):
        pos = tuple(rng.uniform(-500.0, 500.0, 3).tolist())
        V, psi0 = float(rng.uniform(0.0, 20.0)), float(rng.uniform(-3.0, 3.0))
        w = (0.0, 1e-10, 0.01, float(rng.uniform(-0.2, 0.2)))[k % 4]
        climb = float(rng.uniform(-2.0, 2.0))
        t_any = (float(rng.uniform(0.0, 900.0)), np.float64(rng.uniform(0.0, 900.0)), 7)[k % 3]
        st = ConstantTurn(pos, V, psi0, w, climb).state(t_any)
        t = float(t_any)
        psi = psi0 + w * t
        if abs(w) > 1e-9:
            dn = V / w * (math.sin(psi) - math.sin(psi0))
            de = V / w * (math.cos(psi0) - math.cos(psi))
        else:
            dn, de = V * t * math.cos(psi0), V * t * math.sin(psi0)
        want = (np.array(pos, float) + np.array([dn, de, -climb * t])).tolist()
        assert st.floats is not None
        assert list(st.floats[9:12]) == want
        assert all(type(x) is float for x in st.floats[9:18])
        assert st.position.tolist() == want and st.t == t_any
