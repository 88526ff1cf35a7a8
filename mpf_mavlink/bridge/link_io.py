"""The bridge's link to one vehicle (:class:`VehicleLink`): what the vehicle tells us
(samples to its :class:`LinkHandlers`, acknowledgements to its commands, parameters, its
clock, arrival times), what we send, the timeouts on the wall or the vehicle's clock, and the
bounded wait every life-cycle step spins in."""

from __future__ import annotations

import math
import struct
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mpf_mavlink.bridge.commands import CommandChannel
from mpf_mavlink.mavlink import CommandAckSample, Flavour, HeartbeatSample, decode, dialect
from mpf_mavlink.mavlink.codec import AttitudeSample, GlobalPositionSample, LocalPositionSample

#: How often the bridge asks PX4 for TIMESYNC (s): the 16 answers kept (controller.py) span
#: 8 s, over which a line follows the clocks' drift.
TIMESYNC_PERIOD_S = 0.5
#: How often the companion HEARTBEAT goes out (s): MAVLink's 1 Hz convention.
HEARTBEAT_PERIOD_S = 1.0
#: The longest single wait for a message (s): duties (heartbeat, re-sends) run at least this often.
MAX_WAIT_S = 0.01

_INT_PARAM_TYPES = frozenset({1, 2, 3, 4, 5, 6})  # MAV_PARAM_TYPE_(U)INT8/16/32

#: The samples whose time stamp is the vehicle's "now" (the instant of the state they carry),
#: which alone move the vehicle's clock as the bridge sees it: ATTITUDE_TARGET's stamp is when
#: the autopilot took our setpoint (frames old, frozen on PX4 v1.16) and WIND_COV's time_usec
#: may be another clock, so either would move the clock back (or far ahead) and hold off a
#: lockstep timeout by a frame or more.
_CLOCK_SAMPLES = frozenset({AttitudeSample, LocalPositionSample, GlobalPositionSample})


def param_value(msg: Any, bytewise: bool) -> float | None:
    """A PARAM_VALUE's value; None if not finite. PX4 encodes integer parameters bytewise (the
    int's bits in the float field), ArduPilot casts them to float."""
    v = msg.param_value
    if bytewise and int(getattr(msg, "param_type", 9)) in _INT_PARAM_TYPES:
        return float(struct.unpack("<i", struct.pack("<f", v))[0])
    return float(v) if math.isfinite(v) else None


def param_set_value(value: float, param_type: int, bytewise: bool) -> float:
    """The float a PARAM_SET carries for ``value`` of a parameter of ``param_type``."""
    if bytewise and param_type in _INT_PARAM_TYPES:
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return float(value)


def _ignore_sample(sample: Any, rx: float | None) -> None:
    return None


def _nothing() -> None:
    return None


def _never(now: float) -> float:
    return math.inf


@dataclass(frozen=True)
class LinkHandlers:
    """Who receives what the vehicle link delivers (``rx``: the receive time, s since the
    epoch, as the tlog records it): ``heartbeat`` the autopilot's HeartbeatSamples,
    ``vehicle`` its other decoded samples (attitude, positions, VFR_HUD, wind, home, set-point
    echoes, TIMESYNC; COMMAND_ACKs go to :attr:`VehicleLink.commands`, PARAM_VALUEs to
    :attr:`VehicleLink.params`), ``target`` the live target's samples, ``tick()`` after every
    wait and every datagram's messages (a stream link: every message), ``due(now)`` the
    monotonic time (s) by which ``tick`` must run next."""

    heartbeat: Callable[[HeartbeatSample, float | None], None] = _ignore_sample
    vehicle: Callable[[Any, float | None], None] = _ignore_sample
    target: Callable[[Any, float | None], None] = _ignore_sample
    tick: Callable[[], None] = _nothing
    due: Callable[[float], float] = _never


