"""Bus scheduler logic with a scripted transport: order, priorities, unit pacing, retries.

The transport here is a stand-in for the wire only; the scheduler under test is the real
one. Real pymodbus traffic is covered in tests/integration.
"""

from __future__ import annotations

import asyncio
import itertools
import time
from dataclasses import dataclass, field

import pytest

from bridge.core.entity import Table
from bridge.core.protocol import ExceptionMeaning, Protocol
from bridge.core.request import Read, Write
from bridge.errors import BusError, CommandExpiredError, DeviceExceptionError, DeviceTimeoutError
from bridge.modbus.scheduler import BusScheduler, Priority


@dataclass
class _Bus:
    id: str = "test"


@dataclass
class ScriptedTransport:
    """Answers from a script: a value tuple, or an exception to raise, per call."""

    script: list[object] = field(default_factory=list)
    calls: list[tuple[int, object, float]] = field(default_factory=list)
    gate: asyncio.Event | None = None
    connected: bool = False
    open_failures: int = 0
    bus: _Bus = field(default_factory=_Bus)

    async def open(self) -> None:
        if self.open_failures:
            self.open_failures -= 1
            raise BusError("test: cannot open /dev/null")
        self.connected = True

    def close(self) -> None:
        self.connected = False

    async def execute(self, unit: int, request: object, timeout: float) -> tuple[int, ...]:
        self.calls.append((unit, request, time.monotonic()))
        if self.gate is not None:
            await self.gate.wait()
        answer = self.script.pop(0) if self.script else (0,)
        if isinstance(answer, Exception):
            raise answer
        return answer  # type: ignore[return-value]


READ = Read(Table.HOLDING, 0, 1)
WRITE = Write(6, Table.HOLDING, 0, (1,))


async def started(
    transport: ScriptedTransport, gap: float = 0.0
) -> tuple[BusScheduler, asyncio.Task[None]]:
    scheduler = BusScheduler(transport, gap)  # type: ignore[arg-type]
    return scheduler, asyncio.create_task(scheduler.run())


async def stop(task: asyncio.Task[None]) -> None:
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


@pytest.mark.asyncio
async def test_a_write_waits_only_for_the_transaction_in_flight() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    polls = [asyncio.create_task(scheduler.submit(u, READ, timeout=1)) for u in (1, 2, 3)]
    await asyncio.sleep(0.01)  # unit 1's poll is in flight, 2 and 3 queued
    write = asyncio.create_task(scheduler.submit(9, WRITE, timeout=1, priority=Priority.WRITE))
    await asyncio.sleep(0.01)
    transport.gate.set()
    await asyncio.gather(write, *polls)
    assert [unit for unit, _, _ in transport.calls] == [1, 9, 2, 3]
    await stop(task)


@pytest.mark.asyncio
async def test_a_read_back_goes_before_the_polls_queued_during_its_write() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)

    async def write_then_read_back() -> None:
        await scheduler.submit(9, WRITE, timeout=1, priority=Priority.WRITE)
        await scheduler.submit(9, READ, timeout=1, priority=Priority.READ_NOW)

    command = asyncio.create_task(write_then_read_back())
    await asyncio.sleep(0.01)  # the write is in flight
    polls = [asyncio.create_task(scheduler.submit(u, READ, timeout=1)) for u in (1, 2)]
    await asyncio.sleep(0.01)
    transport.gate.set()
    await asyncio.gather(command, *polls)
    assert [(unit, request) for unit, request, _ in transport.calls] == [
        (9, WRITE),
        (9, READ),
        (1, READ),
        (2, READ),
    ]
    await stop(task)


@pytest.mark.asyncio
async def test_a_command_queued_during_the_silence_goes_before_the_polls() -> None:
    transport = ScriptedTransport()
    scheduler, task = await started(transport, gap=0.2)
    polls = [asyncio.create_task(scheduler.submit(u, READ, timeout=1)) for u in (1, 2)]
    await asyncio.sleep(0.05)  # unit 1 answered; the bus keeps silent before the next frame
    write = asyncio.create_task(scheduler.submit(9, WRITE, timeout=1, priority=Priority.WRITE))
    await asyncio.gather(write, *polls)
    assert [unit for unit, _, _ in transport.calls] == [1, 9, 2]
    await stop(task)


@pytest.mark.asyncio
async def test_a_resting_unit_does_not_hold_up_the_others() -> None:
    transport = ScriptedTransport()
    scheduler, task = await started(transport)
    slow = Protocol(min_request_interval=0.2)
    await scheduler.submit(1, READ, timeout=1, protocol=slow)
    first = asyncio.create_task(scheduler.submit(1, READ, timeout=1, protocol=slow))
    others = [asyncio.create_task(scheduler.submit(u, READ, timeout=1)) for u in (2, 3)]
    await asyncio.gather(first, *others)
    units = [unit for unit, _, _ in transport.calls]
    assert units == [1, 2, 3, 1]
    times = {i: t for i, (_, _, t) in enumerate(transport.calls)}
    assert times[3] - times[0] >= 0.2
    await stop(task)


