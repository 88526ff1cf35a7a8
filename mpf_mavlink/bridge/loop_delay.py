"""The loop delay (:class:`LoopDelay`): from an ATTITUDE sample's time to when the setpoint
answering it acts, both on the autopilot's clock, and the body-rate setpoints still in flight
over the prediction horizon. Pure: time comes from the samples and the record times passed in.

The delay d from an ATTITUDE sample's time to when the setpoint answering it acts, both on
the autopilot's clock, is measured two ways:

1. The ATTITUDE_TARGET echo, when its stamp moves: an autopilot that stamps the set-point
   it uses with the time it received it (PX4 with attitude set-points, our SIL) gives d
   directly, everything included. It is preferred whenever it exists.
2. TIMESYNC (PX4 body rates): PX4 v1.16 in body-rate OFFBOARD stamps ATTITUDE_TARGET with
   the last attitude set-point from before OFFBOARD, frozen for the whole flight (its body
   rates move, its time does not), so (1) never measures. PX4 answers TIMESYNC with its
   boot clock (the clock of time_boot_ms, in ns): the instant a setpoint reaches PX4, on
   PX4's clock, is its send time plus the clocks' offset plus the uplink latency, and d
   is that minus the ATTITUDE's time. Each answer gives an offset assuming half its
   round trip each way; the uplink latency added back is half the median round trip: on
   a steady link their sum is tc1 - ts1, the request's own uplink latency plus the
   offset, so an asymmetric link does not bias it. The clocks drift: PX4 SITL's lockstep
   clock ran 1.1 % slow on a loaded host (11 ms/s), so the offset is a straight line
   fitted to the last answers (queued ones, round trip beyond twice the median, left
   out) and read at the send time. It
   covers the telemetry's age when sent, the link both ways and the bridge's own time;
   what it leaves out is PX4's receiver-to-rate-controller hop (one uORB publication,
   at most a rate-loop period, a few ms): a lower bound by that much.
   The other candidate, the ATTITUDE body rates' response to the rates sent, measures the
   delay plus the rate loop's own lag, which the prediction must not add (the rate loop
   is modelled as tracking the setpoint), and needs excitation a circle does not give.
Both are deterministic functions of the tlog (record times and message contents), so a
replay measures the same delays: the send time is the tlog record time of the step's
first SET_ATTITUDE_TARGET (:meth:`LoopDelay.note_sent`).
"""

from __future__ import annotations

import collections
import math
from typing import Any

#: TIMESYNC answers kept for the clock offset (the bridge asks every 0.5 s: 8 s of them)
TIMESYNC_WINDOW = 16
#: Loop delays kept per source; the median of them is used (one late echo does not move it)
DELAYS_KEPT = 9
#: Body-rate setpoints kept (with their times) for the echo match and the prediction
SENT_KEPT = 64
#: A delay beyond this (s) is no link to mend (a clock jump, another setpoint's echo)
MAX_DELAY_S = 0.5


