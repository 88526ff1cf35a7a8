"""Where the bridge's target comes from (:class:`mpf_mavlink.bridge.controller.Controller`
picks one): the config's scripted motion (:class:`ScriptedTarget`), a live MAVLink target
extrapolated from its last report (:class:`ExtrapolatedTarget`) or filtered by the target
estimator (:class:`LiveTarget`). All give the target's state at mission time t (s), or a
string saying why there is none. No I/O, no clock: times come from the samples.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mpf_mavlink.bridge.estimator import Estimator
from mpf_mavlink.core import so3
from mpf_mavlink.core.target import TargetMotion, TargetState
from mpf_mavlink.core.target_report import Report, TargetFilterParams


class ScriptedTarget:
    """The config's target motion, at mission time t (s)."""

    live = False

    def __init__(self, motion: TargetMotion) -> None:
        self.motion = motion

    def update(
        self, sample: Any, t_mission: float | None
    ) -> None:  # pragma: no cover - nothing to take
        return None

    def restamp(self, t0: float) -> None:
        return None

    def state(self, t: float) -> TargetState | str:
        return self.motion.state(t)

    def state_later(self, t: float) -> TargetState | Callable[[], TargetState] | str:
        """:meth:`state` (see :meth:`LiveTarget.state_later`)."""
        return self.motion.state(t)


def _heading_frame(
    vel: np.ndarray, acc: np.ndarray, fallback_yaw: float
) -> tuple[np.ndarray, np.ndarray]:
    """Level heading frame of a target (x along the horizontal velocity) and its turn rate."""
    vh2 = float(vel[0] ** 2 + vel[1] ** 2)
    if vh2 > 0.25:  # > 0.5 m/s: the velocity defines the heading
        yaw = math.atan2(vel[1], vel[0])
        chid = float(vel[0] * acc[1] - vel[1] * acc[0]) / vh2
    else:
        yaw, chid = fallback_yaw, 0.0
    return so3.rot_z(yaw), np.array([0.0, 0.0, chid])


class ExtrapolatedTarget:
    """The live target before the estimator (``target_estimator.mode: last_sample``): the latest
    FOLLOW_TARGET, or GLOBAL_POSITION_INT (+ ATTITUDE), from one id, extrapolated.

    Samples are stamped with the vehicle's mission time at receipt (the sender's clock is not
    the autopilot's) and extrapolated to the control time; older than ``timeout_s``: stale.

    A target that sends both (the SIL boat, PX4's follow-me peers) sends the same instant twice;
    GLOBAL_POSITION_INT carries no acceleration nor turn rate, so while a FOLLOW_TARGET that
    carries them is fresh (younger than ``timeout_s``) a GLOBAL_POSITION_INT is ignored: taken,
    it replaced the state and zeroed the turn rate the feedforward needs.
    """

    live = True

    def __init__(self, est: Estimator, timeout_s: float) -> None:
        self.est = est
        self.timeout_s = timeout_s
        self.base: TargetState | None = None
        self.att: Any = None
        self.att_stamp = -math.inf
        self.rich_stamp = -math.inf  # the last FOLLOW_TARGET with acceleration or attitude
        self.samples = 0

    def update(self, sample: Any, t_mission: float | None) -> None:
        if t_mission is None:
            return
        name = type(sample).__name__
        if name == "AttitudeSample":
            self.att, self.att_stamp = sample, t_mission
            return
        if name not in ("FollowTargetSample", "GlobalPositionSample"):
            return
        if name == "GlobalPositionSample" and t_mission - self.rich_stamp <= self.timeout_s:
            return  # the richer FOLLOW_TARGET state stands (see the class docstring)
        pos = self.est.origin.ned(sample.lat_deg, sample.lon_deg, sample.alt_amsl_m)
        if pos is None:
            return
        vel = np.asarray(sample.vel_ned if sample.vel_ned is not None else np.zeros(3), float)
        acc = np.zeros(3)
        R = omega = None
        if name == "FollowTargetSample":
            if sample.acc_ned is not None:
                acc = np.asarray(sample.acc_ned, float)
            if sample.R_B_N is not None:
                R = np.asarray(sample.R_B_N, float)
                omega = (
                    np.asarray(sample.rates_frd, float)
                    if sample.rates_frd is not None
                    else np.zeros(3)
                )
            fallback = 0.0
            if sample.acc_ned is not None or sample.R_B_N is not None:
                self.rich_stamp = t_mission
        else:
            fallback = sample.heading_rad if sample.heading_rad is not None else 0.0
            if self.att is not None and t_mission - self.att_stamp <= self.timeout_s:
                R = np.asarray(self.att.R_B_N, float)
                omega = np.asarray(self.att.rates_frd, float)
        if R is None:
            if self.base is not None and name == "GlobalPositionSample":
                # acceleration from successive velocities keeps the heading frame's turn rate
                dt = t_mission - self.base.t
                if 0.02 < dt < 1.0:
                    acc = (vel - self.base.velocity) / dt
            R, omega = _heading_frame(vel, acc, fallback)
        assert omega is not None  # set together with R above
        self.base = TargetState(t_mission, pos, vel, acc, R, omega, np.zeros(3))
        self.samples += 1

    def restamp(self, t0: float) -> None:
        """Move the stamps into the mission time base that starts at boot time t0 (s)."""
        if self.base is not None:
            self.base = dataclasses.replace(self.base, t=self.base.t - t0)
        # the target's ATTITUDE stamp too: left in the old base it would look fresh for ever
        self.att_stamp -= t0
        self.rich_stamp -= t0

    def state(self, t: float) -> TargetState | str:
        if self.base is None:
            return "no live target yet"
        age = t - self.base.t
        if age > self.timeout_s:
            return f"live target stale ({age:.2f} s old)"
        return self.base.extrapolate(t)

    def state_later(self, t: float) -> TargetState | Callable[[], TargetState] | str:
        """:meth:`state` (see :meth:`LiveTarget.state_later`)."""
        return self.state(t)


