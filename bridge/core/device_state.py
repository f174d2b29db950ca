"""What one device knows, apart from how it is talked to (bridge/modbus/device_link.py). Pure.

Its register image (every address as last read or written), its decoded values, the
refusals it taught (bridge/core/refusal_memory.py), the registers per read it showed it
takes, and the read limits and poll plans that follow from them (one plan per set of
intervals due together, bridge/core/schedule.py; planned once, planned again when a
refusal is learnt, answered again or re-checked). The guard of its dangerous bits
(bridge/core/guard.py) is here too: this mapping's, joined with the mappings the device
had before.

The modbus edge feeds it what the bus answered (``keep``, ``store``) and asks it what to
read (``plan``, ``reads_for``). Nothing here waits, sends, logs or notifies: a method whose
change the caller must act on returns it (``decode_fresh``: the keys whose value changed;
``keep``: the addresses answered again; ``avoid``: those refused for the first time).

Its counters (bridge/core/counters.py) stand between what is read and ``values``: a
counter's lower reading is held back (its value stays), a rollover continued, a confirmed
reset taken; ``decode_fresh`` keeps each reading that was not a plain rise in
``counter_news`` for the caller to count and log (``take_counter_news``), and
``seed_counters`` takes the values published before a restart.

Not the published document (bridge/core/state.py): this is what it is built from.
"""

from __future__ import annotations

from collections import ChainMap
from collections.abc import Iterable
from datetime import datetime

from bridge.core.bracket import Bracket, Observation, Verdict, needs_after, verdict
from bridge.core.codec import Image, Value, decimals_of, decode
from bridge.core.counters import Kind, Reading, counters_of
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.mapping import Mapping, Point, printed_address
from bridge.core.planner import (
    Address,
    Plan,
    ReadLimits,
    addresses_of,
    join_reads,
    limits_for,
    plan_reads,
)
from bridge.core.protocol import Protocol
from bridge.core.refusal_memory import RefusalMemory
from bridge.core.request import Read, Write
from bridge.core.schedule import PollRule, PollSpec
from bridge.core.state import published
from bridge.core.timing import LinkTiming
from bridge.core.write_plan import stored
from bridge.errors import MissingDataError

NO_LIMIT = 0x10000  # more registers than any read asks for
_KEPT = 64  # key sets whose sharers are kept (due intervals' keys, a command's keys)
_READINGS = 8  # readings of an exponent register kept (a pass reads it at most three times)
DEFAULT_RULE = PollRule()


