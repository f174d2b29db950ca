"""The poll planner: the reads that fetch a set of points in the least bus time. Pure.

Words: a *point* is an entity resolved to wire addresses; an *atom* is what a read carries
whole: the points that share registers, merged (bit fields of one word, a word and its
bits, identical spans); a *block* is one read: a contiguous run of atoms of one table and
the holes between them.

A block never holds an unreadable address (reserved in the mapping, or refused by the
device and learnt), never an address no entity defines when the device does not allow
readable gaps, never crosses a segment boundary, never exceeds the segment's (else the
device's) max count. An atom is never split across reads, so a u32 is never torn, UNLESS
it is longer than that max (Nastec: one register per read): it is then cut into single
registers that group like any other atoms, which reads it in limit-sized chunks from its
first register (the 6-register Nastec MAC address takes six reads). A 64-bit number is
never cut (no tear check joins four words): where reads are shorter (a limit learnt from
the device) it is left out, named in ``Plan.unplannable``.

A ``scale_by`` number is read with its exponent register wherever one read can hold both:
its atom runs from the first to the last register of the two (``Point.extent``), so the
value is scaled by the exponent of its own request. Where no read can (the two farther
apart than the max count, a segment boundary, an unreadable register or, without
readable gaps, an undefined one between them: SunSpec model 129's third and fourth
curves, the 7xx DER curves), it is read *bracketed* (bridge/core/bracket.py): its atom is
its own registers, its exponent is planned as a point of its own (due or not), and
``Plan.bracketed`` holds one ``Bracket`` per exponent with every far value it scales. A
pass reads the exponent before the values and again after them (the plan's own read of
it serves the side it lies on; the other gets a dedicated one-register read, shared by
every value of that exponent, and joined with its neighbours' (``join_reads``: SunSpec's
factors lie side by side): ``Plan.extra``, counted by ``cost_of``), and the device
state decodes a value only when every reading of its exponent from before to after is
the same (bridge/core/device_state.py); else it keeps its last value that pass, counted
in health as ``scaled_values_held``. Where atoms of values near their exponents overlap
into one longer than a read, the value farthest from its exponent is bracketed, until
they fit. Only a value whose exponent register cannot be read at all is left out.

``plan_reads`` is exact: dynamic programming over the sorted atoms of each table (blocks
are contiguous runs of atoms; reading an atom twice never pays). A hole is read through
only where one block costs no more time than two (``LinkTiming.read_cost``). Ties in time
go to fewer reads, then to the longer first block. A point with no readable way (one of its
own registers unreadable, or its atom across a segment boundary) is left out and named in
``Plan.unplannable``; ``plan_reads`` does not raise.

Across poll intervals (bridge/core/schedule.py) the planner is given the points due now:
every interval due in one pass is planned as one set, so entities due together share
reads. A point not due is never a reason to read: it is a hole like an unmapped register,
read through only under the rule above (one block costs no more than two reads, and the
device allows the hole). Such a point lying in a hole that was read comes along for free,
and it is decoded too (``DeviceState.keys_of``): its value is as fresh as its neighbours'.

When a device refuses a merged block (illegal address or quantity), the engine bisects:

    def locate(block):                       # the device refused block
        parts = split_read(block, points, halves=True)  # trimmed to their atoms
        if not parts:                        # one atom: it is refused itself
            remember(addresses_of(block))
            return
        refused = [part for part in parts if device refuses part]
        for part in refused:
            locate(part)
        if not refused:                      # both halves pass: the hole between them
            remember(unread(block, parts))   # (empty: the quantity; lower max_registers)

and then plans again with ``limits_for(mapping, refused=remembered)``.
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Iterable, Iterator, Sequence
from dataclasses import dataclass

from bridge.core.address import Addressing, to_wire
from bridge.core.bracket import Bracket, brackets_of
from bridge.core.entity import Table
from bridge.core.mapping import Mapping, Point
from bridge.core.protocol import Reserved
from bridge.core.request import Read
from bridge.core.timing import LinkTiming

DEFAULT_TIMING = LinkTiming()
MAX_REGISTERS = 125  # FC03/04 quantity limit of the Modbus specification
MAX_BITS = 2000  # FC01/02
_TIE = 1e-9  # seconds: costs closer than this are equal (float noise)

Address = tuple[Table, int]


@dataclass(frozen=True, slots=True)
class WireSegment:
    """Inclusive wire range ``first..last`` of ``table`` a read may not cross, with its own
    max count (registers, or bits on a bit table; the tighter of it and the device's
    applies) or None for the device's."""

    table: Table
    first: int
    last: int
    max_count: int | None = None


