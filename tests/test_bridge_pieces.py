"""The bridge's pieces alone: stream negotiation against a fake vehicle, the session's mode
requests and pilot watch against scripted HEARTBEAT/COMMAND_ACK, the control loop's
watchdog and re-sends. A fake link on a fake monotonic clock: deterministic and instant."""

from __future__ import annotations

import dataclasses
import heapq
import math
from pathlib import Path
from typing import Any

import pytest

from mpf_mavlink.bridge import control_step, link_io, session, streams
from mpf_mavlink.bridge.base import BridgeResult, Phase, State, _Stop
from mpf_mavlink.bridge.control_step import ControlLoop
from mpf_mavlink.bridge.controller import Controller, ControlSetup
from mpf_mavlink.bridge.link_io import LinkHandlers, VehicleLink
from mpf_mavlink.bridge.operator import OperatorDisplay
from mpf_mavlink.bridge.session import Session
from mpf_mavlink.bridge.streams import StreamNegotiator
from mpf_mavlink.config import bridge as bridge_config  # noqa: F401
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.mavlink import Flavour
from mpf_mavlink.mavlink import dialect as d
from mpf_mavlink.mavlink.modes import px4_custom_mode

ROOT = Path(__file__).resolve().parents[1]
MAV_RESULT_ACCEPTED, MAV_RESULT_UNSUPPORTED = 0, 3
PX4_POSCTL, PX4_OFFBOARD, PX4_HOLD = px4_custom_mode(3, 0), px4_custom_mode(6, 0), None


class FakeClock:
    """time.monotonic for the pieces: advanced only by the fake link's waits."""

    def __init__(self) -> None:
        self.t = 100.0

    def monotonic(self) -> float:
        return self.t


