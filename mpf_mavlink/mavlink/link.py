"""A MAVLink 2 link to one vehicle: URL validation, source filtering, counters, tlog hook.

Connection strings (pymavlink's syntax):
  ``udpin:HOST:PORT``   listen (bind) and reply to whoever sent last; PX4 SITL offboard 14540
  ``udpout:HOST:PORT``  send to HOST:PORT, receive the replies on the same socket
  ``udp:HOST:PORT``     pymavlink's legacy form, same as ``udpin``
  ``tcp:HOST:PORT``     connect (ArduPilot SITL: tcp:127.0.0.1:5760)
  ``tcpin:HOST:PORT``   listen for one TCP client
  ``/dev/ttyUSB0``, ``/dev/ttyACM0:921600``, ``/dev/ttyS1,57600``  serial device [:baud]

Serial ports go through pyserial (as pymavlink's own ``mavserial`` does); a pseudo-terminal
works like a real port.
"""

from __future__ import annotations

import os
import select
import socket
import time
from collections import Counter
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink.boot_clock import BootClockGate
from mpf_mavlink.mavlink.encode import encode_companion_heartbeat
from mpf_mavlink.mavlink.link_send import LinkCounters, LinkRecord, LinkSender
from mpf_mavlink.mavlink.ports import _Serial, _TcpClient
from mpf_mavlink.mavlink.pymav import DIALECT_NAME, dialect, mavutil
from mpf_mavlink.mavlink.url import MAV_COMP_ID_ONBOARD_COMPUTER, ParsedUrl, parse_url

if TYPE_CHECKING:
    from mpf_mavlink.mavlink.tlog import TlogWriter

UDP_MAX_PACKET_LEN = 65535  # pymavlink's mavutil.UDP_MAX_PACKET_LEN


# ---------------------------------------------------------------------------------------------
# Link
# ---------------------------------------------------------------------------------------------
class DatagramReader:
    """Reads a pymavlink UDP connection datagram by datagram (:meth:`read`, then :meth:`recv`).

    MAVLink over UDP never splits a frame across datagrams, but pymavlink parses a UDP link
    as one byte stream: a frame whose length byte points past the end of its datagram (a
    truncated or corrupted packet) would be completed with the NEXT datagram's packets, and
    when its CRC then fails, that whole stretch (up to 280 bytes of good telemetry, a
    COMMAND_ACK) is thrown away. Here such a leftover is dropped (counted in ``bad_data``)
    before the next datagram is parsed.

    Every datagram goes to pymavlink's parser (the only MAVLink framer here).

    The socket is read here, not through ``mavudp.recv`` (whose bookkeeping of the sender's
    address is kept): a datagram is read once ``poll`` says one is waiting, so a control
    frame costs one wait and one read instead of a read that fails (an exception), a wait and
    a read."""

    __slots__ = ("conn", "counters", "_pending", "_port", "_poll")

    def __init__(self, conn: Any, counters: LinkCounters) -> None:
        self.conn = conn
        self.counters = counters
        self._pending: list[Any] = []  # the current datagram's messages, last first
        self._port = conn.port
        self._poll = select.poll()
        self._poll.register(conn.port.fileno(), select.POLLIN)

    def recv(self) -> Any:
        """The next message of the datagram read last (None: it has none left)."""
        # mavudp's pre_message does nothing, and post_message keeps pymavlink's own per-system
        # tables (last messages, modes, loss counts) that nothing here reads: both skipped,
        # they cost a quarter of a message's receive
        if self._pending:
            return self._pending.pop()
        mav = self.conn.mav
        if len(mav.buf) > mav.buf_index:
            msg = mav.parse_char(b"")
            if msg is not None:
                return msg
            if len(mav.buf) > mav.buf_index:  # a frame cut short by its datagram's end
                self.counters.bad_data += 1
                mav.buf, mav.buf_index = bytearray(), 0
                mav.expected_length = dialect.HEADER_LEN_V1 + 2
        return None

    def read(self, timeout_s: float) -> bool:
        """Read the next datagram, waiting up to ``timeout_s`` (s) for one; False: none came.
        Its messages then come from :meth:`recv`. Raises OSError (a dead socket)."""
        if not self._poll.poll(timeout_s * 1e3 if timeout_s > 0.0 else 0):
            return False
        try:
            data, addr = self._port.recvfrom(UDP_MAX_PACKET_LEN)
        except (BlockingIOError, ConnectionRefusedError):  # as mavudp.recv: no data
            return False
        conn = self.conn
        if conn.udp_server:  # as mavudp.recv: replies go to every address heard from
            # the time an address was last heard is read only to expire it (mavudp.write
            # with a timeout): without one, a known sender costs no clock read
            if conn.timeout > 0 or addr not in conn.clients:
                conn.clients.add(addr)
                conn.clients_last_alive[addr] = time.time()
        elif conn.broadcast:
            conn.last_address = addr
        if not data:
            return True
        mav = conn.mav
        if conn.first_byte:
            conn.auto_mavlink_version(data)
        try:
            msg = mav.parse_char(data)
        except Exception:  # noqa: BLE001 - a pymavlink parse bug must not take the loop down
            self.counters.bad_data += 1
            mav.buf, mav.buf_index = bytearray(), 0
            mav.expected_length = dialect.HEADER_LEN_V1 + 2
            return True
        if msg is not None:
            self._pending = [msg]
        return True