@dataclass(frozen=True, slots=True)
class ReadLimits:
    """What a device allows in one read, and what the planner optimises for."""

    max_registers: int = MAX_REGISTERS
    max_bits: int = MAX_BITS
    readable_gaps: bool = True
    unreadable: frozenset[Address] = frozenset()
    defined: frozenset[Address] = frozenset()
    segments: tuple[WireSegment, ...] = ()
    timing: LinkTiming = DEFAULT_TIMING

    def max_count(self, table: Table) -> int:
        return self.max_bits if table.is_bits else self.max_registers


@dataclass(frozen=True, slots=True)
class Plan:
    """Reads sorted by (table, address), the keys of points no read can fetch, and the
    ``scale_by`` values read apart from their exponent (bridge/core/bracket.py)."""

    reads: tuple[Read, ...]
    unplannable: tuple[str, ...] = ()
    bracketed: tuple[Bracket, ...] = ()
    extra: tuple[Read, ...] = ()  # the dedicated exponent reads the brackets add to a pass


def limits_for(
    mapping: Mapping,
    *,
    max_registers: int | None = None,
    max_bits: int | None = None,
    refused: frozenset[Address] = frozenset(),
    timing: LinkTiming = DEFAULT_TIMING,
) -> ReadLimits:
    """The read limits of a device: the mapping's protocol rules in wire addresses, the
    device config's max counts (when given) and the addresses the device was seen to refuse.

    ``defined`` holds the registers of every readable entity whatever the options (every
    ``when`` of a valid mapping can be met, and variants do not move addresses).
    """
    protocol = mapping.protocol
    reserved, defined, segments = mapping.memo("wire limits", lambda: _wire_limits(mapping))
    return ReadLimits(
        max_registers=_checked("max_registers", max_registers, protocol.max_read_registers),
        max_bits=_checked("max_bits", max_bits, protocol.max_read_bits),
        readable_gaps=protocol.readable_gaps,
        unreadable=reserved | refused,
        defined=defined,
        segments=segments,
        timing=timing,
    )


def _wire_limits(
    mapping: Mapping,
) -> tuple[frozenset[Address], frozenset[Address], tuple[WireSegment, ...]]:
    """The reserved and the defined registers and the segments of a mapping, in wire
    addresses (the same for every device of the model)."""
    protocol = mapping.protocol
    rule = protocol.addressing
    reserved = frozenset(
        itertools.chain.from_iterable(
            itertools.product((r.table,), range(to_wire(r.start, rule), _end(r, rule) + 1))
            for r in protocol.reserved
        )
    )
    defined = frozenset(
        (e.table, to_wire(e.address, rule) + offset)
        for e in mapping.entities.values()
        if e.readable
        for offset in range(e.register_count)
    )
    segments = tuple(
        WireSegment(s.table, to_wire(s.start, rule), to_wire(s.end, rule), s.max_read_registers)
        for s in protocol.segments
    )
    return reserved, defined, tuple(sorted(segments, key=lambda s: (s.table, s.first)))


def _end(reserved: Reserved, rule: Addressing) -> int:
    return to_wire(reserved.start if reserved.end is None else reserved.end, rule)


def _checked(name: str, value: int | None, default: int) -> int:
    if value is None:
        return default
    top = MAX_BITS if name == "max_bits" else MAX_REGISTERS
    if not 1 <= value <= top:
        raise ValueError(f"{name} must be within 1..{top}, not {value}")
    return value


