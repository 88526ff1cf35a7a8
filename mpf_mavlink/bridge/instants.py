"""Which vehicle samples are control instants (:class:`ControlInstants`): every ATTITUDE and,
in the multi-rate loop (``mavlink.position_instants``, PX4 body rates), a LOCAL_POSITION_NED
between two of them. The periods (s, filtered) of both streams decide which."""

from __future__ import annotations

from typing import Any

from mpf_mavlink.bridge.estimator import Estimator


def _period(T: float, prev: Any, sample: Any) -> float:
    """A stream's period (s) filtered over ~10 samples, from the time since its previous sample
    ``prev`` (None: the first); gaps of 1 s or more and repeated times leave it as it was."""
    if prev is None:
        return T
    dt = float(sample.t_boot_s) - float(prev.t_boot_s)
    if not 0.0 < dt < 1.0:
        return T
    return dt if T == 0.0 else T + 0.1 * (dt - T)


class ControlInstants:
    """The streams' periods and whether the latest instant is a position sample's."""

    def __init__(self, est: Estimator, position_instants: bool) -> None:
        self.est = est
        self.position_instants = position_instants
        self.att_period_s = 0.0
        self.pos_period_s = 0.0
        self.at_position = False  # the latest control instant is a position sample's
        self.t_prev_boot: float | None = None  # autopilot time (s) of the latest step
        self.position_steps = 0  # steps made at position instants

    def after_update(self, sample: Any, attitude: bool, prev_att: Any, prev_loc: Any) -> bool:
        """``sample`` was given to the estimator (``attitude``: stored as the attitude; the
        previous attitude and position samples were ``prev_att``, ``prev_loc``): whether it
        is a control instant."""
        est = self.est
        if attitude:
            self.att_period_s = _period(self.att_period_s, prev_att, sample)
            self.at_position = False
            return True
        loc = est.local
        if type(sample).__name__ != "LocalPositionSample" or loc is None or loc is not sample:
            return False
        self.pos_period_s = _period(self.pos_period_s, prev_loc, sample)
        if self.position_instants and self._position_instant(loc.t_boot_s):
            self.at_position = True
            return True
        return False

    def stepped(self, t_boot_s: float) -> None:
        """A step was made at autopilot time t_boot_s (s)."""
        self.t_prev_boot = t_boot_s
        self.position_steps += self.at_position

    def _position_instant(self, tp: float) -> bool:
        """Whether a position sample of autopilot time tp (s) is a control instant: at least
        half a position period after the latest ATTITUDE and the latest step, and earlier than
        the next ATTITUDE is due by more than half a position period. A position that comes
        with (about) the same instant as an ATTITUDE (the streams share a clock: 50 Hz each, or
        every fifth position at 10 Hz ATTITUDE) leaves the step to that ATTITUDE, whichever of
        the two arrives first; so with both streams at one rate, in phase or not (a real PX4
        samples each stream on its own schedule), this never steps: the ATTITUDE-only loop."""
        a = self.est.att
        T = self.att_period_s
        if a is None or not T > 0.0:
            return False
        half = 0.5 * self.pos_period_s
        last = a.t_boot_s if self.t_prev_boot is None else max(a.t_boot_s, self.t_prev_boot)
        return bool(tp - last >= half and tp - a.t_boot_s < T - half)
