"""The simulated vehicle's autopilot emulation (PX4 commander / ArduPlane rules): offboard
and GUIDED setpoints, their time-outs and failsafes, commands and their ACKs, mode changes.
The rules are listed in :mod:`sim.vehicle.vehicle`."""

from __future__ import annotations

import math

from sim.vehicle.base import (
    _AP_DATA_STREAMS,
    _STREAM_IDS,
    ARDUPILOT_FORCE_DISARM,
    ARDUPLANE_MODES,
    ARDUPLANE_NUMBERS,
    CRUISE,
    GUIDED,
    LOITER,
    OFFBOARD,
    PX4_AUTO_SUB,
    PX4_MAIN,
    PX4_MAIN_NAMES,
    PX4_OFFBOARD_MAX_GAP_S,
    PX4_OFFBOARD_MIN_STREAM_S,
    PX4_SUB_NAMES,
    M,
    _clip,
    _finite,
    px4_custom_mode,
    px4_decode_custom_mode,
)
from sim.vehicle.endpoint import MavEndpoint


class AutopilotEmulation(MavEndpoint):
    """What the stock autopilot does with setpoints, commands and mode requests."""

    def _offboard_available(self) -> bool:
        t, last, start = self._boot_t, self._sp_last, self._sp_stream_start
        return (
            last is not None
            and start is not None
            and t - last <= PX4_OFFBOARD_MAX_GAP_S
            and t - start >= PX4_OFFBOARD_MIN_STREAM_S - 1e-9
        )

    # ------------------------------------------------------------------ control (one physics step)
    def _control(self, st) -> tuple[float, float, float, float]:
        dt, ap, t = self.dt, self.ap, self._boot_t
        beh = self._behaviour
        if beh == OFFBOARD:
            if self._sp_last is None or t - self._sp_last > self.com_of_loss_t:
                self._statustext(
                    M.MAV_SEVERITY_CRITICAL, "Failsafe: no offboard signal, switching to Hold"
                )
                self._set_px4_mode(PX4_MAIN["AUTO"], PX4_AUTO_SUB["LOITER"])
                beh = self._behaviour
            else:
                assert self._sp is not None  # offboard is only available with a setpoint
                kind, vals, thrust = self._sp
                if kind == "rates":
                    a, e, r = ap.rates_to_surfaces(dt, vals, tuple(st.pqr), st.airspeed)
                else:
                    roll_sp, pitch_sp = vals
                    shaper = getattr(self, "_shaper", None)
                    if shaper is not None:
                        roll_sp, pitch_sp = shaper(roll_sp, pitch_sp)
                    a, e, r = ap.attitude_to_surfaces(dt, roll_sp, pitch_sp, st)
                scale = getattr(self, "thrust_scale", 1.0)  # the profile's full thrust
                return a, e, r, (thrust * scale if self.armed else 0.0)
        if beh == GUIDED:
            return self._guided_control(st)
        if beh == LOITER:
            out = ap.loiter_step(dt, st, self._center, self.cruise_airspeed, self._alt_sp,
                                 self._hold_radius, self.loiter_direction)  # fmt: skip
        elif beh == CRUISE:
            roll = ap.hold.heading_roll(self._course, (st.velocity_ned[0], st.velocity_ned[1]))
            out = ap.hold_step(dt, st, self.cruise_airspeed, self._alt_sp, roll)
        else:  # LEVEL: wings level, trim pitch, trim throttle
            a, e, r = ap.attitude_to_surfaces(dt, 0.0, ap.hold.gains.pitch_trim, st)
            out = (a, e, r, ap.hold.trim_throttle)
        a, e, r, thr = out
        return a, e, r, (thr if self.armed else 0.0)

    def _guided_control(self, st) -> tuple[float, float, float, float]:
        dt, ap, t = self.dt, self.ap, self._boot_t
        ft, fv, to = self._forced_t, self._forced, self.guided_timeout
        fresh = [x is not None and t - x < to for x in ft]
        gl = self._guided_loiter
        center, alt_sp, radius, direction = (
            gl if gl is not None
            else (self._center, self._alt_sp, self.loiter_radius, self.loiter_direction)
        )  # fmt: skip
        if fresh[0]:
            roll_sp = fv[0]
        else:
            pos, vel = st.position_ned, st.velocity_ned
            roll_sp = ap.hold.loiter_roll(center, (float(pos[0]), float(pos[1])),
                                          (float(vel[0]), float(vel[1])), radius,
                                          direction)  # fmt: skip
        climb = -float(st.velocity_ned[2])
        _, pitch_tecs, thr_tecs = ap.hold.update(
            dt,
            self.cruise_airspeed,
            alt_sp,
            st.airspeed,
            -float(st.position_ned[2]),
            climb,
            roll_sp,
        )
        pitch_sp = fv[1] if fresh[1] else pitch_tecs
        shaper = getattr(self, "_shaper", None)
        if shaper is not None:  # the firmware's own attitude loop: lag, gain, bias (profile)
            roll_sp, pitch_sp = shaper(roll_sp, pitch_sp)
        a, e, r = ap.attitude_to_surfaces(dt, roll_sp, pitch_sp, st)
        if fresh[2]:
            r = _clip(math.degrees(fv[2]) / 45.0, -1.0, 1.0)  # ArduPlane: +-4500 cdeg = full rudder
        thr = fv[3] if fresh[3] else thr_tecs
        return a, e, r, (thr if self.armed else 0.0)

    def _apply_due(self) -> None:
        q, t = self._in, self._boot_t + 1e-9
        while q and q[0][0] <= t:
            _, msg = q.popleft()
            self._handle(msg)

    def _handle(self, msg) -> None:
        mt = msg.get_type()
        if mt == "SET_ATTITUDE_TARGET":
            if msg.target_system not in (0, self.sysid):
                self.dropped["wrong_target"] += 1
                return
            (self._sat_px4 if self.px4 else self._sat_ardupilot)(msg)
        elif mt in ("COMMAND_LONG", "COMMAND_INT"):
            if msg.target_system not in (0, self.sysid):
                return
            try:
                self._command(msg)
            except (ValueError, OverflowError):  # a NaN / huge where an integer belongs
                self._ack(msg.command, M.MAV_RESULT_DENIED, msg)
        elif mt == "SET_MODE":
            if msg.target_system not in (0, self.sysid):
                return
            if self.px4:
                main, sub = px4_decode_custom_mode(msg.custom_mode)
                res = self._do_set_mode(float(msg.base_mode), float(main), float(sub))
                self._ack(M.MAV_CMD_DO_SET_MODE, res, msg)  # PX4 turns SET_MODE into DO_SET_MODE
            else:
                res = self._do_set_mode(float(msg.base_mode), float(msg.custom_mode), 0.0)
                self._ack(M.MAVLINK_MSG_ID_SET_MODE, res, msg)  # ArduPilot acks with command 11
        elif mt == "REQUEST_DATA_STREAM":
            if msg.target_system not in (0, self.sysid) or self.px4:
                return  # PX4 ignores it (MAV_CMD_SET_MESSAGE_INTERVAL only)
            hz = float(msg.req_message_rate) if msg.start_stop else 0.0
            # ArduPilot caps a stream at 1.25 main-loop periods (40 Hz at Plane's 50 Hz loop)
            hz = min(hz, 1.0 / (1.25 * self.frame_period))
            groups = _AP_DATA_STREAMS.values() if msg.req_stream_id == 0 else (
                [_AP_DATA_STREAMS[msg.req_stream_id]] if msg.req_stream_id in _AP_DATA_STREAMS else [])  # fmt: skip
            for group in groups:
                for name in group:
                    setattr(self.rates, name, hz)
                    self._next.pop(name, None)
        elif mt in self.gcs.HANDLES:
            try:
                self.gcs.handle(msg)
            except (ValueError, OverflowError, TypeError):  # malformed: no answer, no crash
                self.dropped["malformed"] = self.dropped.get("malformed", 0) + 1
        elif mt == "TIMESYNC" and msg.tc1 == 0:
            self._mav.send(self._mav.timesync_encode(int(self._boot_t * 1e9), msg.ts1))

    # PX4 offboard setpoint
    def _sat_px4(self, msg) -> None:
        tm = msg.type_mask
        att_ignore, thr_ignore = bool(tm & 128), bool(tm & 64)
        rates = (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
        used = [] if thr_ignore else [msg.thrust]
        if att_ignore:
            if tm & 7 == 7:
                self.dropped["no_axes"] += 1
                return
            used += [rates[i] for i in range(3) if not tm & (1 << i)]
        else:
            used += list(msg.q)
        if not _finite(*used):
            self.dropped["nonfinite"] += 1
            return
        thrust = 0.0 if thr_ignore else _clip(float(msg.thrust), 0.0, 1.0)
        if att_ignore:
            sp = (
                "rates",
                tuple(0.0 if tm & (1 << i) else float(rates[i]) for i in range(3)),
                thrust,
            )
        else:
            from mpf_mavlink.core.frames import matrix_to_euler, quat_wxyz_to_matrix

            try:
                roll, pitch, _ = matrix_to_euler(quat_wxyz_to_matrix(msg.q))
            except ValueError:
                self.dropped["nonfinite"] += 1
                return
            sp = ("att", (roll, pitch), thrust)
        self._sp = sp
        # what ATTITUDE_TARGET echoes: PX4 stamps the setpoint when its receiver publishes it
        self._sp_echo = (self._ms(), msg.type_mask, tuple(msg.q), rates, float(msg.thrust))
        if thr_ignore and self.px4_require_thrust:
            return  # applied if already offboard, but not counted as an offboard signal
        t = self._boot_t
        if self._sp_last is None or t - self._sp_last > PX4_OFFBOARD_MAX_GAP_S:
            self._sp_stream_start = t
        self._sp_last = t

    # ArduPlane guided attitude
    def _sat_ardupilot(self, msg) -> None:
        if self._behaviour != GUIDED:
            self.dropped["not_guided"] += 1
            return
        q = list(msg.q)
        if not _finite(*q) or (not (msg.type_mask & 64) and not _finite(msg.thrust)):
            self.dropped["nonfinite"] += 1
            return
        from mpf_mavlink.core.frames import matrix_to_euler, quat_wxyz_to_matrix

        inv = (~msg.type_mask) & 0xFF
        am = inv & 0x87
        t = self._boot_t
        try:
            euler = matrix_to_euler(quat_wxyz_to_matrix(q)) if am else (0.0, 0.0, 0.0)
        except ValueError:
            self.dropped["nonfinite"] += 1
            return
        for i, bit in enumerate((0x81, 0x82, 0x84)):
            if am & bit:
                self._forced[i] = float(euler[i])
                self._forced_t[i] = t
        if inv & 0x40:
            self._forced[3] = _clip(float(msg.thrust), 0.0, 1.0)
            self._forced_t[3] = t

    # commands
    def _ack(self, command: int, result: int, msg, reason: str | None = None) -> None:
        self._mav.send(
            self._mav.command_ack_encode(
                command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            )
        )
        if reason:
            self._statustext(
                M.MAV_SEVERITY_WARNING if result != M.MAV_RESULT_ACCEPTED else M.MAV_SEVERITY_INFO,
                reason,
            )

    def _command(self, msg) -> None:
        cmd = msg.command
        p1, p2, p3 = msg.param1, msg.param2, msg.param3
        if cmd == M.MAV_CMD_DO_SET_MODE:
            res = self._do_set_mode(p1, p2, p3)
            reason = self._reject_reason
            self._reject_reason = None
            self._ack(cmd, res, msg, reason)
        elif cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p1 >= 0.5:
                self.armed = True
                self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            elif abs(p2 - ARDUPILOT_FORCE_DISARM) < 0.5:
                self.armed = False
                self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            else:  # in the air: both autopilots refuse a disarm unless forced
                res = M.MAV_RESULT_TEMPORARILY_REJECTED if self.px4 else M.MAV_RESULT_FAILED
                self._ack(cmd, res, msg, "Disarm refused: vehicle is flying (use force 21196)")
        elif cmd == M.MAV_CMD_DO_REPOSITION and not self.px4:
            # ArduPlane takes it as COMMAND_INT only; a COMMAND_LONG is UNSUPPORTED (4.7 SITL)
            res = (
                self._reposition(msg)
                if msg.get_type() == "COMMAND_INT"
                else M.MAV_RESULT_UNSUPPORTED
            )
            self._ack(cmd, res, msg)
        elif cmd == M.MAV_CMD_DO_REPOSITION:
            self._ack(cmd, self._px4_reposition(msg), msg)
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            self._ack(cmd, self._takeoff(msg), msg)
        elif cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES or (
            cmd == M.MAV_CMD_REQUEST_MESSAGE and int(p1) == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
        ):
            self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            self.gcs.send_autopilot_version()
        elif cmd == M.MAV_CMD_GET_HOME_POSITION:
            self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
            self._send_stream("home_position")
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            name = _STREAM_IDS.get(int(p1))
            if name is None:
                self._ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)
            else:
                self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
                self._send_stream(name)
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            name = _STREAM_IDS.get(int(p1))
            if name is None:
                self._ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)
                return
            if p2 < 0:
                hz = 0.0
            elif p2 == 0:
                hz = getattr(self.stock, name)
            else:
                hz = 1e6 / p2
                if not self.px4 and p2 * 0.8 < self.frame_period * 1e6:
                    # ArduPilot (GCS_Common.cpp, cap_message_interval): an interval shorter
                    # than 1.25 main-loop periods is refused, saying so (50 Hz at Plane's 50 Hz)
                    self._statustext(M.MAV_SEVERITY_INFO, f"Requested rate for message ID {int(p1)} too fast. Increase SCHED_LOOP_RATE")  # fmt: skip
                    self._ack(cmd, M.MAV_RESULT_DENIED, msg)
                    return
            setattr(self.rates, name, hz)
            self._next.pop(name, None)
            self._ack(cmd, M.MAV_RESULT_ACCEPTED, msg)
        else:
            self._ack(cmd, M.MAV_RESULT_UNSUPPORTED, msg)

    def _reposition(self, msg) -> int:
        """ArduPlane's MAV_CMD_DO_REPOSITION (COMMAND_INT): in GUIDED (or with the change-mode
        flag) the guided target becomes a loiter of radius param3 (> 0; else the loiter radius)
        about (x, y, z), counter-clockwise when param4 is non-zero; the forced attitude stays."""
        from mpf_mavlink.core.frames import geodetic_to_ned

        lat, lon = msg.x * 1e-7, msg.y * 1e-7
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0) or (msg.x == 0 and msg.y == 0):
            return M.MAV_RESULT_DENIED
        alt = float(msg.z)
        if msg.frame in (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            alt += self.home_lla[2]
        elif msg.frame not in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            return M.MAV_RESULT_DENIED
        if not (int(msg.param2) & 1) and self._behaviour != GUIDED:
            return M.MAV_RESULT_FAILED
        if self._behaviour != GUIDED:
            self._set_ap_mode(ARDUPLANE_NUMBERS["GUIDED"])
        n, e, d = (float(v) for v in geodetic_to_ned(lat, lon, alt, *self.home_lla))
        r = (
            float(msg.param3)
            if math.isfinite(msg.param3) and msg.param3 > 0
            else self.loiter_radius
        )
        ccw = math.isfinite(msg.param4) and msg.param4 != 0.0
        self._guided_loiter = ((n, e), -d, r, -1 if ccw else 1)
        return M.MAV_RESULT_ACCEPTED

    def _command_position(self, msg) -> tuple[float, float, float] | None:
        """(lat deg, lon deg, altitude AMSL m) of a COMMAND_INT (x, y 1e7, z; a global frame)
        or COMMAND_LONG (param5..7); None when not finite or out of range. A NaN altitude is
        the current one (the MAVLink rule for "keep")."""
        if msg.get_type() == "COMMAND_INT":
            if msg.frame not in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT,
                                 M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):  # fmt: skip
                return None
            lat, lon, alt = msg.x * 1e-7, msg.y * 1e-7, float(msg.z)
            rel = msg.frame in (
                M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            )
        else:
            lat, lon, alt, rel = float(msg.param5), float(msg.param6), float(msg.param7), False
        if not (_finite(lat, lon) and abs(lat) <= 90.0 and abs(lon) <= 180.0) or (
            lat == 0 and lon == 0
        ):
            return None
        if not math.isfinite(alt):
            alt = float(self.plant.state().alt_m)
        elif rel:
            alt += self.home_lla[2]
        return lat, lon, alt

    def _px4_reposition(self, msg) -> int:
        """PX4's MAV_CMD_DO_REPOSITION: with the change-mode flag (param2 bit 0), or already in
        Hold, the vehicle loiters about the point (radius param3 when > 0, as PX4's fixed-wing
        navigator) at its altitude; without either it is accepted and changes nothing."""
        from mpf_mavlink.core.frames import geodetic_to_ned

        pos = self._command_position(msg)
        if pos is None:
            return M.MAV_RESULT_DENIED
        hold = px4_custom_mode(PX4_MAIN["AUTO"], PX4_AUTO_SUB["LOITER"])
        if not (int(msg.param2) & 1) and self._custom_mode != hold:
            return M.MAV_RESULT_ACCEPTED
        if self._custom_mode != hold:
            self._set_px4_mode(PX4_MAIN["AUTO"], PX4_AUTO_SUB["LOITER"])
        n, e, d = (float(x) for x in geodetic_to_ned(*pos, *self.home_lla))
        self._center, self._alt_sp = (n, e), -d
        if math.isfinite(msg.param3) and msg.param3 > 0:
            self._hold_radius = float(msg.param3)
        return M.MAV_RESULT_ACCEPTED

    def _takeoff(self, msg) -> int:
        """MAV_CMD_NAV_TAKEOFF in the air. PX4 accepts it and enters AUTO.TAKEOFF (here: a loiter
        climbing to param7, AMSL, where it is). ArduPlane answers FAILED (4.7 SITL does so from
        the ground; its TAKEOFF is a mode, not this command)."""
        if not self.px4:
            return M.MAV_RESULT_FAILED
        alt = float(msg.param7) if msg.get_type() == "COMMAND_LONG" else float(msg.z)
        self._set_px4_mode(PX4_MAIN["AUTO"], PX4_AUTO_SUB["TAKEOFF"])
        if math.isfinite(alt):
            self._alt_sp = alt - self.home_lla[2]
        return M.MAV_RESULT_ACCEPTED

    def _do_set_mode(self, p1: float, p2: float, p3: float) -> int:
        self._reject_reason = None
        if not (int(p1) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
            self._reject_reason = "Mode change refused: custom mode flag (param1 = 1) not set"
            return M.MAV_RESULT_UNSUPPORTED if not self.px4 else M.MAV_RESULT_DENIED
        if self.px4:
            main, sub = int(round(p2)), int(round(p3))
            if main not in PX4_MAIN_NAMES or (
                main == PX4_MAIN["AUTO"] and sub not in PX4_SUB_NAMES and sub != 0
            ):
                self._reject_reason = f"Mode change refused: unknown PX4 mode {main}/{sub}"
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            if (
                main == PX4_MAIN["OFFBOARD"]
                and self._behaviour != OFFBOARD
                and not self._offboard_available()
            ):
                self._reject_reason = (
                    "Mode change refused: offboard setpoints not streaming (> 2 Hz for 1 s)"
                )
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            if main == PX4_MAIN["AUTO"] and sub == 0:
                sub = PX4_AUTO_SUB["MISSION"]  # PX4: AUTO without a sub mode is MISSION
            if px4_custom_mode(main, sub if main == PX4_MAIN["AUTO"] else 0) != self._custom_mode:
                self._set_px4_mode(main, sub)  # re-selecting the current mode changes nothing
            return M.MAV_RESULT_ACCEPTED
        number = int(round(p2))
        if number not in ARDUPLANE_MODES:
            self._reject_reason = f"Mode change refused: unknown ArduPlane mode {number}"
            return M.MAV_RESULT_FAILED
        if number != self._custom_mode:
            self._set_ap_mode(number)
        return M.MAV_RESULT_ACCEPTED
