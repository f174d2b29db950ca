"""One device's write path: what it knows (bridge/core/device_state.py) and its link to the
bus (bridge/modbus/device_link.py), the changes passed on through a callback.

Write: check every key (known, writable, dangerous-write guard) -> read what the writes
depend on (the word of a bit field, a sign register, limit registers, the current value
of an EEPROM parameter) -> encode every key (type, range, enum, EEPROM rate limit; keys
see the words the keys before them leave) -> one frame per word -> write ahead of polls,
as one ``WriteSequence`` when there is more than one frame (undone if a later frame
fails, finished before a stopping bus ends) -> publish what the unit acknowledged -> read
back (a key with a ``verify_delay`` that long later, off the bus: polls and other devices
go on; with ``later``, after the command, so that the device's next command goes on too).
Anything refused raises before a byte reaches the wire; one refused key refuses the whole
command.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from bridge.core.address import to_wire
from bridge.core.codec import Value, decode, encode
from bridge.core.device_state import DeviceState
from bridge.core.entity import Table
from bridge.core.mapping import Point
from bridge.core.request import Read, Write, WriteSequence
from bridge.core.write_plan import (
    contradictions,
    dependencies,
    frames_of,
    stored,
    unchanged,
    undo_of,
)
from bridge.errors import (
    CommandExpiredError,
    CommandRejectedError,
    MissingDataError,
    ModbusError,
    PartialWriteError,
    ValueRejectedError,
    WriteForbiddenError,
)
from bridge.modbus.bracket_read import read_after, read_before
from bridge.modbus.device_link import Changes, Link
from bridge.modbus.scheduler import Priority

log = logging.getLogger(__name__)
Address = tuple[Table, int]
Later = list[tuple[float, Point]]  # read backs due after a verify_delay: (when, point)


@dataclass(slots=True)
class WriteCounters:
    done: int = 0
    skipped_unchanged: int = 0
    rejected: int = 0
    failed: int = 0
    expired: int = 0
    last_write: dict[Address, float] = field(default_factory=dict)  # EEPROM registers
    last_attempt: dict[Address, float] = field(default_factory=dict)  # write_interval


class DeviceWriter:
    """Writes to one device through its link, against what it knows; the values a write
    changed go to ``on_change``."""

    def __init__(self, state: DeviceState, link: Link, on_change: Changes) -> None:
        self.state = state
        self.link = link
        self.on_change = on_change
        self.counters = WriteCounters()

    async def write_many(
        self,
        items: dict[str, object],
        *,
        deadline: float | None = None,
        later: Later | None = None,
    ) -> dict[str, Value]:
        """Validate every key, write them all ahead of polls, read back; return the values.

        All or nothing: every key is checked and encoded before anything is sent, and one
        refused key (CommandRejectedError, naming each) means nothing is written. The
        frames of all keys go out as one sequence (a sign and a magnitude, a pulse, two bit
        fields of one word) that is never left half done: if a frame after the first fails,
        the frames done are undone and PartialWriteError says what the device holds now.
        ``deadline`` (monotonic): the first frame must be sent by then, else the command is
        dropped with CommandExpiredError. ``later``: where the read backs of keys with a
        ``verify_delay`` go, for ``read_back_later`` once the caller let the device's next
        command go (without it they wait here). ``self.counters``: each key written (done) or
        left unchanged (skipped_unchanged); each command rejected, failed or expired.
        """
        try:
            return await self._write_many(items, deadline, later)
        except ValueRejectedError:
            self.counters.rejected += 1
            raise
        except CommandExpiredError:
            self.counters.expired += 1
            raise
        except (ModbusError, MissingDataError):
            self.counters.failed += 1
            raise

    async def _write_many(
        self, items: dict[str, object], deadline: float | None, later: Later | None
    ) -> dict[str, Value]:
        points = self._allowed(items)
        _check_conditions_alone(points)
        needed = [r for p in points for r in dependencies(p, self._required(p))]
        await self._refresh(list(dict.fromkeys(needed)))
        self._check_requirements(points)
        plan = self._encode_all(points, items)
        held = {p.key: self._held(p) for p in points if p.key not in plan}
        if not plan:
            return held  # every key unchanged (EEPROM, a toggle in place): nothing to write
        writes = frames_of(plan, {p.key for p in points if p.entity.pulse})
        resendable = all(p.entity.idempotent and p.state_source is None for p in points)
        retries = self.link.retries if resendable else 0  # a toggle is never resent
        request: Write | WriteSequence = (
            writes[0]
            if len(writes) == 1
            else WriteSequence(tuple(writes), undo_of(writes, self.state.image))
        )
        attempts = self.counters.last_attempt
        spaced = [
            _written(p) for p in points if p.entity.write_interval is not None and p.key in plan
        ]
        before = {a: attempts[a] for a in spaced if a in attempts}
        for address in spaced:  # an attempt counts: a toggle that timed out may have acted
            attempts[address] = time.monotonic()
        try:
            await self.link.submit(request, Priority.WRITE, retries=retries, deadline=deadline)
        except PartialWriteError as partial:
            raise await self._report_partial(points, partial) from None
        except CommandExpiredError as expired:
            if not expired.sent:  # nothing went out: the spacing is as it was
                for address in spaced:
                    attempts.pop(address, None)
                attempts.update(before)
            raise
        for write in writes:
            self.state.store(write)
            self.state.stamp(stored(write), time.monotonic())
        self.counters.done += len(plan)  # per key, like skipped_unchanged
        written = [p for p in points if p.key in plan]
        for point in written:
            if point.entity.eeprom:
                self.counters.last_write[_written(point)] = time.monotonic()
            if point.entity.readable and point.entity.press is None:
                self._publish_acknowledged(point, plan[point.key])
        await self._read_backs(written, items, held, later, plan)
        return {p.key: held[p.key] for p in points}

    async def _read_backs(
        self,
        written: list[Point],
        items: dict[str, object],
        held: dict[str, Value],
        later: Later | None,
        plan: dict[str, tuple[Write, ...]],
    ) -> None:
        """Each written key's value read back into ``held``; a key with a ``verify_delay``
        goes to ``later`` (held as acknowledged meanwhile), or, without ``later``, all are
        read after the longest delay (the bus is not held while waiting). One read back
        serves every key of a register, and the other entities on the registers written
        are read back with them (``_read_back_sharers``)."""
        delayed = {p.key for p in written if p.entity.verify_delay}
        if later is not None:
            now = time.monotonic()
            later.extend(
                (now + (p.entity.verify_delay or 0.0), p) for p in written if p.key in delayed
            )
        elif delayed:
            await asyncio.sleep(max(p.entity.verify_delay or 0.0 for p in written))
            delayed = set()  # waited: every key is read back now
        fresh: set[Address] = set()
        for point in written:
            if point.key in delayed:
                held[point.key] = self._held(point)
            else:
                held[point.key] = await self._written_value(point, items[point.key], fresh)
        now_read = [p for p in written if p.key not in delayed]
        await self._read_back_sharers(now_read, plan, fresh)

    async def read_back_later(self, later: Later) -> None:
        """The read backs a command left for after its ``verify_delay`` (``write_many``'s
        ``later``), each when due; a failure raises (ModbusError) and counts as failed."""
        for due, point in sorted(later, key=lambda entry: entry[0]):
            await asyncio.sleep(max(0.0, due - time.monotonic()))
            try:
                await self._read_back(point, set())
            except ModbusError:
                self.counters.failed += 1
                raise

    def inherit(self, earlier: DeviceWriter) -> None:
        """Share the spacing of the writer this one replaces (a mapping reload): a toggle or
        an EEPROM parameter written just before, or by a command still running on the
        earlier writer, is not written again sooner for it."""
        self.counters.last_write = earlier.counters.last_write
        self.counters.last_attempt = earlier.counters.last_attempt

    def _allowed(self, items: dict[str, object]) -> list[Point]:
        """The points of a command, each known, writable and not guarded; else nothing."""
        points: list[Point] = []
        refused: dict[str, ValueRejectedError] = {}
        for key in items:
            point = self.state.points.get(key)
            try:
                if point is None:
                    raise WriteForbiddenError(f"{key}: no such entity on {self.link.device.id}")
                self._check_allowed(point)
            except ValueRejectedError as exc:
                refused[key] = exc
                continue
            points.append(point)
        if refused:
            raise CommandRejectedError(refused, list(items))
        return points

    def _encode_all(
        self, points: list[Point], items: dict[str, object]
    ) -> dict[str, tuple[Write, ...]]:
        """Every key encoded against what the device holds, each key seeing the words the
        keys before it leave (two bit fields of one word); unchanged EEPROM values left
        out. CommandRejectedError naming every refused key."""
        after: dict[Address, int] = dict(self.state.image)
        plan: dict[str, tuple[Write, ...]] = {}
        asked: dict[str, tuple[Write, ...]] = {}  # unchanged ones too: for contradictions
        refused: dict[str, ValueRejectedError] = {}
        for point in points:
            entity = point.entity
            try:
                writes = encode(point, items[point.key], after)
                asked[point.key] = writes
                self._check_unguarded(point, writes, after)
                if not writes or (
                    entity.eeprom and entity.readable and unchanged(point, writes, after)
                ):
                    self.counters.skipped_unchanged += 1  # no wear, no second toggle
                    continue
                if entity.eeprom:
                    self._check_eeprom_rate(point)
                self._check_write_interval(point)
            except ValueRejectedError as exc:
                refused[point.key] = exc
                continue
            plan[point.key] = writes
            for write in writes:
                after |= stored(write)
        for key, why in contradictions(points, asked).items():
            refused.setdefault(key, ValueRejectedError(why))
        if refused:
            raise CommandRejectedError(refused, list(items))
        return plan

    def _required(self, point: Point) -> list[Point]:
        """The points a write of ``point`` requires a value of (``requires``)."""
        return [self.state.points[k] for k in point.entity.requires if k in self.state.points]

    def _check_requirements(self, points: list[Point]) -> None:
        """Every key whose ``requires`` do not hold now (read fresh) is refused with the
        reason; one refused key refuses the command."""
        refused: dict[str, ValueRejectedError] = {}
        for point in points:
            for required in self._required(point):
                wanted = point.entity.requires[required.key]
                allowed = wanted if isinstance(wanted, list) else [wanted]
                value = decode(required, self.state.image)
                if value not in allowed:
                    refused[point.key] = WriteForbiddenError(
                        f"{point.key} refused: {required.entity.name} ({required.key}) reads "
                        f"{_word(value)}, needs {' or '.join(_word(v) for v in allowed)}: the "
                        "device does not accept this command now"
                    )
                    break
        if refused:
            raise CommandRejectedError(refused, [p.key for p in points])

    def _check_write_interval(self, point: Point) -> None:
        """A toggle is never sent twice within its ``write_interval`` (attempts count)."""
        interval = point.entity.write_interval
        last = self.counters.last_attempt.get(_written(point))
        if interval is None or last is None:
            return
        waited = time.monotonic() - last
        if waited < interval:
            raise WriteForbiddenError(
                f"{point.key} was sent {waited:.1f} s ago: not again within {interval:g} s "
                "(the device may still be acting on it)"
            )

    def _held(self, point: Point) -> Value:
        """The value the device holds as last read (an unchanged EEPROM parameter, a
        toggle whose state is already the one asked for)."""
        if point.state_source is not None:
            return self.state.values.get(point.state_source.key)
        if point.key in self.state.values:
            return self.state.values[point.key]
        try:
            return decode(point, self.state.image)
        except MissingDataError:
            return None

    async def _written_value(self, point: Point, value: object, fresh: set[Address]) -> Value:
        if point.state_source is not None:  # a toggle: the state it flips, as read now
            return await self._read_back(point.state_source, fresh)
        if point.entity.verify and point.entity.readable:
            return await self._read_back(point, fresh)
        return _as_value(value) if point.entity.press is None else None

    async def _read_back_sharers(
        self, written: list[Point], plan: dict[str, tuple[Write, ...]], fresh: set[Address]
    ) -> None:
        """The other entities on the registers a verified write set (a raw word, a select
        beside the switch written, or a write-only switch's register as a sensor reads
        it) are read back too, with the registers read back already: each publishes what
        the device holds now, not what it held before the write."""
        cells = {
            cell
            for p in written
            if p.entity.verify and p.state_source is None
            for write in plan[p.key]
            for cell in stored(write)
        }
        points = [self.state.points[k] for k in self.state.readers_of(cells)]
        if points:
            await self._read_back_keys(points, fresh)

    async def _report_partial(
        self, points: list[Point], partial: PartialWriteError
    ) -> PartialWriteError:
        """Read what the device holds after a compound write failed half way, log it at
        ERROR and return the error that says so (for ``<device>/error``)."""
        readable = [p for p in points if p.entity.readable]
        now: dict[str, Value] = {}
        for point in readable:
            try:
                now[point.key] = await self._read_back(point, set())
            except ModbusError:
                now[point.key] = None
        shown = ", ".join(f"{k}={v!r}" for k, v in now.items()) or "nothing readable"
        error = PartialWriteError(
            partial.done, partial.total, restored=partial.restored, cause=partial.cause, now=shown
        )
        log.error("%s: %s", self.link.device.id, error)
        return error

    def _publish_acknowledged(self, point: Point, writes: tuple[Write, ...]) -> None:
        """Publish what the device acknowledged at once (FC06/FC16 answer only after the
        unit took the registers), before the read-back that confirms or corrects it: the
        value is on MQTT one transaction earlier. Only where the written registers are the
        ones read (not coils, not a separate command register)."""
        if point.write_address != point.address or any(w.function in (5, 15) for w in writes):
            return
        written = {(w.table, w.address + i) for w in writes for i in range(len(w.values))}
        if {(point.table, a) for a in point.span} <= written:
            self._decode(self.state.sharing([point.key]), written)

    def _check_allowed(self, point: Point) -> None:
        entity = point.entity
        if not entity.writable:
            raise WriteForbiddenError(f"{point.key} is read-only")
        if entity.dangerous and not self.link.device.allow_dangerous_writes:
            raise self._guarded(point.key)
        protocol, device = self.state.protocol, self.link.device
        unlock = protocol.unlock
        if unlock is None or unlock.lock is None or not device.has_password:
            return
        if point.table is Table.HOLDING and point.write_address == to_wire(
            unlock.lock, protocol.addressing
        ):
            raise WriteForbiddenError(
                f"{point.key} would lock {device.id}, and the bridge unlocks it again on its "
                "next request with the password in its config: to keep it locked, remove "
                f"devices.{device.id}.password (or password_file, password_env) first"
            )

    def _check_unguarded(
        self, point: Point, writes: tuple[Write, ...], before: dict[Address, int]
    ) -> None:
        """No frame of the command changes a guarded bit of this mapping or of one the
        device had before (the guard survives mapping reloads); ``before``: what the
        device holds, fresh for a bit field's word. A harmless bit field beside a guarded
        one writes the guarded bits back as they were read."""
        if self.link.device.allow_dangerous_writes:
            return
        guard = self.state.guard
        image = dict(before)
        for w in writes:
            if guard.dangerous_changed(w.table, w.address, w.values, image):
                limit = point.entity.dangerous_below
                below = f": a value below {limit:g}" if limit is not None else ""
                raise self._guarded(point.key + below)
            image |= stored(w)

    def _guarded(self, subject: str) -> WriteForbiddenError:
        return WriteForbiddenError(
            f"{subject} is a guarded write (dangerous); set allow_dangerous_writes: true "
            f"for device {self.link.device.id} to permit it"
        )

    def _check_eeprom_rate(self, point: Point) -> None:
        """An EEPROM parameter is rewritten at most once per ``eeprom_write_interval``."""
        last = self.counters.last_write.get(_written(point))
        wait = self.state.protocol.eeprom_write_interval
        if last is not None and time.monotonic() - last < wait:
            left = wait - (time.monotonic() - last)
            raise WriteForbiddenError(
                f"{point.key} is stored in EEPROM: next write allowed in {left:.0f} s"
            )

    async def _refresh(self, reads: list[Read]) -> None:
        fresh: set[Address] = set()
        for read in reads:
            if not await self.link.read_block(read, Priority.WRITE, fresh):
                raise MissingDataError(
                    f"{self.link.device.id}: cannot read {read.table.value} {read.address} "
                    "that the write depends on"
                )

    async def _read_back(self, point: Point, fresh: set[Address]) -> Value:
        """Read ``point`` (and its sign) unless this command's read backs read it already;
        every entity sharing its registers is decoded from that read."""
        targets = [point] + ([point.sign] if point.sign is not None else [])
        await self._read_back_keys(targets, fresh)
        return self.state.values.get(point.key)

    async def _read_back_keys(self, targets: list[Point], fresh: set[Address]) -> None:
        """Read ``targets`` unless this command read them already (a value read apart from
        its exponent with the exponent before and after it: bridge/modbus/bracket_read.py)."""
        plan = self.state.plan_for(targets)
        since = await read_before(self.state, self.link, plan.bracketed, Priority.WRITE, fresh)
        for read in plan.reads:
            if not {(read.table, a) for a in read.span} <= fresh:
                await self.link.read_block(read, Priority.WRITE, fresh)
        await read_after(
            self.state, self.link, plan.bracketed, since, priority=Priority.WRITE, fresh=fresh
        )
        self._decode(self.state.sharing(p.key for p in targets), fresh, since)

    def _decode(self, keys: Iterable[str], fresh: set[Address], since: int | None = None) -> None:
        """Decode what was read or acknowledged fresh (a bracketed value: read after
        ``since``); pass on what changed."""
        changed = self.state.decode_fresh(keys, fresh, since)
        if changed:
            self.on_change(changed)


def _check_conditions_alone(points: list[Point]) -> None:
    """A key with ``requires`` goes in a command of its own: its conditions are checked
    against the device as read before the command, which the command's other keys may
    change (a mode written with the start it conditions)."""
    if len(points) < 2:
        return
    refused: dict[str, ValueRejectedError] = {
        p.key: WriteForbiddenError(
            f"{p.key} has conditions ({', '.join(p.entity.requires)}) checked against the "
            "device as read before the command: send it in a command of its own"
        )
        for p in points
        if p.entity.requires
    }
    if refused:
        raise CommandRejectedError(refused, [p.key for p in points])


def _word(value: object) -> str:
    """A value as a refusal names it: on/off for booleans."""
    if isinstance(value, bool):
        return "on" if value else "off"
    return str(value)


def _as_value(value: object) -> Value:
    return value if isinstance(value, bool | int | float | str) else None


def _written(point: Point) -> Address:
    """The register or coil a write of ``point`` goes to (the key of its write spacing)."""
    space = Table.COIL if point.table is Table.COIL else Table.HOLDING
    return (space, point.write_address)
