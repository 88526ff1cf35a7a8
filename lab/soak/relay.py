"""A UDP impairment relay between the bridge and a vehicle, on real loopback sockets.

Topology (both peers keep their ordinary pymavlink URLs)::

    vehicle --udpout:127.0.0.1:V--> [vehicle side :V] relay [bridge side :eph] --> udpin:B bridge
            <-------------- (to the vehicle's last source address)  <------ (replies to :eph)

The vehicle side is bound to a known port ``V`` and learns the vehicle's address from the last
datagram it received (a restarted vehicle process comes back from a new source port, as a
rebooted autopilot would). The bridge side sends to the bridge's listening port ``B`` from an
ephemeral port; the bridge answers there (pymavlink ``udpin`` replies to its clients).

Each direction ("down": vehicle -> bridge, "up": bridge -> vehicle) has its own
:class:`Impairment` and its own seeded random generator, so a run is reproducible for a given
seed and traffic order. Per datagram, in this order: blackout (dropped), loss (dropped),
corruption (``corrupt_bytes`` random bytes XORed with a random non-zero value), delay
(``delay_s`` + uniform [0, ``jitter_s``]), reordering (held back ``reorder_s`` more),
duplication (a second copy ``dup_gap_s`` later). Delayed datagrams are released from a heap by
release time, so jitter larger than the packet interval reorders them, as a real network does.

Everything is counted (:class:`DirStats`) and every received datagram can be kept with its fate
(:attr:`UdpRelay.log`) so that tests judge what the vehicle actually received, independently of
the bridge's own records. Extra datagrams (fuzz, spoofing, a ground station) are put on the
wire with :meth:`UdpRelay.inject`; they share the destination socket, hence the receiver's
parser stream, with the relayed traffic.
"""

from __future__ import annotations

import heapq
import random
import select
import socket
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

DOWN = "down"  # vehicle -> bridge (telemetry, target, acks)
UP = "up"  # bridge -> vehicle (setpoints, mode requests, heartbeats)
DIRECTIONS = (DOWN, UP)


@dataclass(frozen=True)
class Impairment:
    """What one direction of the link suffers. Probabilities in [0, 1], times in seconds."""

    loss: float = 0.0  # a datagram is dropped
    delay_s: float = 0.0  # fixed one-way delay
    jitter_s: float = 0.0  # extra delay, uniform in [0, jitter_s]
    duplicate: float = 0.0  # a datagram is delivered twice
    dup_gap_s: float = 0.001  # the copy follows this much later
    reorder: float = 0.0  # a datagram is held back reorder_s more (overtaken by the next ones)
    reorder_s: float = 0.03
    corrupt: float = 0.0  # corrupt_bytes random bytes of a datagram are damaged
    corrupt_bytes: int = 1

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder", "corrupt"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"Impairment.{name} must be in [0, 1], got {p}")
        for name in ("delay_s", "jitter_s", "dup_gap_s", "reorder_s"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"Impairment.{name} must be >= 0, got {getattr(self, name)}")
        if self.corrupt_bytes < 1:
            raise ValueError("Impairment.corrupt_bytes must be >= 1")


@dataclass(frozen=True)
class Blackout:
    """Drop everything in ``direction`` (None: both) during [start_s, end_s) of relay time.
    ``sysid``: only the MAVLink frames from this system id (e.g. the moving target's feed),
    cut out of the datagrams that carry them; None: whole datagrams."""

    start_s: float
    end_s: float
    direction: str | None = None
    sysid: int | None = None

    def active(self, t: float, direction: str) -> bool:
        return self.start_s <= t < self.end_s and (
            self.direction is None or self.direction == direction
        )


@dataclass
class DirStats:
    received: int = 0  # datagrams that arrived at the relay
    delivered: int = 0  # datagrams sent on (copies and injections included)
    dropped_loss: int = 0
    dropped_blackout: int = 0
    corrupted: int = 0
    duplicated: int = 0
    reordered: int = 0
    delayed: int = 0  # held back by delay or jitter (> 0 s)
    injected: int = 0  # extra datagrams put on the wire by inject()
    no_destination: int = 0  # arrived before the other side was known, or the send failed
    filtered_frames: int = 0  # frames cut out of datagrams by a per-system blackout
    bytes_in: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class Datagram:
    """One datagram as the relay saw it (``t`` relay-monotonic seconds, see :attr:`UdpRelay.t0`)."""

    t: float
    direction: str
    data: bytes
    fate: str  # "delivered" | "loss" | "blackout" | "injected" | "no_destination"
    corrupted: bool = False
    sent: bytes | None = None  # what went on towards the receiver (corrupted or not); None: dropped