# --- planning ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Unit:
    """A run of registers the DP places whole: an atom, or one register of an atom too long
    for any read. ``region`` is the index of the segment holding it, -1 outside all."""

    start: int
    stop: int
    region: int
    limit: int


def plan_reads(points: Iterable[Point], limits: ReadLimits) -> Plan:
    """The reads of least bus time that fetch every readable point (see the module doc)."""
    readable = [p for p in points if p.entity.readable]
    defined = limits.defined | {(p.table, a) for p in readable for a in p.span}
    reads: list[Read] = []
    unplannable: set[str] = set()
    brackets: list[Bracket] = []
    for table in sorted({p.table for p in readable}):
        mine = [p for p in readable if p.table is table]
        units, lost, far = _units(table, mine, limits, defined)
        unplannable |= lost
        planned = _plan_table(table, units, limits, defined)
        reads += planned
        brackets += brackets_of(_far_values(mine, far), planned)
    before = join_reads([b.exponent for b in brackets if b.before], limits)
    after = join_reads([b.exponent for b in brackets if b.after], limits)
    return Plan(tuple(reads), tuple(sorted(unplannable)), tuple(brackets), before + after)


def join_reads(reads: Iterable[Read], limits: ReadLimits) -> tuple[Read, ...]:
    """Exponent reads of registers next to each other as one read (SunSpec's factors lie
    side by side), within the max count and a segment; sorted."""
    joined: list[Read] = []
    for read in sorted(set(reads), key=lambda r: (r.table, r.address)):
        last = joined[-1] if joined else None
        if last is not None and last.table is read.table and last.span.stop == read.address:
            both = Read(read.table, last.address, last.count + read.count)
            place = _region(both.table, both.address, both.span.stop, limits)
            if place is not None and both.count <= place[1]:
                joined[-1] = both
                continue
        joined.append(read)
    return tuple(joined)


def _far_values(points: Sequence[Point], far: set[str]) -> Iterator[tuple[str, Table, range, int]]:
    for p in points:
        if p.key in far and p.scale_source is not None:
            yield p.key, p.table, p.span, p.scale_source.address


def _units(
    table: Table, points: Sequence[Point], limits: ReadLimits, defined: frozenset[Address]
) -> tuple[list[_Unit], set[str], set[str]]:
    """The DP units of one table's points, the keys of points no read can fetch, and the
    keys of ``scale_by`` values read apart from their exponent (bracketed)."""
    lost = {p.key for p in points if any((table, a) in limits.unreadable for a in p.span)}
    lost |= {p.key for p in points if _wide(p) and _too_long(table, p, limits)}
    far = {p.key for p in points if not _scaled_readable(table, p, limits, defined)}
    lost |= {
        p.key
        for p in points
        if p.key in far
        and p.scale_source is not None
        and not _exponent_readable(table, p.scale_source, limits)
    }
    far -= lost
    while True:
        units: list[_Unit] = []
        cut: set[str] = set()
        kept = [p for p in points if p.key not in lost]
        for start, stop, keys in _atoms([*kept, *_exponents(kept, far)], far):
            place = _region(table, start, stop, limits)
            if place is None:
                cut.update(keys)
                continue
            region, limit = place
            if stop - start <= limit:
                units.append(_Unit(start, stop, region, limit))
                continue
            whole = [p for p in points if p.key in keys and p.scale_source is not None]
            whole = [p for p in whole if p.key not in far]
            if whole:  # a value too far to be read with its exponent: read bracketed
                far.add(max(whole, key=lambda p: (len(p.extent), p.key)).key)
                break
            units += [_Unit(a, a + 1, region, limit) for a in range(start, stop)]
        else:
            return units, lost | cut, far - cut


def _exponents(points: Sequence[Point], far: set[str]) -> list[Point]:
    """The exponents of the bracketed values: read by the plan, due or not."""
    found = {p.scale_source.key: p.scale_source for p in points if p.key in far and p.scale_source}
    own = {p.key for p in points}
    return [p for k, p in sorted(found.items()) if k not in own]


