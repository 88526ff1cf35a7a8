"""The command channel: acknowledgements matched by command id, IN_PROGRESS skipped, earlier
answers forgotten when a command is sent again, a bounded backlog."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from mpf_mavlink.bridge.commands import MAX_PENDING_ACKS, CommandChannel
from mpf_mavlink.mavlink import CommandAckSample, dialect

ARM, MODE = 400, 176
ACCEPTED, DENIED = dialect.MAV_RESULT_ACCEPTED, dialect.MAV_RESULT_DENIED
IN_PROGRESS = dialect.MAV_RESULT_IN_PROGRESS


def ack(command: int, result: int) -> CommandAckSample:
    return CommandAckSample(command, result, result == ACCEPTED, f"R{result}")


class ScriptedPump:
    """Answers each send with the acknowledgements scripted for it, delivered on the next
    spin; records what was sent and for how long each spin waited."""

    def __init__(self) -> None:
        self.channel: CommandChannel | None = None
        self.sent: list[Any] = []
        self.replies: list[list[CommandAckSample]] = []
        self.waits: list[float] = []
        self._due: list[CommandAckSample] = []

    def send(self, msg: Any) -> None:
        self.sent.append(msg)
        self._due += self.replies.pop(0) if self.replies else []

    def spin(self, timeout_s: float, until: Callable[[], bool] | None = None) -> bool:
        self.waits.append(timeout_s)
        assert self.channel is not None
        for a in self._due:
            self.channel.deliver(a)
            if until is not None and until():
                self._due = self._due[self._due.index(a) + 1 :]
                return True
        self._due = []
        return until is not None and until()


def channel() -> tuple[CommandChannel, ScriptedPump]:
    pump = ScriptedPump()
    ch = CommandChannel(pump)
    pump.channel = ch
    return ch, pump


def test_command_returns_the_final_ack_of_its_own_command() -> None:
    ch, pump = channel()
    pump.replies = [[ack(MODE, ACCEPTED), ack(ARM, IN_PROGRESS), ack(ARM, DENIED)]]
    got = ch.command("arm", ARM, 1.5)
    assert got is not None and got.command == ARM and got.result == DENIED
    assert pump.sent == ["arm"] and pump.waits == [1.5]
    # the other command's answer stays for whoever waits for it
    assert [a.command for a in ch.take(MODE)] == [MODE]


def test_command_without_an_answer_times_out_with_none() -> None:
    ch, pump = channel()
    pump.replies = [[ack(ARM, IN_PROGRESS)]]
    assert ch.command("arm", ARM, 0.7) is None
    assert pump.waits == [0.7]


def test_earlier_answers_are_forgotten_when_the_command_is_sent_again() -> None:
    ch, _ = channel()
    ch.deliver(ack(ARM, DENIED))  # an answer to an earlier request
    ch.send("arm", ARM)
    assert ch.take(ARM) == []


def test_until_ends_the_wait_before_an_answer() -> None:
    ch, pump = channel()
    assert ch.command("arm", ARM, 2.0, until=lambda: True) is None


def test_send_all_keeps_every_answer_of_the_batch() -> None:
    ch, pump = channel()
    pump.replies = [[ack(511, ACCEPTED)], [ack(511, DENIED)]]
    ch.send_all(["a", "b"], 511)
    pump.spin(0.1)
    assert [a.result for a in ch.take(511)] == [ACCEPTED, DENIED]


def test_the_backlog_of_unread_answers_is_bounded() -> None:
    """One more than the bound: the oldest is dropped, the newest kept."""
    ch, _ = channel()
    for k in range(MAX_PENDING_ACKS + 1):
        ch.deliver(ack(1000 + k, ACCEPTED))
    assert ch.take(1000) == []
    assert len(ch.take(1000 + MAX_PENDING_ACKS)) == 1