def mavlink_sysid(data: bytes) -> int | None:
    """System id of the first MAVLink frame of a datagram (v1 0xFE: byte 3, v2 0xFD: byte 5)."""
    if len(data) >= 6 and data[0] == 0xFD:
        return data[5]
    if len(data) >= 4 and data[0] == 0xFE:
        return data[3]
    return None


def split_frames(data: bytes) -> list[bytes] | None:
    """The MAVLink frames of a datagram (several per datagram are common: PX4 and the SIL vehicle
    pack a whole telemetry frame into one), by their header lengths; None when the datagram is
    not a clean sequence of frames (then it can only be judged as a whole)."""
    out, i, n = [], 0, len(data)
    while i < n:
        if data[i] == 0xFD and i + 10 <= n:
            size = 10 + data[i + 1] + 2 + (13 if data[i + 2] & 0x01 else 0)
        elif data[i] == 0xFE and i + 6 <= n:
            size = 6 + data[i + 1] + 2
        else:
            return None
        if i + size > n:
            return None
        out.append(data[i : i + size])
        i += size
    return out


def _bind(host: str, port: int) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)  # a fuzz burst must not overflow it
    s.bind((host, port))
    s.setblocking(False)
    return s


class UdpRelay:
    """Relay between a vehicle (``udpout`` to ``vehicle_port``) and a bridge (``udpin`` on
    ``bridge_port``). Start with :meth:`start`, stop with :meth:`stop` (or use ``with``).

    ``down`` / ``up``: impairments of each direction; ``blackouts``: fixed windows in relay time
    (add more at run time with :meth:`blackout`); ``seed``: the random generators' seed;
    ``keep_log``: keep every datagram (:attr:`log`) for later analysis.
    """

    def __init__(
        self,
        vehicle_port: int,
        bridge_port: int,
        *,
        host: str = "127.0.0.1",
        down: Impairment = Impairment(),
        up: Impairment = Impairment(),
        blackouts: Iterable[Blackout] = (),
        seed: int = 0,
        keep_log: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.imp = {DOWN: down, UP: up}
        self._blackouts: list[Blackout] = list(blackouts)
        self._rng = {DOWN: random.Random(f"{seed}-down"), UP: random.Random(f"{seed}-up")}
        self.stats = {DOWN: DirStats(), UP: DirStats()}
        self.keep_log = keep_log
        self.log: list[Datagram] = []
        self._clock = clock
        self.vsock = _bind(host, vehicle_port)
        self.bsock = _bind(host, 0)
        self.vehicle_port = self.vsock.getsockname()[1]
        self.bridge_addr = (host, int(bridge_port))
        self.vehicle_addr: tuple[str, int] | None = None
        self._heap: list[tuple[float, int, str, bytes]] = []
        self._seq = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.t0 = clock()
        # the longest the relay's own loop went without running (its process stalled: the GIL,
        # or the machine); a judge of timing must know when the relay itself was late
        self.max_loop_gap_s = 0.0
        self.loop_gaps: list[tuple[float, float]] = []  # (relay t, gap s) of gaps > 0.1 s

    # -- control ---------------------------------------------------------------------------
    def now(self) -> float:
        """Relay time (s since construction)."""
        return self._clock() - self.t0

    def blackout(
        self,
        duration_s: float,
        direction: str | None = None,
        sysid: int | None = None,
        start_in_s: float = 0.0,
    ) -> Blackout:
        """Start a blackout ``start_in_s`` from now, lasting ``duration_s``; returns it (relay
        time)."""
        t = self.now() + start_in_s
        b = Blackout(t, t + duration_s, direction, sysid)
        with self._lock:
            self._blackouts.append(b)
        return b

    def set_impairment(self, direction: str, imp: Impairment) -> None:
        with self._lock:
            self.imp[direction] = imp

    def inject(self, direction: str, data: bytes) -> bool:
        """Put ``data`` on the wire now, as if it came from the other side of ``direction``
        (``DOWN``: towards the bridge, from the bridge-side socket). False when the destination
        is not known yet (UP before the vehicle spoke) or the send failed."""
        with self._lock:
            st = self.stats[direction]
            st.injected += 1
            ok = self._send(direction, bytes(data))
            if self.keep_log:
                fate = "injected" if ok else "no_destination"
                self.log.append(
                    Datagram(
                        self.now(), direction, bytes(data), fate, False, bytes(data) if ok else None
                    )
                )
        return ok

    def start(self) -> UdpRelay:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, daemon=True, name="UdpRelay")
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        for s in (self.vsock, self.bsock):
            try:
                s.close()
            except OSError:
                pass

    def __enter__(self) -> UdpRelay:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def counters(self) -> dict[str, dict[str, int]]:
        with self._lock:
            return {d: self.stats[d].as_dict() for d in DIRECTIONS}

    def datagrams(self, direction: str | None = None, start: int = 0) -> list[Datagram]:
        """A snapshot of the log from index ``start`` (optionally one direction)."""
        with self._lock:
            part = self.log[start:]
        return [d for d in part if direction is None or d.direction == direction]

    # -- the loop --------------------------------------------------------------------------
    def _send(self, direction: str, data: bytes) -> bool:
        """Caller holds the lock."""
        st = self.stats[direction]
        try:
            if direction == DOWN:
                self.bsock.sendto(data, self.bridge_addr)
            else:
                if self.vehicle_addr is None:
                    st.no_destination += 1
                    return False
                self.vsock.sendto(data, self.vehicle_addr)
        except OSError:  # nobody listening yet (ICMP port unreachable): a radio would lose it too
            st.no_destination += 1
            return False
        st.delivered += 1
        return True

    def _schedule(self, t_release: float, direction: str, data: bytes) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (t_release, self._seq, direction, data))

    def _arrive(self, direction: str, data: bytes) -> None:
        """Caller holds the lock."""
        t = self.now()
        st, imp, rng = self.stats[direction], self.imp[direction], self._rng[direction]
        st.received += 1
        st.bytes_in += len(data)
        fate, corrupted = "delivered", False
        payload = data  # what goes on: the datagram, less the frames of blacked-out systems
        active = [b for b in self._blackouts if b.active(t, direction)]
        if any(b.sysid is None for b in active):
            st.dropped_blackout += 1
            fate = "blackout"
        elif active:  # cut the frames of the blacked-out systems out of the datagram
            cut = {b.sysid for b in active}
            frames = split_frames(data)
            if frames is None:
                frames = [data] if mavlink_sysid(data) not in cut else []
            kept = [f for f in frames if mavlink_sysid(f) not in cut]
            st.filtered_frames += len(frames) - len(kept)
            if not kept:
                st.dropped_blackout += 1
                fate = "blackout"
            elif len(kept) < len(frames):
                payload = b"".join(kept)
        if fate == "delivered" and imp.loss > 0.0 and rng.random() < imp.loss:
            st.dropped_loss += 1
            fate = "loss"
        if self.keep_log and fate != "delivered":
            self.log.append(Datagram(t, direction, data, fate))
        if fate != "delivered":
            return
        out = payload
        if imp.corrupt > 0.0 and out and rng.random() < imp.corrupt:
            buf = bytearray(out)
            for _ in range(imp.corrupt_bytes):
                buf[rng.randrange(len(buf))] ^= rng.randrange(1, 256)
            out, corrupted = bytes(buf), True
            st.corrupted += 1
        if self.keep_log:
            self.log.append(Datagram(t, direction, data, fate, corrupted, out))
        delay = imp.delay_s + (rng.uniform(0.0, imp.jitter_s) if imp.jitter_s > 0.0 else 0.0)
        if imp.reorder > 0.0 and rng.random() < imp.reorder:
            delay += imp.reorder_s
            st.reordered += 1
        copies = [delay]
        if imp.duplicate > 0.0 and rng.random() < imp.duplicate:
            copies.append(delay + imp.dup_gap_s)
            st.duplicated += 1
        for i, d in enumerate(copies):
            if d <= 0.0 and i == 0:
                self._send(direction, out)
            else:
                if i == 0:
                    st.delayed += 1
                self._schedule(t + d, direction, out)

    def _release_due(self) -> float:
        """Send what is due; return the wait until the next release (s), at most 50 ms."""
        now = self.now()
        while self._heap and self._heap[0][0] <= now:
            _, _, direction, data = heapq.heappop(self._heap)
            self._send(direction, data)
        return min(0.05, self._heap[0][0] - now) if self._heap else 0.05

    def _run(self) -> None:
        socks = [self.vsock, self.bsock]
        wait = 0.05
        last = self._clock()
        while not self._stop.is_set():
            now = self._clock()
            gap = now - last - max(0.0, wait)
            last = now
            if gap > self.max_loop_gap_s:
                self.max_loop_gap_s = gap
            if gap > 0.1:
                self.loop_gaps.append((now - self.t0, gap))
            try:
                readable, _, _ = select.select(socks, [], [], max(0.0, wait))
            except (OSError, ValueError):
                return  # sockets closed under us by stop()
            for s in readable:
                for _ in range(1000):  # drain, but keep releasing delayed datagrams on time
                    try:
                        data, addr = s.recvfrom(65536)
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:  # ICMP "port unreachable" from an earlier send: not data
                        continue
                    with self._lock:
                        if s is self.vsock:
                            self.vehicle_addr = addr
                            self._arrive(DOWN, data)
                        else:
                            self._arrive(UP, data)
            with self._lock:
                wait = self._release_due()


__all__ = [
    "Blackout",
    "Datagram",
    "DirStats",
    "DOWN",
    "Impairment",
    "UP",
    "UdpRelay",
    "mavlink_sysid",
    "split_frames",
]