class LoopDelay:
    """The loop delay in use (:attr:`delay_s`, s) and how it was measured; ``rates_pipeline``:
    body rates are sent (PX4), the only case with TIMESYNC and setpoints in flight."""

    def __init__(self, known_delay_s: float, rates_pipeline: bool) -> None:
        self.delay_s = float(known_delay_s)
        self.rates_pipeline = rates_pipeline
        # body rates sent: (mission time of the ATTITUDE answered, (p, q, r))
        self.sent: collections.deque[tuple[float, tuple[float, float, float]]] = collections.deque(
            maxlen=SENT_KEPT
        )
        self.delays: collections.deque[float] = collections.deque(maxlen=DELAYS_KEPT)  # echoes
        self.ts_delays: collections.deque[float] = collections.deque(maxlen=DELAYS_KEPT)
        self.echo_tb: float | None = None  # the stamp of the latest echo (s, autopilot time)
        self.echoes_frozen = 0  # echoes whose stamp had not moved: no measurement
        # TIMESYNC answers: (receive time s, round trip s, vehicle clock minus ours s)
        self.timesync: collections.deque[tuple[float, float, float]] = collections.deque(
            maxlen=TIMESYNC_WINDOW
        )
        self.tx_due: float | None = None  # the autopilot time of the step not yet sent

    def sent_rates(self, t: float, rates: tuple[float, float, float], t_boot_s: float) -> None:
        """A step at mission time t (s) commanded body ``rates``; its ATTITUDE's autopilot time
        ``t_boot_s`` (s) waits for :meth:`note_sent`."""
        if self.sent and t <= self.sent[-1][0]:  # a restarted clock: the old ones are moot
            self.sent.clear()
        self.sent.append((t, rates))
        self.tx_due = t_boot_s

    def delay_source(self) -> str:
        """Where :attr:`delay_s` comes from: "echo", "timesync" or "mavlink.known_delay_s"."""
        return "echo" if self.delays else "timesync" if self.ts_delays else "mavlink.known_delay_s"

    def _use_delay(self) -> None:
        q = self.delays or self.ts_delays
        if q:
            self.delay_s = sorted(q)[len(q) // 2]

    def timesync_answer(self, sample: Any, rx: float | None) -> None:
        """A TIMESYNC answer to one of our requests (ts1 = our clock when sent, ns): its round
        trip and the offset of the vehicle's clock from ours (s), assuming a symmetric link.
        An answer to someone else's request (a round trip outside [0, 1] s) is ignored."""
        if rx is None or not self.rates_pipeline:
            return
        ts = sample.ts1_ns * 1e-9
        rtt = rx - ts
        if not 0.0 <= rtt <= 1.0:
            return
        self.timesync.append((rx, rtt, sample.tc1_ns * 1e-9 - 0.5 * (ts + rx)))

    def clock_offset(self, t: float) -> tuple[float, float] | None:
        """(vehicle clock minus ours at our time t, half the median round trip), both s, from
        the TIMESYNC answers kept; None without any."""
        if not self.timesync:
            return None
        rtts = sorted(r for _, r, _ in self.timesync)
        med = rtts[len(rtts) // 2]
        good = [(x, o) for x, r, o in self.timesync if r <= 2.0 * med + 1e-4]
        n = len(good)
        tl, ol = good[-1]
        if n < 3 or tl - good[0][0] < 1.0:
            return ol, 0.5 * med
        # least squares o = a + b (x - tl), centred on the latest answer
        mx = sum(x - tl for x, _ in good) / n
        mo = sum(o for _, o in good) / n
        sxx = sum((x - tl - mx) ** 2 for x, _ in good)
        b = sum((x - tl - mx) * (o - mo) for x, o in good) / sxx
        return mo + b * (t - tl - mx), 0.5 * med

    def note_sent(self, t_tx: float) -> None:
        """The latest step's setpoint was sent at t_tx (s, the tlog record time of its first
        SET_ATTITUDE_TARGET): with TIMESYNC answers, one measurement of the loop delay (see
        above). Re-sends of the same setpoint do not count."""
        tb, self.tx_due = self.tx_due, None
        got = None if tb is None else self.clock_offset(t_tx)
        if tb is None or got is None:
            return
        off, one_way = got
        d = t_tx + off + one_way - tb
        if 0.0 <= d <= MAX_DELAY_S:  # beyond: a clock jump, not a link to mend
            self.ts_delays.append(d)
            self._use_delay()

    def echo(self, sample: Any, t0: float) -> None:
        """The autopilot's ATTITUDE_TARGET: when our setpoint reached it. Only an echo whose
        stamp moved since the previous one measures (a frozen stamp, PX4 v1.16's body-rate
        OFFBOARD, says nothing about when). The setpoint is found by its body rates (float32
        on the wire) among those sent; the loop delay is the echo's time minus the time of the
        ATTITUDE that setpoint answered, both on the autopilot's clock. The delay in use is
        the median of the last 9 (one late echo does not move it)."""
        prev, self.echo_tb = self.echo_tb, sample.t_boot_s
        if prev is not None and sample.t_boot_s <= prev:
            self.echoes_frozen += 1
            return
        if not self.sent or not math.isfinite(t0):
            return
        te = sample.t_boot_s - t0
        a, b, c = sample.rates_frd
        for ts, (p, q, r) in reversed(self.sent):
            if ts > te:
                continue
            if (
                abs(p - a) <= 1e-6 * max(1.0, abs(p))
                and abs(q - b) <= 1e-6 * max(1.0, abs(q))
                and abs(r - c) <= 1e-6 * max(1.0, abs(r))
            ):
                d = te - ts
                if (
                    0.0 <= d <= MAX_DELAY_S
                ):  # beyond: not this setpoint's echo, or not a link to mend
                    self.delays.append(d)
                    self._use_delay()
                return

    def segments(self, t: float, tau: float, rates: Any, qb: float) -> list[tuple[float, Any]]:
        """The body rates over [t, t + tau]: the PX4 rate setpoints already sent act from
        their ATTITUDE's time + the loop delay, one period each (the rate loop tracks them);
        before the first of them and for ArduPlane (attitude setpoints) the measured ``rates``.
        ``qb``: the pitch-rate bias the autopilot flies on top of the rates sent (rad/s)."""
        if not self.rates_pipeline or not self.sent:
            return [(tau, rates)]
        d = self.delay_s
        segs: list[tuple[float, Any]] = []
        now = t
        end = t + tau
        # ``sent`` is in time order: walk back to the latest setpoint acting now (those before
        # it matter no more), then forward through those that start within the horizon
        later: list[tuple[float, tuple[float, float, float]]] = []
        for ts, (p_, q_, r_) in reversed(self.sent):
            a = ts + d  # when that setpoint starts acting
            if a <= now:
                rates = (p_, q_ + qb, r_)  # acting now (the latest that started)
                break
            later.append((a, (p_, q_ + qb, r_)))
        for a, r in reversed(later):
            if a >= end:
                break
            segs.append((a - now, rates))
            now, rates = a, r
        segs.append((end - now, rates))
        return segs
