"""A serial line without serial hardware: a pseudo-terminal whose far end is a TCP port.

The bridge opens ``/dev/pts/N`` like any serial device (pyserial, a baud rate it sets and the
pty ignores); a thread copies bytes between the pty's master and the autopilot's SERIALn TCP
port, as a USB-serial cable and a telemetry radio would. Raw mode on both ends: no line
discipline may touch a MAVLink byte (no echo, no CR/LF mapping, no ^C).
"""

from __future__ import annotations

import os
import select
import socket
import threading
import time
import tty


class PtyRelay:
    """``PtyRelay(port).device`` is the pty the bridge opens; bytes go to/from TCP ``port``."""

    def __init__(self, port: int, host: str = "127.0.0.1", timeout_s: float = 30.0) -> None:
        t_end = time.monotonic() + timeout_s
        while True:
            try:
                self.sock = socket.create_connection((host, port), timeout=2.0)
                break
            except OSError:
                if time.monotonic() > t_end:
                    raise
                time.sleep(0.5)
        self.sock.setblocking(False)
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)  # kept open: the line survives the bridge closing and reopening
        os.set_blocking(self.master, False)  # a full line drops bytes, as a UART overrun does
        self.device = os.ttyname(self.slave)
        self.bytes_up = self.bytes_down = self.dropped = 0  # to the autopilot / to the bridge
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, name="pty-relay", daemon=True)
        self._t.start()

    def _run(self) -> None:
        to_sock = b""
        while not self._stop.is_set():
            fd = self.sock.fileno()
            r, w, _ = select.select([self.master, fd], [fd] if to_sock else [], [], 0.2)
            if self.master in r:
                try:
                    to_sock += os.read(self.master, 4096)
                except BlockingIOError:
                    pass
                except OSError:  # EIO: no process holds the slave open right now
                    time.sleep(0.05)
            if fd in r:
                data = self.sock.recv(4096)
                if not data:
                    return  # the autopilot closed its port
                self.bytes_down += len(data)
                try:
                    os.write(self.master, data)
                except OSError:  # the bridge is not reading: those bytes are lost
                    self.dropped += len(data)
            if to_sock and (fd in w or not r):
                try:
                    n = self.sock.send(to_sock)
                    self.bytes_up += n
                    to_sock = to_sock[n:]
                except BlockingIOError:
                    pass

    def close(self) -> None:
        self._stop.set()
        self._t.join(2.0)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self.sock.close()
