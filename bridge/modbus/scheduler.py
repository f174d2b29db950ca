"""One scheduler per bus: one frame in flight, the inter-frame silence, writes before polls.

Devices submit jobs and await them. The scheduler runs the most urgent job whose unit
may be addressed now (``min_interval`` per unit, e.g. the Smartgen's 1 s between
requests): a command waits at most for the one transaction in flight, and a unit that
must rest does not hold up the others. Where another master's request (``PROXY``) and a
due poll could take the same slot, the bridge's fair share decides (bridge/core/
fair_share.py), so masters never starve the polls of a slow device. A job still waiting
at its deadline is ended then (a command's expiry; a master's request answered 0x06
instead of waiting on), not when its unit would be free. Between two frames the bus stays
silent for at least 3.5 characters at its baud rate. A lost port or gateway is reopened with backoff
while jobs wait (after each connect, the bus stays silent ``connect_delay`` seconds); every
job still ends in its own deadline's error, never hangs.

A write is never cut short: a compound write (``WriteSequence``: a sign and a magnitude,
a pulse's edges, the keys of one /set) goes out frame after frame with nothing between
them, and when a frame after the first fails the frames already written are undone. A
command's deadline is checked right before its first frame is sent and before a resend
of it after a timeout, never later: the frames after the first always follow. When the
bus is stopped (shutdown, a mapping reload), the write in flight is finished first, for at
most ``FINISH_WRITE`` seconds.

On links whose replies do not name their request (RTU, ASCII, RTU over TCP: no
transaction id), a unit that did not answer in time may still answer, and its late reply
would be taken for the answer to its next request (another block's registers under this
block's keys). So after a timeout the bus stays silent one more timeout (a late reply
must not collide with another unit's, whose replies are told apart by unit id), the unit
that timed out is not addressed again for ``LATE_GUARD`` timeouts (a reply up to three
timeouts after its request is never taken for another of that unit's requests), and
bytes arriving while no request is outstanding are discarded (pymodbus drops them) and
keep the bus silent until the line has been quiet for ``SETTLE`` seconds; they count as
frame errors and are logged once per burst. Every reply is checked against its request
(unit, function code, byte count) by the transport.

One module, about 450 lines, on purpose: the queue, the silences, the late-reply guard and
the deadline checks all decide around the one frame in flight, and split apart each would
need the others' state.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

from bridge.core.commands import past_deadline
from bridge.core.fair_share import BUS, FairShare
from bridge.core.health import exception_meaning
from bridge.core.protocol import Protocol
from bridge.core.request import Read, Write, WriteSequence
from bridge.errors import (
    BusError,
    CommandExpiredError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    ModbusError,
    PartialWriteError,
)
from bridge.modbus.transport import Transport

log = logging.getLogger(__name__)

REOPEN_INITIAL = 0.5
REOPEN_MAX = 30.0
FINISH_WRITE = 2.0  # seconds a stopping bus gives the write in flight to end
LATE_GUARD = 2.0  # timeouts a unit rests after a timeout on a link without transaction ids
SETTLE = 0.1  # seconds of silence after bytes nobody asked for, before the next frame
BURST = 10.0  # seconds: unsolicited bytes this far apart are logged as separate bursts


class Priority(IntEnum):
    WRITE = 0  # commands, and the reads that are part of one (read-modify-write, read-back)
    KEEPALIVE = 1  # a device's communication watchdog must hear from the bridge in time
    READ_NOW = 2  # reads on request (/get, management reads)
    PROXY = 3  # requests of other masters through the Modbus TCP server (bridge/gateway.py)
    POLL = 4


@dataclass(slots=True)
class _Job:
    priority: int
    sequence: int
    unit: int
    request: Read | Write | WriteSequence
    timeout: float
    retries: int
    protocol: Protocol
    future: asyncio.Future[tuple[int, ...]]
    deadline: float | None = None
    sent: bool = False  # a frame of it went out (a resend after the deadline is dropped)
    answered: Callable[[float], None] | None = None  # told each frame's answer time
    yielded: Callable[[], None] | None = None  # told when a poll took its slot (fair share)


_Entry = tuple[int, int, _Job]  # (priority, sequence, job): the heap's order


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

    def __init__(
        self,
        transport: Transport,
        gap: float,
        *,
        late_replies: bool = False,
        connect_delay: float = 0.0,
        fair: FairShare | None = None,
    ) -> None:
        self.transport = transport
        self.fair = fair or FairShare()  # the polls' share against other masters
        self.gap = gap
        self.late_replies = late_replies  # True: replies carry no transaction id
        self.connect_delay = connect_delay  # silence after each (re)connect
        self.counters = BusCounters()
        self._queue: list[_Entry] = []  # a heap: the most urgent job first
        self._sequence = itertools.count()
        self._wakeup = asyncio.Event()
        self._last_end = 0.0
        self._unit_last: dict[int, float] = {}
        self._quiet_until = 0.0  # after a timeout: a late reply may still come
        self._resting: dict[int, float] = {}  # unit -> not addressed before (late replies)
        self._unsolicited_seen = 0
        self._unsolicited_logged = float("-inf")
        self._reopen_delay = 0.0
        self._reopen_at = 0.0
        self.down_reason: str | None = None  # why the last open failed, until one succeeds

    @property
    def bus_id(self) -> str:
        return self.transport.bus.id

    async def submit(
        self,
        unit: int,
        request: Read | Write | WriteSequence,
        *,
        timeout: float,
        priority: Priority = Priority.POLL,
        retries: int = 0,
        protocol: Protocol | None = None,
        deadline: float | None = None,
        answered: Callable[[float], None] | None = None,
        yielded: Callable[[], None] | None = None,
    ) -> tuple[int, ...]:
        """Queue one transaction and wait for its result (or its error).

        ``protocol`` gives the device's own exception meanings and its minimum time
        between two requests; ``retries`` resends after a timeout or a transmission error
        (each frame of a sequence); a job still waiting at ``deadline`` (monotonic) fails
        with CommandExpiredError and is never sent. A sequence that fails after its first
        frame raises PartialWriteError. ``answered`` is told the seconds of each frame from
        its sending to its answer (the device's own time: not the wait in the queue, the
        gap or the unit's pacing); ``yielded`` is told each time a poll takes the slot it
        contested (a ``PROXY`` job: the fair share).
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
            answered=answered,
            yielded=yielded,
        )
        self._push(job)
        return await future

    def _push(self, job: _Job) -> None:
        heapq.heappush(self._queue, (job.priority, job.sequence, job))
        self._wakeup.set()

    async def run(self) -> None:
        """Serve jobs until cancelled; then every job still waiting (or cut short) is
        cancelled, so no submitter waits for ever."""
        in_flight: list[_Job] = []
        try:
            while True:
                job = await self._next_job()
                in_flight[:] = [job]
                if isinstance(job.request, Read):
                    await self._serve(job)
                else:
                    await self._serve_to_the_end(job)
                # let the job's submitter run first: its follow-up (the read-back after a
                # write, a poll's next block) is queued before the next job is chosen
                await asyncio.sleep(0)
        finally:
            for job in in_flight + [entry[2] for entry in self._queue]:
                if not job.future.done():
                    job.future.cancel()
            self.transport.close()

    async def _next_job(self) -> _Job:
        """The most urgent job whose unit may be addressed now (waits for one if none)."""
        while True:
            now = time.monotonic()
            start = max(now, self._silent_from())
            job, earliest = self._take_ready(start)
            if job is not None and start > now:
                self._push(job)
                await asyncio.sleep(start - now)  # the silence first, then choose: a
                continue  # command queued meanwhile goes before the polls
            if job is not None:
                return job
            self._wakeup.clear()
            delay = None if earliest is None else max(0.0, earliest - now)
            # asyncio.timeout, not wait_for: 3.11's wait_for can swallow a cancellation
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(delay):
                    await self._wakeup.wait()

    def _take_ready(self, start: float) -> tuple[_Job | None, float | None]:
        """Take the most urgent job that may go at ``start`` off the heap (jobs whose
        submitter gave up are dropped, jobs past their deadline ended; jobs of units that
        must still wait stay); else None and when the first waiting unit is free or the
        first waiting deadline passes. A ``PROXY`` job contests its slot with a ready poll
        (of its unit, else of the bus): the fair share decides which goes."""
        now = time.monotonic()
        kept: list[_Entry] = []
        chosen: _Job | None = None
        same: _Entry | None = None  # the most urgent ready poll of the chosen proxy's unit
        other: _Entry | None = None  # ... of any other unit
        earliest: float | None = None
        while self._queue:
            entry = heapq.heappop(self._queue)
            job = entry[2]
            if self._ended(job, now):
                continue
            when = self._unit_ready(job, start)
            if when > start:
                kept.append(entry)
                if job.deadline is not None and not job.sent:
                    when = min(when, job.deadline)
                earliest = when if earliest is None else min(earliest, when)
            elif chosen is None:
                chosen = job
                if job.priority != Priority.PROXY:
                    break
            elif job.priority == Priority.POLL and job.unit == chosen.unit and same is None:
                same = entry
                break  # nothing after it can change the contest
            elif job.priority == Priority.POLL and other is None:
                other = entry
            else:
                kept.append(entry)
        if chosen is not None and chosen.priority == Priority.PROXY:
            chosen, left = self._contest(chosen, same, other, final=start <= now)
            kept += left
        for entry in kept:
            heapq.heappush(self._queue, entry)
        return chosen, earliest

    def _ended(self, job: _Job, now: float) -> bool:
        """The job is over before it was sent: its submitter gave up, or its deadline
        passed while it waited (a master's request for a unit resting after a timeout
        ends as that timeout: the device did not answer, the bus was not merely busy)."""
        if job.future.done():
            return True
        if job.deadline is None or job.sent or not past_deadline(job.deadline, now):
            return False
        if job.priority == Priority.PROXY and self._resting.get(job.unit, 0.0) > now:
            _settle(job, DeviceTimeoutError(f"unit {job.unit} did not answer its last request"))
        else:
            _settle(job, _expired(job))
        return True

    def _contest(
        self, proxy: _Job, same: _Entry | None, other: _Entry | None, *, final: bool
    ) -> tuple[_Job, list[_Entry]]:
        """The job that takes the slot a master's request contests with a ready poll (of
        its unit, else of the bus), and the entries that go back to the queue. A choice
        made before the bus's silence is made again after it: only a ``final`` one counts
        in the fair share."""
        contest, key = (same, proxy.unit) if same is not None else (other, BUS)
        back = [entry for entry in (same, other) if entry is not None]
        if contest is None or not (self.fair.decide(key) if final else self.fair.poll_turn(key)):
            return proxy, back
        if final and proxy.yielded is not None:
            proxy.yielded()
        back.remove(contest)
        return contest[2], [*back, (proxy.priority, proxy.sequence, proxy)]

    def _silent_from(self) -> float:
        """When the bus may carry the next frame: after the gap, after a timeout's quiet,
        and ``SETTLE`` after the last bytes that arrived unasked (late replies, noise)."""
        ready = max(self._last_end + self.gap, self._quiet_until)
        if not self.late_replies:
            return ready
        transport = self.transport
        if transport.unsolicited > self._unsolicited_seen:
            self.counters.frame_errors += transport.unsolicited - self._unsolicited_seen
            self._unsolicited_seen = transport.unsolicited
            if transport.unsolicited_at - self._unsolicited_logged > BURST:
                log.warning(
                    "%s: bytes arrived while no request was outstanding (a late reply or "
                    "noise); discarded, the bus waits for the line to be quiet",
                    self.bus_id,
                )
            self._unsolicited_logged = transport.unsolicited_at
        return max(ready, transport.unsolicited_at + SETTLE)

    def _unit_ready(self, job: _Job, start: float) -> float:
        return max(start, self._unit_free(job.unit, job.protocol))

    def _unit_free(self, unit: int, protocol: Protocol) -> float:
        """When ``unit`` may be addressed: its pacing, and its rest after a timeout."""
        last = self._unit_last.get(unit)
        paced = float("-inf") if last is None else last + protocol.min_request_interval
        return max(paced, self._resting.get(unit, float("-inf")))

    async def _serve_to_the_end(self, job: _Job) -> None:
        """Serve a write even while this bus task is being cancelled: the write in flight
        (every frame of a sequence, or its undo) ends first, within ``FINISH_WRITE``."""
        # Its own task, not the TaskGroup's: the group would cancel it together with the bus.
        serving = asyncio.ensure_future(self._serve(job))
        try:
            await asyncio.shield(serving)
        except asyncio.CancelledError:
            if not serving.done():
                try:
                    async with asyncio.timeout(FINISH_WRITE):
                        await asyncio.shield(serving)
                    log.info("%s: the write in flight finished before stopping", self.bus_id)
                except TimeoutError:
                    serving.cancel()
                    log.error(
                        "%s: stopped %.0f s into a write to unit %d; it may be incomplete",
                        self.bus_id,
                        FINISH_WRITE,
                        job.unit,
                    )
            raise

    async def _serve(self, job: _Job) -> None:
        """Run one job; a timeout or a transmission error sends it back to the queue while
        retries last, so a resend keeps the gap and the unit's pacing like any frame."""
        if job.future.done():  # the submitter gave up (cancelled)
            return
        if isinstance(job.request, WriteSequence):
            await self._serve_sequence(job, job.request)
            return
        try:
            values = await self._attempt(job, job.request, first=True)
        except _Resend:
            self._push(job)
            return
        except ModbusError as error:
            _settle(job, error)
            return
        except CommandExpiredError as expired:
            _settle(job, expired)
            return
        if not job.future.done():
            job.future.set_result(values)

    async def _attempt(self, job: _Job, request: Read | Write, *, first: bool) -> tuple[int, ...]:
        """One frame of ``job``: its result, or the error to end it with; ``_Resend`` when a
        retry is left and the frame should be queued again. ``first``: the job's deadline
        is checked right before the frame goes out (after the port is open)."""
        try:
            await self._ensure_open()
            if first and past_deadline(job.deadline, time.monotonic()):
                raise _expired(job)
            job.sent = True
            return await self._transaction(job, request)
        except DeviceExceptionError as raw:
            meaning = exception_meaning(raw.code, job.protocol)
            error: ModbusError = DeviceExceptionError(raw.code, meaning.name, meaning.action)
            resend = meaning.action == "retry"
        except DeviceTimeoutError as timeout:
            error, resend = timeout, True
        except (BusError, FrameError) as failure:
            error, resend = failure, False
        if resend and job.retries > 0:
            job.retries -= 1
            raise _Resend from error
        raise error

    async def _serve_sequence(self, job: _Job, sequence: WriteSequence) -> None:
        """Every frame of a compound write back to back (keeping the gap and the unit's
        pacing); if one after the first fails, undo the frames done, newest first."""
        for index, write in enumerate(sequence.writes):
            try:
                await self._frame(job, write, first=index == 0)
            except (ModbusError, CommandExpiredError) as error:
                if index == 0 or not isinstance(error, ModbusError):
                    _settle(job, error)
                    return
                restored = await self._undo(job, sequence.undo[:index])
                _settle(
                    job,
                    PartialWriteError(index, len(sequence.writes), restored=restored, cause=error),
                )
                return
        if not job.future.done():
            job.future.set_result(())

    async def _frame(self, job: _Job, write: Write, *, first: bool) -> None:
        """One frame of a sequence, resent in place while the job's retries last."""
        while True:
            await self._pause(job.unit, job.protocol)
            try:
                await self._attempt(job, write, first=first)
                return
            except _Resend:
                continue

    async def _undo(self, job: _Job, undo: tuple[Write | None, ...]) -> bool:
        """Put back what the frames done changed, newest first; True if every undo went."""
        restored = True
        for write in reversed(undo):
            if write is None:
                continue
            try:
                await self._frame(job, write, first=False)
            except ModbusError as error:
                log.error(
                    "%s: unit %d: undoing a partial write failed: %s", self.bus_id, job.unit, error
                )
                restored = False
        return restored

    async def _pause(self, unit: int, protocol: Protocol) -> None:
        """The silence after the previous frame and the unit's own pacing."""
        ready = max(self._silent_from(), self._unit_free(unit, protocol))
        delay = ready - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)

    async def _transaction(self, job: _Job, request: Read | Write) -> tuple[int, ...]:
        started = time.monotonic()
        try:
            return await self.transport.execute(job.unit, request, job.timeout)
        except DeviceTimeoutError:
            self.counters.timeouts += 1
            if self.late_replies:
                now = time.monotonic()
                self._quiet_until = now + job.timeout
                self._resting[job.unit] = now + LATE_GUARD * job.timeout
            raise
        except FrameError:
            self.counters.frame_errors += 1
            raise
        except DeviceExceptionError:
            self.counters.exceptions += 1
            raise
        finally:
            ended = time.monotonic()
            if job.answered is not None:
                job.answered(ended - started)
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
            self.down_reason = str(exc)
            self.counters.reopenings += 1
            self._reopen_delay = min(REOPEN_MAX, max(REOPEN_INITIAL, self._reopen_delay * 2))
            self._reopen_at = time.monotonic() + self._reopen_delay
            raise
        if self._reopen_delay:
            log.info("%s: bus back", self.bus_id, extra={"event": "bus_up", "bus": self.bus_id})
        self._reopen_delay = 0.0
        self._reopen_at = 0.0
        self.down_reason = None
        if self.connect_delay:  # nothing else can use a bus that is not connected yet
            await asyncio.sleep(self.connect_delay)


class _Resend(Exception):  # noqa: N818 - a signal inside the scheduler, never raised out
    """A frame failed in a way worth sending it again, and the job has retries left."""


def _settle(job: _Job, exc: Exception) -> None:
    if not job.future.done():
        job.future.set_exception(exc)


def _expired(job: _Job) -> CommandExpiredError:
    """The error of a job whose deadline passed before its (re)send."""
    if not job.sent:
        return CommandExpiredError("expired: not sent within the command expiry")
    return CommandExpiredError(
        "expired before its resend: sent once without an answer (the device may have acted "
        "on it), not sent again after the command expiry",
        sent=True,
    )