def _exponent_readable(table: Table, source: Point, limits: ReadLimits) -> bool:
    """A bracketed value's exponent register can be read on its own (one register: it
    fits any read and crosses no segment boundary)."""
    return all((table, a) not in limits.unreadable for a in source.span)


def _scaled_readable(
    table: Table, point: Point, limits: ReadLimits, defined: frozenset[Address]
) -> bool:
    """A ``scale_by`` point: one request may read it with its exponent (every register
    between them readable, inside one segment and the max count)."""
    if point.scale_source is None:
        return True
    extent = point.extent
    if any((table, a) in limits.unreadable for a in extent):
        return False
    if not limits.readable_gaps and any((table, a) not in defined for a in extent):
        return False
    place = _region(table, extent.start, extent.stop, limits)
    return place is not None and len(extent) <= place[1]


def _wide(point: Point) -> bool:
    """A 64-bit number: read whole or not at all (no tear check joins four words)."""
    return point.count == 4 and point.entity.kind == "number"


def _too_long(table: Table, point: Point, limits: ReadLimits) -> bool:
    place = _region(table, point.address, point.address + point.count, limits)
    return place is not None and place[1] < point.count


def _atoms(
    points: Iterable[Point], far: Collection[str] = ()
) -> list[tuple[int, int, tuple[str, ...]]]:
    """Points of one table merged where they share a register: (start, stop, keys). A
    ``scale_by`` point spans its exponent's register too (``Point.extent``): read whole;
    unless it is read bracketed (``far``): its own registers then."""

    def reach(p: Point) -> range:
        return p.span if p.key in far else p.extent

    atoms: list[tuple[int, int, tuple[str, ...]]] = []
    for p in sorted(points, key=lambda p: (reach(p).start, len(reach(p)), p.key)):
        start, stop = reach(p).start, reach(p).stop
        if atoms and start < atoms[-1][1]:
            first, last, keys = atoms[-1]
            atoms[-1] = (first, max(last, stop), (*keys, p.key))
        else:
            atoms.append((start, stop, (p.key,)))
    return atoms


def _region(table: Table, start: int, stop: int, limits: ReadLimits) -> tuple[int, int] | None:
    """(segment index or -1, max count) of the range start..stop-1; None if it crosses a
    segment boundary."""
    regions = {_segment_of(table, address, limits) for address in range(start, stop)}
    if len(regions) != 1:
        return None
    region = regions.pop()
    device = limits.max_count(table)
    if region < 0:
        return region, device
    return region, min(device, limits.segments[region].max_count or device)


def _segment_of(table: Table, address: int, limits: ReadLimits) -> int:
    """Index of the (first) segment holding an address, -1 for none."""
    for index, segment in enumerate(limits.segments):
        if segment.table is table and segment.first <= address <= segment.last:
            return index
    return -1


def _plan_table(
    table: Table, units: Sequence[_Unit], limits: ReadLimits, defined: frozenset[Address]
) -> list[Read]:
    """Exact DP from the last unit back: best[i] = cheapest cover of units[i:]."""
    count = len(units)
    cost = [0.0] * (count + 1)
    reads = [0] * (count + 1)
    last = [0] * count
    for i in reversed(range(count)):
        for j in _block_ends(table, units, i, limits, defined):
            block = Read(table, units[i].start, units[j].stop - units[i].start)
            candidate = limits.timing.read_cost(block) + cost[j + 1]
            better = candidate < cost[i] - _TIE or (
                candidate <= cost[i] + _TIE and reads[j + 1] + 1 <= reads[i]
            )
            if j == i or better:
                cost[i], reads[i], last[i] = candidate, reads[j + 1] + 1, j
    plan: list[Read] = []
    i = 0
    while i < count:
        j = last[i]
        plan.append(Read(table, units[i].start, units[j].stop - units[i].start))
        i = j + 1
    return plan


