"""A scripted lockstep peer for the SIL vehicle: answers every ATTITUDE with a body-rate
SET_ATTITUDE_TARGET stamped with its time_boot_ms, computed from that ATTITUDE alone.

Because each answer is a pure function of the telemetry it answers, a flight against this peer
depends only on the vehicle's rules, not on when either process got the CPU: what the lockstep
equivalence test (serial vs overlapped frames) and the vehicle's per-frame CPU benchmark
(``scripts/bench --only sil_vehicle_frame_us``) need. The law is a roll/pitch hold on a slow
roll sweep: p = k (roll_ref(t) - roll), q = k (pitch_ref - pitch), r = 0, fixed thrust, so a
setpoint applied one frame early or late changes the flown trajectory.
"""

from __future__ import annotations

import math
import socket
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

RATES_THRUST = 128  # type_mask: attitude ignored -> body rates + thrust


def command(ms: int, roll: float, pitch: float) -> tuple[float, float, float, float]:
    """(p, q, r rad/s, thrust 0..1) answering an ATTITUDE stamped ``ms`` with ``roll``,
    ``pitch`` (rad): a 0.3 rad roll sweep of period ~16 s, pitch 0.05 rad, gain 2 1/s."""
    t = ms * 1e-3
    return 2.0 * (0.3 * math.sin(0.4 * t) - roll), 2.0 * (0.05 - pitch), 0.0, 0.5


class ScriptedPeer:
    """A UDP endpoint bound to ``127.0.0.1:port`` (0: any free port, see :attr:`port`) that the
    vehicle sends to (``udpout``); it answers each ATTITUDE as :func:`command` says."""

    def __init__(self, port: int = 0, sysid: int = 255, compid: int = 190) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.port = int(self.sock.getsockname()[1])
        self.sock.settimeout(None)
        self._out = _Sink()
        self.mav = M.MAVLink(self._out, srcSystem=sysid, srcComponent=compid)
        self.parser = M.MAVLink(None)
        self.parser.robust_parsing = True
        self.addr: Any = None
        self.answers = 0
        self.attitudes = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def handle(self, data: bytes, addr: Any) -> None:
        """One datagram from the vehicle: answer the ATTITUDE it carries, if any."""
        self.addr = addr
        for msg in self.parser.parse_buffer(data) or ():
            if msg.get_type() != "ATTITUDE":
                continue
            self.attitudes += 1
            p, q, r, thrust = command(msg.time_boot_ms, msg.roll, msg.pitch)
            self.send(
                self.mav.set_attitude_target_encode(
                    msg.time_boot_ms, 1, 1, RATES_THRUST, [1.0, 0.0, 0.0, 0.0], p, q, r, thrust
                )
            )
            self.answers += 1

    def request_offboard(self) -> None:
        """MAV_CMD_DO_SET_MODE to PX4's OFFBOARD (custom main mode 6) for system 1."""
        self.send(self.mav.command_long_encode(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0))

    def send(self, msg: Any) -> None:
        buf = bytes(msg.pack(self.mav))
        self.sock.sendto(buf, self.addr)

    def serve(self, timeout_s: float | None = None) -> bool:
        """Wait for one datagram (up to ``timeout_s``; None: forever) and handle it; False on a
        timeout or a closed socket."""
        self.sock.settimeout(timeout_s)
        try:
            data, addr = self.sock.recvfrom(65535)
        except (TimeoutError, OSError):
            return False
        self.handle(data, addr)
        return True

    def pump(self) -> None:
        """Handle every datagram waiting now, without waiting."""
        self.sock.setblocking(False)
        try:
            while True:
                data, addr = self.sock.recvfrom(65535)
                self.handle(data, addr)
        except (BlockingIOError, InterruptedError):
            pass

    def close(self) -> None:
        self.sock.close()


class _Sink:
    def write(self, buf: bytes) -> None:  # pymavlink's encoder wants a file; we send ourselves
        pass


def serve_forever(port_out: Any, stop: Any, delay_s: float = 0.0) -> None:
    """Child process body: bind a peer, tell the parent its port, answer until ``stop`` is set,
    sleeping ``delay_s`` (wall s) before handling each datagram (a peer that takes its time)."""
    peer = ScriptedPeer()
    port_out.send(peer.port)
    if delay_s > 0.0:
        handle = peer.handle

        def slow(data: bytes, addr: Any) -> None:
            time.sleep(delay_s)
            handle(data, addr)

        peer.handle = slow  # type: ignore[method-assign]
    while not stop.is_set():
        peer.serve(0.2)
    peer.close()


__all__ = ["RATES_THRUST", "ScriptedPeer", "command", "serve_forever"]
