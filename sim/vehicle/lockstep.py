"""The lockstep hand-shake's bookkeeping: which telemetry left when, which answer a frame
awaits, and whether it has come.

A frame waits for the SET_ATTITUDE_TARGET stamped with (at least) the time_boot_ms of the
ATTITUDE it answers (the bridge stamps its setpoints so); a late answer to an earlier frame must
not count, or one slow answer would leave every later command one frame late for the rest of
the run. The ATTITUDE awaited is the latest one whose answer would act within the next frame:
with a command latency of a frame or more, that is an earlier frame's, and the bridge computes
while the vehicle steps (the latency is the lookahead that lets the two peers run in parallel).

With ``overlap`` off the vehicle awaits the answer to the telemetry it has just written,
whatever the latency: the peers strictly alternate. The flight is the same either way (an answer
acts at the time its stamp says, not when it was read: tests/test_sil_lockstep.py compares the
two bit for bit); only the wall time differs.

A bridge that also answers LOCAL_POSITION_NED between ATTITUDE samples (a multi-rate loop:
mavlink.position_instants) is awaited on those frames too, from its first answer stamped with a
position-only frame's time on; before that (and for a bridge that never does) they are not
awaited, so a peer answering ATTITUDE only is not held up by them.

A mode change the peer has asked for (SET_MODE, MAV_CMD_DO_SET_MODE) ends the waits until it
is applied: a bridge that hands back asks for the hold mode instead of answering, and waiting for
an answer that will not come would only cost wall time (the command acts at the time it was
read plus the command latency, however long the vehicle waited)."""

from __future__ import annotations

from collections import deque
from typing import Any

_REMEMBERED = 512  # frames whose stamps are remembered (10 s at 50 Hz)


_DO_SET_MODE = 176  # MAV_CMD_DO_SET_MODE


def is_mode_request(msg: Any, mtype: str, sysid: int) -> bool:
    """Whether ``msg`` (of type ``mtype``) asks vehicle ``sysid`` for a mode change."""
    if mtype == "SET_MODE":
        return msg.target_system in (0, sysid)
    return (
        mtype in ("COMMAND_LONG", "COMMAND_INT")
        and msg.command == _DO_SET_MODE
        and msg.target_system in (0, sysid)
    )


class Lockstep:
    """Stamps written, answers received, the stamp awaited (all ms of the boot clock)."""

    def __init__(
        self,
        frame_period: float,
        command_latency_s: float,
        overlap: bool = True,
        modes_end_waits: bool = True,
    ) -> None:
        self.frame_period = float(frame_period)
        # False: a peer that answers every frame (clock answers included) is awaited through
        # its mode changes too, so the frame a mode request is read in never depends on timing
        self.modes_end_waits = bool(modes_end_waits)
        self.command_latency_s = float(command_latency_s)
        self.overlap = bool(overlap)
        self.overlapped = 0  # frames that awaited an earlier frame's answer, not the last one's
        self.await_ms = -1  # time_boot_ms of the ATTITUDE awaited
        self.answer_ms = -1  # the highest stamp of the setpoints received
        self.unstamped = False  # a setpoint stamped 0 since the last ATTITUDE was written
        self._written: deque[tuple[int, float]] = deque(maxlen=_REMEMBERED)  # (ms, boot s)
        self._att_t: dict[int, float] = {}  # the same, by ms
        self._pos_t: dict[int, float] = {}  # position-only frames: ms -> boot s written
        self.answers_positions = False
        self.answers = 0  # SET_ATTITUDE_TARGET messages received
        self.modes_pending = 0  # mode changes read and not yet applied

    @property
    def answered(self) -> bool:
        return (
            self.answer_ms >= self.await_ms
            or self.unstamped
            or (self.modes_pending > 0 and self.modes_end_waits)
        )

    def on_mode_request(self) -> None:
        """A mode change for the vehicle was read (it is applied when due)."""
        self.modes_pending += 1

    def answered_t(self) -> float | None:
        """The boot time (s) the telemetry of the latest answer received left at, if known."""
        return self._att_t.get(self.answer_ms)

    def on_clock(self, stamp_ms: int) -> None:
        """A clock answer (SYSTEM_TIME) stamped ``stamp_ms``: frames up to it are answered."""
        if stamp_ms > self.answer_ms:
            self.answer_ms = stamp_ms

    def mode_request_applied(self) -> None:
        """A mode change read before was applied (or one never read here: nothing pending)."""
        if self.modes_pending > 0:
            self.modes_pending -= 1

    def on_answer(self, stamp_ms: int) -> float | None:
        """A SET_ATTITUDE_TARGET stamped ``stamp_ms`` arrived: the boot time (s) its telemetry
        left at, when known (its command latency then runs from there)."""
        if stamp_ms == 0:  # a peer that does not stamp its setpoints: any answer counts
            self.unstamped = True
        elif stamp_ms > self.answer_ms:
            self.answer_ms = stamp_ms
        self.answers += 1
        pos = self._pos_t
        if not self.answers_positions and stamp_ms in pos:
            self.answers_positions = True  # a multi-rate peer: await its position frames
        return self._att_t.get(stamp_ms, pos.get(stamp_ms))

    def written(self, att_ms: int, pos_ms: int, t: float) -> None:
        """A frame left at boot time ``t`` (s) with ATTITUDE stamped ``att_ms`` and
        LOCAL_POSITION_NED ``pos_ms`` (-1: none)."""
        if att_ms >= 0:  # (every frame: _attitude written out)
            w = self._written
            if len(w) == w.maxlen:
                self._att_t.pop(w[0][0], None)
            w.append((att_ms, t))
            self._att_t[att_ms] = t
            self.unstamped = False
        if pos_ms > att_ms:  # a position newer than any ATTITUDE in the frame
            if self.answers_positions:
                self._attitude(pos_ms, t)
            else:  # remembered (not awaited) so that an answer stamped with it is recognised
                p = self._pos_t
                p[pos_ms] = t
                if len(p) > _REMEMBERED:
                    p.pop(next(iter(p)))

    def _attitude(self, ms: int, t: float) -> None:
        w = self._written
        if len(w) == w.maxlen:
            self._att_t.pop(w[0][0], None)
        w.append((ms, t))
        self._att_t[ms] = t
        self.unstamped = False

    def choose(self, t: float) -> None:
        """At the end of the frame that ends at boot time ``t`` (s): the answer to an ATTITUDE
        written at tw acts at tw + latency, so await the latest one that acts before the end of
        the next frame."""
        w = self._written
        if not self.overlap:
            self.await_ms = w[-1][0] if w else -1
            return
        horizon = t + self.frame_period - self.command_latency_s - 1e-6
        # every frame: the last two frames written decide (the loop below does the same)
        if w:
            m, tw = w[-1]
            if tw < horizon:
                self.await_ms = m
                return
            if len(w) > 1:
                m, tw = w[-2]
                if tw < horizon:
                    self.await_ms = m
                    self.overlapped += 1
                    return
        for i, (m, tw) in enumerate(reversed(w)):
            if tw < horizon:
                self.await_ms = m
                if i:
                    self.overlapped += 1
                return
        self.await_ms = -1
