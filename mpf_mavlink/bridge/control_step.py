"""The bridge's control loop (:class:`ControlLoop`): one
:class:`~mpf_mavlink.bridge.controller.Controller` step per control instant while setpoints
stream, the setpoint on the wire, its re-sends, and the telemetry watchdog."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from mpf_mavlink.bridge.base import Phase, State, _Stop
from mpf_mavlink.bridge.controller import Controller, Step
from mpf_mavlink.bridge.link_io import VehicleLink
from mpf_mavlink.core.adapter import Setpoint, safe_setpoint
from mpf_mavlink.mavlink import (
    Flavour,
    encode_set_attitude_target_quat,
    encode_set_attitude_target_rates,
)


class ControlLoop:
    """Controller steps, setpoints and the watchdog. ``record(step)`` is called for each step
    while TRACKING, ``show(step)`` after each setpoint (the operator's display)."""

    def __init__(
        self,
        ctl: Controller,
        vl: VehicleLink,
        phase: Phase,
        record: Callable[[Step, bool], None],
        show: Callable[[Step], None],
        envelope: Callable[[Step], tuple[bool, str | None]] | None = None,
    ) -> None:
        self.ctl, self.vl, self.phase = ctl, vl, phase
        self.m = m = vl.m
        self._record, self._show = record, show
        # each tracking step: (a command was clipped, why the envelope policy hands back)
        self._envelope = envelope
        # the longest a setpoint goes unrepeated: 10 % under 1 / min_setpoint_rate_hz, so that the
        # process's wake-up latency cannot pull the stream below that rate (a re-send exactly on
        # the period left a 10 Hz telemetry stream at 20 Hz at best, and PRESTREAM's check of it
        # failed whenever the machine was busy)
        self.period_s = 0.9 / m.min_setpoint_rate_hz
        self.streaming = False
        self.last_sp: Setpoint | None = None
        self.last_time_boot_ms = 0
        # the latest ATTITUDE and the latest good control step, on both clocks (wall, vehicle)
        self.last_att_mono = self.last_good_mono = -math.inf
        self.last_att_vt: float | None = None
        self.last_good_vt: float | None = None
        self.last_send_mono = -math.inf
        self.first_send_mono: float | None = None
        # the same instants on the vehicle's clock (lockstep: the prestream and re-sends count it)
        self.last_send_vt: float | None = None
        self.first_send_vt: float | None = None
        self.prestream_sends = 0
        self.t_engage: float | None = None  # mission time (s) tracking started
        self.t_last: float | None = None  # mission time (s) of the latest step
        self.n = {"setpoints_sent": 0, "setpoints_resent": 0, "safe_setpoints": 0, "law_evals": 0}

    # -- the hooks of VehicleLink -------------------------------------------------------------
    def on_vehicle(self, sample: Any, rx: float | None) -> None:
        """A decoded vehicle sample: into the controller; a control instant steps."""
        if not self.ctl.feed_vehicle(sample, rx):
            return
        if type(sample).__name__ == "AttitudeSample":  # the telemetry timeout counts ATTITUDE
            self.last_att_mono, self.last_att_vt = time.monotonic(), self.vl.vehicle_t
        if self.streaming and self.phase.state < State.HANDBACK:
            self.step()

    def due(self, now: float) -> float:
        """When the next re-send may be due (monotonic s): the link's wait ends by then."""
        return self.last_send_mono + self.period_s if self.streaming else math.inf

    def tick(self, now: float) -> None:
        """While streaming: re-send the last setpoint when telemetry is slower than
        ``min_setpoint_rate_hz``, and stop (raise :class:`_Stop`) when it is lost."""
        if not self.streaming:
            return
        vl, timeout = self.vl, self.m.telemetry_timeout_s
        # re-send only while the last ATTITUDE is young enough that the last re-send still
        # falls within telemetry_timeout_s of it: commands never outlive the telemetry by more
        att_left = vl.left(self.last_att_mono, self.last_att_vt, timeout)
        if self.phase.state != State.HANDBACK:  # HANDBACK: wings level until the hold is confirmed
            self._watchdog(att_left, timeout)
        if att_left >= self.period_s and self.last_sp is not None:
            if vl.elapsed(self.last_send_mono, self.last_send_vt) >= self.period_s:
                self.send_setpoint(self.last_sp, self.last_time_boot_ms)
                self.n["setpoints_resent"] += 1

    def _watchdog(self, att_left: float, timeout: float) -> None:
        vl = self.vl
        if att_left < 0.0:
            since = vl.since(self.last_att_mono, self.last_att_vt)
            raise _Stop(f"telemetry lost: no ATTITUDE for {since}; stopped commanding", "telemetry")
        if vl.left(self.last_good_mono, self.last_good_vt, timeout) < 0.0:
            # ATTITUDE still arrives but none made a control step: the cause is the controller's
            why = self.ctl.why_not or "no control step"
            if "target" in why:
                raise _Stop(f"{why}; stopped commanding", "target")
            since = vl.since(self.last_good_mono, self.last_good_vt)
            raise _Stop(
                f"telemetry lost: no usable state for {since} ({why}); stopped commanding",
                "telemetry",
            )

    # -- streaming ---------------------------------------------------------------------------
    def start(self) -> None:
        """Start streaming, the staleness clocks afresh (the checks did not pump messages)."""
        self.first_send_mono, self.first_send_vt, self.prestream_sends = None, None, 0
        self.streaming = True
        self.last_good_mono = self.last_att_mono = time.monotonic()
        self.last_good_vt = self.last_att_vt = self.vl.vehicle_t

    def prestreamed(self) -> bool:
        """Setpoints have streamed for ``prestream_s`` at ``min_setpoint_rate_hz`` or faster."""
        if self.first_send_mono is None:
            return False
        span = self.prestream_span_s()
        return bool(
            span >= self.m.prestream_s
            and (self.prestream_sends - 1) / span >= self.prestream_rate_hz()
        )

    def prestream_rate_hz(self) -> float:
        """The setpoint rate the prestream must reach (Hz): ``min_setpoint_rate_hz``; in
        lockstep the setpoints answer the vehicle's frames on its clock, so no faster than the
        slowest ATTITUDE stream accepted (``attitude_min_hz``) can be asked of them."""
        m = self.m
        if m.lockstep and m.attitude_min_hz > 0.0:
            return float(min(m.min_setpoint_rate_hz, m.attitude_min_hz))
        return float(m.min_setpoint_rate_hz)

    def prestream_span_s(self) -> float:
        """From the first to the last setpoint of the prestream (s; lockstep: vehicle time)."""
        if self.first_send_mono is None:
            return 0.0
        if self.m.lockstep:
            first, last = self.first_send_vt, self.last_send_vt
            return 0.0 if first is None or last is None else max(0.0, last - first)
        return self.last_send_mono - self.first_send_mono

    def hold_wings_level(self) -> None:
        """From now on re-send a wings-level setpoint (the hand-back's)."""
        if self.last_sp is not None:
            self.last_sp = safe_setpoint(self.ctl.ad_params, self.ctl.roll())
            self.streaming = True

    # -- control -----------------------------------------------------------------------------
    def step(self) -> None:
        ctl = self.ctl
        st = ctl.step()
        if st is None:
            return
        self.n["law_evals"] += 1
        self.t_last = st.t
        self.send_setpoint(st.setpoint, st.time_boot_ms)
        t_tx = self.vl.last_tx_record_s()
        if t_tx is not None:  # its record time, as replay reads it
            ctl.delay.note_sent(t_tx)
        self.last_sp, self.last_time_boot_ms = st.setpoint, st.time_boot_ms
        self.last_good_mono, self.last_good_vt = time.monotonic(), self.vl.vehicle_t
        self._show(st)  # after the setpoint: off its path
        if self.phase.state == State.TRACKING:
            clipped, hand_back = self._envelope(st) if self._envelope else (False, None)
            self._record(st, clipped)
            if self.t_engage is not None and st.t - self.t_engage >= self.m.mission_duration_s:
                raise _Stop(f"mission duration {self.m.mission_duration_s:g} s reached", "duration")
            if hand_back is not None:
                raise _Stop(hand_back, "envelope")

    def send_setpoint(self, sp: Setpoint, time_boot_ms: int) -> None:
        vl = self.vl
        if sp.safe:
            self.n["safe_setpoints"] += 1
        try:
            if vl.flavour is Flavour.PX4:
                msg = encode_set_attitude_target_rates(
                    vl.link.mav, time_boot_ms, vl.sysid, vl.compid, *sp.body_rates_frd, sp.thrust
                )
            else:
                msg = encode_set_attitude_target_quat(
                    vl.link.mav, time_boot_ms, vl.sysid, vl.compid,
                    sp.q_wxyz, sp.thrust, sp.body_rates_frd,
                )  # fmt: skip
        except ValueError:  # the adapter already guarantees finite values; belt and braces
            self.n["safe_setpoints"] += 1
            return self.send_setpoint(safe_setpoint(self.ctl.ad_params), time_boot_ms)
        vl.send(msg)
        now = time.monotonic()
        self.last_send_mono, self.last_send_vt = now, vl.vehicle_t
        if time_boot_ms > vl.answered_ms:
            vl.answered_ms = time_boot_ms  # lockstep: this frame needs no clock answer
        self.n["setpoints_sent"] += 1
        if self.phase.state == State.PRESTREAM:
            if self.first_send_mono is None:
                self.first_send_mono, self.first_send_vt = now, vl.vehicle_t
            self.prestream_sends += 1
