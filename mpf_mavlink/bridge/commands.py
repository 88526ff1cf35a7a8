"""Commands to the vehicle and their COMMAND_ACKs (:class:`CommandChannel`): the one place the
bridge matches an acknowledgement to the command it answers (by MAV_CMD id, as COMMAND_ACK
carries it for COMMAND_LONG and COMMAND_INT alike), skips MAV_RESULT_IN_PROGRESS (a final
result follows it) and retries."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from mpf_mavlink.mavlink import CommandAckSample, dialect

#: Acknowledgements kept unread at most: a vehicle that acknowledges what nobody waits for
#: (another GCS's commands on a shared system id) cannot grow the list without bound.
MAX_PENDING_ACKS = 64


class _Pump(Protocol):
    """What the channel needs of the link: send, and pump messages until a condition."""

    def send(self, msg: Any) -> None: ...

    def spin(self, timeout_s: float, until: Callable[[], bool] | None = None) -> bool: ...


def is_final(ack: CommandAckSample) -> bool:
    """Whether ``ack`` ends its command (MAV_RESULT_IN_PROGRESS promises another ACK)."""
    return bool(ack.result != dialect.MAV_RESULT_IN_PROGRESS)


class CommandChannel:
    """Sends commands over ``pump`` and hands back their acknowledgements; the link gives it
    every COMMAND_ACK of the vehicle (:meth:`deliver`)."""

    def __init__(self, pump: _Pump) -> None:
        self._pump = pump
        self._acks: deque[CommandAckSample] = deque(maxlen=MAX_PENDING_ACKS)

    def deliver(self, ack: CommandAckSample) -> None:
        """A COMMAND_ACK from the vehicle (kept until someone takes its command's)."""
        self._acks.append(ack)

    def send(self, msg: Any, command_id: int) -> None:
        """Send ``msg`` (a COMMAND_LONG / COMMAND_INT / SET_MODE carrying ``command_id``),
        forgetting the acknowledgements of that command that arrived before it: they answer
        an earlier request."""
        self.take(command_id)
        self._pump.send(msg)

    def send_all(self, msgs: list[Any], command_id: int) -> None:
        """Send several requests of one command (e.g. an interval per message), forgetting
        that command's earlier acknowledgements once, before the first."""
        self.take(command_id)
        for msg in msgs:
            self._pump.send(msg)

    def take(self, command_id: int) -> list[CommandAckSample]:
        """The acknowledgements of ``command_id`` received since the last take, oldest first
        (those of other commands stay)."""
        mine = [a for a in self._acks if a.command == command_id]
        if mine:
            rest = [a for a in self._acks if a.command != command_id]
            self._acks.clear()
            self._acks.extend(rest)
        return mine

    def command(
        self,
        msg: Any,
        command_id: int,
        timeout_s: float,
        until: Callable[[], bool] | None = None,
    ) -> CommandAckSample | None:
        """Send ``msg`` and wait up to ``timeout_s`` (s) for its final acknowledgement (an
        IN_PROGRESS one is skipped); None when none came, or when ``until()`` held first."""
        self.send(msg, command_id)
        got: list[CommandAckSample] = []

        def answered() -> bool:
            got.extend(a for a in self.take(command_id) if is_final(a))
            return bool(got) or (until is not None and until())

        self._pump.spin(timeout_s, answered)
        return got[0] if got else None
