"""The bridge's telemetry and mode timeouts against a lockstep simulation (``mavlink.lockstep``).

The SIL vehicle (sim/vehicle/vehicle.py, kinematic plant) runs in a thread of this process with a
lockstep clock; the bridge (run_bridge, the code that flies real autopilots) runs in the main
thread and talks to it over UDP loopback. A loaded host is made deliberately: the vehicle's
clock stalls for longer than the telemetry timeout now and then (a simulation process that the
scheduler left waiting), which is no lost link: no simulated time passes either.
"""

from __future__ import annotations

import dataclasses
import os
import re
import socket
import threading
import time
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")

from mpf_mavlink.bridge.base import BridgeOptions, BridgeResult
from mpf_mavlink.bridge.live import run_bridge
from mpf_mavlink.config.schema import load_config

# a lifecycle flight of seconds has no steady window: it ends NOT JUDGED (exit 6), not PASS
from mpf_mavlink.runs.verdict import EXIT_NOT_JUDGED as NOT_JUDGED  # noqa: E402
from sim.sil import bridge_config, build_vehicle
from sim.vehicle.clock import LockstepClock

ROOT = Path(__file__).resolve().parents[1]
TRACK_S = 3.0  # seconds of tracking (vehicle time): several stalls, a short test


def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = int(s.getsockname()[1])
    s.close()
    return port


class StallingClock(LockstepClock):
    """A lockstep clock whose simulation stalls ``stall_s`` of wall time after every
    ``every`` frames once the bridge is tracking (:meth:`tracking`, given to :func:`fly` as
    ``during``): no telemetry and no simulated time meanwhile. Before, the vehicle is in
    lockstep without stalls, so the hand-over (stream rates, modes) is not what is tested."""

    def __init__(self, every: int, stall_s: float) -> None:
        super().__init__()
        self.every, self.stall_s, self.stalls, self._n = every, stall_s, 0, 0
        self.tracking_ = False

    def tracking(self, vehicle: Any) -> None:
        self.tracking_ = True

    def wait(self, sim_t: float, poll: Any, has_peer: Any) -> None:
        super().wait(sim_t, poll, has_peer)
        if has_peer() and self.tracking_:
            self._n += 1
            if self._n % self.every == 0:
                self.stalls += 1
                time.sleep(self.stall_s)


def fly(
    tmp_path: Path, clock: Any, sets: list[str], during: Any = None, track_s: float = TRACK_S
) -> BridgeResult:
    """The demo mission on the kinematic plant, ``track_s`` of tracking; ``during(vehicle)``
    runs in a thread once the bridge reports TRACKING."""
    cfg = load_config(
        str(ROOT / "configs" / "default.yaml"),
        ["sil.plant=kinematic", "sil.turbulence=none", "mavlink.plots=false", *sets],
    )
    port = free_port()
    v = build_vehicle(cfg, f"udpout:127.0.0.1:{port}", clock=clock)
    v.start_in_thread()

    def log(line: str) -> None:
        if line == "[TRACKING]" and during is not None:
            threading.Thread(target=during, args=(v,), daemon=True).start()

    try:
        bcfg = bridge_config(cfg)
        opts = BridgeOptions(
            url=f"udpin:127.0.0.1:{port}", out_dir=tmp_path / "run", duration_s=track_s
        )
        return run_bridge(bcfg, opts, log=log)
    finally:
        v.close()


def after_vehicle_s(v: Any, dt: float) -> None:
    """Wait until the vehicle's simulated time has gone ``dt`` past now (lockstep runs faster
    than real time: wall seconds would be many vehicle seconds)."""
    t0 = v.t
    while v.t < t0 + dt:
        time.sleep(0.005)


def _clocks(reason: str) -> tuple[float, float]:
    """(vehicle s, wall s) from 'no ATTITUDE for V s of vehicle time (W s wall)'."""
    m = re.search(r"no ATTITUDE for ([\d.]+) s of vehicle time \(([\d.]+) s wall\)", reason)
    assert m, reason
    return float(m[1]), float(m[2])


@pytest.mark.slow  # two short flights, ~15 s
def test_a_stalling_lockstep_simulation_is_flown_to_the_end_not_lost(tmp_path):
    # 0.8 s stalls (1.6x the 0.5 s telemetry timeout) every 25 frames (0.5 s of vehicle time):
    # on the wall clock the telemetry goes silent for longer than the timeout at every stall
    m = load_config(str(ROOT / "configs" / "default.yaml")).section("mavlink")
    assert m.telemetry_timeout_s == 0.5 and m.lockstep_wall_timeout_s >= 10.0 * 0.8
    clock = StallingClock(every=25, stall_s=0.8)
    res = fly(tmp_path / "lockstep", clock, ["mavlink.lockstep=true"], during=clock.tracking)
    # 3 s of tracking cross >= 5 stalls (one every 0.5 s) and the mission ends by its duration
    assert clock.stalls >= 5, clock.stalls
    assert res.exit_code == NOT_JUDGED, res.exit_reason
    assert res.exit_reason.startswith("mission duration") and res.handback_confirmed
    assert res.tracked_s >= TRACK_S - 0.02  # one 20 ms frame
    # the same vehicle, timeouts on the wall clock (a real link's): lost at the first stall
    clock = StallingClock(every=25, stall_s=0.8)
    res = fly(tmp_path / "wall", clock, ["mavlink.lockstep=false"], during=clock.tracking)
    assert res.exit_code == 4 and "telemetry lost" in res.exit_reason, res.exit_reason
    # lost at the first stall (a loaded host may lose it even before: wall-clock timeouts)
    assert clock.stalls <= 1 and res.tracked_s < 0.5 + 0.02


