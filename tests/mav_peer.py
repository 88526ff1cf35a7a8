"""A scripted MAVLink autopilot for the bridge tests: a real pymavlink endpoint on loopback UDP
(or the master side of a pty pair, i.e. a serial link), in a background thread.

It plays PX4 (autopilot 12, custom_mode = main << 16 | sub << 24) or ArduPlane (autopilot 3,
mode numbers): HEARTBEAT, COMMAND_ACK to DO_SET_MODE / ARM, and telemetry (ATTITUDE or
ATTITUDE_QUATERNION, LOCAL_POSITION_NED, VFR_HUD, optionally GLOBAL_POSITION_INT +
HOME_POSITION, WIND) of a crude kinematic plane at constant airspeed: in its offboard mode it
integrates the commanded roll rate (PX4) or follows the commanded roll (ArduPlane); the heading
turns at g tan(roll) / V. ``truth`` keeps what each telemetry tick reported.

Like PX4 it refuses OFFBOARD unless setpoints have streamed for >= 1 s (and the last is
< 0.5 s old). Everything it receives is recorded with the monotonic time of arrival.
"""

from __future__ import annotations

import math
import os
import select
import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any

from mpf_mavlink.mavlink import dialect as mavlink
from mpf_mavlink.mavlink.modes import (
    arduplane_mode_from_name,
    px4_custom_mode,
    px4_decode_custom_mode,
    px4_mode_from_name,
)

G = 9.80665


@dataclass
class Rx:
    t: float  # monotonic time of arrival (s)
    mode: int  # the peer's custom_mode when it arrived
    msg: Any


class _UdpTransport:
    def __init__(self, port: int) -> None:
        held = []
        while True:  # the kernel may hand us the bridge's (just freed) port: never take it
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind(("127.0.0.1", 0))
            if self.sock.getsockname()[1] != port:
                break
            held.append(self.sock)
        for h in held:
            h.close()
        self.sock.setblocking(False)
        self.dest = ("127.0.0.1", port)
        self.fd = self.sock.fileno()

    def write(self, buf: bytes) -> None:
        try:
            self.sock.sendto(bytes(buf), self.dest)
        except OSError:
            pass  # nobody listening yet (ICMP port unreachable): like a radio

    def read(self) -> bytes:
        try:
            return self.sock.recv(65536)
        except (BlockingIOError, ConnectionRefusedError, OSError):
            return b""

    def close(self) -> None:
        self.sock.close()


class _PtyTransport:
    def __init__(self) -> None:
        import tty

        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.fd = self.master

    def write(self, buf: bytes) -> None:
        try:
            os.write(self.master, bytes(buf))
        except OSError:
            pass

    def read(self) -> bytes:
        try:
            return os.read(self.master, 65536)
        except (BlockingIOError, OSError):
            return b""

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


@dataclass
class PeerOptions:
    flavour: str = "px4"  # "px4" | "ardupilot"
    sysid: int = 1
    compid: int = 1
    telemetry_hz: float = 50.0
    heartbeat_hz: float = 2.0
    start_mode: str | None = None  # None: POSCTL (PX4) / FBWA (ArduPlane)
    position_ned: tuple[float, float, float] = (-200.0, 0.0, -100.0)
    yaw: float = 0.0
    airspeed: float = 15.0
    send_local: bool = True
    send_global: bool = False
    home: tuple[float, float, float] = (47.397742, 8.545594, 488.0)  # lat, lon, alt AMSL
    send_wind: bool = False
    wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)
    signing_key: bytes | None = None
    ack_result: int | None = None  # force this MAV_RESULT for DO_SET_MODE (None: behave)
    boot_time_s: float = 100.0  # time_boot_ms starts here (s)
    start_armed: bool = True  # False: disarmed until an ARM command is accepted
    arm_result: int | None = None  # force this MAV_RESULT for ARM_DISARM, stay as is (None: obey)
    attitude_quaternion: bool = False  # send ATTITUDE_QUATERNION instead of ATTITUDE
    # PX4 v1.16 in body-rate OFFBOARD: an ATTITUDE_TARGET per tick carrying the body rates in
    # use, stamped with this frozen time (ms; None: no echo); TIMESYNC answered on the boot
    # clock; the offboard-loss parameters (integers bytewise, as PX4 sends them), PARAM_SET
    # answered by PARAM_VALUE, MAV_CMD_DO_REPOSITION (COMMAND_INT) acknowledged
    frozen_echo_ms: int | None = None
    px4_params: bool = True


