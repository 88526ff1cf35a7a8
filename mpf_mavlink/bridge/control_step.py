"""The bridge's control step: one :class:`~mpf_mavlink.bridge.controller.Controller` step per
ATTITUDE sample, its recording (time series, setpoints, verdict rows) and the setpoint on the wire."""

from __future__ import annotations

import math
import time
from typing import Any

from mpf_mavlink.bridge.base import BridgeBase, State, _Stop
from mpf_mavlink.bridge.controller import Step
from mpf_mavlink.core.adapter import Setpoint, safe_setpoint
from mpf_mavlink.mavlink import (
    Flavour,
    dialect,
    encode_set_attitude_target_quat,
    encode_set_attitude_target_rates,
)


class ControlStep(BridgeBase):
    """One control step per ATTITUDE sample, what it records and the setpoint it sends."""

    def _send_text(self, text: str) -> None:
        """A STATUSTEXT (severity INFO) from us: the tlog's record of a decision."""
        self._send(self.link.mav.statustext_encode(dialect.MAV_SEVERITY_INFO, text.encode("ascii")))

    def _send(self, msg: Any) -> None:
        self.link.send(msg)

    # -- timeouts ----------------------------------------------------------------------------
    def _left(
        self, since_mono: float, since_vt: float | None, timeout_s: float, wall_s: float = 0.0
    ) -> float:
        """Seconds left until ``timeout_s`` has passed since an instant (``since_mono`` on the
        wall clock, ``since_vt`` on the vehicle's); negative once it has. A real link: wall
        time. Lockstep (``mavlink.lockstep``): the vehicle's time, which stands still while the
        simulation is starved, bounded by ``wall_s`` (default ``lockstep_wall_timeout_s``) of
        wall time for a vehicle that sends nothing at all."""
        wall = time.monotonic() - since_mono
        if not self.m.lockstep:
            return timeout_s - wall
        bound = wall_s or self.m.lockstep_wall_timeout_s
        return min(timeout_s - self._vehicle_since(since_vt), bound - wall)

    def _vehicle_since(self, since_vt: float | None) -> float:
        """Vehicle seconds since ``since_vt``; 0 before any time stamp or after a reboot (its
        clock restarted: the mode change it comes back in, or the wall bound, ends the run)."""
        if self.vehicle_t is None or since_vt is None:
            return 0.0
        return max(0.0, self.vehicle_t - since_vt)

    def _since(self, since_mono: float, since_vt: float | None) -> str:
        """How long ago an instant was, for a log line (in lockstep both clocks)."""
        wall = time.monotonic() - since_mono
        if not self.m.lockstep:
            return f"{wall:.2f} s"
        return f"{self._vehicle_since(since_vt):.2f} s of vehicle time ({wall:.2f} s wall)"

    # -- control -----------------------------------------------------------------------------
    def _control_step(self) -> None:
        st = self.ctl.step()
        if st is None:
            return
        self.n["law_evals"] += 1
        self.t_last = st.t
        self._send_setpoint(st.setpoint, st.time_boot_ms)
        tl = self.link.tlog
        if tl is not None and tl.last_us is not None:  # its record time, as replay reads it
            self.ctl.note_sent(tl.last_us * 1e-6)
        self.last_sp, self.last_time_boot_ms = st.setpoint, st.time_boot_ms
        self.last_good_mono, self.last_good_vt = time.monotonic(), self.vehicle_t
        self.display.values(self.link, st, int(self.state))  # after the setpoint: off its path
        if self.state == State.TRACKING:
            self._record(st)
            if self.t_engage is not None and st.t - self.t_engage >= self.m.mission_duration_s:
                raise _Stop(f"mission duration {self.m.mission_duration_s:g} s reached", "duration")

    def _record(self, st: Step) -> None:
        self.table.append(st.row())
        self.sp_rows.append(tuple(st.setpoint_row()))
        e = st.estimate
        R2 = e.R_B_N[2]
        self.judge_rows.append(
            (
                -float(e.vehicle.position[2]),
                float(e.vehicle.airspeed),
                math.atan2(float(R2[1]), float(R2[2])),
                math.asin(max(-1.0, min(1.0, -float(R2[0])))),
            )
        )

    def _send_setpoint(self, sp: Setpoint, time_boot_ms: int) -> None:
        if sp.safe:
            self.n["safe_setpoints"] += 1
        try:
            if self.flavour is Flavour.PX4:
                msg = encode_set_attitude_target_rates(
                    self.link.mav,
                    time_boot_ms,
                    self.m.vehicle_sysid,
                    self.vehicle_compid,
                    *sp.body_rates_frd,
                    sp.thrust,
                )
            else:
                msg = encode_set_attitude_target_quat(
                    self.link.mav,
                    time_boot_ms,
                    self.m.vehicle_sysid,
                    self.vehicle_compid,
                    sp.q_wxyz,
                    sp.thrust,
                    sp.body_rates_frd,
                )
        except ValueError:  # the adapter already guarantees finite values; belt and braces
            sp = safe_setpoint(self.ad_params)
            self.n["safe_setpoints"] += 1
            return self._send_setpoint(sp, time_boot_ms)
        self._send(msg)
        now = time.monotonic()
        self.last_send_mono = now
        self.n["setpoints_sent"] += 1
        if self.state == State.PRESTREAM:
            if self.first_send_mono is None:
                self.first_send_mono = now
            self.prestream_sends += 1
