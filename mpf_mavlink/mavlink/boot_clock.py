"""The vehicle's boot clock: which time stamps to believe (:class:`BootClockGate`), and when a
reboot resets it."""

from __future__ import annotations

from dataclasses import dataclass

#: Messages whose time_boot_ms is the time of a set-point the autopilot holds, not the time of
#: the message: old stamps are normal there (see :meth:`BootClockGate.check`).
SETPOINT_STAMPED = frozenset(
    {"ATTITUDE_TARGET", "POSITION_TARGET_LOCAL_NED", "POSITION_TARGET_GLOBAL_INT"}
)


# ---------------------------------------------------------------------------------------------
# The vehicle's boot clock
# ---------------------------------------------------------------------------------------------
@dataclass
class _Candidate:
    """A clock the gate has heard but not adopted: its offset (s), last receive time (s), the
    newest t_boot per message type (each must increase) and how many samples it has."""

    off: float
    t_rx: float
    last: dict[str, float]
    count: int = 1


class BootClockGate:
    """Accepts a vehicle's ``time_boot_ms`` only when it is consistent with its clock so far.

    Everything downstream (the estimator, the law's integration of s, the mission duration, the
    setpoints' time stamps) runs on the autopilot's clock, so ONE frame with a valid CRC and an
    absurd time (2^31 ms, an hour ahead) must not become "now". With ``t_rx`` our receive time
    (the tlog's record time, so that a replay can take the same decisions), the offset
    ``off = t_boot - t_rx`` of a sample is the vehicle's clock minus its latency. Hence:

    - AHEAD: no sample can be ahead of the least-delayed one seen, ``hi`` (the largest offset,
      let down by ``drift_s_per_s`` to follow a clock slower than ours), by more than
      ``fwd_tol_s``. The bound is NOT the last accepted sample: that one may have waited in a
      full socket buffer (the bridge reads nothing during its checks) and the next one, after
      the datagrams the kernel dropped, is legitimately far ahead of it;
    - BEHIND: a sample more than ``back_tol_s`` behind the last accepted one is not the same
      clock (a lockstep simulation at 0.4x..5x of the wall clock moves the offset by a few
      tens of ms per sample, not seconds);
    - STALE: a consistent sample not newer than the last one of its message type (reordered or
      duplicated by the link; a timestamp in the past lands here too).

    The FIRST clock is not simply the first sample's: a forged frame that happens to come first
    would become the reference and every genuine sample after it would be rejected. Until a
    clock is established, samples are sorted into candidate clocks (offsets within
    ``fwd_tol_s + 0.25`` s, ``t_boot`` increasing per message type); the first to gather
    ``reset_count``
    samples is adopted (50 ms of a 50 Hz ATTITUDE + LOCAL_POSITION_NED stream). A repeated
    constant or a random time never forms one. Samples dropped meanwhile return "settling".

    A rebooted vehicle (or any real clock jump) starts a new, self-consistent clock: rejected
    samples that agree with each other (``off`` within ``fwd_tol_s + 0.25`` s of the previous
    one) for ``reset_confirm_s`` and at least ``reset_count`` samples become the new reference,
    counted in ``resets``. Junk in between does not reset that candidate; any accepted sample
    clears it. Until then the new clock is rejected, so a reboot in flight looks like a
    telemetry loss to the bridge (it stops commanding), never like a jump of its clock.
    """

    def __init__(
        self,
        fwd_tol_s: float = 0.25,
        back_tol_s: float = 2.0,
        reset_count: int = 5,
        reset_confirm_s: float = 0.5,
        drift_s_per_s: float = 1e-3,
    ) -> None:
        self.fwd_tol_s, self.back_tol_s = fwd_tol_s, back_tol_s
        self.reset_count, self.reset_confirm_s = reset_count, reset_confirm_s
        self.drift_s_per_s = drift_s_per_s  # 1000 ppm: any crystal, not an attacker's seconds
        self.off: float | None = None  # offset of the last accepted sample (s)
        self.hi = 0.0  # the least-delayed offset (s), as of ``hi_t``
        self.hi_t = 0.0
        self.resets = 0
        self._cand: list[float] | None = None  # [offset, first t_rx, count, last t_rx]
        self._last: dict[str, float] = {}  # message type -> newest accepted t_boot (s)
        self._first: list[_Candidate] = []  # candidate first clocks

    def _adopt(self, mtype: str, t_boot_s: float, off: float, t_rx: float) -> None:
        self.off, self.hi, self.hi_t, self._cand = off, off, t_rx, None
        self._last = {mtype: t_boot_s}

    def _settle(self, mtype: str, t_boot_s: float, off: float, t_rx: float) -> str | None:
        """Before any clock is established: vote for a candidate clock, adopt the first that
        has ``reset_count`` samples."""
        tol = self.fwd_tol_s + 0.25
        for c in self._first:
            last = c.last.get(mtype)
            if abs(off - c.off) <= tol and (last is None or t_boot_s > last):
                c.off, c.t_rx = off, t_rx
                c.last[mtype] = t_boot_s
                c.count += 1
                if c.count >= self.reset_count:
                    self._first = []
                    self._adopt(mtype, t_boot_s, off, t_rx)
                    self._last = c.last
                    return None
                return "settling"
        self._first.append(_Candidate(off, t_rx, {mtype: t_boot_s}))
        if len(self._first) > 32:  # forget the candidate heard from longest ago
            self._first.remove(min(self._first, key=lambda c: c.t_rx))
        return "settling"

    def restarting(self, t_rx: float, within_s: float = 1.0) -> bool:
        """Whether a new clock BEHIND the established one has been heard within ``within_s``
        (s) of ``t_rx``: the vehicle's boot clock restarted (a reboot) and is being confirmed."""
        c = self._cand
        return (
            self.off is not None
            and c is not None
            and c[2] >= 2
            and t_rx - c[3] <= within_s
            and c[0] < self.off - self.back_tol_s
        )

    def check(self, mtype: str, t_boot_s: float, t_rx: float) -> str | None:
        """None to accept the sample; "time" (inconsistent clock), "stale" or "settling" (no
        clock established yet) to reject it. A set-point echo (:data:`SETPOINT_STAMPED`)
        carries the time of its set-point, not the time it was sent: any time up to "now" is
        consistent (PX4 v1.16 in body-rate OFFBOARD keeps the stamp of the last attitude
        set-point from before OFFBOARD for the whole flight), a time ahead of "now" is not, and
        it never moves the clock."""
        # every vehicle sample passes here: max(0.0, x) and max(hi, off) are written as the
        # conditionals they are (same values, NaN included), without the calls
        off = t_boot_s - t_rx
        if mtype in SETPOINT_STAMPED:
            if self.off is None:
                return "settling"
            since = t_rx - self.hi_t
            hi = self.hi - self.drift_s_per_s * (since if since > 0.0 else 0.0)
            return None if off - hi <= self.fwd_tol_s and t_boot_s >= 0.0 else "time"
        last_off = self.off
        if last_off is None:
            return self._settle(mtype, t_boot_s, off, t_rx)
        since = t_rx - self.hi_t
        hi = self.hi - self.drift_s_per_s * (since if since > 0.0 else 0.0)
        if off - hi <= self.fwd_tol_s and off - last_off >= -self.back_tol_s:
            last = self._last.get(mtype)
            if last is not None and t_boot_s <= last:
                return "stale"
            self.off, self._cand = off, None
            self.hi, self.hi_t = off if off > hi else hi, t_rx
            self._last[mtype] = t_boot_s
            return None
        c = self._cand
        if c is not None and abs(off - c[0]) <= self.fwd_tol_s + 0.25:
            c[0], c[2], c[3] = off, c[2] + 1, t_rx
        elif c is None or t_rx - c[3] > 0.2:  # a lone outlier cannot displace a live candidate
            self._cand = c = [off, t_rx, 1.0, t_rx]
        if c[2] >= self.reset_count and t_rx - c[1] >= self.reset_confirm_s:
            self._adopt(mtype, t_boot_s, off, t_rx)
            self.resets += 1
            return None
        return "time"