@pytest.mark.slow  # ~14 s: the 2 s bound, then a 3 x 2.5 s hand-back to a dead vehicle
def test_a_silent_lockstep_vehicle_is_lost_after_the_wall_bound(tmp_path):
    # the vehicle stops 1 s into tracking: no message and no vehicle time any more; lost
    # after lockstep_wall_timeout_s (2 s here) of wall time, the vehicle clock having stood still
    t_stop: list[float] = []

    def stop(v: Any) -> None:
        after_vehicle_s(v, 1.0)
        v.stop()
        t_stop.append(time.monotonic())

    res = fly(
        tmp_path,
        "lockstep",
        ["mavlink.lockstep=true", "mavlink.lockstep_wall_timeout_s=2.0"],
        during=stop,
        track_s=60.0,
    )
    assert res.exit_code == 4 and "telemetry lost" in res.exit_reason, res.exit_reason
    if "no usable state" in res.exit_reason:
        # a loaded bridge can read the last ATTITUDE without a control step on it (a backlog
        # drained): its last good state is then a frame older and crosses the same wall bound
        # first; the vehicle's clock still stood still since (at most one 20 ms frame, printed
        # to 10 ms)
        pattern = r"no usable state for ([\d.]+) s of vehicle time \(([\d.]+) s wall\)"
        m = re.search(pattern, res.exit_reason)
        assert m, res.exit_reason
        vehicle_s, wall_s = float(m[1]), float(m[2])
        assert vehicle_s <= 0.02 + 0.005
    else:
        vehicle_s, wall_s = _clocks(res.exit_reason)
        assert vehicle_s == 0.0  # nothing came after the last ATTITUDE
    # detected at the bound (checked every <= 10 ms of the bridge's loop); the 1 s of slack
    # above is for a loaded host that leaves the bridge waiting, far below the 10 s default
    assert t_stop and 2.0 <= wall_s < 2.0 + 1.0


def test_a_lockstep_vehicle_that_stops_its_attitude_is_lost_on_vehicle_time(tmp_path):
    # the vehicle lives on (position, heartbeat, ... keep coming with its time) but ATTITUDE
    # stops: lost after telemetry_timeout_s (0.5 s) of VEHICLE time, long before the wall bound
    def mute(v: Any) -> None:
        after_vehicle_s(v, 1.0)
        v.telemetry.rates = dataclasses.replace(v.telemetry.rates, attitude=0.0)

    res = fly(tmp_path, "lockstep", ["mavlink.lockstep=true"], during=mute, track_s=60.0)
    assert res.exit_code == 4 and "telemetry lost" in res.exit_reason, res.exit_reason
    vehicle_s, wall_s = _clocks(res.exit_reason)
    # past 0.5 s by at most the 20 ms between two position samples (the vehicle's clock as
    # seen); the reason prints it to 10 ms, so 0.50 when the sum of ms steps rounds down
    assert 0.5 <= vehicle_s <= 0.5 + 0.02 + 0.005
    assert wall_s < 10.0  # not the wall bound (lockstep_wall_timeout_s 10 s)


def test_lockstep_wall_bound_below_the_telemetry_timeout_is_refused(tmp_path):
    from mpf_mavlink.errors import MpfError

    with pytest.raises(MpfError, match=r"mavlink\.lockstep_wall_timeout_s: 0\.2 is below"):
        load_config(
            str(ROOT / "configs" / "default.yaml"),
            ["mavlink.lockstep=true", "mavlink.lockstep_wall_timeout_s=0.2"],
        )


def test_an_attitude_that_is_no_new_instant_is_named_when_it_starves_the_loop():
    """An ATTITUDE whose time_boot_ms does not advance makes no control step; the controller
    says why, so a bridge whose steps stop while ATTITUDE still arrives ends with "telemetry
    lost: no usable state ... (no new ATTITUDE instant ...)" instead of an empty reason (CI,
    stop 21: the blackout's last ATTITUDE before the cut was such a sample)."""
    import numpy as np

    from mpf_mavlink.bridge.controller import Controller, ControlSetup
    from mpf_mavlink.mavlink.codec import AttitudeSample, LocalPositionSample

    ctl = Controller(ControlSetup.of(load_config(str(ROOT / "configs" / "default.yaml"))))
    ctl.feed_vehicle(AttitudeSample(1.0, np.eye(3), np.zeros(3)), 10.0)
    ctl.feed_vehicle(LocalPositionSample(1.0, np.zeros(3), np.array([16.0, 0.0, 0.0])), 10.0)
    ctl.set_origin()
    ctl.init_s()
    assert ctl.step() is not None and ctl.why_not == ""
    # the same instant again (received 20 ms later): an ATTITUDE, but no step
    assert ctl.feed_vehicle(AttitudeSample(1.0, np.eye(3), np.zeros(3)), 10.02)
    assert ctl.step() is None
    assert ctl.why_not.startswith("no new ATTITUDE instant")
    # a newer one steps again and clears the reason
    assert ctl.feed_vehicle(AttitudeSample(1.02, np.eye(3), np.zeros(3)), 10.04)
    assert ctl.step() is not None and ctl.why_not == ""