def _block_ends(
    table: Table, units: Sequence[_Unit], i: int, limits: ReadLimits, defined: frozenset[Address]
) -> Iterator[int]:
    """Every j such that units[i..j] may form one block. Each rule only gets harder as the
    block grows, so the first failure ends the search."""
    first = units[i]
    yield i
    for j in range(i + 1, len(units)):
        unit = units[j]
        if unit.region != first.region or unit.stop - first.start > first.limit:
            return
        for address in range(units[j - 1].stop, unit.start):
            if not _hole_readable(table, address, limits, defined, first.region):
                return
        yield j


def _hole_readable(
    table: Table, address: int, limits: ReadLimits, defined: frozenset[Address], region: int
) -> bool:
    """May a block of ``region`` read ``address`` without needing it?"""
    if (table, address) in limits.unreadable:
        return False
    if not limits.readable_gaps and (table, address) not in defined:
        return False
    return _segment_of(table, address, limits) == region


# --- figures and baselines ----------------------------------------------------------------


def cost_of(plan: Plan | Iterable[Read], timing: LinkTiming) -> float:
    """Seconds of bus time for one pass over the reads (a plan's: its brackets' dedicated
    exponent reads too)."""
    reads = (*plan.reads, *plan.extra) if isinstance(plan, Plan) else plan
    return sum(timing.read_cost(read) for read in reads)


def one_read_per_entity(
    points: Iterable[Point], limits: ReadLimits | None = None
) -> tuple[Read, ...]:
    """The baseline: one read per readable point, as Home Assistant's integration polls.

    With ``limits``, points no read can fetch are left out and a point longer than its max
    count is read in chunks (what a user would have to configure); without, every point is
    read whole.
    """
    reads: list[Read] = []
    for point in points:
        if not point.entity.readable:
            continue
        step = point.count
        if limits is not None:
            place = _region(point.table, point.address, point.address + point.count, limits)
            if place is None or any((point.table, a) in limits.unreadable for a in point.span):
                continue
            step = place[1]
        stop = point.address + point.count
        reads += [
            Read(point.table, a, min(step, stop - a)) for a in range(point.address, stop, step)
        ]
    return tuple(sorted(reads, key=lambda r: (r.table, r.address, r.count)))


# --- refusals -------------------------------------------------------------------------------


def split_read(read: Read, points: Iterable[Point], *, halves: bool = False) -> tuple[Read, ...]:
    """Smaller reads to try after a device refused ``read``; ``()`` when it holds one atom
    (or part of one) and there is nothing smaller to try.

    By default one read per atom inside (n reads for n atoms). ``halves=True``: the atoms
    in two halves, for bisection (about 2·log2(n) reads find one refused atom or hole).
    Every part is trimmed to its atoms, so what lies between parts is holes.
    """
    end = read.address + read.count
    inside = [
        p
        for p in points
        if p.entity.readable
        and p.table is read.table
        and p.address < end
        and read.address < p.address + p.count
    ]
    # a value whose exponent lies outside the read was read bracketed: its own registers
    apart = {p.key for p in inside if p.extent.start < read.address or p.extent.stop > end}
    atoms = [(max(a, read.address), min(b, end)) for a, b, _ in _atoms(inside, apart)]
    if len(atoms) <= 1:
        return ()
    if halves:
        middle = len(atoms) // 2
        atoms = [(atoms[0][0], atoms[middle - 1][1]), (atoms[middle][0], atoms[-1][1])]
    return tuple(Read(read.table, start, stop - start) for start, stop in atoms)


def holes(read: Read, points: Iterable[Point]) -> frozenset[Address]:
    """The addresses of ``read`` that no readable point needs."""
    needed = {
        a for p in points if p.entity.readable and p.table is read.table for _, a in p.footprint
    }
    return frozenset((read.table, a) for a in read.span if a not in needed)


def unread(read: Read, parts: Iterable[Read]) -> frozenset[Address]:
    """The addresses of ``read`` no part covers: the holes to blame when the device refused
    ``read`` but accepted every part (empty: it refused the quantity)."""
    covered = {a for part in parts for a in part.span}
    return frozenset((read.table, a) for a in read.span if a not in covered)


def addresses_of(read: Read) -> frozenset[Address]:
    """Every address a read covers: what to remember when the device refuses it whole."""
    return frozenset((read.table, a) for a in read.span)