def _count_bad(c: LinkCounters, msg: Any, signing_counts_itself: bool) -> None:
    """Count a BAD_DATA: an unsigned or badly signed packet while signing is on, or a bad
    frame (a hardened signing setup counts its bad signatures itself)."""
    if str(getattr(msg, "reason", "")) != "Invalid signature":
        c.bad_data += 1
        return
    data = bytes(getattr(msg, "data", b"") or b"")
    signed = len(data) > 2 and data[0] == 0xFD and bool(data[2] & 0x01)
    if not signed:
        c.rejected_unsigned += 1
    elif not signing_counts_itself:
        c.rejected_bad_signature += 1


def _wait_readable(conn: Any, timeout_s: float) -> None:
    """Wait until the connection has data or timeout_s (s) passed."""
    fd = getattr(conn, "fd", None)
    if fd is None or getattr(conn, "portdead", False):
        time.sleep(timeout_s)
        return
    try:
        select.select([fd], [], [], timeout_s)
    except (OSError, ValueError):
        time.sleep(timeout_s)


class Link:
    """One MAVLink connection, filtered to the vehicle (and the other sources we trust).

    ``vehicle_sysid``: the autopilot's system id; None accepts every source (replay tools only).
    ``vehicle_compid``: None accepts any component of that system (autopilot, camera, ...).
    ``allowed_sysids``: other systems whose messages we take (a FOLLOW_TARGET / GLOBAL_POSITION_INT
    target, a GCS). Everything else is dropped and counted in ``counters.rejected_sysid``.
    ``vehicle_autopilot``: once known (:func:`wait_heartbeat` pins it), a HEARTBEAT from the
    vehicle's ids with another MAV_AUTOPILOT value is dropped (``counters.rejected_identity``):
    an autopilot does not change its type in flight, so that is corruption or an impostor.
    The vehicle's ``time_boot_ms`` passes a :class:`BootClockGate` (``counters.rejected_time``,
    ``rejected_stale``, ``clock_resets``).
    """

    def __init__(
        self,
        conn: Any,
        *,
        url: str,
        vehicle_sysid: int | None = 1,
        vehicle_compid: int | None = None,
        allowed_sysids: Iterable[int] = (),
        tlog: TlogWriter | None = None,
        clock: Callable[[], float] = time.time,
        vehicle_time: bool = False,
    ) -> None:
        self.conn = conn
        self.url = url
        self.vehicle_sysid = vehicle_sysid
        self.vehicle_compid = vehicle_compid
        self.vehicle_autopilot: int | None = None
        self.clock_gate = BootClockGate()
        self.allowed_sysids = frozenset(int(s) for s in allowed_sysids)
        self.counters = LinkCounters()
        # lockstep: record times follow the vehicle's clock (link_send.VehicleTimeStamps)
        self.record = LinkRecord(tlog, clock, self.counters, vehicle_time)
        self._signing_counts_itself = False  # set by signing.enable_signing(hardened=True)
        self._closed = False
        # a UDP link is read datagram by datagram
        self._udp = (
            DatagramReader(conn, self.counters) if isinstance(conn, mavutil.mavudp) else None
        )
        self.sender = LinkSender(conn, self.record, self.counters, self._udp is not None)

    # -- identity ---------------------------------------------------------------------------
    @property
    def mav(self) -> Any:
        """The pymavlink ``MAVLink`` object (encoders take it; it owns seq and signing)."""
        return self.conn.mav

    @property
    def source_system(self) -> int:
        return int(self.conn.mav.srcSystem)

    @property
    def source_component(self) -> int:
        return int(self.conn.mav.srcComponent)

    def expect_vehicle(
        self, sysid: int | None, compid: int | None = None, autopilot: int | None = None
    ) -> None:
        self.vehicle_sysid, self.vehicle_compid, self.vehicle_autopilot = sysid, compid, autopilot

    def allow_sysid(self, sysid: int) -> None:
        self.allowed_sysids = self.allowed_sysids | {int(sysid)}

    def accepts(self, sysid: int, compid: int) -> bool:
        mav = self.conn.mav
        if sysid == mav.srcSystem and compid == mav.srcComponent:
            return False  # our own packets echoed by a router
        if self.vehicle_sysid is None:
            return True
        if sysid == self.vehicle_sysid:
            return self.vehicle_compid is None or compid == self.vehicle_compid
        return sysid in self.allowed_sysids

    # -- receive ----------------------------------------------------------------------------
    def _read_one(self) -> tuple[bool, Any]:
        """(more, msg): msg is an accepted message or None; more=False when no data is left.

        Every message received passes here (a few a control frame): the source checks are
        written out inline, with the link's fields read once, rather than as calls
        (:meth:`accepts`); the record (:meth:`_record`) and the clock gate
        (:func:`_clock_rejects`) are one call each."""
        udp = self._udp
        try:
            msg = udp.recv() if udp is not None else self.conn.recv_msg()
        except OSError:
            self.counters.io_errors += 1
            return False, None
        except Exception:  # noqa: BLE001 - a pymavlink parse bug must not take the loop down
            self.counters.bad_data += 1
            return True, None
        if msg is None:
            return False, None
        c = self.counters
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            _count_bad(c, msg, self._signing_counts_itself)
            return True, None
        c.rx_packets += 1
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        vsys = self.vehicle_sysid
        vehicle = sysid == vsys and vsys is not None
        tb_s = None
        if vehicle:
            tb = getattr(msg, "time_boot_ms", None)
            if isinstance(tb, int):
                tb_s = tb * 1e-3  # the vehicle's clock
        t_rec = self.record.rx(msg, tb_s)
        if mtype.startswith("UNKNOWN_"):
            c.unknown_msgid += 1
            return True, None
        # what accepts() says: not our own packets echoed by a router; the vehicle's
        # (component); the other systems allowed
        if vehicle:
            mav = self.conn.mav
            vcomp = self.vehicle_compid
            ok = (vcomp is None or compid == vcomp) and not (
                sysid == mav.srcSystem and compid == mav.srcComponent
            )
        else:
            ok = self.accepts(sysid, compid)
        if not ok:
            c.rejected_sysid += 1
            c.rejected_by_source[(sysid, compid)] += 1
            return True, None
        if (
            vehicle
            and mtype == "HEARTBEAT"
            and self.vehicle_autopilot is not None
            and getattr(msg, "autopilot", None) != self.vehicle_autopilot
        ):
            c.rejected_identity += 1
            return True, None
        if tb_s is not None and _clock_rejects(self, mtype, tb_s, t_rec):
            return True, None
        c.rx_by_type[mtype] += 1
        return True, msg

    def recv(self, timeout_s: float = 0.0) -> Any:
        """Next accepted message, waiting at most ``timeout_s`` (0 = poll). Never raises on
        malformed input: bad frames, spoofed ids and rejected signatures are counted instead."""
        if self._closed:
            return None
        deadline: float | None = None
        udp = self._udp
        while True:
            more, msg = self._read_one()
            if msg is not None:
                return msg
            if more:
                continue
            self.record.idle()  # nothing left to read
            now = time.monotonic()
            if deadline is None:
                deadline = now + max(0.0, float(timeout_s))
            remaining = deadline - now
            if udp is not None:
                try:
                    if udp.read(min(remaining, 0.05)):
                        continue
                except OSError:
                    self.counters.io_errors += 1
                    if remaining > 0:
                        time.sleep(min(remaining, 0.05))  # a dead socket: no busy loop
                        continue
                if remaining <= 0:
                    return None
                continue
            if remaining <= 0:
                return None
            _wait_readable(self.conn, min(remaining, 0.05))

    def buffered(self) -> bool:
        """Whether messages of the datagram read last are still to come from :meth:`recv`
        (UDP; a stream link says False): a caller can take them before its periodic duties."""
        udp = self._udp
        if udp is None:
            return False
        mav = self.conn.mav  # pymavlink holds what follows a frame it parsed
        return bool(udp._pending) or len(mav.buf) > mav.buf_index

    def recv_all(self, timeout_s: float = 0.0) -> list[Any]:
        """Every accepted message available now (waiting up to timeout_s for the first)."""
        out = []
        m = self.recv(timeout_s)
        while m is not None:
            out.append(m)
            m = self.recv(0.0)
        return out

    # -- send -------------------------------------------------------------------------------
    def send(self, msg: Any) -> None:
        """Pack (MAVLink 2, signed if signing is on), log and write one message."""
        if self._closed:
            raise MpfError(f"link {self.url} is closed")
        self.sender.send(msg)

    def send_many(self, msgs: list[Any]) -> None:
        """Several messages in one write (:meth:`LinkSender.send_many`)."""
        if self._closed:
            raise MpfError(f"link {self.url} is closed")
        self.sender.send_many(msgs)

    def clock(self) -> float:
        """The link's clock (s since the epoch): what its tlog records are stamped with."""
        return self.record.clock()

    @property
    def tlog(self) -> TlogWriter | None:
        return self.record.tlog

    @property
    def last_tx_s(self) -> float | None:
        """Record time (s) of the latest packet sent."""
        return self.record.last_tx_s

    def send_heartbeat(self) -> None:
        """Companion heartbeat (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID), ~1 Hz."""
        self.send(encode_companion_heartbeat(self.conn.mav))

    # -- lifetime ---------------------------------------------------------------------------
    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self.conn.close()
        except Exception:  # noqa: BLE001 - closing must not fail the caller's cleanup
            pass
        self.record.close()

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Link({self.url!r}, vehicle={self.vehicle_sysid}/{self.vehicle_compid})"


