"""The lockstep's overlap: with a command latency of one frame the vehicle steps frame k+1 while
its peer answers frame k's ATTITUDE (the answer acts at the end of frame k+1 anyway). That must
be a speed-up only: the flight is bit for bit the one of the strictly alternating lockstep.

The peer (bench/sil_peer.py) runs in a process of its own, answering each ATTITUDE with body
rates computed from that ATTITUDE alone, so any difference between the runs can only come from
when the vehicle applies the answers; it sleeps before each answer, so that the overlapped
vehicle really is stepping (or waiting) while the peer works, at whatever point the scheduler
puts it."""

from __future__ import annotations

import multiprocessing
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from bench.sil_peer import serve_forever
from sim.vehicle.config import VehicleConfig
from sim.vehicle.vehicle import SimVehicle

FRAME_S = 0.02


def _fly(
    overlap: bool, latency_s: float, seconds: float, spin_s: float = 0.0
) -> tuple[dict[str, Any], SimVehicle]:
    ctx = multiprocessing.get_context("fork")
    rx, tx = ctx.Pipe(duplex=False)
    stop = ctx.Event()
    peer = ctx.Process(target=serve_forever, args=(tx, stop, 0.001), daemon=True)
    peer.start()
    try:
        assert rx.poll(30.0), "the scripted peer did not start"
        port = rx.recv()
        cfg = VehicleConfig(
            flavour="px4",
            url=f"udpout:127.0.0.1:{port}",
            plant="jsbsim",
            physics_rate_hz=100.0,
            frame_period=FRAME_S,
            clock="lockstep",
            # a wall-clock bound no loaded machine reaches: a timeout would advance a frame
            # without its answer, which is exactly what the comparison must not contain
            answer_timeout_s=30.0,
            command_latency_s=latency_s,
            lockstep_overlap=overlap,
            lockstep_spin_s=spin_s,
            trim_seconds=3.0,
            wind_ned=(0.0, 4.0, 0.0),
            turbulence="light",
            seed=7,
        )
        v = SimVehicle(cfg)
        v.run(1.2)  # > 1 s of setpoints streamed: PX4 accepts OFFBOARD
        # the mode request applied at a given frame in both runs: an unstamped command acts
        # from when it is read, which is the one thing the overlap changes
        mav = M.MAVLink(None, 255, 190)
        v.dispatch(mav.command_long_encode(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0))
        assert v.mode_name == "OFFBOARD"
        v.run(seconds)
        truth = v.truth()
        v.close()
        return truth, v
    finally:
        stop.set()
        peer.join(5.0)
        if peer.is_alive():
            peer.terminate()


@pytest.mark.parametrize("latency_s", [FRAME_S, 2.5 * FRAME_S])
def test_the_overlapped_lockstep_flies_the_serial_flight_bit_for_bit(latency_s):
    seconds = 6.0
    serial, vs = _fly(False, latency_s, seconds)
    overlapped, vo = _fly(True, latency_s, seconds)
    frames = int(round((1.2 + seconds) / FRAME_S))
    for v in (vs, vo):
        assert v.clock.timeouts == 0  # every frame ended on its answer
        assert v.lockstep.answers >= frames - 2  # the peer answered (nearly) every ATTITUDE
    # serial: every frame awaited its own answer; overlapped: all but the first awaited an
    # earlier frame's (that is what lets the peer compute while the vehicle steps)
    assert vs.lockstep.overlapped == 0
    assert vo.lockstep.overlapped >= frames - 5
    # the peer flew it: the roll follows its 0.3 rad sweep, so a setpoint applied a frame
    # early or late would change the trajectory
    roll = overlapped["euler"][:, 0]
    assert np.ptp(roll[-int(seconds / FRAME_S) :]) > 0.2
    assert serial["position_ned"].shape[0] >= frames
    assert serial.keys() == overlapped.keys()
    for key in serial:  # no target here: its columns are empty in both
        a, b = serial[key], overlapped[key]
        assert a.shape == b.shape, key
        assert np.array_equal(a, b), f"{key} differs between the serial and overlapped lockstep"


def test_the_spinning_wait_flies_the_sleeping_flight_bit_for_bit():
    """sil.lockstep_spin_s changes how the vehicle waits for the answer, never which answer
    ends which frame: the truth equals the serial, sleeping lockstep's bit for bit. The spin
    (10 ms) outlasts the peer's 1 ms sleep before each answer, so the answers do come while it
    spins."""
    seconds = 4.0
    serial, _ = _fly(False, FRAME_S, seconds)
    spun, v = _fly(True, FRAME_S, seconds, spin_s=0.01)
    frames = int(round((1.2 + seconds) / FRAME_S))
    assert v.clock.timeouts == 0
    # nearly every frame's answer came while spinning (a preempted one may end in the sleep)
    assert v.clock.spun >= 0.8 * frames and v.clock.spin_cpu_s > 0.0
    assert serial.keys() == spun.keys()
    for key in serial:
        a, b = serial[key], spun[key]
        assert a.shape == b.shape, key
        assert np.array_equal(a, b), f"{key} differs between the sleeping and spinning wait"
