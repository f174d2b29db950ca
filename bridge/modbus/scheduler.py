"""One scheduler per bus: one frame in flight, the inter-frame silence, writes before polls.

Devices submit jobs and await them. The scheduler runs the most urgent job whose unit
may be addressed now (``min_interval`` per unit, e.g. the Smartgen's 1 s between
requests): a command waits at most for the one transaction in flight, and a unit that
must rest does not hold up the others. Between two frames the bus stays silent for at
least 3.5 characters at its baud rate. A lost port or gateway is reopened with backoff
while jobs wait; every job still ends in its own deadline's error, never hangs.

On links whose replies do not name their request (RTU, ASCII, RTU over TCP: no
transaction id), the bus stays silent for one more timeout after a timeout: the unit may
still answer, and its late reply would be taken for the answer to its next request
(another block's registers under this block's keys) or collide with another unit's.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import time
from dataclasses import dataclass, field
from enum import IntEnum

from bridge.core.health import exception_meaning
from bridge.core.protocol import Protocol
from bridge.core.request import Read, Write
from bridge.errors import (
    BusError,
    CommandExpiredError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
)
from bridge.modbus.transport import Transport

log = logging.getLogger(__name__)

REOPEN_INITIAL = 0.5
REOPEN_MAX = 30.0


class Priority(IntEnum):
    WRITE = 0  # commands: before anything else
    READ_NOW = 1  # reads for a command (read-modify-write, read-back, get)
    POLL = 2


@dataclass(order=True, slots=True)
class _Job:
    priority: int
    sequence: int
    unit: int = field(compare=False)
    request: Read | Write = field(compare=False)
    timeout: float = field(compare=False)
    retries: int = field(compare=False)
    protocol: Protocol = field(compare=False)
    future: asyncio.Future[tuple[int, ...]] = field(compare=False)
    deadline: float | None = field(default=None, compare=False)


@dataclass(slots=True)
class BusCounters:
    """What the bus did, for health reports (every frame counts, resends included)."""

    transactions: int = 0
    timeouts: int = 0
    frame_errors: int = 0
    exceptions: int = 0  # exception replies
    busy_seconds: float = 0.0
    reopenings: int = 0


class BusScheduler:
    """Serialises all traffic of one bus."""

    def __init__(self, transport: Transport, gap: float, *, late_replies: bool = False) -> None:
        self.transport = transport
        self.gap = gap
        self.late_replies = late_replies  # True: replies carry no transaction id
        self.counters = BusCounters()
        self._queue: list[_Job] = []
        self._sequence = itertools.count()
        self._wakeup = asyncio.Event()
        self._last_end = 0.0
        self._unit_last: dict[int, float] = {}
        self._quiet_until = 0.0  # after a timeout: a late reply may still come
        self._reopen_delay = 0.0
        self._reopen_at = 0.0

    @property
    def bus_id(self) -> str:
        return self.transport.bus.id

    async def submit(
        self,
        unit: int,
        request: Read | Write,
        *,
        timeout: float,
        priority: Priority = Priority.POLL,
        retries: int = 0,
        protocol: Protocol | None = None,
        deadline: float | None = None,
    ) -> tuple[int, ...]:
        """Queue one transaction and wait for its result (or its error).

        ``protocol`` gives the device's own exception meanings and its minimum time
        between two requests; ``retries`` resends after a timeout or a transmission error;
        a job still waiting at ``deadline`` (monotonic) fails with CommandExpiredError and
        is never sent.
        """
        future: asyncio.Future[tuple[int, ...]] = asyncio.get_running_loop().create_future()
        job = _Job(
            priority,
            next(self._sequence),
            unit,
            request,
            timeout,
            retries,
            protocol or Protocol(),
            future,
            deadline,
        )
        self._queue.append(job)
        self._wakeup.set()
        return await future

    async def run(self) -> None:
        """Serve jobs until cancelled."""
        try:
            while True:
                job = await self._next_job()
                await self._serve(job)
                # let the job's submitter run first: its follow-up (the read-back after a
                # write, a poll's next block) is queued before the next job is chosen
                await asyncio.sleep(0)
        finally:
            for job in self._queue:
                if not job.future.done():
                    job.future.cancel()
            self.transport.close()

    async def _next_job(self) -> _Job:
        """The most urgent job whose unit may be addressed now (waits for one if none)."""
        while True:
            self._queue = sorted(j for j in self._queue if not j.future.done())
            now = time.monotonic()
            start = max(now, self._last_end + self.gap, self._quiet_until)
            ready_at = [(self._unit_ready(job, start), job) for job in self._queue]
            ready = [job for when, job in ready_at if when <= start]
            if ready and start > now:
                await asyncio.sleep(start - now)  # the silence first, then choose: a
                continue  # command queued meanwhile goes before the polls
            if ready:
                self._queue.remove(ready[0])
                return ready[0]
            earliest = min((when for when, _ in ready_at), default=None)
            self._wakeup.clear()
            delay = None if earliest is None else max(0.0, earliest - now)
            # asyncio.timeout, not wait_for: 3.11's wait_for can swallow a cancellation
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(delay):
                    await self._wakeup.wait()

    def _unit_ready(self, job: _Job, start: float) -> float:
        last = self._unit_last.get(job.unit)
        interval = job.protocol.min_request_interval
        return start if last is None else max(start, last + interval)

    async def _serve(self, job: _Job) -> None:
        """Run one job; a timeout or a transmission error sends it back to the queue while
        retries last, so a resend keeps the gap and the unit's pacing like any frame."""
        if job.future.done():  # the submitter gave up (cancelled)
            return
        if job.deadline is not None and time.monotonic() > job.deadline:
            _settle(job, CommandExpiredError("expired: not sent within the command expiry"))
            return
        try:
            await self._ensure_open()
            values = await self._transaction(job)
        except DeviceExceptionError as raw:
            meaning = exception_meaning(raw.code, job.protocol)
            error: Exception = DeviceExceptionError(raw.code, meaning.name, meaning.action)
            resend = meaning.action == "retry"
        except DeviceTimeoutError as timeout:
            error, resend = timeout, True
        except (BusError, FrameError) as failure:
            error, resend = failure, False
        else:
            if not job.future.done():
                job.future.set_result(values)
            return
        if resend and job.retries > 0:
            job.retries -= 1
            self._queue.append(job)
            return
        _settle(job, error)

    async def _transaction(self, job: _Job) -> tuple[int, ...]:
        started = time.monotonic()
        try:
            return await self.transport.execute(job.unit, job.request, job.timeout)
        except DeviceTimeoutError:
            self.counters.timeouts += 1
            if self.late_replies:
                self._quiet_until = time.monotonic() + job.timeout
            raise
        except FrameError:
            self.counters.frame_errors += 1
            raise
        except DeviceExceptionError:
            self.counters.exceptions += 1
            raise
        finally:
            ended = time.monotonic()
            self.counters.transactions += 1
            self.counters.busy_seconds += ended - started
            self._last_end = ended
            self._unit_last[job.unit] = ended

    async def _ensure_open(self) -> None:
        """Open the port if needed; while it stays down, fail fast until the next try."""
        if self.transport.connected:
            return
        now = time.monotonic()
        if now < self._reopen_at:
            raise BusError(
                f"{self.bus_id}: bus down, next attempt in {self._reopen_at - now:.1f} s"
            )
        try:
            await self.transport.open()
        except BusError as exc:
            if self._reopen_delay == 0:
                log.warning("%s", exc, extra={"event": "bus_down", "bus": self.bus_id})
            self.counters.reopenings += 1
            self._reopen_delay = min(REOPEN_MAX, max(REOPEN_INITIAL, self._reopen_delay * 2))
            self._reopen_at = time.monotonic() + self._reopen_delay
            raise
        if self._reopen_delay:
            log.info("%s: bus back", self.bus_id, extra={"event": "bus_up", "bus": self.bus_id})
        self._reopen_delay = 0.0
        self._reopen_at = 0.0


def _settle(job: _Job, exc: Exception) -> None:
    if not job.future.done():
        job.future.set_exception(exc)
