"""The moving target as its own MAVLink system: HEARTBEAT (rover or boat) at 1 Hz and its
position (FOLLOW_TARGET + GLOBAL_POSITION_INT at a fixed rate, or a realistic feed:
:mod:`sim.target.feed`), on the target's clock (its epoch: the vehicle's readiness or the
mission origin the bridge announces)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as M

from mpf_mavlink.bridge.controller import parse_marker
from mpf_mavlink.quaternion import quat_of_rows
from sim.plant.kinematic_plant import ned_to_geodetic_fast
from sim.vehicle.clock import StepClock
from sim.vehicle.link import Link
from sim.vehicle.telemetry import SPEC

_AHEAD = 50  # position fixes computed at once (5 s at 10 Hz)


def _floats(v: Any) -> list[float]:
    return v.tolist() if type(v) is np.ndarray else [float(x) for x in v]


class TargetStream:
    """The target's messages through the vehicle's link. ``motion.state(t)`` gives its truth
    (:mod:`mpf_mavlink.core.target`); ``epoch_boot_s`` is the boot time of its t = 0."""

    def __init__(
        self,
        motion: Any,
        clock: StepClock,
        link: Link,
        origin: Any,
        home_alt_m: float,
        rate_hz: float,
        boat: bool,
        epoch_from_bridge: bool,
        feed: dict[str, Any] | None,
        epoch_unix_s: float | None = None,
    ) -> None:
        self.motion = motion
        # a fleet's common epoch (Unix s): the target's t = 0 placed on the boot clock at the
        # first frame, when the realtime clock runs with the wall clock
        self._epoch_unix_s = epoch_unix_s
        self.clock, self.link = clock, link
        self.origin = origin
        self.home_alt_m = home_alt_m
        self.rate_hz = float(rate_hz)
        self.mav_type = M.MAV_TYPE_SURFACE_BOAT if boat else M.MAV_TYPE_GROUND_ROVER
        self.epoch_from_bridge = epoch_from_bridge
        self.epoch_boot_s = clock.ready_boot_s
        self.epoch_changed = False  # truth rows computed on the old epoch are stale
        self._next: dict[str, float] = {}
        # the position messages' fields of the next due times, by target time (see _fields)
        self._ahead: dict[float, tuple[Any, ...]] = {}
        self.feed = None
        if feed is not None:
            from sim.target.feed import feed_from_options

            self.feed = feed_from_options(motion, link.tmav, ned_to_geodetic_fast, origin, feed)

    @property
    def t(self) -> float:
        """The target's time (s): boot time minus its epoch."""
        return self.clock.boot_s - self.epoch_boot_s

    def take_epoch(self, msg: Any) -> None:
        """The bridge's mission origin (STATUSTEXT ``MPF t0=``, boot s) as the target's t = 0."""
        if not self.epoch_from_bridge:
            return
        text = msg.text if isinstance(msg.text, str) else bytes(msg.text).decode("ascii", "replace")
        mk = parse_marker(text)
        if mk is not None and mk[0] == "t0" and mk[1] is not None:
            self.epoch_boot_s = float(mk[1])
            self.epoch_changed = True

    def _due(self, name: str, hz: float) -> bool:
        t, nxt = self.clock.boot_s, self._next.get(name)
        if nxt is None or t + 1e-9 >= nxt:
            period = 1.0 / hz
            self._next[name] = t + period if nxt is None or t - nxt > period else nxt + period
            return True
        return False

    def frame(self) -> None:
        """Queue what is due this frame."""
        if self._epoch_unix_s is not None:
            self.epoch_boot_s = self.clock.boot_s - (time.time() - self._epoch_unix_s)
            self._epoch_unix_s = None
        if self._due("heartbeat", 1.0):
            self.link.put(
                self.link.target_framer.pack(
                    SPEC["heartbeat"],
                    self.mav_type,
                    M.MAV_AUTOPILOT_INVALID,
                    0,
                    0,
                    M.MAV_STATE_ACTIVE,
                    3,
                )
            )
        if self.feed is not None:
            for buf in self.feed.poll(self.clock.boot_s, self.t):
                self.link.put(buf)
        elif self.rate_hz > 0 and self._due("position", self.rate_hz):
            self._send_position()

    def _fields(self, t: float) -> tuple[Any, ...]:
        """The position messages' fields (all but the stamp) at target time ``t`` (s): lat, lon
        (1e-7 deg), altitude (m), velocity, acceleration, attitude quaternion, body rates,
        GLOBAL_POSITION_INT's altitudes (mm), velocity (cm/s) and heading (cdeg). Read from the
        state's floats (no numpy array is built: the motions give their states as floats)."""
        ts = self.motion.state(t)
        f = ts.floats
        if f is None:
            f = (*ts.R_T_I.ravel().tolist(), *_floats(ts.position), *_floats(ts.velocity),
                 *_floats(ts.acceleration), *_floats(ts.omega_T))  # fmt: skip
        n, e, d = f[9], f[10], f[11]
        lat, lon, alt = ned_to_geodetic_fast(self.origin, n, e, d)
        vel, acc, rates = list(f[12:15]), list(f[15:18]), list(f[18:21])
        yaw = math.atan2(f[3], f[0])
        return (int(round(lat * 1e7)), int(round(lon * 1e7)), alt, vel, acc,
                list(quat_of_rows(f)), rates, int(round(alt * 1000)),
                int(round((alt - self.home_alt_m) * 1000)), int(round(vel[0] * 100)),
                int(round(vel[1] * 100)), int(round(vel[2] * 100)),
                int(round(math.degrees(yaw) * 100)) % 36000)  # fmt: skip

    def _fields_now(self) -> tuple[Any, ...]:
        """:meth:`_fields` of now, computed with those of the next ``_AHEAD`` due times (a pure
        function of the target's time): one burst every few seconds of sim time instead of one
        evaluation every 10th of a second, each of which ran on caches the rest of the frame
        and the peer had made cold (several times its warm cost). The times ahead are
        what :meth:`_due` will give if the frames keep their length; any other time is computed
        when it comes."""
        t = self.t
        f = self._ahead.pop(t, None)
        if f is not None:
            return f
        clock, epoch = self.clock, self.epoch_boot_s
        steps = round(1.0 / (self.rate_hz * clock.dt))
        ahead = {t: self._fields(t)}
        if steps >= 1 and abs(steps * clock.dt * self.rate_hz - 1.0) < 1e-9:
            for j in range(1, _AHEAD):
                tj = (clock.k + j * steps) * clock.dt - epoch  # as StepClock.boot_s - epoch
                ahead[tj] = self._fields(tj)
        self._ahead = ahead
        return ahead.pop(t)

    def _send_position(self) -> None:
        (lat7, lon7, alt, vel, acc, q, rates, alt_mm, rel_mm, vx, vy, vz,
         hdg) = self._fields_now()  # fmt: skip
        pack, ms = self.link.target_framer.pack, self.clock.ms()
        put = self.link.put
        put(
            pack(
                SPEC["follow_target"],
                ms,
                15,
                lat7,
                lon7,
                alt,
                vel,
                acc,
                q,
                rates,
                [0.0, 0.0, 0.0],
                0,
            )
        )
        put(pack(SPEC["global_position_int"], ms, lat7, lon7, alt_mm, rel_mm, vx, vy, vz, hdg))
