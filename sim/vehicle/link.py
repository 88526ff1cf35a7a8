"""The vehicle's MAVLink link: one pymavlink connection, the outgoing and incoming delay queues
(latencies in simulated time), datagram batching, routing between peers, and the lockstep
hand-shake's bookkeeping of what left and what answered (:mod:`sim.vehicle.lockstep`)."""

from __future__ import annotations

import select
import socket
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from sim.vehicle.clock import StepClock
from sim.vehicle.lockstep import Lockstep, is_mode_request

_DATAGRAM_MAX = 1400  # a UDP datagram carries several packets (as PX4 does), up to this size
_READS_MAX = 10000  # datagrams read per poll at most (a flood cannot hold the frame forever)


class Framer:
    """Frames messages with pymavlink for one ``MAVLink`` object (its ids, sequence counter and
    signing), returning the bytes (the vehicle batches them into datagrams)."""

    def __init__(self, mav: Any) -> None:
        self.mav = mav

    def pack(self, cls: Any, *args: Any) -> bytes:
        """One framed message from the field values in pymavlink's ``*_encode`` order."""
        mav = self.mav
        buf = bytes(cls(*args).pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF  # what MAVLink.send does after packing
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(buf)
        return buf


def _ignored(data: bytes, wanted: frozenset[int]) -> int:
    """The number of MAVLink 2 frames in the datagram ``data`` when it is made of whole frames
    none of which is a message in ``wanted`` (ids), else 0 (pymavlink should parse it). Walks
    the headers only: what the vehicle drops on arrival anyway (the bridge's NAMED_VALUE_FLOAT,
    a peer's HEARTBEAT) costs pymavlink's byte-by-byte parser tens of microseconds a packet."""
    i, n, frames = 0, len(data), 0
    while i < n:
        if data[i] != 0xFD or i + 12 > n:
            return 0
        if (data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16) in wanted:
            return 0
        i += 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)  # header+CRC, payload, signature
        frames += 1
    return frames if i == n else 0


def _route(conn: Any, me: tuple[int, int], msgs: Any, src: Any) -> None:
    """Forward what one peer sends to the others, as ArduPilot's MAVLink routing (and PX4's
    forwarding) does: every message not addressed to this vehicle (no target, or another
    system's) from another component, so a ground station on the link sees the bridge's
    NAMED_VALUE_FLOAT and STATUSTEXT. Only with two peers or more (never on the lockstep
    path of a lone bridge). ``me``: the vehicle's (system, component)."""
    port = conn.port
    for msg in msgs:
        if msg.get_type() == "BAD_DATA" or (msg.get_srcSystem(), msg.get_srcComponent()) == me:
            continue
        if getattr(msg, "target_system", 0) == me[0]:
            continue
        buf = msg.get_msgbuf()
        for addr in list(conn.clients):
            if addr != src:
                try:
                    port.sendto(buf, addr)
                except OSError:
                    pass


class _QueueWriter:
    """File-like sink for a pymavlink encoder: packets go to the link's outgoing delay queue."""

    def __init__(self, link: Link) -> None:
        self.link = link

    def write(self, buf: bytes) -> None:
        self.link.put(bytes(buf))


