"""The simulated vehicle's MAVLink endpoint: receiving (delay queue, the bridge's epoch),
telemetry streams at the autopilot's rates, the target's own system, datagram batching and the
lockstep hand-shake. No autopilot decisions here (:mod:`sim.autopilot.emulation`)."""

from __future__ import annotations

import math
import time
from typing import Any

from mpf_mavlink.core.frames import matrix_to_quat_wxyz  # noqa: E402
from sim.plant.kinematic_plant import ned_to_geodetic_fast  # noqa: E402
from sim.vehicle.base import (
    _DATAGRAM_MAX,
    _SPEC,
    _STREAM_ORDER,
    GUIDED,
    OFFBOARD,
    M,
    VehicleBase,
    eas_factor,
)
from sim.vehicle.gcs_services import GcsServices  # noqa: E402

# what the autopilot acts on (through the incoming delay queue); the rest is dropped
_QUEUED = (
    frozenset(("COMMAND_LONG", "COMMAND_INT", "SET_MODE", "TIMESYNC", "REQUEST_DATA_STREAM"))
    | GcsServices.HANDLES
)


# SYS_STATUS sensors: present, enabled and healthy (a simulated airframe lacks none of them)
_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | M.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE | M.MAV_SYS_STATUS_SENSOR_GPS
            | M.MAV_SYS_STATUS_AHRS)  # fmt: skip