class VehicleLink:
    """One vehicle over one MAVLink link (``link``: :class:`~mpf_mavlink.mavlink.link.Link`,
    opened by the bridge). What it receives goes to the :class:`LinkHandlers` given to
    :meth:`subscribe` (none: dropped); commands and their acknowledgements go through
    :attr:`commands` (:class:`~mpf_mavlink.bridge.commands.CommandChannel`)."""

    def __init__(self, m: Any, live_target: bool = False) -> None:
        self.m = m
        self.sysid: int = m.vehicle_sysid
        self.target_sysid: int | None = m.target_sysid if live_target else None
        self.link: Any = None
        self.flavour = Flavour.UNKNOWN
        self.compid = 1
        self.hb: Any = None  # latest autopilot HeartbeatSample
        self.params: dict[str, float] = {}  # PARAM_VALUE answers (name -> value)
        self.param_types: dict[str, int] = {}  # name -> MAV_PARAM_TYPE
        # arrival times (monotonic s) per message type while the stream rates are measured
        self.arrivals: dict[str, deque[float]] | None = None
        # the vehicle's clock (s since its boot): the stamp of its latest state sample
        self.vehicle_t: float | None = None
        self.last_hb_tx_mono = -math.inf
        self.last_ts_tx_mono = -math.inf  # the latest TIMESYNC request (PX4's loop delay)
        # lockstep: the latest ATTITUDE stamp (ms of the boot clock) answered, by a setpoint or
        # a clock answer; the simulation advances past a frame only once it is answered
        self.answered_ms = -1
        self.commands = CommandChannel(self)
        self._to = LinkHandlers()

    @property
    def handlers(self) -> LinkHandlers:
        """The handlers subscribed now (none: :class:`LinkHandlers`' defaults drop all)."""
        return self._to

    def subscribe(self, handlers: LinkHandlers) -> None:
        """Where the received samples and the ticks go from now on (replacing the handlers
        subscribed before; a wait already under way keeps its tick and due)."""
        self._to = handlers

    # -- sending -----------------------------------------------------------------------------
    def send(self, msg: Any) -> None:
        self.link.send(msg)

    def send_text(self, text: str, severity: int | None = None) -> None:
        """A STATUSTEXT from us (severity INFO unless given: the tlog's record of a decision;
        the envelope monitor's are WARNING, for the ground station's operator)."""
        sev = dialect.MAV_SEVERITY_INFO if severity is None else severity
        self.send(self.link.mav.statustext_encode(sev, text.encode("ascii")))

    def last_tx_record_s(self) -> float | None:
        """The record time (s) of the latest message sent, as a tlog reader computes it."""
        t: float | None = self.link.last_tx_s
        return t

    def duties(self, now: float) -> None:
        """The companion HEARTBEAT and (PX4, real time) the TIMESYNC requests."""
        if now - self.last_hb_tx_mono >= HEARTBEAT_PERIOD_S:
            self.last_hb_tx_mono = now
            self.link.send_heartbeat()
        if (
            self.flavour is Flavour.PX4
            and not self.m.lockstep  # a lockstep vehicle's clock is not comparable with ours
            and now - self.last_ts_tx_mono >= TIMESYNC_PERIOD_S
        ):
            # a request (tc1 = 0) stamped with the link's clock, which stamps the tlog too:
            # the answer measures the loop delay (Controller.note_sent)
            self.last_ts_tx_mono = now
            self.send(self.link.mav.timesync_encode(0, int(round(self.link.clock() * 1e9))))

    def close(self) -> None:
        if self.link is not None:
            self.link.close()

    # -- receiving ---------------------------------------------------------------------------
    @staticmethod
    def rx_time(msg: Any) -> float | None:
        """The receive time (s since the epoch) as the tlog records it: the link stamps each
        message with its record time, quantised to the tlog's microseconds, so replay sees
        exactly what we saw (and a run without a tlog sees the same)."""
        t = getattr(msg, "_timestamp", None)
        return None if t is None else round(t * 1e6) * 1e-6

    def dispatch(self, msg: Any) -> None:
        """One received message: bookkeeping here, decoded samples to the hooks. (A few per
        control frame: the type is read once, the receive time quantised inline as
        :meth:`rx_time` does.)"""
        src = msg.get_srcSystem()
        own = src == self.sysid
        mtype = msg.get_type()
        if own:
            if self.arrivals is not None:
                q = self.arrivals.setdefault(mtype, deque(maxlen=400))
                q.append(self.clock())
            if mtype == "PARAM_VALUE":
                self._param(msg)
                return
        elif src != self.target_sysid:
            return
        t = getattr(msg, "_timestamp", None)
        rx = None if t is None else round(t * 1e6) * 1e-6
        msg._timestamp = rx  # decoders copy it into the samples (VFR_HUD, WIND, HEARTBEAT)
        sample = decode(msg, mtype)
        if sample is None:
            return
        if not own:
            self._to.target(sample, rx)
            return
        cls = type(sample)
        if cls is HeartbeatSample:
            if sample.autopilot != dialect.MAV_AUTOPILOT_INVALID:  # not a GCS on our system id
                self.hb = sample
                self._to.heartbeat(sample, rx)
            return
        if cls is CommandAckSample:
            self.commands.deliver(sample)
            return
        if cls in _CLOCK_SAMPLES:
            self.vehicle_t = sample.t_boot_s
        self._to.vehicle(sample, rx)
        if cls is AttitudeSample and self.m.lockstep:
            self.answer_clock(sample.t_boot_s)

    def before_heartbeat(self, msg: Any) -> None:
        """Lockstep: the vehicle's ATTITUDE read while its HEARTBEAT is awaited is answered
        (with a clock answer), or the simulation would wait for it on the wall clock."""
        if self.m.lockstep and msg.get_type() == "ATTITUDE" and msg.get_srcSystem() == self.sysid:
            self.answer_clock(msg.time_boot_ms * 1e-3)

    def answer_clock(self, t_boot_s: float) -> None:
        """Lockstep: let the simulation past the frame of the ATTITUDE stamped ``t_boot_s`` (s of
        the boot clock) when no setpoint answered it, with a SYSTEM_TIME carrying that stamp
        (time_unix_usec 0: no wall time is claimed), so every phase of the life cycle runs on
        the vehicle's time and the flight does not depend on when either process got the CPU."""
        ms = int(round(t_boot_s * 1e3))
        if ms > self.answered_ms:
            self.answered_ms = ms
            self.send(self.link.mav.system_time_encode(0, ms))

    def _param(self, msg: Any) -> None:
        name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else ""
        v = param_value(msg, self.flavour is Flavour.PX4)
        if v is not None:
            self.params[name] = v
            self.param_types[name] = int(msg.param_type)

    def drain(self) -> None:
        """Take in what is waiting, without waiting (nor the periodic duties)."""
        while (msg := self.link.recv(0.0)) is not None:
            self.dispatch(msg)

    def spin(self, timeout_s: float, until: Callable[[], bool] | None = None) -> bool:
        """Pump messages and duties until ``until()`` (True) or the timeout (False). Lockstep
        (once the vehicle's clock is known): the timeout counts vehicle time, so a wait ends
        after the same simulated time however fast the host runs, bounded by
        ``lockstep_wall_timeout_s`` of wall time for a vehicle that sends nothing."""
        t_end = time.monotonic() + timeout_s
        vt_end = math.inf
        if self.m.lockstep and self.vehicle_t is not None:
            vt_end = self.vehicle_t + timeout_s
            t_end = time.monotonic() + max(timeout_s, self.m.lockstep_wall_timeout_s)
        link, dispatch, to = self.link, self.dispatch, self._to
        due, tick = to.due, to.tick
        while True:
            if until is not None and until():
                return True
            now = time.monotonic()
            if now >= t_end or (self.vehicle_t is not None and self.vehicle_t >= vt_end):
                return False
            wait = min(t_end - now, MAX_WAIT_S, max(0.0, due(now) - now))
            msg = link.recv(wait)
            while msg is not None:
                dispatch(msg)
                # the rest of the datagram first (it is here: no wait to work out), the duties
                # once per wake-up
                if not link.buffered():
                    break
                if until is not None and until():
                    return True
                msg = link.recv(0.0)
            tick()

    # -- timeouts ----------------------------------------------------------------------------
    def clock(self) -> float:
        """The life cycle's clock (s): the vehicle's (its latest state's stamp) in lockstep once
        it has one, else the wall clock (monotonic); only differences of it mean anything."""
        if self.m.lockstep and self.vehicle_t is not None:
            return self.vehicle_t
        return time.monotonic()

    def elapsed(self, since_mono: float, since_vt: float | None) -> float:
        """Seconds since an instant (``since_mono`` on the wall clock, ``since_vt`` on the
        vehicle's): vehicle time in lockstep, wall time on a real link."""
        if self.m.lockstep:
            return self.vehicle_since(since_vt)
        return time.monotonic() - since_mono

    def left(
        self, since_mono: float, since_vt: float | None, timeout_s: float, wall_s: float = 0.0
    ) -> float:
        """Seconds left until ``timeout_s`` has passed since an instant (``since_mono`` on the
        wall clock, ``since_vt`` on the vehicle's); negative once it has. A real link: wall
        time. Lockstep (``mavlink.lockstep``): the vehicle's time, which stands still while the
        simulation is starved, bounded by ``wall_s`` (default ``lockstep_wall_timeout_s``) of
        wall time for a vehicle that sends nothing at all."""
        wall = time.monotonic() - since_mono
        m = self.m
        if not m.lockstep:
            return timeout_s - wall
        # twice per control frame (the watchdog): vehicle_since and min() written out
        vt, since = self.vehicle_t, 0.0
        if vt is not None and since_vt is not None and vt - since_vt > 0.0:
            since = vt - since_vt
        left, wall_left = timeout_s - since, (wall_s or m.lockstep_wall_timeout_s) - wall
        return wall_left if wall_left < left else left

    def vehicle_since(self, since_vt: float | None) -> float:
        """Vehicle seconds since ``since_vt``; 0 before any time stamp or after a reboot (its
        clock restarted: the mode change it comes back in, or the wall bound, ends the run)."""
        if self.vehicle_t is None or since_vt is None:
            return 0.0
        return max(0.0, self.vehicle_t - since_vt)

    def since(self, since_mono: float, since_vt: float | None) -> str:
        """How long ago an instant was, for a log line (in lockstep both clocks)."""
        wall = time.monotonic() - since_mono
        if not self.m.lockstep:
            return f"{wall:.2f} s"
        return f"{self.vehicle_since(since_vt):.2f} s of vehicle time ({wall:.2f} s wall)"