class FakeVehicle:
    """A vehicle behind a fake link: streams messages on schedules, answers commands.

    ``accept_intervals``: SET_MESSAGE_INTERVAL accepted (PX4, ArduPilot 4.x) or refused
    (answered UNSUPPORTED, streaming nothing: an old ArduPilot that only knows SRn);
    ``streams``: whether anything streams at all; ``mode_follows``: a DO_SET_MODE changes
    the HEARTBEAT's mode (else it is ACKed but the mode stays)."""

    def __init__(
        self,
        clock: FakeClock,
        accept_intervals: bool = True,
        streams: bool = True,
        mode_follows: bool = True,
        ack_modes: bool = True,
    ) -> None:
        self.clock = clock
        self.enc = d.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = d.MAVLink(None)
        self.accept_intervals, self.streams = accept_intervals, streams
        self.mode_follows, self.ack_modes = mode_follows, ack_modes
        self.custom_mode = PX4_POSCTL
        self.rates: dict[int, float] = {}  # message id -> Hz
        self.queue: list[tuple[float, int, Any]] = []  # (due, seq, message)
        self.seq = 0
        self.sent: list[Any] = []  # what the bridge sent
        self.t_boot0 = clock.t
        self._emit_heartbeat(clock.t)

    # -- what the bridge sends ---------------------------------------------------------------
    def receive(self, msg: Any) -> None:
        self.sent.append(msg)
        now = self.clock.t
        if msg.get_type() == "COMMAND_LONG":
            cmd = int(msg.command)
            if cmd == d.MAV_CMD_SET_MESSAGE_INTERVAL:
                ok = self.accept_intervals
                self._push(now + 0.01, self._ack(cmd, MAV_RESULT_ACCEPTED if ok else
                                                  MAV_RESULT_UNSUPPORTED))  # fmt: skip
                if ok and self.streams and msg.param2 > 0:
                    self._stream(int(msg.param1), 1e6 / msg.param2, now)
            elif cmd == d.MAV_CMD_DO_SET_MODE and self.ack_modes:
                self._push(now + 0.02, self._ack(cmd, MAV_RESULT_ACCEPTED))
                if self.mode_follows:
                    self.custom_mode = int(msg.param2) << 16 | int(msg.param3) << 24
                    self._emit_heartbeat(now + 0.05)
        elif msg.get_type() == "REQUEST_DATA_STREAM" and self.streams:
            groups = {d.MAV_DATA_STREAM_EXTRA1: [d.MAVLINK_MSG_ID_ATTITUDE],
                      d.MAV_DATA_STREAM_POSITION: [d.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                                                   d.MAVLINK_MSG_ID_GLOBAL_POSITION_INT],
                      d.MAV_DATA_STREAM_EXTRA2: [d.MAVLINK_MSG_ID_VFR_HUD]}  # fmt: skip
            for mid in groups.get(int(msg.req_stream_id), []):
                self._stream(mid, float(msg.req_message_rate), now)

    # -- what it sends ---------------------------------------------------------------------
    def _ack(self, cmd: int, result: int) -> Any:
        return self.enc.command_ack_encode(cmd, result)

    def _emit_heartbeat(self, at: float) -> None:
        base = d.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | d.MAV_MODE_FLAG_SAFETY_ARMED
        hb = self.enc.heartbeat_encode(
            d.MAV_TYPE_FIXED_WING, d.MAV_AUTOPILOT_PX4, base, self.custom_mode, 4
        )
        self._push(at, hb)

    def _stream(self, mid: int, hz: float, now: float) -> None:
        first = mid not in self.rates
        self.rates[mid] = hz
        if first:
            self._push(now + 1.0 / hz, ("stream", mid))

    def _sample(self, mid: int, t: float) -> Any:
        ms = int((t - self.t_boot0) * 1000) + 1000
        e = self.enc
        if mid == d.MAVLINK_MSG_ID_ATTITUDE:
            return e.attitude_encode(ms, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        if mid == d.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return e.local_position_ned_encode(ms, 0.0, 0.0, -100.0, 15.0, 0.0, 0.0)
        if mid == d.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return e.global_position_int_encode(ms, 0, 0, 100000, 100000, 1500, 0, 0, 0)
        if mid == d.MAVLINK_MSG_ID_VFR_HUD:
            return e.vfr_hud_encode(15.0, 15.0, 0, 50, 100.0, 0.0)
        return e.heartbeat_encode(d.MAV_TYPE_FIXED_WING, d.MAV_AUTOPILOT_PX4, 129,
                                  self.custom_mode, 4)  # fmt: skip

    def _push(self, at: float, item: Any) -> None:
        self.seq += 1
        heapq.heappush(self.queue, (at, self.seq, item))

    def next_message(self, until: float) -> Any | None:
        """The next message due by ``until`` (the clock moves to it), else None (the clock
        moves to ``until``)."""
        while self.queue and self.queue[0][0] <= until:
            at, _, item = heapq.heappop(self.queue)
            self.clock.t = max(self.clock.t, at)
            if isinstance(item, tuple):
                mid = item[1]
                self._push(at + 1.0 / self.rates[mid], item)
                item = self._sample(mid, at)
            return self.parser.parse_char(item.pack(self.enc))
        self.clock.t = max(self.clock.t, until)
        return None


class FakeLink:
    """The slice of :class:`~mpf_mavlink.mavlink.link.Link` the pieces use."""

    def __init__(self, vehicle: FakeVehicle) -> None:
        self.vehicle = vehicle
        self.mav = d.MAVLink(None, srcSystem=1, srcComponent=191)
        self.tlog = None
        self.heartbeats = 0

    def send(self, msg: Any) -> None:
        msg.pack(self.mav)
        self.vehicle.receive(msg)

    def send_heartbeat(self) -> None:
        self.heartbeats += 1

    def recv(self, timeout_s: float = 0.0) -> Any:
        return self.vehicle.next_message(self.vehicle.clock.t + timeout_s)

    def buffered(self) -> bool:
        return False  # one message at a time, as a stream link

    def clock(self) -> float:
        return self.vehicle.clock.t


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    c = FakeClock()
    for mod in (link_io, streams, session, control_step):
        monkeypatch.setattr(mod, "time", c)
    return c


def px4_cfg(*overrides: str) -> Any:
    return load_config(ROOT / "configs" / "bridge_px4.yaml", list(overrides))


def vehicle_link(vehicle: FakeVehicle, flavour: Flavour = Flavour.PX4, **m_over: Any) -> Any:
    m = dataclasses.replace(px4_cfg().section("mavlink"), **m_over)
    vl = VehicleLink(m)
    vl.link = FakeLink(vehicle)
    vl.flavour = flavour
    vl.subscribe(LinkHandlers(tick=lambda: vl.duties(vehicle.clock.t)))
    return vl


# -- stream negotiation ----------------------------------------------------------------------
def test_streams_reached_with_message_intervals(clock: FakeClock) -> None:
    v = FakeVehicle(clock)
    vl = vehicle_link(v)
    res = BridgeResult("", "", 0)
    assert StreamNegotiator(vl, lambda s: None).negotiate(res) is None
    msgs = res.streams["messages"]
    assert res.streams["method"] == "MAV_CMD_SET_MESSAGE_INTERVAL"
    # a 1 s window counts whole periods: the measured rate is the requested one within one
    # sample per window
    for name in ("ATTITUDE", "LOCAL_POSITION_NED", "VFR_HUD"):
        want = msgs[name]["requested_hz"]
        assert abs(msgs[name]["measured_hz"] - want) <= 1.0, (name, msgs[name])
    assert vl.arrivals is None  # measuring ends with the negotiation


def test_streams_fall_back_to_request_data_stream_when_refused(clock: FakeClock) -> None:
    v = FakeVehicle(clock, accept_intervals=False)
    vl = vehicle_link(v, Flavour.ARDUPILOT, wind_rate_hz=0.0)
    res = BridgeResult("", "", 0)
    assert StreamNegotiator(vl, lambda s: None).negotiate(res) is None
    assert res.streams["method"] == "MAV_CMD_SET_MESSAGE_INTERVAL + REQUEST_DATA_STREAM"
    asked = {int(m.req_stream_id): int(m.req_message_rate) for m in v.sent
             if m.get_type() == "REQUEST_DATA_STREAM"}  # fmt: skip
    m = vl.m
    assert asked[d.MAV_DATA_STREAM_EXTRA1] == math.ceil(m.attitude_rate_hz)
    assert asked[d.MAV_DATA_STREAM_POSITION] == math.ceil(m.position_rate_hz)


def test_streams_not_reached_say_which_and_how_fast(clock: FakeClock) -> None:
    v = FakeVehicle(clock, streams=False)
    vl = vehicle_link(v)
    t0 = clock.t
    why = StreamNegotiator(vl, lambda s: None).negotiate(BridgeResult("", "", 0))
    assert why is not None and "ATTITUDE at 0.0 Hz" in why, why
    # it gives up at stream_timeout_s (one 0.1 s wait of slack), not later
    assert clock.t - t0 <= vl.m.stream_timeout_s + 0.1 + 1e-9


# -- the session -----------------------------------------------------------------------------
def make_session(v: FakeVehicle) -> tuple[Session, ControlLoop, Phase]:
    vl = vehicle_link(v)
    cfg = px4_cfg()
    ctl = Controller(ControlSetup.of(cfg, vl.m))
    phase = Phase(lambda s: None)
    loop = ControlLoop(ctl, vl, phase, lambda st: None, lambda st: None)
    s = Session(cfg, loop, phase, OperatorDisplay(False), lambda s: None)
    vl.subscribe(
        dataclasses.replace(vl.handlers, heartbeat=s.on_heartbeat, vehicle=loop.on_vehicle)
    )
    return s, loop, phase


def test_mode_confirmed_by_ack_and_heartbeat(clock: FakeClock) -> None:
    v = FakeVehicle(clock)
    s, _, _ = make_session(v)
    ok, why = s.request_mode("OFFBOARD", s.in_offboard)
    assert (ok, why) == (True, "confirmed")
    assert s.mode_is("OFFBOARD") and s.n["mode_requests"] == 1


def test_mode_accepted_but_not_entered_is_not_confirmed(clock: FakeClock) -> None:
    v = FakeVehicle(clock, mode_follows=False)
    s, _, _ = make_session(v)
    t0 = clock.t
    ok, why = s.request_mode("OFFBOARD", s.in_offboard)
    assert not ok and why.startswith("accepted but the HEARTBEAT still reports"), why
    m = s.m
    assert s.n["mode_requests"] == m.mode_retries  # no re-asks: the ACKs did arrive
    # each attempt waits mode_timeout_s (real link: wall time), in 0.1 s slices
    assert clock.t - t0 <= m.mode_retries * (m.mode_timeout_s + 0.1) + 1e-9


def test_lost_acks_are_asked_again_while_the_heartbeat_shows_the_mode(clock: FakeClock) -> None:
    v = FakeVehicle(clock, ack_modes=False)
    v.custom_mode = PX4_OFFBOARD  # the mode is already there; the ACKs never come
    v._emit_heartbeat(clock.t)
    s, _, _ = make_session(v)
    ok, why = s.request_mode("OFFBOARD", s.in_offboard)
    assert not ok and why == "no COMMAND_ACK"
    assert s.n["mode_requests"] > s.m.mode_retries  # re-asked for the lost ACK


def test_a_mode_change_while_engaged_stops_without_fighting(clock: FakeClock) -> None:
    v = FakeVehicle(clock)
    s, loop, phase = make_session(v)
    assert s.request_mode("OFFBOARD", s.in_offboard)[0]
    s.engaged = True
    v.custom_mode = PX4_POSCTL  # the pilot takes it
    v._emit_heartbeat(clock.t + 0.1)
    with pytest.raises(_Stop) as e:
        s.vl.spin(1.0)
    assert e.value.kind == "pilot" and "by someone else" in e.value.reason
    # the hand-back after a pilot's mode change asks for nothing
    n = s.n["mode_requests"]
    phase.set(State.TRACKING)
    res = BridgeResult("", e.value.reason, 4)
    s.handback(res, "pilot")
    assert phase.state is State.DONE and s.n["mode_requests"] == n
    assert not res.handback_requested


# -- the control loop ------------------------------------------------------------------------
def test_watchdog_stops_when_attitude_stops(clock: FakeClock) -> None:
    v = FakeVehicle(clock)
    s, loop, phase = make_session(v)
    vl = s.vl
    vl.subscribe(dataclasses.replace(vl.handlers, tick=lambda: loop.tick(clock.t)))
    phase.set(State.TRACKING)
    loop.start()  # streaming, no ATTITUDE ever comes
    t0 = clock.t
    with pytest.raises(_Stop) as e:
        vl.spin(10.0)
    assert e.value.kind == "telemetry" and "no ATTITUDE" in e.value.reason
    # the watchdog fires within one wait slice of telemetry_timeout_s
    assert 0.0 <= clock.t - t0 - vl.m.telemetry_timeout_s <= link_io.MAX_WAIT_S + 1e-9
    assert loop.n["setpoints_sent"] == 0  # nothing to re-send before a first step


# -- receive times ---------------------------------------------------------------------------
def test_receive_time_is_the_tlog_record_time_exactly(tmp_path: Path) -> None:
    """The loop's receive time is the link's stamp, which is the tlog record's time to the
    bit: a replay of the tlog sees the same floats, and a run without a tlog (lean) the same
    stamps as with one."""
    import socket

    from mpf_mavlink.mavlink import iter_tlog, open_link

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    tl = tmp_path / "rx.tlog"
    link = open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1, tlog_path=tl)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    enc = d.MAVLink(None, srcSystem=1, srcComponent=1)
    stamps: dict[int, float | None] = {}
    try:
        for k in range(40):
            tx.sendto(bytes(enc.attitude_encode(1000 + 20 * k, 0, 0, 0, 0, 0, 0).pack(enc)),
                      ("127.0.0.1", port))  # fmt: skip
            msg = link.recv(0.2)  # None while the boot-clock gate settles
            if msg is not None:
                stamps[msg.time_boot_ms] = VehicleLink.rx_time(msg)
    finally:
        link.close()
        tx.close()
    recorded = {m.time_boot_ms: t for t, m in iter_tlog(str(tl)) if m.get_type() == "ATTITUDE"}
    assert len(stamps) >= 20 and all(recorded[ms] == t for ms, t in stamps.items())


