"""The bridge's link loop: receive and dispatch messages (tlog time stamps), periodic duties
(companion heartbeat, setpoint re-sends) and the bounded wait every life-cycle step spins in."""

from __future__ import annotations

import math
import struct
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from mpf_mavlink.bridge.base import State, _Stop
from mpf_mavlink.bridge.control_step import ControlStep
from mpf_mavlink.mavlink import Flavour, decode, dialect, is_offboard, mode_name

#: How often the bridge asks PX4 for TIMESYNC (s): the 16 answers kept (controller.py) span
#: 8 s, over which a line follows the clocks' drift.
TIMESYNC_PERIOD_S = 0.5


_INT_PARAM_TYPES = frozenset({1, 2, 3, 4, 5, 6})  # MAV_PARAM_TYPE_(U)INT8/16/32


def param_value(msg: Any, bytewise: bool) -> float | None:
    """A PARAM_VALUE's value; None if not finite. PX4 encodes integer parameters bytewise (the
    int's bits in the float field), ArduPilot casts them to float."""
    v = msg.param_value
    if bytewise and int(getattr(msg, "param_type", 9)) in _INT_PARAM_TYPES:
        return float(struct.unpack("<i", struct.pack("<f", v))[0])
    return float(v) if math.isfinite(v) else None


def param_set_value(value: float, param_type: int, bytewise: bool) -> float:
    """The float a PARAM_SET carries for ``value`` of a parameter of ``param_type``."""
    if bytewise and param_type in _INT_PARAM_TYPES:
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return float(value)


class LinkIO(ControlStep):
    """Receive, dispatch, periodic sends and the bounded wait (:meth:`_spin`)."""

    # -- I/O helpers -------------------------------------------------------------------------
    def _rx_time(self, msg: Any) -> float | None:
        """The receive time (s since the epoch) as the tlog recorded it: the link logs each
        message just before handing it over, so the last record is this one. The same float
        as a tlog reader computes (us * 1e-6), so replay sees exactly what we saw."""
        tl = self.link.tlog if self.link is not None else None
        if tl is not None and tl.last_packet is msg.get_msgbuf() and tl.last_us is not None:
            return tl.last_us * 1e-6
        t = getattr(msg, "_timestamp", None)  # no tlog record for it: quantise alike
        return None if t is None else round(t * 1e6) * 1e-6

    def _dispatch(self, msg: Any) -> None:
        src = msg.get_srcSystem()
        if src == self.m.vehicle_sysid:
            if self._arrivals is not None:
                self._arrivals.setdefault(msg.get_type(), deque(maxlen=400)).append(
                    time.monotonic()
                )
            if msg.get_type() == "PARAM_VALUE":
                name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else ""
                v = param_value(msg, self.flavour is Flavour.PX4)
                if v is not None:
                    self.params[name] = v
                    self.param_types[name] = int(msg.param_type)
                return
        rx = self._rx_time(msg)
        msg._timestamp = rx  # decoders copy it into the samples (VFR_HUD, WIND, HEARTBEAT)
        sample = decode(msg)
        if sample is None:
            return
        name = type(sample).__name__
        if src == self.m.vehicle_sysid:
            if name == "HeartbeatSample":
                if sample.autopilot == dialect.MAV_AUTOPILOT_INVALID:
                    return  # a GCS or companion on the same system id
                self.hb = sample
                if self.engaged and not is_offboard(self.flavour, sample):
                    mode = mode_name(self.flavour, sample)
                    if rx is not None and self.link.clock_gate.restarting(rx):
                        # a vehicle that reboots faster than the telemetry timeout comes back
                        # in its start-up mode: that is no pilot, and the log should say so
                        raise _Stop(
                            f"the vehicle rebooted (its boot clock restarted) and came back in {mode}: stopped commanding",
                            "pilot",
                        )
                    raise _Stop(
                        f"mode changed to {mode} by someone else: stopped commanding, not fighting it",
                        "pilot",
                    )
                return
            if name == "CommandAckSample":
                self.acks.append(sample)
                return
            t_boot = getattr(sample, "t_boot_s", None)
            if t_boot is not None:
                self.vehicle_t = t_boot
            if self.ctl.feed_vehicle(sample, rx):  # a control instant
                if name == "AttitudeSample":  # the telemetry timeout counts ATTITUDE only
                    self.last_att_mono, self.last_att_vt = time.monotonic(), self.vehicle_t
                if self.streaming and self.state < State.HANDBACK:
                    self._control_step()
        elif self.live and src == self.m.target_sysid:
            self.ctl.feed_target(sample, rx)

    def _periodic(self) -> None:
        now = time.monotonic()
        if now - self.last_hb_tx_mono >= 1.0:
            self.last_hb_tx_mono = now
            self.link.send_heartbeat()
        if (
            self.flavour is Flavour.PX4
            and not self.m.lockstep  # a lockstep vehicle's clock is not comparable with ours
            and now - self.last_ts_tx_mono >= TIMESYNC_PERIOD_S
        ):
            # a request (tc1 = 0) stamped with the link's clock, which stamps the tlog too:
            # the answer measures the loop delay (Controller.note_sent)
            self.last_ts_tx_mono = now
            self._send(self.link.mav.timesync_encode(0, int(round(self.link.clock() * 1e9))))
        if not self.streaming:
            return
        period = 1.0 / self.m.min_setpoint_rate_hz
        timeout = self.m.telemetry_timeout_s
        # re-send only while the last ATTITUDE is young enough that the last re-send still
        # falls within telemetry_timeout_s of it: commands never outlive the telemetry by more
        att_left = self._left(self.last_att_mono, self.last_att_vt, timeout)
        fresh = att_left >= period
        if self.state == State.HANDBACK:  # wings-level setpoints until the hold mode is confirmed
            if fresh and self.last_sp is not None and now - self.last_send_mono >= period:
                self._send_setpoint(self.last_sp, self.last_time_boot_ms)
                self.n["setpoints_resent"] += 1
            return
        if att_left < 0.0:
            raise _Stop(
                f"telemetry lost: no ATTITUDE for {self._since(self.last_att_mono, self.last_att_vt)}; stopped commanding",
                "telemetry",
            )
        if self._left(self.last_good_mono, self.last_good_vt, timeout) < 0.0:
            # ATTITUDE still arrives but none made a control step: the cause is the controller's
            why = self.why_not or "no control step"
            if "target" in why:
                raise _Stop(f"{why}; stopped commanding", "target")
            since = self._since(self.last_good_mono, self.last_good_vt)
            raise _Stop(
                f"telemetry lost: no usable state for {since} ({why}); stopped commanding",
                "telemetry",
            )
        if fresh and self.last_sp is not None and now - self.last_send_mono >= period:
            self._send_setpoint(self.last_sp, self.last_time_boot_ms)
            self.n["setpoints_resent"] += 1

    def _spin(self, timeout_s: float, until: Callable[[], bool] | None = None) -> bool:
        """Pump messages (streaming setpoints when on) until ``until()`` or the timeout."""
        t_end = time.monotonic() + timeout_s
        while True:
            if until is not None and until():
                return True
            now = time.monotonic()
            if now >= t_end:
                return False
            wait = min(t_end - now, 0.01)
            if self.streaming:
                wait = min(
                    wait, max(0.0, self.last_send_mono + 1.0 / self.m.min_setpoint_rate_hz - now)
                )
            msg = self.link.recv(wait)
            if msg is not None:
                self._dispatch(msg)
            self._periodic()
