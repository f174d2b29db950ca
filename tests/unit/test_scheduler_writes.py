"""Compound writes in the bus scheduler (issue 11, items 4 and 5), with a scripted transport.

A ``WriteSequence`` goes out frame after frame with no other frame between, is undone when
a frame after the first fails, and is finished before a stopping bus ends. A command's
deadline is checked right before its first frame is sent, also after a slow port opening.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass

import pytest

from bridge.core.entity import Table
from bridge.core.request import Write, WriteSequence
from bridge.errors import (
    CommandExpiredError,
    DeviceExceptionError,
    DeviceTimeoutError,
    PartialWriteError,
)
from bridge.modbus import scheduler as scheduler_module
from bridge.modbus.scheduler import Priority
from tests.unit.test_scheduler import READ, ScriptedTransport, started, stop

SIGN = Write(6, Table.HOLDING, 75, (0x2000,))
MAGNITUDE = Write(6, Table.HOLDING, 51, (5,))
SIGN_BACK = Write(6, Table.HOLDING, 75, (0x0000,))
SEQUENCE = WriteSequence((SIGN, MAGNITUDE), (SIGN_BACK, None))


def sent(transport: ScriptedTransport) -> list[object]:
    return [request for _, request, _ in transport.calls]


@pytest.mark.asyncio
async def test_the_frames_of_a_sequence_go_out_back_to_back() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    command = asyncio.create_task(scheduler.submit(9, SEQUENCE, timeout=1, priority=Priority.WRITE))
    await asyncio.sleep(0.01)  # the sign is in flight
    polls = [asyncio.create_task(scheduler.submit(u, READ, timeout=1)) for u in (1, 2)]
    await asyncio.sleep(0.01)
    transport.gate.set()
    assert await command == ()
    await asyncio.gather(*polls)
    assert sent(transport) == [SIGN, MAGNITUDE, READ, READ]
    await stop(task)


@pytest.mark.asyncio
async def test_a_failed_second_frame_undoes_the_first() -> None:
    failure = DeviceExceptionError(4, "server device failure", "fail")
    transport = ScriptedTransport(script=[(), failure, ()])
    scheduler, task = await started(transport)
    with pytest.raises(PartialWriteError) as caught:
        await scheduler.submit(9, SEQUENCE, timeout=1, priority=Priority.WRITE)
    assert (caught.value.done, caught.value.total, caught.value.restored) == (1, 2, True)
    assert "undone again" in str(caught.value)
    assert sent(transport) == [SIGN, MAGNITUDE, SIGN_BACK]
    await stop(task)


@pytest.mark.asyncio
async def test_an_undo_that_fails_is_reported() -> None:
    timeout = DeviceTimeoutError("unit 9 did not answer")
    transport = ScriptedTransport(script=[(), timeout, timeout])
    scheduler, task = await started(transport)
    with pytest.raises(PartialWriteError, match="NOT undone") as caught:
        await scheduler.submit(9, SEQUENCE, timeout=1, priority=Priority.WRITE)
    assert caught.value.restored is False
    assert isinstance(caught.value.cause, DeviceTimeoutError)
    await stop(task)


@pytest.mark.asyncio
async def test_a_frame_of_a_sequence_is_resent_in_place() -> None:
    timeout = DeviceTimeoutError("unit 9 did not answer")
    transport = ScriptedTransport(script=[(), timeout, ()])
    scheduler, task = await started(transport)
    assert await scheduler.submit(9, SEQUENCE, timeout=1, priority=Priority.WRITE, retries=1) == ()
    assert sent(transport) == [SIGN, MAGNITUDE, MAGNITUDE]
    await stop(task)


@pytest.mark.asyncio
async def test_a_failed_first_frame_writes_nothing_else() -> None:
    failure = DeviceExceptionError(4, "server device failure", "fail")
    transport = ScriptedTransport(script=[failure])
    scheduler, task = await started(transport)
    with pytest.raises(DeviceExceptionError):
        await scheduler.submit(9, SEQUENCE, timeout=1, priority=Priority.WRITE)
    assert sent(transport) == [SIGN]
    await stop(task)


@pytest.mark.asyncio
async def test_a_stopping_bus_finishes_the_sequence_in_flight() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    command = asyncio.create_task(scheduler.submit(9, SEQUENCE, timeout=1, priority=Priority.WRITE))
    await asyncio.sleep(0.01)  # the sign is in flight: stop now (SIGTERM)
    task.cancel()
    command.cancel()  # the command's own task goes too, as at shutdown
    await asyncio.sleep(0.05)
    assert not task.done()  # still finishing the write
    transport.gate.set()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert sent(transport) == [SIGN, MAGNITUDE]


@pytest.mark.asyncio
async def test_a_stopping_bus_waits_for_a_write_only_so_long(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(scheduler_module, "FINISH_WRITE", 0.1)
    transport = ScriptedTransport(gate=asyncio.Event())  # the unit never answers
    scheduler, task = await started(transport)
    write = asyncio.create_task(scheduler.submit(9, SEQUENCE, timeout=5, priority=Priority.WRITE))
    await asyncio.sleep(0.01)
    task.cancel()
    with caplog.at_level(logging.ERROR), pytest.raises(asyncio.CancelledError):
        await asyncio.wait_for(task, 2)
    assert "may be incomplete" in caplog.text
    assert write.cancelled()


@pytest.mark.asyncio
async def test_a_read_in_flight_does_not_hold_up_a_stop() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    read = asyncio.create_task(scheduler.submit(1, READ, timeout=5))
    await asyncio.sleep(0.01)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await asyncio.wait_for(task, 0.5)
    with pytest.raises(asyncio.CancelledError):
        await read


@dataclass
class SlowToOpen(ScriptedTransport):
    """A port that takes a while to open (a USB adapter re-enumerating, a slow gateway)."""

    delay: float = 0.2

    async def open(self) -> None:
        await asyncio.sleep(self.delay)
        await super().open()


@pytest.mark.asyncio
async def test_the_deadline_is_checked_after_the_port_opened() -> None:
    transport = SlowToOpen()
    scheduler, task = await started(transport)
    with pytest.raises(CommandExpiredError):
        await scheduler.submit(
            9, SEQUENCE, timeout=1, priority=Priority.WRITE, deadline=time.monotonic() + 0.1
        )
    transport.connected = False
    with pytest.raises(CommandExpiredError):
        await scheduler.submit(
            9, MAGNITUDE, timeout=1, priority=Priority.WRITE, deadline=time.monotonic() + 0.1
        )
    assert sent(transport) == []
    await stop(task)


@dataclass
class SilentFirst(ScriptedTransport):
    """The unit does not answer the first frame: its timeout lasts ``wait`` seconds."""

    wait: float = 0.2

    async def execute(self, unit: int, request: object, timeout: float) -> tuple[int, ...]:
        if not self.calls:
            self.calls.append((unit, request, time.monotonic()))
            await asyncio.sleep(self.wait)
            raise DeviceTimeoutError(f"unit {unit} did not answer")
        return await super().execute(unit, request, timeout)


@pytest.mark.asyncio
@pytest.mark.parametrize("request_", [MAGNITUDE, SEQUENCE])
async def test_a_resend_after_the_deadline_is_dropped_and_says_the_first_went_out(
    request_: Write | WriteSequence,
) -> None:
    """The first frame went out and timed out past the command's expiry: the resend is not
    sent, and the error does not claim that nothing was (the device may have acted)."""
    transport = SilentFirst()
    scheduler, task = await started(transport)
    with pytest.raises(CommandExpiredError) as caught:
        await scheduler.submit(
            9,
            request_,
            timeout=1,
            priority=Priority.WRITE,
            retries=1,
            deadline=time.monotonic() + 0.1,
        )
    assert caught.value.sent is True
    assert "sent once without an answer" in str(caught.value)
    assert len(sent(transport)) == 1
    await stop(task)


@pytest.mark.asyncio
async def test_a_command_never_sent_says_so() -> None:
    transport = SlowToOpen()
    scheduler, task = await started(transport)
    with pytest.raises(CommandExpiredError) as caught:
        await scheduler.submit(
            9, MAGNITUDE, timeout=1, priority=Priority.WRITE, deadline=time.monotonic() + 0.1
        )
    assert caught.value.sent is False
    assert "not sent within the command expiry" in str(caught.value)
    await stop(task)