def _clock_rejects(link: Link, mtype: str, tb_s: float, t_rec: float) -> bool:
    """Whether ``link``'s clock gate rejects a vehicle message stamped ``tb_s`` (its boot time,
    s) received at ``t_rec`` (s), counted by why; the vehicle's clock moves on otherwise."""
    c, gate, vt = link.counters, link.clock_gate, link.record.vehicle_time
    why = gate.check(mtype, tb_s, t_rec)
    c.clock_resets = gate.resets
    if vt is not None and why != "time":
        vt.commit(t_rec)  # a sample of the vehicle's clock: time moves on
    if why is None:
        return False
    if why == "time":
        c.rejected_time += 1
    elif why == "settling":
        c.clock_settling += 1
    else:
        c.rejected_stale += 1
    return True


def open_link(
    url: str,
    *,
    source_system: int = 1,
    source_component: int = MAV_COMP_ID_ONBOARD_COMPUTER,
    baud: int | None = None,
    timeout_s: float = 3.0,
    vehicle_sysid: int | None = 1,
    vehicle_compid: int | None = None,
    allowed_sysids: Iterable[int] = (),
    tlog_path: str | os.PathLike[str] | None = None,
    tlog_fsync_every_s: float | None = None,
    vehicle_time: bool = False,
) -> Link:
    """Open a MAVLink 2 link; raise MpfError (one line) for any bad URL or failure to open.

    Default identity: system 1 (the vehicle's own id, as a companion computer on the vehicle
    uses; PX4 and ArduPilot check ``target_system`` of setpoints, not the sender) and component
    191 MAV_COMP_ID_ONBOARD_COMPUTER. ``timeout_s`` bounds the TCP connect.
    ``baud`` (serial only) defaults to 57600 unless the URL carries one. ``vehicle_time``:
    record times follow the vehicle's clock (lockstep; ``link_send.VehicleTimeStamps``).
    """
    if not (1 <= int(source_system) <= 255 and 0 <= int(source_component) <= 255):
        raise MpfError(
            f"source ids out of range: system {source_system}, component {source_component}"
        )
    parsed = parse_url(url, baud)
    mavutil.set_dialect(DIALECT_NAME)  # another module may have switched pymavlink's global
    kw = dict(source_system=int(source_system), source_component=int(source_component))
    conn = _connect(url, parsed, float(timeout_s), kw)
    if type(conn.mav).__module__ != dialect.__name__:  # pragma: no cover - defensive
        conn.mav = dialect.MAVLink(
            conn, srcSystem=kw["source_system"], srcComponent=kw["source_component"]
        )
        conn.mav.robust_parsing = True
    tlog = None
    if tlog_path is not None:
        try:
            # records copied into a map of the file (in the page cache at once, as a write
            # would put them, for a copy's cost); where it cannot be mapped, held until the
            # link sends or pauses (Link.recv, LinkRecord.tx); with fsync_every_s 0, neither:
            # each record written and on the disk at once
            from mpf_mavlink.mavlink.tlog import TlogWriter  # only a recording link loads it

            tlog = TlogWriter(
                tlog_path,
                fsync_every_s=tlog_fsync_every_s,
                hold=tlog_fsync_every_s != 0,
                mapped=True,
            )
        except MpfError:
            conn.close()
            raise
    return Link(
        conn,
        url=url,
        vehicle_sysid=vehicle_sysid,
        vehicle_compid=vehicle_compid,
        allowed_sysids=allowed_sysids,
        tlog=tlog,
        vehicle_time=vehicle_time,
    )