def test_young_objects_are_collected_after_a_setpoint_before_the_collector_would() -> None:
    """live._collect_young: a no-op below 70 % of the collector's threshold, a collection of
    generation 0 at it (so the collector's own never lands inside a control step)."""
    import gc

    from mpf_mavlink.bridge import live

    gc.collect()
    live._collect_young()
    assert gc.get_count()[0] < live._GC_EARLY * live._GC_THRESHOLD0  # nothing to do
    keep = [[] for _ in range(int(live._GC_EARLY * live._GC_THRESHOLD0) + 10)]
    assert gc.get_count()[0] >= live._GC_EARLY * live._GC_THRESHOLD0
    live._collect_young()
    assert gc.get_count()[0] < 10
    del keep


def test_only_state_samples_move_the_vehicle_clock() -> None:
    """ATTITUDE_TARGET is stamped when the autopilot took the setpoint (frames old; PX4 v1.16
    freezes it) and WIND_COV's time_usec may be another clock: neither is the vehicle's now.
    Following them back, a lockstep telemetry timeout would fire a frame (or more) late."""
    m = load_config(str(ROOT / "configs" / "default.yaml")).section("mavlink")
    vl = VehicleLink(m)
    tx = d.MAVLink(None, srcSystem=m.vehicle_sysid, srcComponent=1)
    rx = d.MAVLink(None)

    def feed(msg: object) -> None:
        vl.dispatch(rx.parse_char(bytes(msg.pack(tx))))  # type: ignore[attr-defined]

    feed(tx.attitude_encode(17_300, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert vl.vehicle_t == 17.3
    feed(tx.local_position_ned_encode(17_820, 0.0, 0.0, -50.0, 16.0, 0.0, 0.0))
    assert vl.vehicle_t == 17.82
    feed(tx.attitude_target_encode(17_320, 0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.5))
    feed(tx.wind_cov_encode(1_700_000_000_000_000, 1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert vl.vehicle_t == 17.82
    # the 0.5 s telemetry timeout against an ATTITUDE at 17.30: over at 17.82, not held off
    assert vl.vehicle_since(17.3) > m.telemetry_timeout_s