def _floats(a: Any) -> list[Any]:
    """A decoded sample's array (or sequence) as a (nested) list of floats."""
    out: list[Any] = a.tolist() if type(a) is np.ndarray else np.asarray(a, float).tolist()
    return out


def _turn_and_yaw(R: Any, rates: Any) -> tuple[float, float]:
    """Turn rate (rad/s, about down: the NED z component of the body angular velocity
    R_B^N rates) and yaw (rad) of an attitude R_B^N with body rates (FRD, rad/s). Scalars:
    every target fix carries one."""
    (r00, _, _), (r10, _, _), (r20, r21, r22) = _floats(R)
    p, q, r = _floats(rates)
    return r20 * p + r21 * q + r22 * r, math.atan2(r10, r00)


class LiveTarget:
    """A target over MAVLink through the target estimator (:mod:`mpf_mavlink.core.target_filter`).

    FOLLOW_TARGET, GLOBAL_POSITION_INT and ATTITUDE from the target's system become reports
    stamped with their own timestamps (the sender's clock); ``update`` passes the receive time
    in mission time for the clock offset. Positions about the estimator's geodetic origin; a
    FOLLOW_TARGET's ``position_cov`` (eph, epv: m, 1-sigma) replaces the configured position
    noise when both are > 0; its acceleration is not used. The estimate's staleness comes from its
    uncertainty.
    """

    live = True

    def __init__(self, est: Estimator, params: TargetFilterParams) -> None:
        self.est = est
        # the filter is loaded by a flight with a live target only
        from mpf_mavlink.core.target_filter import TargetEstimator

        self.kf = TargetEstimator(params)
        self.samples = 0
        self.last_outcome = ""

    def report(self, sample: Any) -> Report | None:
        """The estimator's report of a decoded sample (None: nothing it can use)."""
        name = type(sample).__name__
        if name == "AttitudeSample":
            turn, yaw = _turn_and_yaw(sample.R_B_N, sample.rates_frd)
            return Report(float(sample.t_boot_s), turn_rate=turn, yaw=yaw, attitude=True)
        if name not in ("FollowTargetSample", "GlobalPositionSample"):
            return None
        pos = self.est.origin.ned_xyz(sample.lat_deg, sample.lon_deg, sample.alt_amsl_m)
        if pos is None:
            return None
        vel = None if sample.vel_ned is None else _floats(sample.vel_ned)
        if name == "GlobalPositionSample":
            return Report(float(sample.t_boot_s), pos, vel, yaw=sample.heading_rad)
        turn_yaw: tuple[float | None, float | None] = (None, None)
        if sample.R_B_N is not None and sample.rates_frd is not None:
            turn_yaw = _turn_and_yaw(sample.R_B_N, sample.rates_frd)
        # position_cov is "eph epv" in the MAVLink definition: horizontal and vertical 1-sigma
        # (m; the third value unused); taken per axis, the conservative reading of eph
        cov = np.asarray(sample.position_cov, float)
        pos_var = None
        if cov.shape == (3,) and cov[0] > 0.0 and cov[1] > 0.0:
            eph, epv = cov.tolist()[:2]
            pos_var = (eph * eph, eph * eph, epv * epv)
        return Report(float(sample.t_s), pos, vel, turn_yaw[0], turn_yaw[1], pos_var,
                      attitude=turn_yaw[1] is not None)  # fmt: skip

    def update(self, sample: Any, t_mission: float | None) -> None:
        if t_mission is None:
            return
        if type(sample).__name__ == "GlobalPositionSample" and self.est.origin.known():
            # the second report of a fix (FOLLOW_TARGET's twin) is dropped by the estimator:
            # decided before the geodetic conversion of a report that would be dropped
            why = self.kf.known_position(float(sample.t_boot_s), t_mission)
            if why is not None:
                self.samples += 1
                self.last_outcome = why
                return
        r = self.report(sample)
        if r is None:
            return
        self.samples += 1
        self.last_outcome = self.kf.add(r, t_mission)

    def restamp(self, t0: float) -> None:
        """Move the receive times into the mission time base that starts at boot time t0 (s)."""
        self.kf.shift_time_base(t0)

    def state(self, t: float) -> TargetState | str:
        return self.kf.state(t)

    def state_later(self, t: float) -> TargetState | Callable[[], TargetState] | str:
        """Whether the target can be placed at t (s) decided now (a reason when it cannot), the
        state itself built by the function returned, when asked: the bridge's logs want the
        target at the sample's instant, the command the one predicted (controller.py), and
        what only the logs need is made after the setpoint went out."""
        kf = self.kf
        placed = kf.place(t)
        if isinstance(placed, str):
            return placed
        return lambda: kf.build(t, placed)


# ----------------------------------------------------------------------------- one step