class MavPeer:
    def __init__(self, opts: PeerOptions, port: int | None = None, pty: bool = False) -> None:
        self.o = opts
        self.tr: Any = _PtyTransport() if pty else _UdpTransport(port or 0)
        self.device = getattr(self.tr, "path", None)
        self.mav = mavlink.MAVLink(self.tr, srcSystem=opts.sysid, srcComponent=opts.compid)
        self.mav.robust_parsing = True
        if opts.signing_key is not None:
            sg = self.mav.signing
            sg.secret_key = opts.signing_key
            sg.sign_outgoing = True
            sg.link_id = 1
            sg.timestamp = int((time.time() - 1420070400) * 100_000)
            sg.allow_unsigned_callback = None
        px4 = opts.flavour == "px4"
        start = opts.start_mode or ("POSCTL" if px4 else "FBWA")
        self.custom_mode = self._mode_num(start)
        self.armed = opts.start_armed
        # what each telemetry tick reported: (time_boot_ms, NED position, (roll, pitch, yaw))
        self.truth: list[tuple[int, tuple[float, float, float], tuple[float, float, float]]] = []
        self.setpoints: list[Rx] = []
        self.commands: list[Rx] = []
        self.data_stream_requests: list[Rx] = []  # REQUEST_DATA_STREAM (never honoured here)
        self.heartbeats_rx: list[Rx] = []
        self.param_sets: list[Rx] = []
        # PX4's stock offboard-loss settings: name -> (value, MAV_PARAM_TYPE)
        self.params: dict[str, tuple[float, int]] = (
            {"COM_OF_LOSS_T": (1.0, 9), "COM_OBL_RC_ACT": (0.0, 6), "NAV_RCL_ACT": (2.0, 6),
             "COM_RCL_EXCEPT": (0.0, 6), "NAV_LOITER_RAD": (80.0, 9)}
            if px4 and opts.px4_params else {}
        )  # fmt: skip
        self.rx_invalid_signature = 0
        self.telemetry = True
        self.last_telemetry_t = -math.inf
        self.lock = threading.Lock()
        n, e, d = opts.position_ned
        self.pos = [n, e, d]
        self.roll, self.pitch, self.yaw = 0.0, 0.02, opts.yaw
        self.p = 0.0
        self.roll_sp = 0.0
        self.last_sp_t = -math.inf
        self.t_start = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._hb_now = False

    # -- helpers -----------------------------------------------------------------------------
    def _mode_num(self, name: str) -> int:
        if self.o.flavour == "px4":
            return px4_custom_mode(*px4_mode_from_name(name))
        return arduplane_mode_from_name(name)

    def in_offboard(self) -> bool:
        if self.o.flavour == "px4":
            return px4_decode_custom_mode(self.custom_mode)[0] == 6
        return self.custom_mode == 15

    def mode_is(self, name: str) -> bool:
        return self.custom_mode == self._mode_num(name)

    def time_boot_ms(self) -> int:
        return int((self.o.boot_time_s + time.monotonic() - self.t_start) * 1000)

    # -- scripted events ----------------------------------------------------------------------
    def start(self) -> MavPeer:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.tr.close()

    def pilot_sets_mode(self, name: str) -> None:
        """Someone else (RC, GCS) changes the mode."""
        with self.lock:
            self.custom_mode = self._mode_num(name)
            self._hb_now = True

    def stop_telemetry(self) -> None:
        with self.lock:
            self.telemetry = False

    def resume_telemetry(self) -> None:
        with self.lock:
            self.telemetry = True

    def send_as(self, sysid: int, msg: Any) -> None:
        """Send ``msg`` from another system id (a spoofer, or a target)."""
        other = mavlink.MAVLink(self.tr, srcSystem=sysid, srcComponent=1)
        if self.o.signing_key is not None:
            other.signing = self.mav.signing
        other.send(msg)

    def wait_for(self, cond: Any, timeout_s: float) -> bool:
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            if cond():
                return True
            time.sleep(0.01)
        return cond()

    # -- loop --------------------------------------------------------------------------------
    def _heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
        )
        ap = (
            mavlink.MAV_AUTOPILOT_PX4
            if self.o.flavour == "px4"
            else mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        )
        self.mav.heartbeat_send(
            mavlink.MAV_TYPE_FIXED_WING, ap, base, self.custom_mode, mavlink.MAV_STATE_ACTIVE
        )

    def _handle(self, m: Any, now: float) -> None:
        t = m.get_type()
        if t == "BAD_DATA":
            if "signature" in str(getattr(m, "reason", "")):
                self.rx_invalid_signature += 1
            return
        rx = Rx(now, self.custom_mode, m)
        if t == "SET_ATTITUDE_TARGET":
            self.setpoints.append(rx)
            self.last_sp_t = now
            if self.o.flavour == "px4":
                self.p = m.body_roll_rate
            else:
                w, x, y, z = m.q
                self.roll_sp = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        elif t == "COMMAND_LONG":
            self.commands.append(rx)
            if m.command == 176:
                self._set_mode(m, now)
            elif m.command == 400:
                if self.o.arm_result is None:
                    self.armed = m.param1 == 1.0
                    self.mav.command_ack_send(400, 0)
                    self._hb_now = True
                else:
                    self.mav.command_ack_send(400, self.o.arm_result)
        elif t == "HEARTBEAT":
            self.heartbeats_rx.append(rx)
        elif t == "COMMAND_INT":
            self.commands.append(rx)
            if m.command == 192 and self.o.flavour == "px4":
                self.mav.command_ack_send(192, 0)
        elif t == "TIMESYNC" and m.tc1 == 0 and self.o.flavour == "px4":
            self.mav.timesync_send(self.time_boot_ms() * 1_000_000, m.ts1)
        elif t in ("PARAM_REQUEST_READ", "PARAM_SET"):
            name = m.param_id.rstrip("\x00") if isinstance(m.param_id, str) else ""
            if name not in self.params:
                return
            if t == "PARAM_SET":
                self.param_sets.append(rx)
                typ = self.params[name][1]
                v = m.param_value
                if typ == 6:  # PX4: bytewise
                    v = float(struct.unpack("<i", struct.pack("<f", v))[0])
                self.params[name] = (float(v), typ)
            v, typ = self.params[name]
            wire = struct.unpack("<f", struct.pack("<i", int(v)))[0] if typ == 6 else v
            names = list(self.params)
            self.mav.param_value_send(name.encode(), wire, typ, len(names), names.index(name))
        elif t == "REQUEST_DATA_STREAM":
            self.data_stream_requests.append(rx)

    def _set_mode(self, m: Any, now: float) -> None:
        if self.o.flavour == "px4":
            num = px4_custom_mode(int(m.param2), int(m.param3))
        else:
            num = int(m.param2)
        result = mavlink.MAV_RESULT_ACCEPTED
        if self.o.ack_result is not None:
            result = self.o.ack_result
        elif self.o.flavour == "px4" and px4_decode_custom_mode(num)[0] == 6:
            # PX4: OFFBOARD needs a setpoint stream of >= 1 s, the last one < 0.5 s old
            first = [r.t for r in self.setpoints if r.t > now - 1.5]
            if not first or now - first[0] < 1.0 or now - self.last_sp_t > 0.5:
                result = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
        self.mav.command_ack_send(176, result)
        if result == mavlink.MAV_RESULT_ACCEPTED:
            self.custom_mode = num
            self._hb_now = True

    def _step(self, dt: float, now: float) -> None:
        fresh = now - self.last_sp_t < 0.5
        if self.in_offboard() and fresh:
            if self.o.flavour == "px4":
                self.roll += self.p * dt
            else:
                self.roll += (self.roll_sp - self.roll) * min(1.0, dt / 0.3)
        else:
            self.p = 0.0
            self.roll += -self.roll * min(1.0, dt / 0.3)
        self.roll = max(-1.2, min(1.2, self.roll))
        V = self.o.airspeed
        r = G * math.tan(self.roll) / V
        self.yaw = (self.yaw + r * dt + math.pi) % (2 * math.pi) - math.pi
        self.pos[0] += V * math.cos(self.yaw) * dt + self.o.wind_ned[0] * dt
        self.pos[1] += V * math.sin(self.yaw) * dt + self.o.wind_ned[1] * dt
        self._r = r

    def _telemetry(self, k: int) -> None:
        tb = self.time_boot_ms()
        V = self.o.airspeed
        vn = V * math.cos(self.yaw) + self.o.wind_ned[0]
        ve = V * math.sin(self.yaw) + self.o.wind_ned[1]
        if self.o.send_local:
            self.mav.local_position_ned_send(tb, self.pos[0], self.pos[1], self.pos[2], vn, ve, 0.0)
        if self.o.send_global and k % 2 == 0:
            from mpf_mavlink.core.frames import ned_to_geodetic

            lat, lon, alt = ned_to_geodetic(self.pos, *self.o.home)
            hdg = int(math.degrees(self.yaw) % 360 * 100)
            self.mav.global_position_int_send(
                tb,
                int(lat * 1e7),
                int(lon * 1e7),
                int(alt * 1000),
                int(-self.pos[2] * 1000),
                int(vn * 100),
                int(ve * 100),
                0,
                hdg,
            )
        if self.o.send_global and k % 25 == 0:
            h = self.o.home
            self.mav.home_position_send(
                int(h[0] * 1e7), int(h[1] * 1e7), int(h[2] * 1000), 0, 0, 0, [1, 0, 0, 0], 0, 0, 0
            )
        if k % 5 == 0:
            self.mav.vfr_hud_send(
                V, math.hypot(vn, ve), int(math.degrees(self.yaw) % 360), 50, -self.pos[2], 0.0
            )
        if self.o.send_wind and k % 10 == 0:
            wn, we, wd = self.o.wind_ned
            self.mav.wind_send(
                math.degrees(math.atan2(-we, -wn)) % 360, math.sqrt(wn * wn + we * we + wd * wd), wd
            )
        self.truth.append(
            (tb, (self.pos[0], self.pos[1], self.pos[2]), (self.roll, self.pitch, self.yaw))
        )
        if self.o.frozen_echo_ms is not None and self.setpoints:
            sp = self.setpoints[-1].msg
            self.mav.attitude_target_send(
                self.o.frozen_echo_ms, 128, [1.0, 0.0, 0.0, 0.0], sp.body_roll_rate,
                sp.body_pitch_rate, sp.body_yaw_rate, sp.thrust,
            )  # fmt: skip
        # ATTITUDE last: the bridge acts on it, with the position of the same instant in hand
        if self.o.attitude_quaternion:
            from mpf_mavlink.quaternion import quat_of_euler

            q = quat_of_euler(self.roll, self.pitch, self.yaw)  # (w, x, y, z) = q1..q4
            self.mav.attitude_quaternion_send(
                tb, *q, self.p, 0.0, getattr(self, "_r", 0.0), [0.0, 0.0, 0.0, 0.0]
            )
        else:
            self.mav.attitude_send(
                tb, self.roll, self.pitch, self.yaw, self.p, 0.0, getattr(self, "_r", 0.0)
            )

    def _run(self) -> None:
        period = 1.0 / self.o.telemetry_hz
        hb_period = 1.0 / self.o.heartbeat_hz
        next_tick = next_hb = time.monotonic()
        last = time.monotonic()
        k = 0
        while not self._stop.is_set():
            now = time.monotonic()
            timeout = max(0.0, min(next_tick, next_hb) - now)
            r, _, _ = select.select([self.tr.fd], [], [], min(timeout, 0.01))
            now = time.monotonic()
            if r:
                data = self.tr.read()
                if data:
                    try:
                        msgs = self.mav.parse_buffer(data) or []
                    except Exception:  # noqa: BLE001
                        msgs = []
                    with self.lock:
                        for m in msgs:
                            self._handle(m, now)
            with self.lock:
                if now >= next_tick:
                    self._step(now - last, now)
                    last = now
                    next_tick += period
                    if next_tick < now:
                        next_tick = now + period
                    if self.telemetry:
                        self._telemetry(k)
                        self.last_telemetry_t = now
                    k += 1
                if now >= next_hb or self._hb_now:
                    self._heartbeat()
                    self._hb_now = False
                    next_hb = now + hb_period