class Outgoing:
    """The outgoing delay queue (a packet leaves ``latency_s`` of sim time after it was queued)
    and the bundling of what is due into datagrams, on pymavlink's connection ``conn`` (``udp``:
    a ``mavudp``); tells ``lockstep`` which telemetry left."""

    def __init__(
        self, conn: Any, udp: bool, clock: StepClock, lockstep: Lockstep, latency_s: float
    ) -> None:
        self.conn, self.clock, self.lockstep = conn, clock, lockstep
        self.latency_s = float(latency_s)
        # a udpout link to one fixed address is written straight to its socket (pymavlink's
        # write re-checks the client list and the address on every packet)
        self._sendto: Callable[[bytes, Any], Any] | None = None
        self._dest: Any = None
        if udp and not conn.udp_server and not getattr(conn, "broadcast", False):
            host, port = conn.destination_addr
            self._sendto, self._dest = conn.port.sendto, (socket.gethostbyname(host), port)
        # (due boot s, packet, ATTITUDE ms or -1, LOCAL_POSITION_NED ms or -1)
        self._out: deque[tuple[float, bytes, int, int]] = deque()
        # without a telemetry latency packets leave at the next flush: a plain list (and the
        # highest ATTITUDE / LOCAL_POSITION_NED stamps in it) instead of the delay queue
        self._now: list[bytes] | None = [] if self.latency_s <= 0.0 else None
        self._now_att = self._now_pos = -1

    def put(self, buf: bytes, attitude_ms: int = -1, position_ms: int = -1) -> None:
        """Queue one framed packet; it leaves ``telemetry_latency_s`` of sim time from now.
        ``attitude_ms``: the time_boot_ms of an ATTITUDE packet (the bridge answers those);
        ``position_ms``: that of a LOCAL_POSITION_NED (a multi-rate bridge answers those too)."""
        now = self._now
        if now is not None:  # no latency: it leaves with this frame's datagram
            now.append(buf)
            if attitude_ms > self._now_att:
                self._now_att = attitude_ms
            if position_ms > self._now_pos:
                self._now_pos = position_ms
            return
        self._out.append((self.clock.boot_s + self.latency_s, buf, attitude_ms, position_ms))

    def flush_due(self) -> None:
        """Send what is due and tell the lockstep which telemetry left."""
        now = self._now
        if now is not None:
            if now:
                self._now = []
                att_ms, pos_ms = self._now_att, self._now_pos
                self._now_att = self._now_pos = -1
                data, send = b"".join(now), self._sendto
                if send is not None and len(data) <= _DATAGRAM_MAX:
                    # every frame: one datagram to the one peer (_send_packets, _write)
                    try:
                        send(data, self._dest)
                    except OSError:
                        pass  # as pymavlink's udp write: a peer not up yet is a datagram lost
                    wrote = True
                else:
                    wrote = self._send_packets(now)
                if wrote:
                    self.lockstep.written(att_ms, pos_ms, self.clock.boot_s)
            return
        q, t = self._out, self.clock.boot_s + 1e-9
        if not q or q[0][0] > t:
            return
        bufs: list[bytes] = []
        att_ms = pos_ms = -1
        while q and q[0][0] <= t:
            _, buf, ms, pms = q.popleft()
            att_ms, pos_ms = max(att_ms, ms), max(pos_ms, pms)
            bufs.append(buf)
        if self._send_packets(bufs):
            self.lockstep.written(att_ms, pos_ms, t - 1e-9)

    def _send_packets(self, bufs: list[bytes]) -> bool:
        """Send ``bufs`` in order, as few datagrams of at most ``_DATAGRAM_MAX`` bytes as they
        fit in (a packet larger than that alone); True if any was written."""
        data = b"".join(bufs)
        if len(data) <= _DATAGRAM_MAX:
            return self._write(data)
        wrote = False
        chunk: list[bytes] = []
        size = 0
        for buf in bufs:
            if chunk and size + len(buf) > _DATAGRAM_MAX:
                wrote |= self._write(b"".join(chunk))
                chunk, size = [], 0
            chunk.append(buf)
            size += len(buf)
        if chunk:
            wrote |= self._write(b"".join(chunk))
        return wrote

    def _write(self, data: bytes) -> bool:
        send = self._sendto
        if send is not None:
            try:
                send(data, self._dest)
            except OSError:
                pass  # as pymavlink's udp write: a peer not up yet is a datagram lost
            return True
        try:
            self.conn.write(data)
            return True
        except OSError:
            return False


