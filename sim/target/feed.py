"""A realistic target feed for the SIL: the simulated target reports itself as a real one does.

A real target (a boat, a truck) reports GPS fixes over a radio: 1-5 Hz, metres of noise, a
fraction of a second of latency (more when the link is busy: reports can arrive out of order),
drop-outs in bursts, often no attitude. :class:`TargetFeed` turns the scripted motion into such
a stream: every ``1 / rate_hz`` s of the target's clock it takes the true state, adds white
Gaussian noise (position per axis, velocity per axis, turn rate), stamps it with the SENDER's
clock (the vehicle's boot clock plus ``clock_offset_s``: the target's clock is not the
autopilot's), loses it with a two-state (Gilbert) burst model of mean loss ``dropout`` and mean
burst ``dropout_burst`` reports, or during a scheduled ``outages`` window (target time), and
delivers it ``latency_s + U(0, latency_jitter_s)`` s later. Messages: FOLLOW_TARGET
(est_capabilities: position + velocity, + attitude and rates when ``attitude``), and/or
GLOBAL_POSITION_INT (+ ATTITUDE when ``attitude``) of the same fix. Everything drawn comes from
one ``numpy`` generator seeded with ``seed``, in report order: the same seed gives the same
reports whatever the machine does.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mpf_mavlink.core.frames import matrix_to_quat_wxyz


@dataclass(frozen=True)
class FeedReport:
    """One report as sent (for the README plot and the tests): sender time (s), target time
    (s), noisy position / velocity (NED), delivery time (vehicle boot s)."""

    t_sender: float
    t_target: float
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    due: float


@dataclass
class TargetFeed:
    """See the module docstring. ``origin``: the plant's geodetic origin (``lat0_deg``,
    ``lon0_deg``, ``alt0_m``), ``to_geodetic(origin, n, e, d)`` -> (lat, lon, alt)."""

    motion: Any
    mav: Any  # a pymavlink MAVLink encoder with the target's system/component ids
    to_geodetic: Any
    origin: Any
    rate_hz: float = 1.0
    position_noise_m: float = 0.0
    vertical_noise_m: float | None = None  # None: position_noise_m
    velocity_noise_m_s: float = 0.0
    turn_rate_noise_rad_s: float = 0.0
    latency_s: float = 0.0
    latency_jitter_s: float = 0.0
    dropout: float = 0.0
    dropout_burst: float = 1.0
    outages: list[tuple[float, float]] = field(default_factory=list)  # (start, duration) s
    attitude: bool = False
    messages: str = "both"  # both | follow_target | global_position_int
    clock_offset_s: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.next_t: float | None = None
        self.queue: list[tuple[float, int, bytes]] = []
        self.seq = 0
        self.bad = False  # Gilbert model state: in a burst of losses
        b = 1.0 / max(1.0, self.dropout_burst)  # P(bad -> good) per report
        self.p_gb = self.dropout * b / (1.0 - self.dropout) if self.dropout < 1.0 else 1.0
        self.p_bg = b
        self.sent: list[FeedReport] = []
        self.lost = 0

    def _lose(self, t_target: float) -> bool:
        """Drawn for every report (so the noise of later reports does not depend on losses)."""
        u = float(self.rng.random())
        self.bad = u < (1.0 - self.p_bg if self.bad else self.p_gb)
        return self.bad or any(s <= t_target < s + d for s, d in self.outages)

    def poll(self, t_boot: float, t_target: float) -> list[bytes]:
        """Called once per vehicle frame: sample what is due, return the packets to send now."""
        if self.next_t is None:
            self.next_t = t_target
        while t_target >= self.next_t - 1e-9:
            # the report of the instant next_t (frames are finer than report periods)
            self._sample(t_boot - (t_target - self.next_t), self.next_t)
            self.next_t += 1.0 / self.rate_hz
        out = []
        while self.queue and self.queue[0][0] <= t_boot + 1e-9:
            out.append(heapq.heappop(self.queue)[2])
        return out

    def _sample(self, t_boot: float, t_target: float) -> None:
        rng = self.rng
        ts = self.motion.state(t_target)
        # one draw per quantity per report, in a fixed order
        sh = self.position_noise_m
        sv = sh if self.vertical_noise_m is None else self.vertical_noise_m
        dp = rng.normal(0.0, 1.0, 3) * (sh, sh, sv)
        dv = rng.normal(0.0, 1.0, 3) * self.velocity_noise_m_s
        dw = float(rng.normal(0.0, 1.0)) * self.turn_rate_noise_rad_s
        jitter = float(rng.random()) * self.latency_jitter_s
        if self._lose(t_target):
            self.lost += 1
            return
        pos = np.asarray(ts.position, float) + dp
        vel = np.asarray(ts.velocity, float) + dv
        rates = np.asarray(ts.omega_T, float) + np.array((0.0, 0.0, dw))
        R = np.asarray(ts.R_T_I, float)
        lat, lon, alt = self.to_geodetic(self.origin, float(pos[0]), float(pos[1]), float(pos[2]))
        t_send = t_boot + self.clock_offset_s
        ms = int(round(t_send * 1000.0))
        due = t_boot + self.latency_s + jitter
        self.sent.append(FeedReport(ms / 1000.0, t_target, tuple(pos), tuple(vel), due))
        lat7, lon7 = int(round(lat * 1e7)), int(round(lon * 1e7))
        mav = self.mav
        bufs = []
        if self.messages in ("both", "follow_target"):
            caps = 0b11 | (0b1000 if self.attitude else 0)
            q = list(matrix_to_quat_wxyz(R)) if self.attitude else [1.0, 0.0, 0.0, 0.0]
            rr = rates.tolist() if self.attitude else [0.0] * 3
            # position_cov is "eph epv": the fix's 1-sigma accuracies, as a GPS reports them
            cov = [sh, sv, 0.0]
            bufs.append(mav.follow_target_encode(ms, caps, lat7, lon7, float(alt), vel.tolist(),
                                                 [0.0] * 3, q, rr, cov, 0).pack(mav))  # fmt: skip
        if self.messages in ("both", "global_position_int"):
            yaw = math.atan2(R[1, 0], R[0, 0])
            alt0 = float(self.origin.alt0_m)
            bufs.append(mav.global_position_int_encode(
                ms, lat7, lon7, int(round(alt * 1000)), int(round((alt - alt0) * 1000)),
                int(round(vel[0] * 100)), int(round(vel[1] * 100)), int(round(vel[2] * 100)),
                # a GPS-only reporter has no heading: UINT16_MAX (unknown)
                int(round(math.degrees(yaw) * 100)) % 36000 if self.attitude else 65535,
            ).pack(mav))  # fmt: skip
            if self.attitude:
                roll = math.atan2(R[2, 1], R[2, 2])
                pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
                # ATTITUDE's rates are body rates; {T} is level here, so r = the turn rate
                bufs.append(mav.attitude_encode(ms, roll, pitch, yaw, *rates.tolist()).pack(mav))
        for b in bufs:
            heapq.heappush(self.queue, (due, self.seq, bytes(b)))
            self.seq += 1
            mav.seq = (mav.seq + 1) & 0xFF  # pack() does not advance it (send() would)


def feed_from_options(
    motion: Any, mav: Any, to_geodetic: Any, origin: Any, o: dict[str, Any]
) -> TargetFeed:
    """A :class:`TargetFeed` from the ``sil.target_feed`` section as a plain dict."""
    o = dict(o)
    outages = [(float(w["start_s"]), float(w["duration_s"])) for w in o.pop("outages", [])]
    return TargetFeed(motion, mav, to_geodetic, origin, outages=outages, **o)


__all__ = ["FeedReport", "TargetFeed", "feed_from_options"]
