"""One device: poll classes on a monotonic schedule, health and backoff, learnt refusals, writes.

Poll: due classes -> precomputed plan -> scheduler (serialised, gap) -> register image ->
decode what was read fresh -> ``on_update`` with the values that changed. Missed ticks are
skipped, not queued. An offline device is probed once per backoff interval only.

Writes go through the device's ``DeviceWriter`` (bridge/modbus/writer.py), which uses the
poller's scheduler access (``submit``, ``read_block``), image, values and ``publish``;
blocks the device refuses are searched and learnt by its ``RefusalLearner``
(bridge/modbus/refusal_learning.py).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from bridge.config import DeviceConfig
from bridge.core.codec import Value, decode, is_unknown_code
from bridge.core.entity import PollClass, Table
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.health import DeviceHealth, Fault, HealthPolicy, Outcome, Transition
from bridge.core.mapping import Mapping, Point
from bridge.core.planner import ReadLimits, addresses_of, limits_for, plan_reads
from bridge.core.protocol import Protocol
from bridge.core.refusal_memory import RefusalMemory
from bridge.core.request import Read, Write, WriteSequence
from bridge.core.timing import LinkTiming
from bridge.core.watchdog import Watchdog
from bridge.errors import (
    BusError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    MissingDataError,
    ModbusError,
)
from bridge.modbus.keepalive import keep_alive
from bridge.modbus.refusal_learning import RefusalLearner, Refused
from bridge.modbus.scheduler import BusScheduler, Priority
from bridge.modbus.tear_check import check_torn
from bridge.modbus.unlock import Unlocker
from bridge.modbus.writer import DeviceWriter, WriteCounters

log = logging.getLogger(__name__)
DEFAULT_POLICY = HealthPolicy()
Address = tuple[Table, int]


@dataclass(frozen=True, slots=True)
class DeviceUpdate:
    """What a poll or a write changed on one device."""

    device_id: str
    values: dict[str, Value]
    changed: frozenset[str]
    online: bool | None


class DevicePoller:
    """Polls and writes one device through its bus scheduler."""

    def __init__(
        self,
        device: DeviceConfig,
        mapping: Mapping,
        scheduler: BusScheduler,
        *,
        timing: LinkTiming,
        timeout: float,
        retries: int = 1,
        on_update: Callable[[DeviceUpdate], None] | None = None,
        policy: HealthPolicy = DEFAULT_POLICY,
        guard: Guard = UNGUARDED,
    ) -> None:
        self.device = device
        self.mapping = _with_overrides(mapping, device)
        self.protocol: Protocol = self.mapping.protocol
        self.points: dict[str, Point] = self.mapping.points(device.options)
        options = tuple(sorted((self.mapping.default_options() | device.options).items()))
        own = self.mapping.memo(("guard", options), lambda: Guard.of(self.points.values()))
        self.guard = guard | own  # ``guard``: what earlier mappings guarded
        self.scheduler = scheduler
        self.timing = timing
        self.timeout = device.protocol.response_timeout or timeout
        self.retries = retries
        self.on_update = on_update
        self.health = DeviceHealth(policy)
        self.writer = DeviceWriter(self)
        self.learner = RefusalLearner(self)
        self.unlocker = Unlocker(device, self.protocol)
        keepalive = self.protocol.keepalive
        self.watchdog = Watchdog(keepalive.interval) if keepalive is not None else None
        self.image: dict[Address, int] = {}
        self.values: dict[str, Value] = {}
        self.refusals = RefusalMemory(policy.refusal_recheck)
        self.max_read: int | None = None  # learnt: fewer registers per read than mapped
        self._plans: dict[PollClass, tuple[Read, ...]] = {}
        self._limits_cache: ReadLimits | None = None
        self._polled_once = False
        self.first_poll_done = False  # every class was asked once (answered or not)
        self._last_traffic = 0.0
        self.unknown_codes = 0  # enum codes read that the mapping has no label for
        self._unknown_logged: set[tuple[str, Value]] = set()

    # --- polling ------------------------------------------------------------------

    @property
    def intervals(self) -> dict[PollClass, float]:
        fast, slow = self.device.poll.fast, self.device.poll.slow
        keepalive = self.protocol.keepalive
        if keepalive is not None:
            fast = min(fast, keepalive.interval)
        return {PollClass.FAST: fast, PollClass.SLOW: slow}

    async def run(self) -> None:
        """Poll until cancelled (and feed the device's watchdog, bridge/modbus/keepalive.py);
        never raises for a device fault."""
        async with asyncio.TaskGroup() as group:
            if self.watchdog is not None:
                group.create_task(keep_alive(self), name=f"keepalive:{self.device.id}")
            await self._poll_loop()

    def plan_of(self, poll_class: PollClass) -> tuple[Read, ...]:
        """The reads of one poll class, as planned now."""
        return self._plan({poll_class})

    async def _poll_loop(self) -> None:
        next_due = dict.fromkeys((PollClass.FAST, PollClass.SLOW, PollClass.ONCE), 0.0)
        while True:
            now = time.monotonic()
            if not self.health.may_poll(now):
                await asyncio.sleep(self.health.next_attempt - now)
                continue
            due = [c for c, at in next_due.items() if at <= now]
            if due:
                await self.poll(due)
                after = time.monotonic()
                for poll_class in due:
                    next_due[poll_class] = _next_tick(
                        next_due[poll_class], self.intervals.get(poll_class), after
                    )
                if PollClass.ONCE in due and not self._polled_once:
                    next_due[PollClass.ONCE] = after + self.device.poll.slow  # until it succeeds
            wake = min(*next_due.values(), self._offline_wake())
            await asyncio.sleep(max(0.0, wake - time.monotonic()))

    @property
    def writes(self) -> WriteCounters:
        """How the commands to this device ended (done, skipped, rejected, failed, expired)."""
        return self.writer.counters

    async def write(self, key: str, value: object, *, deadline: float | None = None) -> Value:
        """Write one value (``write_many`` with one key); the value the device holds."""
        return (await self.write_many({key: value}, deadline=deadline))[key]

    async def write_many(
        self, items: dict[str, object], *, deadline: float | None = None
    ) -> dict[str, Value]:
        """All or nothing: see ``DeviceWriter.write_many``."""
        return await self.writer.write_many(items, deadline=deadline)

    def _offline_wake(self) -> float:
        return self.health.next_attempt if self.health.online is False else float("inf")

    @property
    def refused(self) -> frozenset[Address]:
        """The addresses learnt as refused that plans avoid now (until their re-check)."""
        return self.refusals.refused

    async def poll(self, classes: Iterable[PollClass]) -> None:
        """Read every point of these classes once and publish what changed."""
        chosen = set(classes)
        self.learner.recheck()
        fresh: set[Address] = set()
        plan = self._plan(chosen)
        await self._read_pass(plan, Priority.POLL, fresh, stop=True)
        if PollClass.ONCE in chosen and fresh:
            self._polled_once = True
        keys = [k for k, p in self.points.items() if p.entity.poll_class in chosen]
        await check_torn(self, keys, plan, fresh)
        self.publish(keys, fresh)
        if not self.first_poll_done and set(PollClass) <= chosen:
            self.first_poll_done = True  # units and limits read (or not there): say so once
            self._notify(frozenset())

    async def read_now(self, keys: Iterable[str] | None = None) -> dict[str, Value]:
        """Read these points (all when None) ahead of the polls; return their values."""
        wanted = [self.points[k] for k in keys] if keys is not None else list(self.points.values())
        fresh: set[Address] = set()
        reads = plan_reads(wanted, self.limits()).reads
        await self._read_pass(reads, Priority.READ_NOW, fresh)
        await check_torn(self, [p.key for p in wanted], reads, fresh)
        self.publish([p.key for p in wanted], fresh)
        return {p.key: self.values.get(p.key) for p in wanted}

    def _plan(self, classes: set[PollClass]) -> tuple[Read, ...]:
        reads: list[Read] = []
        for poll_class in sorted(classes):
            if poll_class not in self._plans:
                members = [p for p in self.points.values() if p.entity.poll_class is poll_class]
                self._plans[poll_class] = plan_reads(members, self.limits()).reads
            reads.extend(self._plans[poll_class])
        return tuple(reads)

    def limits(self) -> ReadLimits:
        """The read limits as known now (cached; learning a refusal clears the cache)."""
        if self._limits_cache is None:
            self._limits_cache = limits_for(
                self.mapping,
                max_registers=self.max_read,
                refused=self.refusals.refused,
                timing=self.timing,
            )
        return self._limits_cache

    def forget_plans(self) -> None:
        self._plans.clear()
        self._limits_cache = None

    async def _read_pass(
        self, reads: Iterable[Read], priority: Priority, fresh: set[Address], *, stop: bool = False
    ) -> None:
        """Read these blocks, then judge the blocks refused whole together: holes are
        searched and learnt, a device refusing everything is a fault. ``stop``: give up
        the pass when the unit stops answering (the next cycle tries again)."""
        refused: list[Refused] = []
        for read in reads:
            timeouts = self.health.timeouts
            if await self.read_block(read, priority, fresh, refused) or not stop:
                continue
            if self.health.timeouts > timeouts:
                return  # silent: the refused blocks are judged another time
            if self.health.online is False:
                break  # probing an offline unit: one failed read settles it
        await self.learner.judge(refused, priority, fresh)

    async def read_block(
        self,
        read: Read,
        priority: Priority,
        fresh: set[Address],
        refused: list[Refused] | None = None,
    ) -> bool:
        """One read. A refusal is judged with the rest of the pass (added to ``refused``)
        or, without a pass, on its own; True if the read (or a part of it) answered."""
        try:
            values = await self.submit(read, priority)
        except DeviceExceptionError as exc:
            if exc.action != "refused":
                return False
            if refused is not None:
                refused.append((read, exc))
                return False
            return await self.learner.judge([(read, exc)], priority, fresh)
        except ModbusError:
            return False
        self.keep(read, values, fresh)
        return True

    def keep(self, read: Read, values: tuple[int, ...], fresh: set[Address]) -> None:
        for address, value in zip(read.span, values, strict=True):
            self.image[(read.table, address)] = value
            fresh.add((read.table, address))
        back = self.refusals.answer(addresses_of(read))
        if back:
            log.info("%s answers %s again; read again", self.device.id, self.learner.shown(back))
            self.forget_plans()

    async def submit(
        self,
        request: Read | Write | WriteSequence,
        priority: Priority,
        retries: int | None = None,
        deadline: float | None = None,
    ) -> tuple[int, ...]:
        """One request through the bus scheduler, its outcome counted. A device locked by
        a password is unlocked once and the request sent again (bridge/modbus/unlock.py)."""
        return await self.unlocker.submit(
            lambda: self._submit(request, priority, retries, deadline),
            lambda write: self._submit(write, Priority.WRITE, self.retries, None),
            self._locked_out,
        )

    def _locked_out(self, reason: str) -> None:
        """The device stays locked: in error with the reason (logged once), offline."""
        if self.health.fault is not Fault.LOCKED:
            log.error("%s: %s", self.device.id, reason)
            self.announce(self.health.locked(time.monotonic(), reason), first_contact=False)

    async def _submit(
        self,
        request: Read | Write | WriteSequence,
        priority: Priority,
        retries: int | None,
        deadline: float | None,
    ) -> tuple[int, ...]:
        if retries is None:  # reads are not resent: the next cycle reads again
            retries = 0
        answer: list[float] = []  # the device's time per frame, not the wait before it
        try:
            values = await self.scheduler.submit(
                self.device.unit,
                request,
                timeout=self.timeout,
                priority=priority,
                retries=retries,
                protocol=self.protocol,
                deadline=deadline,
                answered=answer.append,
            )
        except DeviceTimeoutError:
            self._record(Outcome.TIMEOUT)
            raise
        except (BusError, FrameError):
            self._record(Outcome.TIMEOUT)
            raise
        except DeviceExceptionError as exc:
            outcome = {
                "busy": Outcome.BUSY,
                "fail": Outcome.FAILED,
                "locked": Outcome.FAILED,
            }.get(exc.action, Outcome.REFUSED)
            self._record(outcome, code=exc.code)
            raise
        self._record(Outcome.OK, latency=sum(answer))
        return values

    def _record(
        self, outcome: Outcome, *, latency: float | None = None, code: int | None = None
    ) -> None:
        now = time.monotonic()
        self._last_traffic = now
        dog = self.watchdog
        if dog is not None and outcome is not Outcome.TIMEOUT and dog.answered(now):
            log.info("%s answers again: its watchdog is fed", self.device.id)
        first_contact = self.health.online is None
        transition = self.health.record(outcome, now, latency=latency, code=code)
        self.announce(transition, first_contact=first_contact)

    def announce(self, transition: Transition | None, *, first_contact: bool) -> None:
        """Log a change of state once (offline with the reason) and publish it."""
        if transition is None:
            return
        fields = {"device": self.device.id, "unit": self.device.unit, "bus": self.scheduler.bus_id}
        if transition is Transition.OFFLINE:
            health = self.health
            failures, backoff = health.consecutive_failures, health.backoff
            reason = health.offline_reason(time.monotonic())
            log.warning(
                "%s (unit %d on %s) offline %s; retrying every %.1f s or later",
                *fields.values(),
                reason,
                backoff,
                extra=fields
                | {
                    "event": "device_offline",
                    "failures": failures,
                    "backoff_s": backoff,
                    "reason": str(health.fault),
                },
            )
        else:
            word = "online" if first_contact else "back online"
            event = "device_online" if first_contact else "device_recovered"
            log.info("%s %s", self.device.id, word, extra=fields | {"event": event})
        self._notify(frozenset())

    def publish(self, keys: Iterable[str], fresh: set[Address]) -> None:
        changed: set[str] = set()
        refused = self.refusals.refused
        for key in keys:
            point = self.points[key]
            if not point.entity.readable:
                continue
            span = {(point.table, a) for a in point.span}
            if span & refused:
                value: Value = None
            elif span <= fresh:
                try:
                    value = decode(point, self.image)
                except MissingDataError:
                    value = None
            else:
                continue
            if key not in self.values or self.values[key] != value:
                changed.add(key)
                self._count_unknown(point, value)
            self.values[key] = value
        if changed:
            self._notify(frozenset(changed))

    def _count_unknown(self, point: Point, value: Value) -> None:
        """Count an enum code the mapping has no label for as it appears (published as
        ``code_<n>``); say so in the log once per key and code."""
        if not is_unknown_code(point.entity, value):
            return
        self.unknown_codes += 1
        if (point.key, value) not in self._unknown_logged:
            self._unknown_logged.add((point.key, value))
            log.warning(
                "%s: %s reads %s, a code the mapping has no label for; published as is",
                self.device.id,
                point.key,
                value,
            )

    def _notify(self, changed: frozenset[str]) -> None:
        if self.on_update is not None:
            self.on_update(
                DeviceUpdate(self.device.id, dict(self.values), changed, self.health.online)
            )


def _next_tick(due: float, interval: float | None, now: float) -> float:
    """The next tick of a fixed schedule after ``now``; ticks missed meanwhile are skipped."""
    if not interval:
        return float("inf")
    missed = max(0, int((now - due) // interval))
    return due + (missed + 1) * interval


def _with_overrides(mapping: Mapping, device: DeviceConfig) -> Mapping:
    """The mapping with this device's protocol overrides applied."""
    overrides = device.protocol.model_dump(exclude_none=True)
    overrides.pop("response_timeout", None)
    if not overrides:
        return mapping
    protocol = mapping.protocol.model_copy(update=overrides)
    return mapping.model_copy(update={"protocol": protocol})
