"""Clocks for the simulated MAVLink vehicle (:mod:`sim.vehicle.vehicle`).

The vehicle advances its physics in frames of one telemetry period (default 20 ms of SIMULATED
time) and, after each frame, asks its clock to wait. The clock calls back into the vehicle:

* ``poll(timeout_s) -> bool`` - read incoming MAVLink for up to ``timeout_s`` wall seconds;
  returns True once "the answer" has arrived (a SET_ATTITUDE_TARGET received after the last
  telemetry frame was written);
* ``has_peer() -> bool`` - whether anybody is connected (a ``udpin`` link learns its peer from
  the first packet it receives).

Two clocks:

* :class:`LockstepClock` - wait for the answer, at most ``answer_timeout_s`` of WALL time, then
  advance anyway. A bridge that answers every frame drives the simulation as fast as both sides
  can compute (faster than real time); a dead or silent bridge still sees simulated time pass
  (at ``frame_period / answer_timeout_s`` of real time, e.g. 20 ms / 50 ms = 0.4x), so its
  offboard-loss timeout is met in sim time. While the bridge answers, a frame waits up to
  ``answered_timeout_s`` (1 s) instead: a bridge that is only slow for once (descheduled on a
  loaded machine) is waited for rather than left a frame behind, which would make the flight
  depend on the machine's load; the first frame it leaves unanswered brings the short timeout
  back. A mode change it asks for ends the waits until it is applied (the hand-back:
  :mod:`sim.vehicle.lockstep`). With nobody connected at all the clock paces at real time (a
  vehicle alone in the world behaves like a real one). ``answer_timeout_s = 0`` gives a
  free-running simulation (never waits). ``spin_s``: before it sleeps, the wait polls the socket
  for up to that much wall time (yielding the core to anything else runnable between polls):
  a peer's answer that lands in a sleeping process costs the peer's send a wake-up of this one
  (on a virtual machine an inter-processor interrupt), paid on the simulation's critical path,
  the bridge's frame; a process that slept also finds its caches cold. A wait that outlasts the
  spin (a loaded machine, a slow peer) sleeps as before, and after a run of them the spin rests
  for a while, so a machine with more simulations than cores does not burn its cores polling.
  Only the wait changes: the same answer ends the same frame (the flight is the same).
  ``spin_cpu_s`` is the CPU time spent spinning, which is waiting, not the vehicle's work.
* :class:`RealtimeClock` - paced to the wall clock (``speed`` x real time), polling the link
  while it waits. If the computation falls more than ``max_lag_s`` behind, the pacing is
  re-anchored instead of bursting to catch up.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import Protocol

PollFn = Callable[[float], bool]
PeerFn = Callable[[], bool]


class Clock(Protocol):
    mode: str

    def start(self, sim_t: float) -> None: ...

    def wait(self, sim_t: float, poll: PollFn, has_peer: PeerFn) -> None: ...


class RealtimeClock:
    """Paced to the wall clock: sim time ``t`` is released at ``wall0 + (t - t0) / speed``."""

    mode = "realtime"

    def __init__(self, speed: float = 1.0, max_lag_s: float = 0.5):
        if speed <= 0:
            raise ValueError("speed must be > 0")
        self.speed = float(speed)
        self.max_lag_s = float(max_lag_s)
        self._wall0: float | None = None
        self._sim0 = 0.0

    def start(self, sim_t: float) -> None:
        self._wall0 = time.monotonic()
        self._sim0 = sim_t

    def wait(self, sim_t: float, poll: PollFn, has_peer: PeerFn) -> None:
        if self._wall0 is None:
            self.start(sim_t)
        assert self._wall0 is not None
        target = self._wall0 + (sim_t - self._sim0) / self.speed
        now = time.monotonic()
        if now - target > self.max_lag_s:  # far behind: re-anchor, do not burst
            self._wall0, self._sim0 = now, sim_t
            poll(0.0)
            return
        while True:
            remaining = target - time.monotonic()
            if remaining <= 0.0:
                poll(0.0)
                return
            if poll(remaining):
                # poll() returns at once after the frame's answer (the lockstep clock's cue):
                # realtime pacing must still wait, so read again at most every 2 ms instead of
                # spinning a core for the rest of the frame
                time.sleep(min(remaining, 0.002))


class LockstepClock:
    """Wait for the bridge's answer to each telemetry frame, with a wall-clock fallback."""

    mode = "lockstep"

    #: spins in a row that ended without the answer before the spin rests, and for how many
    #: frames it then rests (the wait sleeps at once meanwhile)
    SPIN_MISSES_MAX = 8
    SPIN_REST_FRAMES = 250

    def __init__(
        self, answer_timeout_s: float = 0.05, answered_timeout_s: float = 1.0, spin_s: float = 0.0
    ):
        if answer_timeout_s < 0:
            raise ValueError("answer_timeout_s must be >= 0")
        if not spin_s >= 0.0:
            raise ValueError("spin_s must be >= 0")
        self.spin_s = float(spin_s)
        # whether anything waits to be read (the vehicle's link sets it): the spin reads only
        # then; None: it reads every time
        self.ready: Callable[[], bool] | None = None
        self.spin_cpu_s = 0.0  # CPU time spent spinning (s): waiting, not work
        self.spun = 0  # frames whose answer came while spinning
        self._misses = 0  # spins in a row that ended without the answer
        self._rest = 0  # frames left before the spin is tried again
        self.answer_timeout_s = float(answer_timeout_s)
        # after an answered frame (and for a peer's first): never shorter than the plain one,
        # and 0 (free-running) stays 0
        self.answered_timeout_s = (
            max(float(answered_timeout_s), self.answer_timeout_s) if self.answer_timeout_s else 0.0
        )
        self._answering = True  # the last frame ended on its answer
        self._rt = RealtimeClock()  # used while nobody is connected
        self.frames = 0
        self.answered_frames = 0  # frames that ended with an answer (not the timeout)
        self.timeouts = 0  # frames a connected peer left unanswered for their timeout

    def start(self, sim_t: float) -> None:
        self._rt.start(sim_t)

    def wait(self, sim_t: float, poll: PollFn, has_peer: PeerFn) -> None:
        self.frames += 1
        if not has_peer():
            self._rt.wait(sim_t, poll, has_peer)
            self._answering = True  # a peer that comes (or engages) gets the long wait first
            return
        self._rt.start(sim_t)  # keep the realtime anchor fresh for a later disconnect
        timeout = self.answered_timeout_s if self._answering else self.answer_timeout_s
        if self.spin_s > 0.0 and self._answering and timeout > 0.0:
            if self._rest > 0:
                self._rest -= 1
            elif self._spin(poll):
                return
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if poll(max(0.0, remaining)):
                self.answered_frames += 1
                self._answering = True
                return
            if remaining <= 0.0:
                self.timeouts += 1
                self._answering = False
                return

    def _spin(self, poll: PollFn) -> bool:
        """Poll without sleeping for up to ``spin_s`` (wall); True: the answer came."""
        cpu0 = time.thread_time()
        end = time.monotonic() + self.spin_s
        answered = False
        ready = self.ready
        while True:
            if (ready is None or ready()) and poll(0.0):
                answered = True
                break
            if time.monotonic() >= end:
                break
            os.sched_yield()  # a process that needs this core (its peer, another run) gets it
        self.spin_cpu_s += time.thread_time() - cpu0
        if answered:
            self.answered_frames += 1
            self.spun += 1
            self._misses = 0
            return True
        self._misses += 1
        if self._misses >= self.SPIN_MISSES_MAX:
            self._misses, self._rest = 0, self.SPIN_REST_FRAMES
        return False