def _connect(url: str, parsed: ParsedUrl, timeout_s: float, kw: dict[str, int]) -> Any:
    """pymavlink's connection for ``parsed`` (of ``url``), or MpfError (one line) saying why
    not; ``kw`` the source ids."""
    try:
        if parsed.kind == "serial":
            if not os.path.exists(parsed.device):
                raise MpfError(f"serial device {parsed.device} does not exist")
            return _Serial(parsed.device, parsed.baud, **kw)
        if parsed.kind == "tcp":
            return _TcpClient(f"{parsed.host}:{parsed.port}", timeout_s, **kw)
        return mavutil.mavlink_connection(parsed.pymavlink_device, **kw)
    except MpfError:
        raise
    except socket.gaierror:
        raise MpfError(f"MAVLink URL {url!r}: cannot resolve host {parsed.host!r}") from None
    except ConnectionRefusedError:
        raise MpfError(
            f"MAVLink URL {url!r}: connection refused (is the autopilot/SITL running?)"
        ) from None
    except TimeoutError:
        raise MpfError(f"MAVLink URL {url!r}: no TCP connection within {timeout_s:g} s") from None
    except PermissionError:
        what = parsed.device or f"{parsed.host}:{parsed.port}"
        raise MpfError(f"MAVLink URL {url!r}: permission denied for {what}") from None
    except OSError as e:
        what = parsed.device or f"{parsed.host}:{parsed.port}"
        raise MpfError(f"MAVLink URL {url!r}: cannot open {what}: {e.strerror or e}") from None
    except ValueError as e:
        raise MpfError(f"MAVLink URL {url!r}: {e}") from None