class MavEndpoint(VehicleBase):
    """Receive, stream telemetry and the target, batch datagrams, hand-shake in lockstep."""

    # ------------------------------------------------------------------ input
    def has_peer(self) -> bool:
        c = self.conn
        if getattr(c, "udp_server", False):  # pymavlink >= 2.4.4x keeps a set of clients
            return bool(getattr(c, "clients", None)) or getattr(c, "last_address", None) is not None
        if hasattr(c, "listen"):  # tcpin
            return getattr(c, "port", None) is not None
        return True

    def _lockstep_peer(self) -> bool:
        """With ``realtime_until_engaged``: the lockstep clock treats the peer as present only
        while it commands the vehicle (OFFBOARD / GUIDED). Until the bridge has taken control its
        hand-over rules run on wall-clock timers (>= 1 s of setpoints at >= 20 Hz before the mode
        request) while the autopilot's run on vehicle time; pacing that phase at real time keeps
        both in one time base, so the engagement happens after the same simulated time whatever
        the clock (lockstep and realtime runs start tracking from the same state)."""
        return self._behaviour in (OFFBOARD, GUIDED) and self.has_peer()

    def poll(self, timeout: float = 0.0) -> bool:
        """Read incoming MAVLink (waiting up to ``timeout`` wall s for the first byte).

        Returns True when a SET_ATTITUDE_TARGET arrived after the last telemetry was written.
        """
        if self._answered:
            self._drain()
            return True
        if timeout > 0.0:
            try:
                self.conn.select(timeout)
            except Exception:  # pragma: no cover
                time.sleep(min(timeout, 0.001))
        self._drain()
        return self._answered

    def _drain(self) -> None:
        if self._udp:
            self._drain_udp()
            return
        recv = self.conn.recv_msg
        for _ in range(10000):
            try:
                msg = recv()
            except (ConnectionError, OSError):
                return
            if msg is None:
                return
            self._on_msg(msg)

    def _drain_udp(self) -> None:
        """Read whole datagrams; a datagram that is one SET_ATTITUDE_TARGET (the bridge's answer,
        50 per simulated second) is decoded without pymavlink, anything else goes to pymavlink."""
        conn = self.conn
        port, server, parse = conn.port, conn.udp_server, conn.mav.parse_buffer
        for _ in range(10000):
            try:
                data, addr = port.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:  # ICMP for an earlier send (peer not up yet): cleared
                continue
            except OSError:
                return
            if server:  # what pymavlink's mavudp.recv does: remember the peer to answer it
                if addr not in conn.clients:
                    # a new peer hears who we are first: before our next 1 Hz HEARTBEAT a ground
                    # station takes the target's (system 2) 10 Hz positions for the vehicle's
                    self._next.pop("heartbeat", None)
                conn.clients.add(addr)
                conn.clients_last_alive[addr] = time.time()
            msgs = parse(data) or ()
            for msg in msgs:
                self._on_msg(msg)
            if server and len(conn.clients) > 1:
                self._route(msgs, addr)

    def _route(self, msgs: Any, src: Any) -> None:
        """Forward what one peer sends to the others, as ArduPilot's MAVLink routing (and PX4's
        forwarding) does: every message not addressed to this vehicle (no target, or another
        system's) from another component, so a ground station on the link sees the bridge's
        NAMED_VALUE_FLOAT and STATUSTEXT. Only with two peers or more (never on the lockstep
        path of a lone bridge)."""
        port, me = self.conn.port, (self.sysid, self.compid)
        for msg in msgs:
            if msg.get_type() == "BAD_DATA" or (msg.get_srcSystem(), msg.get_srcComponent()) == me:
                continue
            if getattr(msg, "target_system", 0) in (self.sysid,):
                continue
            buf = msg.get_msgbuf()
            for addr in list(self.conn.clients):
                if addr != src:
                    try:
                        port.sendto(buf, addr)
                    except OSError:
                        pass

    def _on_msg(self, msg: Any) -> None:
        mt = msg.get_type()
        if mt == "BAD_DATA":
            return
        self.rx_count += 1
        due = self._boot_t + self.command_latency_s
        if mt == "SET_ATTITUDE_TARGET":
            tb = msg.time_boot_ms
            if tb == 0:  # a peer that does not stamp its setpoints: any answer counts
                self._unstamped = True
            elif tb > self._answer_ms:
                self._answer_ms = tb
            self.answers += 1
            if not self.answers_positions and tb in self._pos_t:
                self.answers_positions = True  # a multi-rate peer: await its position frames
            tw = self._att_t.get(tb, self._pos_t.get(tb)) if self._lockstep_clock else None
            if tw is not None:
                # lockstep: the bridge answered at once in vehicle time, the latency runs
                # from the ATTITUDE it answers (not from when this process got to read it)
                due = max(self._boot_t, tw + self.command_latency_s)
        elif mt == "STATUSTEXT":
            if self._epoch_from_bridge:
                self._take_epoch(msg)
            return
        elif mt not in _QUEUED:
            return
        q = self._in
        i = len(q)
        while i > 0 and q[i - 1][0] > due:  # kept in order of due time
            i -= 1
        q.insert(i, (due, msg))

    def _take_epoch(self, msg: Any) -> None:
        """The bridge's mission origin (``MPF t0=``, autopilot boot s) as the target's t = 0."""
        from mpf_mavlink.bridge.controller import parse_marker

        text = msg.text if isinstance(msg.text, str) else bytes(msg.text).decode("ascii", "replace")
        mk = parse_marker(text)
        if mk is not None and mk[0] == "t0" and mk[1] is not None:
            with self._lock:
                self.target_epoch_boot_s = float(mk[1])
                self._tgt_rows.clear()  # truth() recomputes them on the new clock

    def _due(self, name: str, hz: float) -> bool:
        if hz <= 0:
            return False
        t = self._boot_t
        nxt = self._next.get(name)
        if nxt is None or t + 1e-9 >= nxt:
            period = 1.0 / hz
            nxt = t + period if nxt is None or t - nxt > period else nxt + period
            self._next[name] = nxt
            return True
        return False

    def _telemetry(self) -> None:
        """Queue the streams that are due (step_once has sent LOCAL_POSITION_NED and ATTITUDE
        already, in a datagram of their own: a peer that acts on ATTITUDE - the bridge answers
        each one with a setpoint - starts on it with the position and velocity of the same
        instant, and the slower streams, encoded after that datagram left and parsed by the peer
        after its answer, stay off the lockstep path telemetry -> answer -> next frame; they
        reach the peer at most one 20 ms frame later, as the phases of independent autopilot
        streams do anyway). A velocity one frame old would not do: the bridge's wind frame is
        the direction of ground velocity - wind, and 20 ms more lag in it costs the tight
        guidance gains of the demo a factor 2-3 in tracking error (measured)."""
        r, nxt, t = self.rates, self._next, self._k * self.dt + 1e-9
        if self.wind_estimate_tau_s > 0.0:
            self._update_wind_estimate(t)
        for name in _STREAM_ORDER:
            n = nxt.get(name)
            if n is not None and t < n:
                continue  # not due (the common case: a cheap test before _due's bookkeeping)
            if self._due(name, getattr(r, name)):
                self._send_stream(name)
        if self.target is not None:
            if self._due("target_heartbeat", 1.0):
                self._put(self._ftp.pack(_SPEC["heartbeat"], self._target_type, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                         M.MAV_STATE_ACTIVE, 3))  # fmt: skip
            if self.target_feed is not None:
                for buf in self.target_feed.poll(self._k * self.dt, self.target_t):
                    self._put(buf)
            elif self._due("target", self.target_rate_hz):
                self._send_target()

    def _update_wind_estimate(self, t: float) -> None:
        """Advance the reported wind: a first-order lag (``wind_estimate_tau_s``) of the true
        air-mass velocity, the way an autopilot's estimator follows it (PX4 EKF2's wind states
        are a random walk observed through airspeed: gusts of a second or two barely move them).
        It starts at the truth: a vehicle that has flown a while has converged on the steady wind.
        Horizontal only: neither PX4's EKF2 nor ArduPilot's EKF2/EKF3 estimates a vertical wind
        (their getWind sets z = 0), so no autopilot reports one (ArduPlane's WIND.speed_z here
        had carried the lagged vertical gust)."""
        w = self._st.wind_ned
        if self._wind_est is None:
            self._wind_est = (float(w[0]), float(w[1]), 0.0)
        else:
            k = 1.0 - math.exp(-max(0.0, t - self._wind_est_t) / self.wind_estimate_tau_s)
            e0, e1, _ = self._wind_est
            self._wind_est = (e0 + k * (float(w[0]) - e0), e1 + k * (float(w[1]) - e1), 0.0)
        self._wind_est_t = t

    def _send_attitude(self, att: tuple[float, float, float, float, float, float]) -> None:
        """ATTITUDE from (roll, pitch, yaw, p, q, r) (rad, rad/s)."""
        self._sent["attitude"] = self._sent.get("attitude", 0) + 1
        ms = self._ms()
        self._put(self._fp.pack(_SPEC["attitude"], ms, *att), ms)

    def _send_stream(self, name: str) -> None:
        st, ms, S = self._st, self._ms(), _SPEC
        pack, put = self._fp.pack, self._put
        self._sent[name] = self._sent.get(name, 0) + 1
        if name == "heartbeat":
            ap = M.MAV_AUTOPILOT_PX4 if self.px4 else M.MAV_AUTOPILOT_ARDUPILOTMEGA
            put(pack(S["heartbeat"], M.MAV_TYPE_FIXED_WING, ap, self._base_mode(), self._custom_mode,
                     M.MAV_STATE_ACTIVE, 3))  # fmt: skip
        elif name == "attitude":
            self._sent[name] -= 1  # counted by _send_attitude
            self._send_attitude((*st.euler, *st.pqr))
        elif name == "local_position":
            x, y, z = st.position_ned
            vx, vy, vz = st.velocity_ned
            put(pack(S["local_position_ned"], ms, x, y, z, vx, vy, vz), -1, ms)
        elif name == "global_position":
            vx, vy, vz = st.velocity_ned
            hdg = int(round(math.degrees(st.euler[2]) * 100.0)) % 36000
            put(pack(S["global_position_int"],
                ms, int(round(st.lat_deg * 1e7)), int(round(st.lon_deg * 1e7)), int(round(st.alt_m * 1000.0)),
                int(round((st.alt_m - self.home_lla[2]) * 1000.0)),
                int(round(vx * 100)), int(round(vy * 100)), int(round(vz * 100)), hdg))  # fmt: skip
        elif name == "vfr_hud":
            v = st.velocity_ned
            hdg = int(round(math.degrees(st.euler[2]))) % 360
            # both autopilots report an equivalent airspeed (ArduPilot EAS, PX4 calibrated)
            eas = st.airspeed * eas_factor(float(st.alt_m))
            put(pack(S["vfr_hud"], eas, math.hypot(v[0], v[1]), hdg, int(round(100 * st.throttle)),
                     st.alt_m, -float(v[2])))  # fmt: skip
        elif name == "wind":
            w = self._wind_est if self._wind_est is not None else st.wind_ned
            wn, we, wd = (float(v) for v in w)
            if self.px4:
                put(pack(S["wind_cov"], self._us(), wn, we, 0.0, 0.0, 0.0, st.alt_m, 0.0, 0.0))
            else:
                direction = math.degrees(math.atan2(-we, -wn)) % 360.0
                put(pack(S["wind"], direction, math.sqrt(wn * wn + we * we + wd * wd), wd))
        elif name == "home_position":
            lat, lon, alt = self.home_lla
            put(pack(S["home_position"], int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
                     0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, self._us()))  # fmt: skip
        elif name == "sys_status":
            s = _SENSORS
            # health also sets GEOFENCE, as ArduPilot reports a fence it does not have: MAVProxy
            # reads that bit clear as "fence breach" whatever the present bits say
            put(pack(S["sys_status"], s, s, s | M.MAV_SYS_STATUS_GEOFENCE, 100, 12600, 500, 90,
                     0, 0, 0, 0, 0, 0, 0, 0, 0))  # fmt: skip
        elif name == "gps_raw":
            vn, ve = float(st.velocity_ned[0]), float(st.velocity_ned[1])
            cog = int(round(math.degrees(math.atan2(ve, vn)) * 100.0)) % 36000
            # a healthy 3D fix: HDOP 0.8, VDOP 1.2, 14 satellites, 0.5 m / 0.8 m accuracy
            put(pack(S["gps_raw_int"], self._us(), M.GPS_FIX_TYPE_3D_FIX,
                     int(round(st.lat_deg * 1e7)), int(round(st.lon_deg * 1e7)), int(round(st.alt_m * 1000.0)),
                     80, 120, int(round(math.hypot(vn, ve) * 100.0)), cog, 14, 0, 500, 800, 150, 0, 0))  # fmt: skip
        elif name == "system_time":
            put(pack(S["system_time"], self.unix0_us + self._us(), ms))
        elif name == "attitude_target":
            # PX4's ATTITUDE_TARGET: the setpoint in use, stamped when it was received (a
            # companion measures its loop delay from it); nothing before the first setpoint
            echo = getattr(self, "_sp_echo", None)
            if self.px4 and echo is not None:
                t_ms, tm, q, rates, thrust = echo
                put(pack(S["attitude_target"], t_ms, tm, list(q), *rates, thrust))

    def _send_target(self) -> None:
        ts = self.target.state(self.target_t)
        n, e, d = (float(v) for v in ts.position)
        lat, lon, alt = ned_to_geodetic_fast(self.origin, n, e, d)
        q = matrix_to_quat_wxyz(ts.R_T_I)
        vel = [float(v) for v in ts.velocity]
        acc = [float(v) for v in ts.acceleration]
        rates = [float(v) for v in ts.omega_T]
        pack, ms = self._ftp.pack, self._ms()
        lat7, lon7 = int(round(lat * 1e7)), int(round(lon * 1e7))
        self._put(
            pack(
                _SPEC["follow_target"],
                ms,
                15,
                lat7,
                lon7,
                alt,
                vel,
                acc,
                list(q),
                rates,
                [0.0, 0.0, 0.0],
                0,
            )
        )
        yaw = math.atan2(ts.R_T_I[1, 0], ts.R_T_I[0, 0])
        self._put(pack(_SPEC["global_position_int"],
            ms, lat7, lon7, int(round(alt * 1000)), int(round((alt - self.home_lla[2]) * 1000)),
            int(round(vel[0] * 100)), int(round(vel[1] * 100)), int(round(vel[2] * 100)),
            int(round(math.degrees(yaw) * 100)) % 36000))  # fmt: skip

    def _flush(self) -> None:
        """Send the packets that are due, bundled into as few datagrams as fit (PX4 does the same:
        one datagram per send cycle), so the peer wakes up once per frame, not once per packet."""
        self._flush_due()
        # A frame that writes no ATTITUDE still awaits the answer that acts in the next frame:
        # with ATTITUDE at 10 Hz over 20 ms frames the vehicle otherwise ran the four frames
        # between two of them without waiting, and applied each setpoint whenever the bridge's
        # process got to it (the echo measured 100 ms of command latency instead of 20).
        self._choose_await(self._boot_t)

    def _flush_due(self) -> None:
        q, t = self._out, self._boot_t + 1e-9
        if not q or q[0][0] > t:
            return
        wrote = False
        chunk: list[bytes] = []
        size = 0
        att_ms = pos_ms = -1
        while q and q[0][0] <= t:
            _, buf, ms, pms = q.popleft()
            att_ms, pos_ms = max(att_ms, ms), max(pos_ms, pms)
            if chunk and size + len(buf) > _DATAGRAM_MAX:
                wrote |= self._write(b"".join(chunk))
                chunk, size = [], 0
            chunk.append(buf)
            size += len(buf)
        if chunk:
            wrote |= self._write(b"".join(chunk))
        if not wrote:
            return
        if att_ms >= 0:
            self._attitude_written(att_ms, t - 1e-9)
        if pos_ms > att_ms:  # a position newer than any ATTITUDE in the frame
            if self.answers_positions:
                self._attitude_written(pos_ms, t - 1e-9)
            else:
                self._position_written(pos_ms, t - 1e-9)

    def _position_written(self, ms: int, t: float) -> None:
        """A frame with a LOCAL_POSITION_NED newer than its ATTITUDE (if any) left at vehicle
        time ``t``, to a peer not known to answer those: remembered (not awaited) so that an
        answer stamped with it is recognised (and its latency counted from ``t``)."""
        p = self._pos_t
        p[ms] = t
        if len(p) > 512:
            p.pop(next(iter(p)))

    def _attitude_written(self, ms: int, t: float) -> None:
        """An ATTITUDE stamped ``ms`` (or a position of a multi-rate peer's) left at vehicle
        time ``t`` (s): remembered; :meth:`_flush` chooses the one to await."""
        w = self._att_written
        if len(w) == w.maxlen:
            self._att_t.pop(w[0][0], None)
        w.append((ms, t))
        self._att_t[ms] = t
        self._unstamped = False

    def _choose_await(self, t: float) -> None:
        """At the end of the frame that ends at vehicle time ``t`` (s): the answer to an
        ATTITUDE written at tw acts at tw + latency, so await the latest one that acts before
        the end of the next frame."""
        w = self._att_written
        horizon = t + self.frame_period - self.command_latency_s - 1e-6
        for m, tw in reversed(w):
            if tw < horizon:
                self._await_ms = m
                return
        self._await_ms = -1

    @property
    def _answered(self) -> bool:
        return self._answer_ms >= self._await_ms or self._unstamped

    def _write(self, data: bytes) -> bool:
        try:
            self.conn.write(data)
            return True
        except OSError:
            return False