@pytest.mark.asyncio
async def test_the_gap_separates_frames() -> None:
    transport = ScriptedTransport()
    scheduler, task = await started(transport, gap=0.05)
    await asyncio.gather(*(scheduler.submit(u, READ, timeout=1) for u in (1, 2, 3)))
    stamps = [t for _, _, t in transport.calls]
    assert all(later - earlier >= 0.05 for earlier, later in itertools.pairwise(stamps))
    await stop(task)


@pytest.mark.asyncio
async def test_timeouts_are_retried_then_reported() -> None:
    transport = ScriptedTransport(script=[DeviceTimeoutError("t"), DeviceTimeoutError("t"), (7,)])
    scheduler, task = await started(transport)
    assert await scheduler.submit(1, READ, timeout=1, retries=2) == (7,)
    transport.script = [DeviceTimeoutError("t"), (7,)]
    with pytest.raises(DeviceTimeoutError):
        await scheduler.submit(1, WRITE, timeout=1, retries=0)  # a toggle: never resent
    assert scheduler.counters.transactions == 4
    await stop(task)


@pytest.mark.asyncio
async def test_exceptions_take_the_device_meaning() -> None:
    crc = Protocol(
        exceptions={
            4: ExceptionMeaning(name="CRC error", action="retry"),
            8: ExceptionMeaning(name="EEPROM busy", action="busy"),
        }
    )
    transport = ScriptedTransport(script=[DeviceExceptionError(4, "x", "fail"), (5,)])
    scheduler, task = await started(transport)
    assert await scheduler.submit(1, READ, timeout=1, retries=1, protocol=crc) == (5,)
    transport.script = [DeviceExceptionError(8, "x", "fail")]
    with pytest.raises(DeviceExceptionError) as caught:
        await scheduler.submit(1, READ, timeout=1, retries=3, protocol=crc)
    assert (caught.value.meaning, caught.value.action) == ("EEPROM busy", "busy")
    assert len(transport.calls) == 3  # busy is not resent at once
    await stop(task)


@pytest.mark.asyncio
async def test_a_bus_that_will_not_open_fails_fast_then_recovers() -> None:
    transport = ScriptedTransport(open_failures=1)
    scheduler, task = await started(transport)
    with pytest.raises(BusError, match="cannot open"):
        await scheduler.submit(1, READ, timeout=1)
    with pytest.raises(BusError, match="next attempt in"):
        await scheduler.submit(1, READ, timeout=1)
    await asyncio.sleep(0.55)
    assert await scheduler.submit(1, READ, timeout=1) == (0,)
    await stop(task)


@pytest.mark.asyncio
async def test_a_cancelled_submission_is_not_sent() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    busy = asyncio.create_task(scheduler.submit(1, READ, timeout=1))
    await asyncio.sleep(0.01)
    abandoned = asyncio.create_task(scheduler.submit(2, READ, timeout=1))
    await asyncio.sleep(0.01)
    abandoned.cancel()
    transport.gate.set()
    await busy
    await asyncio.sleep(0.01)
    assert [unit for unit, _, _ in transport.calls] == [1]
    await stop(task)


@pytest.mark.asyncio
async def test_a_job_still_waiting_at_its_deadline_is_never_sent() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    busy = asyncio.create_task(scheduler.submit(1, READ, timeout=1))
    await asyncio.sleep(0.01)
    late = asyncio.create_task(
        scheduler.submit(
            2, WRITE, timeout=1, priority=Priority.WRITE, deadline=time.monotonic() + 0.05
        )
    )
    await asyncio.sleep(0.1)  # the deadline passes while unit 1's read is in flight
    transport.gate.set()
    await busy
    with pytest.raises(CommandExpiredError):
        await late
    assert [unit for unit, _, _ in transport.calls] == [1]
    await stop(task)


@pytest.mark.asyncio
async def test_the_answer_time_is_the_devices_not_the_pacing_before_the_frame() -> None:
    """The genset paces its requests 1 s apart: its latency (health p50/p95) is its own
    answer time, measured from the frame sent, not the second its request waited."""
    transport = ScriptedTransport()
    scheduler, task = await started(transport)
    paced = Protocol(min_request_interval=0.3)
    answers: list[float] = []
    await scheduler.submit(1, READ, timeout=1, protocol=paced, answered=answers.append)
    queued = time.monotonic()
    await scheduler.submit(1, READ, timeout=1, protocol=paced, answered=answers.append)
    assert time.monotonic() - queued >= 0.25  # the second waited for the pacing
    assert len(answers) == 2
    assert answers[1] < 0.1  # but the device answered at once
    await stop(task)