AUTOPILOTS = (dialect.MAV_AUTOPILOT_PX4, dialect.MAV_AUTOPILOT_ARDUPILOTMEGA)
MAV_COMP_ID_AUTOPILOT1 = 1


def wait_heartbeat(
    link: Link,
    timeout_s: float = 5.0,
    *,
    pin: bool = True,
    compid: int | None = None,
    autopilots: Iterable[int] | None = AUTOPILOTS,
    on_other: Callable[[Any], None] | None = None,
) -> Any:
    """First HEARTBEAT of the vehicle's autopilot. MpfError after ``timeout_s``. ``on_other``
    sees every other message read meanwhile (a lockstep peer answers the ATTITUDE among them).

    Only from component ``compid`` (default: the link's ``vehicle_compid``, else 1, the id of
    PX4's and ArduPilot's autopilot) and with a MAV_AUTOPILOT in ``autopilots`` (None: any but
    MAV_AUTOPILOT_INVALID, which GCSs and companions send): the identity is pinned from this
    one message, so a camera's, a companion's or a corrupted HEARTBEAT must not be the one.
    The others are counted and named in the timeout error.

    ``pin``: from then on the link takes the vehicle's messages only from that component (a
    camera or gimbal of the same system may send its own ATTITUDE; another component's
    HEARTBEAT is not the autopilot's mode) and only HEARTBEATs with that MAV_AUTOPILOT value.
    """
    want_comp = compid if compid is not None else link.vehicle_compid
    want_comp = MAV_COMP_ID_AUTOPILOT1 if want_comp is None else want_comp
    allowed = None if autopilots is None else frozenset(int(a) for a in autopilots)
    ignored: Counter[tuple[int, int]] = (
        Counter()
    )  # (compid, autopilot) of HEARTBEATs from the vehicle not taken
    deadline = time.monotonic() + float(timeout_s)
    next_hb = time.monotonic()
    while True:
        now = time.monotonic()
        remaining = deadline - now
        if now >= next_hb and remaining > 0:
            # our companion HEARTBEAT (1 Hz): an autopilot or simulator listening (udpin)
            # answers whoever sent first, and would otherwise never learn where we are
            link.send_heartbeat()
            next_hb = now + 1.0
        if remaining <= 0:
            who = "any vehicle" if link.vehicle_sysid is None else f"system {link.vehicle_sysid}"
            c = link.counters
            seen = ", ".join(
                f"component {k[0]} autopilot {k[1]} x{n}" for k, n in ignored.most_common(3)
            )
            raise MpfError(
                f"no HEARTBEAT from {who} on {link.url} within {float(timeout_s):g} s "
                f"({c.rx_packets} packets received, {c.rejected_sysid} from other ids, "
                f"{c.bad_data} bad"
                + (
                    f"; ignored, not a PX4/ArduPilot autopilot on component {want_comp}: {seen}"
                    if seen
                    else ""
                )
                + ")"
            )
        msg = link.recv(max(0.0, min(remaining, next_hb - time.monotonic())))
        if msg is not None and on_other is not None and msg.get_type() != "HEARTBEAT":
            on_other(msg)
        if (
            msg is None
            or msg.get_type() != "HEARTBEAT"
            or msg.autopilot == dialect.MAV_AUTOPILOT_INVALID
            or (link.vehicle_sysid is not None and msg.get_srcSystem() != link.vehicle_sysid)
        ):
            continue
        if msg.get_srcComponent() != want_comp or (
            allowed is not None and msg.autopilot not in allowed
        ):
            ignored[(msg.get_srcComponent(), int(msg.autopilot))] += 1
            continue
        if pin and link.vehicle_sysid is not None:
            link.expect_vehicle(link.vehicle_sysid, want_comp, int(msg.autopilot))
        return msg
