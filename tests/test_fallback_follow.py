"""The fallback loiter point follows a moving target while tracking (bridge/fallback.py
FallbackSetup.follow): re-placed every ``mavlink.fallback_follow_s`` of mission time once the
path's centre has moved FOLLOW_MOVED_M, never waited for, a refusal logged once."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

from mpf_mavlink.bridge.commands import CommandChannel
from mpf_mavlink.bridge.fallback import EARTH_RADIUS_M, FOLLOW_MOVED_M, FallbackSetup
from mpf_mavlink.mavlink import CommandAckSample, dialect
from mpf_mavlink.mavlink.wire_limits import MAV_CMD_DO_REPOSITION

LAT0, LON0, ALT = -35.36, 149.16, 684.0


class _Pump:
    def __init__(self) -> None:
        self.sent: list[Any] = []

    def send(self, msg: Any) -> None:
        self.sent.append(msg)

    def spin(self, timeout_s: float, until: Any = None) -> bool:
        return False


def _setup(follow_s: float) -> tuple[FallbackSetup, _Pump, list[str], dict[str, float]]:
    pump = _Pump()
    mav = dialect.MAVLink(None, srcSystem=255, srcComponent=190)
    vl = SimpleNamespace(
        m=SimpleNamespace(fallback_follow_s=follow_s),
        commands=CommandChannel(pump),
        link=SimpleNamespace(mav=mav),
        sysid=1,
        compid=1,
    )
    logs: list[str] = []
    fb = FallbackSetup(vl, None, None, logs.append)  # type: ignore[arg-type]
    where = {"east_m": 0.0}

    def centre() -> tuple[float, float, float, float, bool]:
        dlon = math.degrees(where["east_m"] / (EARTH_RADIUS_M * math.cos(math.radians(LAT0))))
        return LAT0, LON0 + dlon, ALT, 150.0, True

    fb.path_centre = centre  # type: ignore[method-assign]
    fb._placed = (LAT0, LON0, False)  # as ardupilot_loiter leaves it once accepted
    return fb, pump, logs, where


def test_follows_a_moving_centre_at_the_configured_period() -> None:
    fb, pump, _, where = _setup(5.0)
    for k in range(61):  # 60 s of a target moving 3 m/s east, a step every second
        where["east_m"] = 3.0 * k
        fb.follow(float(k))
    # at t = 5, 10, ..., 60 the centre has moved 15 m since the last placement: 12 placements
    assert len(pump.sent) == fb.replaced == 12
    last = pump.sent[-1]
    assert last.command == MAV_CMD_DO_REPOSITION
    assert (last.param3, last.param4) == (150.0, 1.0)  # the path's radius, counter-clockwise
    east = math.radians(last.y * 1e-7 - LON0) * EARTH_RADIUS_M * math.cos(math.radians(LAT0))
    assert abs(east - 180.0) < 0.02  # 1e-7 deg of longitude is 0.009 m here


def test_a_still_centre_is_not_resent_and_zero_places_once() -> None:
    fb, pump, _, where = _setup(5.0)
    for k in range(60):
        where["east_m"] = 0.9 * FOLLOW_MOVED_M * (k % 2)  # jitter under the threshold
        fb.follow(float(k))
    assert pump.sent == []
    fb0, pump0, _, where0 = _setup(0.0)
    where0["east_m"] = 1000.0
    for k in range(60):
        fb0.follow(float(k))
    assert pump0.sent == []


def test_nothing_follows_a_placement_that_was_refused() -> None:
    fb, pump, _, where = _setup(5.0)
    fb._placed = None  # the first DO_REPOSITION was not accepted
    where["east_m"] = 100.0
    for k in range(30):
        fb.follow(float(k))
    assert pump.sent == []


def test_a_refusal_is_logged_once() -> None:
    fb, pump, logs, where = _setup(1.0)
    denied = CommandAckSample(
        MAV_CMD_DO_REPOSITION, dialect.MAV_RESULT_DENIED, False, "MAV_RESULT_DENIED"
    )
    for k in range(10):
        where["east_m"] = 10.0 * k
        fb.follow(float(k))
        fb.vl.commands.deliver(denied)
    assert len(pump.sent) == 9
    assert [s for s in logs if "refused" in s] == [
        "fallback: re-placing the loiter point refused (MAV_RESULT_DENIED)"
    ]