class Link:
    """Receive into the incoming delay queue, send from the outgoing one, batch datagrams.

    ``accept`` names the message types the autopilot acts on (the rest is dropped on arrival);
    ``on_epoch`` takes the bridge's STATUSTEXT (the target's epoch), ``on_new_peer`` is told
    when a new peer writes (it should hear our HEARTBEAT at once)."""

    def __init__(
        self,
        url: str,
        sysid: int,
        compid: int,
        target_ids: tuple[int, int],
        clock: StepClock,
        lockstep: Lockstep,
        *,
        telemetry_latency_s: float,
        command_latency_s: float,
        lockstep_clock: bool,
        accept: frozenset[str],
    ) -> None:
        self.url = url
        self.sysid, self.compid = sysid, compid
        self.clock = clock
        self.lockstep = lockstep
        self.command_latency_s = float(command_latency_s)
        self._lockstep_clock = lockstep_clock  # an answer's latency runs from its telemetry
        self.accept = accept
        # a peer in lockstep in every phase: its commands act a frame after the latency from the
        # telemetry its latest answer answered (not from when they were read), so the frame a
        # mode request acts in does not depend on which wait read it
        self.commands_on_answers = False
        # ids of what _on_msg acts on: a datagram with none of them is not parsed (see _ignored)
        self._wanted = frozenset(
            mid
            for mid, cls in M.mavlink_map.items()
            if cls.msgname in accept
            or cls.msgname in ("SET_ATTITUDE_TARGET", "STATUSTEXT", "SYSTEM_TIME")
        )
        self.conn = mavutil.mavlink_connection(
            url,
            source_system=sysid,
            source_component=compid,
            dialect="ardupilotmega",
            autoreconnect=True,
        )
        # plain UDP links are read datagram by datagram (the setpoints decoded without pymavlink)
        self._udp = type(self.conn).__name__ == "mavudp"
        c = self.conn
        # a link that neither listens for UDP clients nor accepts TCP ones (udpout, serial...)
        # always has its peer
        self._fixed_peer = not getattr(c, "udp_server", False) and not hasattr(c, "listen")
        # the lockstep wait polls the UDP socket with one prepared poll object (mavfile.select
        # builds three lists and a select call each time)
        self._poller: Any = None
        if self._udp:
            self._poller = select.poll()
            self._poller.register(c.port.fileno(), select.POLLIN)
        self.out = Outgoing(c, self._udp, clock, lockstep, telemetry_latency_s)
        self.incoming: deque[tuple[float, Any]] = deque()  # (due boot s, message)
        self.mav = M.MAVLink(_QueueWriter(self), srcSystem=sysid, srcComponent=compid)
        self.tmav = M.MAVLink(
            _QueueWriter(self), srcSystem=target_ids[0], srcComponent=target_ids[1]
        )
        self.framer, self.target_framer = Framer(self.mav), Framer(self.tmav)
        self.statustexts: list[tuple[float, str]] = []  # (t, text) sent
        self.rx_count = 0
        # True right after a read found nothing more waiting: the frame that follows the
        # lockstep wait need not read again (a syscall that would find nothing)
        self.drained = False
        self.on_epoch: Callable[[Any], None] = lambda msg: None
        self.on_new_peer: Callable[[], None] = lambda: None

    # ------------------------------------------------------------------ output
    def put(self, buf: bytes, attitude_ms: int = -1, position_ms: int = -1) -> None:
        """:meth:`Outgoing.put`."""
        self.out.put(buf, attitude_ms, position_ms)

    def statustext(self, severity: int, text: str) -> None:
        self.statustexts.append((self.clock.t, text))
        self.mav.send(self.mav.statustext_encode(severity, text.encode()[:50]))

    def ack(self, command: int, result: int, msg: Any, reason: str | None = None) -> None:
        """COMMAND_ACK of ``msg`` to its sender; a STATUSTEXT saying why, when given."""
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        self.mav.send(self.mav.command_ack_encode(command, result, 0, 0, *src))
        if reason:
            ok = result == M.MAV_RESULT_ACCEPTED
            self.statustext(M.MAV_SEVERITY_INFO if ok else M.MAV_SEVERITY_WARNING, reason)

    def flush(self) -> None:
        """Send the packets that are due, bundled into as few datagrams as fit (PX4 does the same:
        one datagram per send cycle), so the peer wakes up once per frame, not once per packet.
        A frame that writes no ATTITUDE still awaits the answer that acts in the next frame (with
        ATTITUDE at 10 Hz over 20 ms frames the vehicle would otherwise apply each setpoint
        whenever the bridge's process got to it)."""
        self.out.flush_due()
        self.lockstep.choose(self.clock.boot_s)

    # ------------------------------------------------------------------ input
    def has_peer(self) -> bool:
        if self._fixed_peer:  # (every lockstep wait: no attribute probes that raise)
            return True
        c = self.conn
        if getattr(c, "udp_server", False):  # pymavlink >= 2.4.4x keeps a set of clients
            return bool(getattr(c, "clients", None)) or getattr(c, "last_address", None) is not None
        if hasattr(c, "listen"):  # tcpin
            return getattr(c, "port", None) is not None
        return True

    def readable(self) -> bool:
        """Whether a datagram is waiting (UDP; other links: True, read to find out). The
        lockstep clock's spin asks this before it reads: a poll that finds nothing is cheaper
        than a read that fails, and leaves the socket to the peer's send."""
        p = self._poller
        return p is None or bool(p.poll(0))

    def poll(self, timeout: float = 0.0) -> bool:
        """Read incoming MAVLink (waiting up to ``timeout`` wall s for the first byte).
        Returns True when the answer the lockstep awaits has arrived."""
        if self.lockstep.answered:
            self.drain()
            return True
        if timeout > 0.0:
            try:
                if self._poller is not None:
                    self._poller.poll(timeout * 1e3)  # ms, rounded up
                else:
                    self.conn.select(timeout)
            except Exception:  # pragma: no cover
                time.sleep(min(timeout, 0.001))
        if self._udp:
            # the lockstep clock's wait stops reading at the awaited answer: what the peer sent
            # after it is read in the next wait (an answer acts at the time its stamp says,
            # whenever it is read), which saves a read that finds the socket empty every frame
            self._drain_udp(self._lockstep_clock and timeout > 0.0)
        else:
            self.drain()
        return self.lockstep.answered

    def drain(self) -> None:
        if self._udp:
            self._drain_udp()
            return
        recv = self.conn.recv_msg
        for _ in range(_READS_MAX):
            try:
                msg = recv()
            except (ConnectionError, OSError):
                return
            if msg is None:
                self.drained = True
                return
            self._on_msg(msg)

    def _drain_udp(self, until_answered: bool = False) -> None:
        """Read whole datagrams (``until_answered``: until the lockstep's awaited answer has
        come, else until none is left); pymavlink parses each, except one made only of messages
        the vehicle drops, which is not decoded at all (unless it is routed to other peers)."""
        conn = self.conn
        port, server, parse = conn.port, conn.udp_server, conn.mav.parse_buffer
        fast = conn.mav.signing.secret_key is None  # a signed link: pymavlink checks every frame
        wanted, lockstep = self._wanted, self.lockstep
        for _ in range(_READS_MAX):
            try:
                data, addr = port.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                self.drained = True
                return
            except ConnectionRefusedError:  # ICMP for an earlier send (peer not up yet): cleared
                continue
            except OSError:
                return
            if server:  # what pymavlink's mavudp.recv does: remember the peer to answer it
                if addr not in conn.clients:
                    self.on_new_peer()
                conn.clients.add(addr)
                conn.clients_last_alive[addr] = time.time()
            routed = server and len(conn.clients) > 1
            skipped = _ignored(data, wanted) if fast and not routed else 0
            if skipped:
                self.rx_count += skipped
                continue
            msgs = parse(data) or ()
            for msg in msgs:
                self._on_msg(msg)
            if routed:
                _route(conn, (self.sysid, self.compid), msgs, addr)
            if until_answered and lockstep.answered:
                self.drained = True  # the frame that follows need not read (see poll)
                return

    def _on_msg(self, msg: Any) -> None:
        mt = msg.get_type()
        if mt == "BAD_DATA":
            return
        self.rx_count += 1
        now = self.clock.boot_s
        due = now + self.command_latency_s
        if mt == "SET_ATTITUDE_TARGET":
            tw = self.lockstep.on_answer(msg.time_boot_ms)
            if tw is not None and self._lockstep_clock:
                # lockstep: the bridge answered at once in vehicle time, the latency runs
                # from the ATTITUDE it answers (not from when this process got to read it)
                due = max(now, tw + self.command_latency_s)
        elif mt == "STATUSTEXT":
            self.on_epoch(msg)
            return
        elif mt == "SYSTEM_TIME":
            # a lockstep peer's clock answer (it let a frame pass without a setpoint): the
            # frame stamped so is answered; the autopilot has nothing to act on
            self.lockstep.on_clock(msg.time_boot_ms)
            return
        elif mt not in self.accept:
            return
        elif is_mode_request(msg, mt, self.sysid):
            self.lockstep.on_mode_request()
        if self.commands_on_answers and mt != "SET_ATTITUDE_TARGET":
            ta = self.lockstep.answered_t()
            if ta is not None:
                due = max(now, ta + self.command_latency_s + self.lockstep.frame_period)
        q = self.incoming
        i = len(q)
        while i > 0 and q[i - 1][0] > due:  # kept in order of due time
            i -= 1
        q.insert(i, (due, msg))

    def close(self) -> None:
        try:
            self.conn.close()
        except Exception:  # pragma: no cover - closing is best effort
            pass
