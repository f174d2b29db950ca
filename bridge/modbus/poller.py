"""One device: poll intervals on a monotonic schedule, health and backoff, learnt refusals, writes.

Poll: the intervals due (bridge/core/schedule.py) -> their plan, as one set -> scheduler
(serialised, gap) -> register image -> decode what was read fresh (and what was read
along) -> ``on_update`` with the values that changed. Missed ticks are skipped, not
queued. An offline device is probed once per backoff interval only.

The poller wires small parts, each given what the device knows (``DeviceState``,
bridge/core/device_state.py: image, values, refusals, read limits, plans) and how it talks
to its bus (``DeviceLink``, bridge/modbus/device_link.py: submit, read a block, health),
and passing the values they changed to ``values_changed``: writes go through its
``DeviceWriter`` (bridge/modbus/writer.py), blocks the device refuses are searched and
learnt by its ``RefusalLearner`` (bridge/modbus/refusal_learning.py), two-word values read
in two reads are checked by ``check_torn`` (bridge/modbus/tear_check.py), values read
apart from their scale factor get it read before and after them (bridge/modbus/
bracket_read.py), and a device
with a communication watchdog is kept fed by ``keep_alive`` (bridge/modbus/keepalive.py).
None of them imports the poller.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from datetime import UTC, datetime

from bridge.config import DeviceConfig
from bridge.core.codec import Value, is_unknown_code
from bridge.core.counters import Kind, Reading
from bridge.core.device_state import DeviceState
from bridge.core.entity import PollClass
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.health import DeviceHealth, HealthPolicy
from bridge.core.mapping import Mapping, Point
from bridge.core.planner import Address, ReadLimits
from bridge.core.protocol import Protocol
from bridge.core.request import Read
from bridge.core.schedule import ONCE, PollRule, PollSpec, Schedule
from bridge.core.timing import LinkTiming
from bridge.modbus.bracket_read import read_after, read_before
from bridge.modbus.device_link import DeviceLink, Refused
from bridge.modbus.keepalive import keep_alive
from bridge.modbus.refusal_learning import RefusalLearner
from bridge.modbus.scheduler import BusScheduler, Priority
from bridge.modbus.tear_check import check_torn
from bridge.modbus.writer import DeviceWriter, Later, WriteCounters

log = logging.getLogger(__name__)
DEFAULT_POLICY = HealthPolicy()


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
        if device.offline_after is not None:
            policy = replace(policy, offline_after=device.offline_after)
        self.state = DeviceState(
            _with_overrides(mapping, device),
            device.options,
            timing=timing,
            recheck=policy.refusal_recheck,
            guard=guard,  # what earlier mappings guarded
            confirm=device.counter_confirm,
            poll=_poll_rule(mapping, device),
        )
        self.link = DeviceLink(
            device,
            self.state,
            scheduler,
            timeout=device.protocol.response_timeout or timeout,
            retries=retries,
            policy=policy,
            on_change=self._notify,
            judge=self._judge,
        )
        self.on_update = on_update
        self.writer = DeviceWriter(self.state, self.link, self.values_changed)
        self.learner = RefusalLearner(self.state, self.link)
        self._polled_once = False
        self.first_poll_done = False  # every class was asked once (answered or not)
        self.unknown_codes = 0  # enum codes read that the mapping has no label for
        self._unknown_logged: set[tuple[str, Value]] = set()
        self.counter_readings_held = 0  # counter readings not published (counters.py)
        self.counter_resets = 0
        self._held_logged: set[tuple[str, str]] = set()
        self.carried: dict[str, object] | None = None  # seeds kept for a mapping to come

    # --- what the device knows and how it is reached (for readers of the poller) --------

    @property
    def mapping(self) -> Mapping:
        """The mapping with this device's protocol overrides applied."""
        return self.state.mapping

    @property
    def protocol(self) -> Protocol:
        return self.state.protocol

    @property
    def points(self) -> dict[str, Point]:
        return self.state.points

    @property
    def guard(self) -> Guard:
        """This mapping's guard joined with the guards of the mappings before it."""
        return self.state.guard

    @property
    def image(self) -> dict[Address, int]:
        return self.state.image

    @property
    def values(self) -> dict[str, Value]:
        return self.state.values

    @property
    def refused(self) -> frozenset[Address]:
        """The addresses learnt as refused that plans avoid now (until their re-check)."""
        return self.state.refused

    @property
    def max_read(self) -> int | None:
        """Registers per read, when the device showed it takes fewer than mapped."""
        return self.state.max_read

    def limits(self) -> ReadLimits:
        """The read limits as known now."""
        return self.state.limits()

    @property
    def scheduler(self) -> BusScheduler:
        return self.link.scheduler

    @property
    def health(self) -> DeviceHealth:
        return self.link.health

    @property
    def scaled_values_held(self) -> int:
        """Values read apart from their scale factor not published: the factor read
        differently before and after them (bridge/core/bracket.py)."""
        return self.state.scaled_values_held

    # --- polling ------------------------------------------------------------------

    @property
    def intervals(self) -> dict[PollClass, float]:
        """The device's named intervals (``fast`` shortened by a keepalive)."""
        return {PollClass.FAST: self.state.rule.fast, PollClass.SLOW: self.state.rule.slow}

    async def run(self) -> None:
        """Poll until cancelled (and feed the device's watchdog, bridge/modbus/keepalive.py);
        never raises for a device fault."""
        async with asyncio.TaskGroup() as group:
            if self.link.watchdog is not None:
                group.create_task(
                    keep_alive(self.state, self.link, self.values_changed),
                    name=f"keepalive:{self.device.id}",
                )
            await self._poll_loop()

    def plan_of(self, poll: PollSpec) -> tuple[Read, ...]:
        """The reads of one interval (``fast``, ``slow``, ``once`` or seconds), as planned now."""
        return self.state.plan([poll])

    def _schedule(self) -> Schedule:
        """Every interval in use (and the named ones: an empty class ticks as before),
        due now."""
        return Schedule.of(self._every_interval(), time.monotonic())

    async def _poll_loop(self) -> None:
        schedule = self._schedule()
        while True:
            now = time.monotonic()
            if not self.health.may_poll(now):
                await asyncio.sleep(self.health.next_attempt - now)
                continue
            due = schedule.due(now)
            if due:
                await self.poll(due)
                after = time.monotonic()
                schedule.served(due, after)
                if ONCE in due and not self._polled_once:
                    schedule.retry(ONCE, after + self.device.poll.slow)  # until it succeeds
            wake = min(schedule.wake(), self._offline_wake())
            await asyncio.sleep(max(0.0, wake - time.monotonic()))

    @property
    def writes(self) -> WriteCounters:
        """How the commands to this device ended (done, skipped, rejected, failed, expired)."""
        return self.writer.counters

    async def write(self, key: str, value: object, *, deadline: float | None = None) -> Value:
        """Write one value (``write_many`` with one key); the value the device holds."""
        return (await self.write_many({key: value}, deadline=deadline))[key]

    async def write_many(
        self,
        items: dict[str, object],
        *,
        deadline: float | None = None,
        later: Later | None = None,
    ) -> dict[str, Value]:
        """All or nothing: see ``DeviceWriter.write_many``."""
        return await self.writer.write_many(items, deadline=deadline, later=later)

    def _offline_wake(self) -> float:
        return self.health.next_attempt if self.health.online is False else float("inf")

    async def poll(self, due: Iterable[PollSpec]) -> None:
        """Read every point of these intervals once, in one plan, and pass on what
        changed (with the values read along in the plan's holes)."""
        chosen = frozenset(map(self.state.rule.seconds, due))
        self.learner.recheck()
        fresh: set[Address] = set()
        plan, brackets = self.state.plan(chosen), self.state.brackets(chosen)
        since = await read_before(self.state, self.link, brackets, Priority.POLL, fresh)
        await self._read_pass(plan, Priority.POLL, fresh, stop=True)
        if ONCE in chosen and fresh:
            self._polled_once = True
        await read_after(
            self.state, self.link, brackets, since, priority=Priority.POLL, fresh=fresh
        )
        keys = self.state.sharing(self.state.keys_of(chosen))  # and their registers' views
        await check_torn(self.state, self.link, keys, plan, fresh)
        self._decode(keys, fresh, since)
        if not self.first_poll_done and self._every_interval() <= chosen:
            self.first_poll_done = True  # units and limits read (or not there): say so once
            self._notify(frozenset())

    def _every_interval(self) -> frozenset[float]:
        named = (PollClass.FAST, PollClass.SLOW, PollClass.ONCE)
        return frozenset({*self.state.intervals.values(), *map(self.state.rule.seconds, named)})

    async def read_now(self, keys: Iterable[str] | None = None) -> dict[str, Value]:
        """Read these points (all when None) ahead of the polls; return their values."""
        wanted = [self.points[k] for k in keys] if keys is not None else list(self.points.values())
        fresh: set[Address] = set()
        plan = self.state.plan_for(wanted)
        since = await read_before(self.state, self.link, plan.bracketed, Priority.READ_NOW, fresh)
        await self._read_pass(plan.reads, Priority.READ_NOW, fresh)
        await read_after(
            self.state, self.link, plan.bracketed, since, priority=Priority.READ_NOW, fresh=fresh
        )
        await check_torn(self.state, self.link, [p.key for p in wanted], plan.reads, fresh)
        self._decode(self.state.sharing(p.key for p in wanted), fresh, since)
        return {p.key: self.values.get(p.key) for p in wanted}

    async def _read_pass(
        self, reads: Iterable[Read], priority: Priority, fresh: set[Address], *, stop: bool = False
    ) -> None:
        """Read these blocks, then judge the blocks refused whole together: holes are
        searched and learnt, a device refusing everything is a fault. ``stop``: give up
        the pass when the unit stops answering (the next cycle tries again)."""
        refused: list[Refused] = []
        for read in reads:
            timeouts = self.health.timeouts
            if await self.link.read_block(read, priority, fresh, refused) or not stop:
                continue
            if self.health.timeouts > timeouts:
                return  # silent: the refused blocks are judged another time
            if self.health.online is False:
                break  # probing an offline unit: one failed read settles it
        await self.learner.judge(refused, priority, fresh)

    async def _judge(self, refused: list[Refused], priority: Priority, fresh: set[Address]) -> bool:
        """A block refused outside a pass (a write's read, a keepalive read), judged alone."""
        return await self.learner.judge(refused, priority, fresh)

    def _decode(self, keys: Iterable[str], fresh: set[Address], since: int) -> None:
        """Decode what this pass (its requests after ``since``) read fresh; pass on what
        changed."""
        changed = self.state.decode_fresh(keys, fresh, since)
        if changed:
            self.values_changed(changed)
        else:
            self._counter_news()

    def values_changed(self, changed: frozenset[str]) -> None:
        """Count the new unknown enum codes among ``changed`` and the counters' news, then
        notify ``on_update``."""
        for key in changed:
            self._count_unknown(self.points[key], self.values[key])
        self._counter_news()
        self._notify(changed)

    def seed_counters(self, document: dict[str, object]) -> None:
        """The device's counters as published before this start (its retained document):
        a lower first reading is then held like any other (bridge/core/counters.py). A
        device with no points yet (a SunSpec device not walked) keeps the document for the
        mapping it gets (``carried``: ``Engine.replace_mapping`` seeds that poller)."""
        if not self.points:
            self.carried = document
            return
        changed = self.state.seed_counters(document)
        if changed:
            log.info(
                "%s: counters carried on from the last published state: %s",
                self.device.id,
                ", ".join(f"{k} {self.values[k]}" for k in sorted(changed)),
            )
            self._notify(changed)

    def _counter_news(self) -> None:
        """Count and log the counter readings held back, rolled over or reset; a total
        counter's confirmed reset starts its ``last_reset``."""
        for key, reading in self.state.take_counter_news():
            if reading.kind is Kind.HELD:
                self.counter_readings_held += 1
                self._log_held(key, reading)
            elif reading.kind is Kind.RESET:
                self.counter_resets += 1
                log.warning(
                    "%s: %s went back from %s to %s, %d lower readings in a row: "
                    "published as a reset",
                    self.device.id,
                    key,
                    reading.before,
                    reading.value,
                    self.state.counters[key].rule.confirm,
                    extra={"event": "counter_reset", "key": key},
                )
                if self.points[key].entity.ha.state_class == "total":
                    self.state.last_reset[key] = datetime.now(UTC).isoformat(timespec="seconds")
            elif reading.kind is Kind.WRAP:
                log.info("%s: %s rolled over; counted on at %s", self.device.id, key, reading.value)

    def _log_held(self, key: str, reading: Reading) -> None:
        """Once per key and reason at WARNING (then at DEBUG): what was read, what stays."""
        first = (key, reading.reason) not in self._held_logged
        self._held_logged.add((key, reading.reason))
        log.log(
            logging.WARNING if first else logging.DEBUG,
            "%s: %s read %s (%s) below %s: not published, %s stays until the count goes on "
            "or the same lower value is read %d times in a row%s",
            self.device.id,
            key,
            reading.read,
            reading.reason,
            reading.before,
            reading.before,
            self.state.counters[key].rule.confirm,
            "" if not first else " (said once per counter and cause; counted in bridge/health)",
            extra={"event": "counter_held", "key": key},
        )

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


def _poll_rule(mapping: Mapping, device: DeviceConfig) -> PollRule:
    """The device's poll config as a rule; its ``fast`` no longer than a keepalive asks."""
    keepalive = mapping.protocol.keepalive
    fast = device.poll.fast if keepalive is None else min(device.poll.fast, keepalive.interval)
    return device.poll.rule(fast)


def _with_overrides(mapping: Mapping, device: DeviceConfig) -> Mapping:
    """The mapping with this device's protocol overrides applied."""
    overrides = device.protocol.model_dump(exclude_none=True)
    overrides.pop("response_timeout", None)
    if not overrides:
        return mapping
    # one copy for every device of the model with the same overrides, as every device
    # without overrides shares the mapping: its points, guard and read limits are worked
    # out once (a copy of its own per device made 247 Nastec units work out their
    # reserved registers 247 times at a start, seconds of a held event loop: issue 27)
    key = ("overridden", tuple(sorted(overrides.items())))
    protocol = mapping.protocol.model_copy(update=overrides)
    return mapping.memo(key, lambda: mapping.model_copy(update={"protocol": protocol}))
