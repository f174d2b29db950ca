"""One device: poll classes on a monotonic schedule, health and backoff, learnt refusals, writes.

Poll: due classes -> precomputed plan -> scheduler (serialised, gap) -> register image ->
decode what was read fresh -> ``on_update`` with the values that changed. Missed ticks are
skipped, not queued. An offline device is probed once per backoff interval only.

Write: check (known, writable, dangerous-write guard, EEPROM rate limit) -> read what the
write depends on (the word of a bit field, a sign register, limit registers, the current
value of an EEPROM parameter) -> encode (type, range, enum) -> write ahead of polls ->
read back -> publish. Anything refused raises before a byte reaches the wire.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from bridge.config import DeviceConfig
from bridge.core.codec import Value, decode, encode
from bridge.core.entity import PollClass, Table
from bridge.core.health import DeviceHealth, HealthPolicy, Outcome, Transition
from bridge.core.mapping import Mapping, Point
from bridge.core.planner import ReadLimits, limits_for, plan_reads
from bridge.core.protocol import Protocol
from bridge.core.refusal import Refusal, refusal_search
from bridge.core.request import Read, Write
from bridge.core.timing import LinkTiming
from bridge.errors import (
    BusError,
    CommandExpiredError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    MissingDataError,
    ModbusError,
    ValueRejectedError,
)
from bridge.modbus.scheduler import BusScheduler, Priority

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


@dataclass(slots=True)
class WriteCounters:
    done: int = 0
    skipped_unchanged: int = 0
    rejected: int = 0
    failed: int = 0
    expired: int = 0
    last_write: dict[int, float] = field(default_factory=dict)


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
    ) -> None:
        self.device = device
        self.mapping = _with_overrides(mapping, device)
        self.protocol: Protocol = self.mapping.protocol
        self.points: dict[str, Point] = self.mapping.points(device.options)
        self.scheduler = scheduler
        self.timing = timing
        self.timeout = device.protocol.response_timeout or timeout
        self.retries = retries
        self.on_update = on_update
        self.health = DeviceHealth(policy)
        self.writes = WriteCounters()
        self.image: dict[Address, int] = {}
        self.values: dict[str, Value] = {}
        self.refused: set[Address] = set()
        self.max_read: int | None = None  # learnt: fewer registers per read than mapped
        self._plans: dict[PollClass, tuple[Read, ...]] = {}
        self._limits_cache: ReadLimits | None = None
        self._polled_once = False
        self._last_traffic = 0.0

    # --- polling ------------------------------------------------------------------

    @property
    def intervals(self) -> dict[PollClass, float]:
        fast, slow = self.device.poll.fast, self.device.poll.slow
        keepalive = self.protocol.keepalive
        if keepalive is not None:
            fast = min(fast, keepalive.interval)
        return {PollClass.FAST: fast, PollClass.SLOW: slow}

    async def run(self) -> None:
        """Poll until cancelled; never raises for a device fault."""
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

    def _offline_wake(self) -> float:
        return self.health.next_attempt if self.health.online is False else float("inf")

    async def poll(self, classes: Iterable[PollClass]) -> None:
        """Read every point of these classes once and publish what changed."""
        chosen = set(classes)
        fresh: set[Address] = set()
        for read in self._plan(chosen):
            timeouts = self.health.timeouts
            if not await self._read(read, Priority.POLL, fresh) and (
                self.health.timeouts > timeouts or self.health.online is False
            ):
                break  # a unit that stopped answering: the next cycle tries again
        if PollClass.ONCE in chosen and fresh:
            self._polled_once = True
        keys = [k for k, p in self.points.items() if p.entity.poll_class in chosen]
        self._publish(keys, fresh)

    async def read_now(self, keys: Iterable[str] | None = None) -> dict[str, Value]:
        """Read these points (all when None) ahead of the polls; return their values."""
        wanted = [self.points[k] for k in keys] if keys is not None else list(self.points.values())
        fresh: set[Address] = set()
        limits = self._limits()
        for read in plan_reads(wanted, limits).reads:
            await self._read(read, Priority.READ_NOW, fresh)
        self._publish([p.key for p in wanted], fresh)
        return {p.key: self.values.get(p.key) for p in wanted}

    def _plan(self, classes: set[PollClass]) -> tuple[Read, ...]:
        reads: list[Read] = []
        for poll_class in sorted(classes):
            if poll_class not in self._plans:
                members = [p for p in self.points.values() if p.entity.poll_class is poll_class]
                self._plans[poll_class] = plan_reads(members, self._limits()).reads
            reads.extend(self._plans[poll_class])
        return tuple(reads)

    def _limits(self) -> ReadLimits:
        """The read limits as known now (cached; learning a refusal clears the cache)."""
        if self._limits_cache is None:
            self._limits_cache = limits_for(
                self.mapping,
                max_registers=self.max_read,
                refused=frozenset(self.refused),
                timing=self.timing,
            )
        return self._limits_cache

    def _forget_plans(self) -> None:
        self._plans.clear()
        self._limits_cache = None

    async def _read(self, read: Read, priority: Priority, fresh: set[Address]) -> bool:
        """One read; learns refused addresses by splitting a refused block."""
        try:
            values = await self._submit(read, priority)
        except DeviceExceptionError as exc:
            if exc.action == "refused":
                return await self._learn_refusal(read, priority, fresh, exc)
            return False
        except ModbusError:
            return False
        self._keep(read, values, fresh)
        return True

    async def _learn_refusal(
        self, read: Read, priority: Priority, fresh: set[Address], exc: DeviceExceptionError
    ) -> bool:
        """Bisect a refused block with real reads; remember what the device refused (or the
        smaller read limit it showed) so later plans avoid it. True if any part answered."""
        search = refusal_search(read, list(self.points.values()))
        answered = False
        try:
            part = next(search)
            while True:
                ok = await self._probe(part, priority, fresh)
                answered = answered or ok
                part = search.send(ok)
        except StopIteration as done:
            refusal: Refusal = done.value
        except ModbusError:
            return answered  # the device stopped answering meanwhile: learn next time
        self._remember(refusal.refused, exc)
        if refusal.max_count is not None:
            self.max_read = min(self.max_read or refusal.max_count, refusal.max_count)
            log.warning(
                "%s: at most %d registers per read; plans adjusted", self.device.id, self.max_read
            )
            self._forget_plans()
        return answered

    async def _probe(self, read: Read, priority: Priority, fresh: set[Address]) -> bool:
        """One read of a bisection: True answered (values kept), False refused."""
        try:
            values = await self._submit(read, priority)
        except DeviceExceptionError as exc:
            if exc.action == "refused":
                return False
            raise
        self._keep(read, values, fresh)
        return True

    def _keep(self, read: Read, values: tuple[int, ...], fresh: set[Address]) -> None:
        for address, value in zip(read.span, values, strict=True):
            self.image[(read.table, address)] = value
            fresh.add((read.table, address))

    def _remember(self, addresses: frozenset[Address], exc: DeviceExceptionError) -> None:
        """Never read these addresses again (logged once, with the device's reason)."""
        newly = addresses - self.refused
        if newly:
            shown = ", ".join(f"{t.value} {a}" for t, a in sorted(newly))
            log.warning("%s refused %s (%s); not read again", self.device.id, shown, exc.meaning)
            self.refused |= newly
            self._forget_plans()

    async def _submit(
        self,
        request: Read | Write,
        priority: Priority,
        retries: int | None = None,
        deadline: float | None = None,
    ) -> tuple[int, ...]:
        if retries is None:  # reads are not resent: the next cycle reads again
            retries = 0
        started = time.monotonic()
        try:
            values = await self.scheduler.submit(
                self.device.unit,
                request,
                timeout=self.timeout,
                priority=priority,
                retries=retries,
                protocol=self.protocol,
                deadline=deadline,
            )
        except DeviceTimeoutError:
            self._record(Outcome.TIMEOUT)
            raise
        except (BusError, FrameError):
            self._record(Outcome.TIMEOUT)
            raise
        except DeviceExceptionError as exc:
            outcome = {"busy": Outcome.BUSY, "fail": Outcome.FAILED}.get(
                exc.action, Outcome.REFUSED
            )
            self._record(outcome, code=exc.code)
            raise
        self._record(Outcome.OK, latency=time.monotonic() - started)
        return values

    def _record(
        self, outcome: Outcome, *, latency: float | None = None, code: int | None = None
    ) -> None:
        now = time.monotonic()
        self._last_traffic = now
        first_contact = self.health.online is None
        transition = self.health.record(outcome, now, latency=latency, code=code)
        if transition is None:
            return
        fields = {"device": self.device.id, "unit": self.device.unit, "bus": self.scheduler.bus_id}
        if transition is Transition.OFFLINE:
            failures, backoff = self.health.consecutive_failures, self.health.backoff
            log.warning(
                "%s (unit %d on %s) offline after %d failed requests; retrying every %.1f s "
                "or later",
                *fields.values(),
                failures,
                backoff,
                extra=fields
                | {"event": "device_offline", "failures": failures, "backoff_s": backoff},
            )
        else:
            word = "online" if first_contact else "back online"
            event = "device_online" if first_contact else "device_recovered"
            log.info("%s %s", self.device.id, word, extra=fields | {"event": event})
        self._notify(frozenset())

    def _publish(self, keys: Iterable[str], fresh: set[Address]) -> None:
        changed: set[str] = set()
        for key in keys:
            point = self.points[key]
            if not point.entity.readable:
                continue
            span = {(point.table, a) for a in point.span}
            if span & self.refused:
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
            self.values[key] = value
        if changed:
            self._notify(frozenset(changed))

    def _notify(self, changed: frozenset[str]) -> None:
        if self.on_update is not None:
            self.on_update(
                DeviceUpdate(self.device.id, dict(self.values), changed, self.health.online)
            )

    # --- writing ------------------------------------------------------------------

    async def write(self, key: str, value: object, *, deadline: float | None = None) -> Value:
        """Validate, write ahead of polls, read back; return the value the device holds.

        ``deadline`` (monotonic): the first write must be sent by then, else the command is
        dropped with CommandExpiredError; the writes after it (a sign, a pulse's second
        half) always follow, so a command is never left half done. Every command ends in
        one of ``self.writes``: done, skipped_unchanged, rejected, failed or expired.
        """
        try:
            return await self._write(key, value, deadline)
        except ValueRejectedError:
            self.writes.rejected += 1
            raise
        except CommandExpiredError:
            self.writes.expired += 1
            raise
        except (ModbusError, MissingDataError):
            self.writes.failed += 1
            raise

    async def _write(self, key: str, value: object, deadline: float | None) -> Value:
        point = self.points.get(key)
        if point is None:
            raise ValueRejectedError(f"{key}: no such entity on {self.device.id}")
        entity = point.entity
        self._check_allowed(point)
        await self._refresh(_dependencies(point))
        writes = encode(point, value, self.image)
        if entity.eeprom and entity.readable and self._unchanged(point, writes):
            self.writes.skipped_unchanged += 1  # the same value again: no wear, no refusal
            return self.values.get(key, decode(point, self.image))
        if entity.eeprom:
            self._check_eeprom_rate(point)
        retries = self.retries if entity.idempotent else 0
        for index, write in enumerate(writes):
            await self._submit(
                write,
                Priority.WRITE,
                retries=retries,
                deadline=deadline if index == 0 else None,
            )
            self._store(write)
            if entity.eeprom:
                self.writes.last_write[write.address] = time.monotonic()
        self.writes.done += 1
        if entity.readable and entity.press is None:
            self._publish_acknowledged(point, writes)
        if entity.verify and entity.readable:
            return await self._read_back(point)
        return _as_value(value) if entity.press is None else None

    def _publish_acknowledged(self, point: Point, writes: tuple[Write, ...]) -> None:
        """Publish what the device acknowledged at once (FC06/FC16 answer only after the
        unit took the registers), before the read-back that confirms or corrects it: the
        value is on MQTT one transaction earlier. Only where the written registers are the
        ones read (not coils, not a separate command register)."""
        if point.write_address != point.address or any(w.function in (5, 15) for w in writes):
            return
        written = {(w.table, w.address + i) for w in writes for i in range(len(w.values))}
        if {(point.table, a) for a in point.span} <= written:
            self._publish([point.key], written)

    def _check_allowed(self, point: Point) -> None:
        entity = point.entity
        if not entity.writable:
            raise ValueRejectedError(f"{point.key} is read-only")
        if entity.dangerous and not self.device.allow_dangerous_writes:
            raise ValueRejectedError(
                f"{point.key} is a guarded write (dangerous); set allow_dangerous_writes: true "
                f"for device {self.device.id} to permit it"
            )

    def _check_eeprom_rate(self, point: Point) -> None:
        """An EEPROM parameter is rewritten at most once per ``eeprom_write_interval``."""
        last = self.writes.last_write.get(point.write_address)
        wait = self.protocol.eeprom_write_interval
        if last is not None and time.monotonic() - last < wait:
            left = wait - (time.monotonic() - last)
            raise ValueRejectedError(
                f"{point.key} is stored in EEPROM: next write allowed in {left:.0f} s"
            )

    async def _refresh(self, reads: list[Read]) -> None:
        fresh: set[Address] = set()
        for read in reads:
            if not await self._read(read, Priority.READ_NOW, fresh):
                raise MissingDataError(
                    f"{self.device.id}: cannot read {read.table.value} {read.address} "
                    "that the write depends on"
                )

    def _unchanged(self, point: Point, writes: tuple[Write, ...]) -> bool:
        return (
            all(
                self.image.get((w.table, w.address + i)) == v
                for w in writes
                for i, v in enumerate(w.values)
            )
            and point.write_address == point.address
        )

    def _store(self, write: Write) -> None:
        if write.function in (5, 15):
            return  # coil commands may live in another space than the status bits
        for offset, word in enumerate(write.values):
            self.image[(write.table, write.address + offset)] = word

    async def _read_back(self, point: Point) -> Value:
        targets = [point] + ([point.sign] if point.sign is not None else [])
        fresh: set[Address] = set()
        for read in plan_reads(targets, self._limits()).reads:
            await self._read(read, Priority.READ_NOW, fresh)
        self._publish([point.key], fresh)
        return self.values.get(point.key)


def _dependencies(point: Point) -> list[Read]:
    """What a write of ``point`` must read fresh first: the word of a bit field (even of a
    write-only bit), a sign register, limit registers, an EEPROM parameter's current value."""
    entity = point.entity
    sources = [p for p in (point.sign, point.min_source, point.max_source) if p is not None]
    reads = [Read(p.table, p.address, p.count) for p in sources]
    if entity.field_width is not None or (entity.eeprom and entity.readable):
        reads.append(Read(point.table, point.address, point.count))
    return list(dict.fromkeys(reads))


def _next_tick(due: float, interval: float | None, now: float) -> float:
    """The next tick of a fixed schedule after ``now``; ticks missed meanwhile are skipped."""
    if not interval:
        return float("inf")
    missed = max(0, int((now - due) // interval))
    return due + (missed + 1) * interval


def _as_value(value: object) -> Value:
    return value if isinstance(value, bool | int | float | str) else None


def _with_overrides(mapping: Mapping, device: DeviceConfig) -> Mapping:
    """The mapping with this device's protocol overrides applied."""
    overrides = device.protocol.model_dump(exclude_none=True)
    overrides.pop("response_timeout", None)
    if not overrides:
        return mapping
    protocol = mapping.protocol.model_copy(update=overrides)
    return mapping.model_copy(update={"protocol": protocol})