def make_clock(clock: str | Clock = "lockstep", **kw: float) -> Clock:
    """``"lockstep"`` (kw: answer_timeout_s, spin_s), ``"realtime"`` (kw: speed) or a clock
    object."""
    if not isinstance(clock, str):
        return clock
    if clock == "lockstep":
        return LockstepClock(
            answer_timeout_s=kw.get("answer_timeout_s", 0.05),
            answered_timeout_s=kw.get("answered_timeout_s", 1.0),
            spin_s=kw.get("spin_s", 0.0),
        )
    if clock == "realtime":
        return RealtimeClock(speed=kw.get("speed", 1.0))
    raise ValueError(f"unknown clock {clock!r}: use 'lockstep' or 'realtime'")


class StepClock:
    """The vehicle's own time: physics steps of ``dt`` since boot (the trim flight included).

    ``boot_s`` is what MAVLink's time_boot_ms carries; ``t`` counts from when the vehicle was
    ready (``mark_ready``), the time of the truth record and the scripted target.

    ``boot_s`` and ``t`` are plain attributes, kept by :meth:`advance` (and the ``k`` setter):
    every piece of the vehicle reads them, a dozen times a frame, and a property is a Python
    call each time."""

    __slots__ = ("dt", "_k", "k0", "boot_s", "t", "_ms")

    def __init__(self, dt: float, k: int = 0):
        self.dt = float(dt)
        self.k0 = int(k)  # physics steps since boot when the vehicle was ready
        self.k = int(k)  # physics steps since boot

    @property
    def k(self) -> int:
        return self._k

    @k.setter
    def k(self, k: int) -> None:
        self._k = k
        self.boot_s = k * self.dt
        self.t = (k - self.k0) * self.dt
        self._ms = -1  # ms() of this k, not computed yet

    def advance(self) -> None:
        """One physics step on."""
        k = self._k = self._k + 1
        self.boot_s = k * self.dt
        self.t = (k - self.k0) * self.dt
        self._ms = -1

    def mark_ready(self) -> None:
        self.k0 = self._k
        self.t = 0.0

    @property
    def ready_boot_s(self) -> float:
        """Boot time (s) of t = 0."""
        return self.k0 * self.dt

    def ms(self) -> int:
        ms = self._ms
        if ms < 0:
            ms = self._ms = int(round(self.boot_s * 1000.0))
        return ms

    def us(self) -> int:
        return int(round(self._k * self.dt * 1e6))
