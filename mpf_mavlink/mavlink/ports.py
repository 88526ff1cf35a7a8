"""Transports pymavlink's own classes do not cover the way the bridge needs: a pyserial
port (8N1, bounded writes, a dead port marked without a print) and a TCP client."""

from __future__ import annotations

import socket
from typing import Any

from mpf_mavlink.errors import MpfError
from mpf_mavlink.mavlink.pymav import mavutil


# ---------------------------------------------------------------------------------------------
# Transports that pymavlink's own classes do not cover the way we need
# ---------------------------------------------------------------------------------------------
class _Serial(mavutil.mavfile):  # type: ignore[misc, unused-ignore]  # pymavlink is untyped
    """An 8N1 serial port through pyserial (what pymavlink's own ``mavserial`` and every MAVLink
    ground tool use; Linux, macOS and Windows alike). Non-blocking reads; writes bounded by a
    0.5 s timeout so that a stuck port drops a frame instead of stalling the control loop;
    pymavlink's ``mavserial`` prints and reconnects on errors, which a bridge must not do."""

    def __init__(self, device: str, baud: int, source_system: int, source_component: int) -> None:
        import serial

        try:
            self.port = serial.Serial(
                device, int(baud), timeout=0, write_timeout=0.5,
                dsrdtr=False, rtscts=False, xonxoff=False,
            )  # fmt: skip
        except (serial.SerialException, ValueError, OSError) as e:
            raise MpfError(f"serial {device}: cannot open the port at {baud} baud ({e})") from None
        self.device = device
        self.baud = baud
        fd = self.port.fileno()
        mavutil.set_close_on_exec(fd)
        mavutil.mavfile.__init__(
            self, fd, device, source_system=source_system, source_component=source_component
        )

    def recv(self, n: int | None = None) -> bytes:
        import serial

        if n is None:
            n = self.mav.bytes_needed()
        try:
            return bytes(self.port.read(max(n, 256)))
        except (serial.SerialException, OSError):
            # pyserial's word for the other end of a pty closing or a USB adapter unplugged
            self.portdead = True
            return b""

    def write(self, buf: bytes) -> int:
        import serial

        try:
            return int(self.port.write(bytes(buf)) or 0)
        except serial.SerialTimeoutException:
            return 0  # the port is stuck: drop this frame rather than hang the loop
        except (serial.SerialException, OSError):
            self.portdead = True
            return 0

    def close(self) -> None:
        self.port.close()


class _TcpClient(mavutil.mavtcp):  # type: ignore[misc, unused-ignore]  # pymavlink is untyped
    """pymavlink's TCP client with one connection attempt bounded by a timeout (no retries,
    no sleeps, no prints)."""

    def __init__(self, device: str, connect_timeout_s: float, **kw: Any) -> None:
        self._connect_timeout_s = connect_timeout_s
        super().__init__(device, retries=0, autoreconnect=False, **kw)

    def do_connect(self) -> None:
        self.port = socket.create_connection(self.destination_addr, timeout=self._connect_timeout_s)
        self.port.setblocking(False)
        mavutil.set_close_on_exec(self.port.fileno())
        self.port.setsockopt(socket.SOL_TCP, socket.TCP_NODELAY, 1)

    def handle_eof(self) -> None:
        self.portdead = True

    def handle_disconnect(self) -> None:
        self.portdead = True