class DeviceState:
    """One device's image, values, learnt refusals and read limits, and its poll plans."""

    def __init__(
        self,
        mapping: Mapping,
        options: dict[str, str],
        *,
        timing: LinkTiming,
        recheck: float,
        guard: Guard = UNGUARDED,
        confirm: dict[str, int] | None = None,
        poll: PollRule = DEFAULT_RULE,
    ) -> None:
        """``mapping`` with the device's protocol overrides applied; ``options`` its option
        values; ``recheck``: seconds a learnt refusal is trusted; ``guard``: what the
        mappings the device had before guarded; ``confirm``: lower readings in a row that
        confirm a counter's reset, by key (else the entity's, else counters.CONFIRM);
        ``poll``: the device's intervals, which resolve each entity's (``intervals``)."""
        self.mapping = mapping
        self.protocol: Protocol = mapping.protocol
        self.points: dict[str, Point] = mapping.points(options)
        chosen = tuple(sorted((mapping.default_options() | options).items()))
        own = mapping.memo(("guard", chosen), lambda: Guard.of(self.points.values()))
        self.guard = guard | own
        self.timing = timing
        self.image: dict[Address, int] = {}
        self.read_at: dict[Address, float] = {}  # when each word of the image was read or written
        self.request_of: dict[Address, int] = {}  # the request each word read came in (numbered)
        self.requests = 0
        self.values: dict[str, Value] = {}
        self.counters = counters_of(self.points.values(), confirm)
        self.counter_news: list[tuple[str, Reading]] = []  # held, wrapped, reset readings
        self.last_reset: dict[str, str] = {}  # a total counter's last confirmed reset
        self.refusals = RefusalMemory(recheck)
        self.max_read: int | None = None  # learnt: fewer registers per read than mapped
        self.rule = poll
        self.intervals = poll.intervals({k: p.entity for k, p in self.points.items()})
        self._plans: dict[frozenset[float], tuple[Plan, tuple[str, ...]]] = {}
        # the exponent registers' readings (request number, word), for bracketed values
        self.readings: dict[Address, list[Observation]] = {
            cell: []
            for p in self.points.values()
            if p.scale_source is not None
            for cell in p.scale_source.addresses
        }
        self.scaled_values_held = 0  # bracketed values whose exponent changed as they were read
        self.published = frozenset(published(self.points))  # keys whose values go out
        self._limits: ReadLimits | None = None
        self._readers: dict[Address, tuple[str, ...]] | None = None
        self._sharing: dict[tuple[str, ...], tuple[str, ...]] = {}

    # --- plans -------------------------------------------------------------------------

    @property
    def refused(self) -> frozenset[Address]:
        """The addresses learnt as refused that plans avoid now (until their re-check)."""
        return self.refusals.refused

    def limits(self) -> ReadLimits:
        """The read limits as known now (kept until a refusal changes them)."""
        if self._limits is None:
            self._limits = limits_for(
                self.mapping,
                max_registers=self.max_read,
                refused=self.refusals.refused,
                timing=self.timing,
            )
        return self._limits

    def plan(self, due: Iterable[PollSpec]) -> tuple[Read, ...]:
        """The reads of the entities whose interval is due (``fast``/``slow``/``once`` or
        seconds), planned as one set: entities due together share reads."""
        return self._planned(due)[0].reads

    def brackets(self, due: Iterable[PollSpec]) -> tuple[Bracket, ...]:
        """The values of ``plan(due)`` read apart from their exponent (bridge/core/
        bracket.py): their exponent is read before and after them."""
        return self._planned(due)[0].bracketed

    def keys_of(self, due: Iterable[PollSpec]) -> tuple[str, ...]:
        """The keys a pass over ``plan(due)`` decodes, in mapping order: those due, and
        those not due whose registers all lie in its reads (read along for free in a hole
        the planner read through: their value is as fresh as the others')."""
        return self._planned(due)[1]

    def _planned(self, due: Iterable[PollSpec]) -> tuple[Plan, tuple[str, ...]]:
        chosen = frozenset(self.rule.seconds(spec) for spec in due)
        if chosen not in self._plans:
            members = [p for k, p in self.points.items() if self.intervals[k] in chosen]
            plan = plan_reads(members, self.limits())
            covered = {(r.table, a) for r in plan.reads for a in r.span}
            keys = tuple(
                k
                for k, p in self.points.items()
                if self.intervals[k] in chosen or (p.entity.readable and p.footprint <= covered)
            )
            self._plans[chosen] = (plan, keys)
        return self._plans[chosen]

    def readers_of(self, cells: Iterable[Address]) -> tuple[str, ...]:
        """The readable keys with a register (or bit) among ``cells``, in mapping order:
        every entity a read or write of those registers concerns (a raw word, its switch,
        its select, its bits)."""
        if self._readers is None:
            readers: dict[Address, list[str]] = {}
            for key, point in self.points.items():
                if point.entity.readable:
                    for address in point.addresses:
                        readers.setdefault(address, []).append(key)
            self._readers = {address: tuple(keys) for address, keys in readers.items()}
        found = {key for cell in cells for key in self._readers.get(cell, ())}
        return tuple(key for key in self.points if key in found)

    def sharing(self, keys: Iterable[str]) -> tuple[str, ...]:
        """``keys`` and every readable key that shares a register with one of them (a
        poll class's keys are asked each cycle: kept)."""
        chosen = tuple(keys)
        found = self._sharing.get(chosen)
        if found is None:
            cells = {a for k in chosen for a in self.points[k].addresses}
            found = tuple(dict.fromkeys([*chosen, *self.readers_of(cells)]))
            if len(self._sharing) < _KEPT:
                self._sharing[chosen] = found
        return found

    def reads_for(self, points: Iterable[Point]) -> tuple[Read, ...]:
        """The reads of these points (not kept: a read on request, a read back)."""
        return self.plan_for(points).reads

    def plan_for(self, points: Iterable[Point]) -> Plan:
        """The plan of these points, with its brackets (not kept)."""
        return plan_reads(list(points), self.limits())

    def forget_plans(self) -> None:
        self._plans.clear()
        self._limits = None

    # --- what the bus answered -----------------------------------------------------------

    def keep(self, read: Read, values: tuple[int, ...], fresh: set[Address]) -> frozenset[Address]:
        """Put a read's answer in the image (and its addresses in ``fresh``); return the
        addresses it had refused before (now readable: the plans are made again)."""
        self.requests += 1
        for address, value in zip(read.span, values, strict=True):
            cell = (read.table, address)
            self.image[cell] = value
            self.request_of[cell] = self.requests
            fresh.add(cell)
            if cell in self.readings:  # an exponent: its last readings, for bracketed values
                seen = self.readings[cell][1 - _READINGS :]
                self.readings[cell] = [*seen, (self.requests, value)]
        back = self.refusals.answer(addresses_of(read))
        if back:
            self.forget_plans()
        return back

    def store(self, write: Write) -> None:
        """What the device acknowledged writing goes in the image (words no request read:
        a ``scale_by`` value waits for its read back, with its exponent)."""
        cells = stored(write)
        self.image.update(cells)
        for cell in cells:
            self.request_of.pop(cell, None)

    def stamp(self, cells: Iterable[Address], now: float) -> None:
        """The words of ``cells`` in the image are as the device held them at ``now``
        (monotonic): read or acknowledged written then."""
        for cell in cells:
            self.read_at[cell] = now

    def decode_fresh(
        self, keys: Iterable[str], fresh: set[Address], since: int | None = None
    ) -> frozenset[str]:
        """Decode the readable ``keys`` whose registers are all in ``fresh`` (refused ones
        become None); return the keys whose value changed. The others keep their value.
        A ``scale_by`` value needs its exponent's register fresh too, read in the same
        request, or read bracketed in the pass whose requests are numbered after ``since``
        (the exponent read the same before and after the value: ``_bracketed``): never with
        another moment's exponent."""
        changed: set[str] = set()
        refused = self.refusals.refused
        for key in keys:
            point = self.points[key]
            if not point.entity.readable:
                continue
            span = point.footprint
            image: Image = self.image
            if not span.isdisjoint(refused):
                value: Value = None
            elif span <= fresh:
                if point.scale_source is not None:
                    found = self._scaled_image(point, point.scale_source, since)
                    if found is None:
                        continue
                    image = found
                try:
                    value = decode(point, image)
                except MissingDataError:
                    value = None
            else:
                continue
            if key in self.counters:
                reading = self.counters[key].read(value)
                if reading.kind not in (Kind.FIRST, Kind.RISE):
                    self.counter_news.append((key, reading))
                if not reading.published:
                    continue  # held: the published value stays
                value = _counted(value, reading, decimals_of(point, image))
            if key not in self.values or self.values[key] != value:
                changed.add(key)
            self.values[key] = value
        return frozenset(changed)

    def _scaled_image(self, point: Point, source: Point, since: int | None) -> Image | None:
        """The image to decode a ``scale_by`` value with: its exponent (``source``, one
        register) as read in the request of its words, or, read apart (bracketed), as read
        before and after them in requests after ``since``, every reading the same; None
        when neither (a changed exponent is counted: ``scaled_values_held``)."""
        cell = (source.table, source.address)
        requests = {self.request_of.get(c) for c in point.addresses}
        if None in requests:
            return None
        readings = self.readings.get(cell, [])
        if len(requests) == 1:  # its exponent in the same request (a later read may differ)
            (number,) = requests
            word = next((w for n, w in readings if n == number), None)
            if word is not None:
                return self._with(cell, word)
        if since is None:
            return None
        numbers = {n for n in requests if n is not None}
        bracket = [r for r in readings if r[0] > since]
        found = verdict(bracket, numbers)
        if found is Verdict.CHANGED:
            self.scaled_values_held += 1
        if found is not Verdict.SAME:
            return None
        return self._with(cell, next(w for n, w in reversed(bracket) if n < min(numbers)))

    def _with(self, cell: Address, word: int) -> Image:
        """The image with ``cell`` as ``word`` (the image itself when it holds it)."""
        if self.image.get(cell) == word:
            return self.image
        return ChainMap({cell: word}, self.image)

    def unconfirmed(self, brackets: Iterable[Bracket], since: int) -> tuple[Read, ...]:
        """The exponent reads still to send after a pass (requests after ``since``): those
        with no reading after the last word of a value they bracket that the pass read."""
        reads: list[Read] = []
        for bracket in brackets:
            cell = (bracket.exponent.table, bracket.exponent.address)
            cells = {c for k in bracket.keys for c in self.points[k].addresses}
            requests = {n for c in cells if (n := self.request_of.get(c, 0)) > since}
            readings = [r for r in self.readings.get(cell, ()) if r[0] > since]
            if requests and needs_after(readings, requests):
                reads.append(bracket.exponent)
        return join_reads(reads, self.limits())

    def exponents_before(self, brackets: Iterable[Bracket]) -> tuple[Read, ...]:
        """The exponent reads to send before a pass: those whose plan read follows a
        value's (joined where they lie side by side)."""
        return join_reads((b.exponent for b in brackets if b.before), self.limits())

    # --- counters ------------------------------------------------------------------------

    def take_counter_news(self) -> list[tuple[str, Reading]]:
        """The counter readings held, wrapped or reset since the last call."""
        news, self.counter_news = self.counter_news, []
        return news

    def seed_counters(self, document: dict[str, object]) -> frozenset[str]:
        """Take the counters' values from the device document published before a restart
        (and the total counters' ``last_reset``); return the keys whose value it changed."""
        changed: set[str] = set()
        for key, counter in self.counters.items():
            value = document.get(key)
            if counter.seed(value) and self.values.get(key) != value:  # type: ignore[arg-type]
                self.values[key] = value  # type: ignore[assignment]
                changed.add(key)
        resets = document.get("last_reset")  # a total counter's, kept as it was
        if isinstance(resets, dict):
            for key, when in resets.items():
                if key in self.counters and _is_time(when):
                    self.last_reset.setdefault(key, when)
        return frozenset(changed)

    def carry_counters(self, earlier: DeviceState) -> frozenset[str]:
        """Take the counters' published values from the state a mapping reload replaces
        (a counter the new mapping still has goes on from there)."""
        document: dict[str, object] = {k: c.published for k, c in earlier.counters.items()}
        return self.seed_counters(document | {"last_reset": dict(earlier.last_reset)})

    # --- what the device refused ---------------------------------------------------------

    def avoid(self, addresses: Iterable[Address], now: float) -> frozenset[Address]:
        """Plan around these refused addresses until their re-check; return those refused
        for the first time."""
        avoided = self.refusals.refused
        found = frozenset(addresses)
        first = self.refusals.learn(found, now)
        if found - avoided:
            self.forget_plans()
        return first

    def limit_reads(self, count: int) -> bool:
        """Read no more than ``count`` registers at once (the device showed it takes no
        more); True if that is fewer than before."""
        if count >= (self.max_read or NO_LIMIT):
            return False
        self.max_read = count
        self.forget_plans()
        return True

    def recheck(self, now: float) -> frozenset[Address]:
        """Forget the refusals due for a re-check (the next plan reads them); return them."""
        due = self.refusals.expire(now)
        if due:
            self.forget_plans()
        return due

    def shown(self, addresses: Iterable[Address]) -> str:
        """``holding 0x00A0 (wire 159)``: the address as the manual prints it, and as sent."""
        points = self.points.values()
        return ", ".join(
            f"{table.value} {printed_address(points, table, wire, self.protocol)} (wire {wire})"
            for table, wire in sorted(addresses)
        )


def _counted(read: Value, reading: Reading, decimals: int | None) -> Value:
    """What a counter publishes: the value as decoded on a plain rise, else the counter's
    value (a rollover's continuation, a reset) in the decoded value's type and decimals
    (``decimals``: the point's, a ``scale_by`` value's at the exponent it was read with)."""
    if reading.kind in (Kind.FIRST, Kind.RISE) or reading.value is None:
        return read
    if isinstance(read, int) and float(reading.value).is_integer():
        return int(reading.value)
    return reading.value if decimals is None else round(reading.value, decimals)


def _is_time(text: object) -> bool:
    """An ISO 8601 time with its offset (what a last_reset is), short enough to be one."""
    if not isinstance(text, str) or len(text) > 40:
        return False
    try:
        return datetime.fromisoformat(text).tzinfo is not None
    except ValueError:
        return False
