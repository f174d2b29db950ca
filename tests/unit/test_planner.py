"""Poll planner and wire-time model: tables, invariants, exact plans, brute-force optimality.

The reference helpers below (``_Reference``) restate the planning rules address by address,
without the planner's atoms or DP, so the invariants and the brute force check the planner
against an independent reading of the rules.
"""

from __future__ import annotations

import bisect
import functools
import itertools
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import replace
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core.entity import Entity, PollClass, Table
from bridge.core.mapping import Mapping, Point, builtin_mapping_path, load_mapping
from bridge.core.planner import (
    Plan,
    ReadLimits,
    WireSegment,
    addresses_of,
    cost_of,
    holes,
    limits_for,
    one_read_per_entity,
    plan_reads,
    split_read,
    unread,
)
from bridge.core.refusal import refusal_search, run_search
from bridge.core.request import Read, Write
from bridge.core.timing import LinkTiming

H, C, IN = Table.HOLDING, Table.COIL, Table.INPUT
RTU = LinkTiming()
CHAR = 10 / 9600
TIE = 1e-9

# --- building points ---------------------------------------------------------------------


@functools.cache
def _entity(table: Table, kind: str, access: str) -> Entity:
    fields: dict[str, Any] = {"name": "X", "address": 0, "table": table, "access": access}
    if kind.startswith("ascii"):
        fields |= {"type": "ascii", "count": int(kind[5:])}
    elif kind.startswith("bit"):
        fields |= {"bit": int(kind[3:])}
    elif kind != "u16" and not table.is_bits:
        fields["type"] = kind
    return Entity.model_validate(fields)


def pt(key: str, address: int, kind: str = "u16", table: Table = H, access: str = "r") -> Point:
    """A point of ``kind`` (u16, u32, f32, bitN, asciiN; bool on bit tables) at a wire address."""
    entity = _entity(table, "bool" if table.is_bits else kind, access)
    return Point(
        key=key, entity=entity, address=address, write_address=address, write_function=None
    )


def spans(plan: Plan | Iterable[Read]) -> list[tuple[str, int, int]]:
    reads = plan.reads if isinstance(plan, Plan) else plan
    return [(r.table.value, r.address, r.count) for r in reads]


@functools.cache
def shipped(name: str) -> Mapping:
    return load_mapping(builtin_mapping_path(name))


def head(read: Read, unit: int = 1) -> str:
    """The request frame without its CRC, as a manual prints it."""
    body = bytes([unit, read.function]) + read.address.to_bytes(2, "big")
    return (body + read.count.to_bytes(2, "big")).hex(" ").upper()


# --- the rules, restated address by address -------------------------------------------------


class _Reference:
    """What a valid plan is, written independently of the planner's atoms and DP."""

    def __init__(self, points: Iterable[Point], limits: ReadLimits) -> None:
        self.limits = limits
        self.points = [p for p in points if p.entity.readable]
        self.defined = limits.defined | {(p.table, a) for p in self.points for a in p.span}
        kept = [
            p for p in self.points if not any((p.table, a) in limits.unreadable for a in p.span)
        ]
        self.lost = {p.key for p in self.points} - {p.key for p in kept}
        self.atoms: list[tuple[Table, frozenset[int], frozenset[str]]] = []
        for table, group in self._components(kept):
            addresses = frozenset(a for p in group for a in p.span)
            keys = frozenset(p.key for p in group)
            if len({self.region(table, a) for a in addresses}) > 1:
                self.lost |= keys
            else:
                self.atoms.append((table, addresses, keys))
        self.atom_of = {(t, a): addresses for t, addresses, _ in self.atoms for a in addresses}

    @staticmethod
    def _components(points: list[Point]) -> Iterator[tuple[Table, list[Point]]]:
        """Groups of points that share a register, by merging owners address by address."""
        owner: dict[tuple[Table, int], list[Point]] = {}
        for p in points:
            group = [p]
            for other in {id(g): g for a in p.span if (g := owner.get((p.table, a)))}.values():
                group += other
            for q in group:
                for a in q.span:
                    owner[(q.table, a)] = group
        unique = {id(g): g for g in owner.values()}
        for group in unique.values():
            yield group[0].table, group

    @functools.cache  # noqa: B019 - one reference per test
    def region(self, table: Table, address: int) -> int:
        for index, s in enumerate(self.limits.segments):
            if s.table is table and s.first <= address <= s.last:
                return index
        return -1

    def limit(self, table: Table, region: int) -> int:
        device = self.limits.max_bits if table.is_bits else self.limits.max_registers
        if region < 0:
            return device
        return min(device, self.limits.segments[region].max_count or device)

    def oversize(self, table: Table, addresses: frozenset[int]) -> bool:
        return len(addresses) > self.limit(table, self.region(table, min(addresses)))

    def needed(self, table: Table) -> list[int]:
        return sorted({a for t, addresses, _ in self.atoms if t is table for a in addresses})

    def valid(self, read: Read) -> bool:
        return self.plain(read) and self.whole(read)

    def plain(self, read: Read) -> bool:
        """Region, length, unreadable and undefined rules: once broken, a longer read from
        the same start breaks them too."""
        table, span = read.table, read.span
        regions = {self.region(table, a) for a in span}
        if len(regions) != 1 or read.count > self.limit(table, regions.pop()):
            return False
        if any((table, a) in self.limits.unreadable for a in span):
            return False
        return self.limits.readable_gaps or all((table, a) in self.defined for a in span)

    def whole(self, read: Read) -> bool:
        """No atom cut, unless it is too long for any read."""
        span = set(read.span)
        touched = {self.atom_of[(read.table, a)] for a in span if (read.table, a) in self.atom_of}
        return all(
            addresses <= span or self.oversize(read.table, addresses) for addresses in touched
        )

    def tables(self) -> list[Table]:
        return sorted({t for t, _, _ in self.atoms})

    def all_plans(self, table: Table) -> Iterator[list[Read]]:
        """Every valid plan of one table: literal enumeration, no memo, small inputs only."""
        needed = self.needed(table)
        top = self.limit(table, -1)

        def extend(index: int) -> Iterator[list[Read]]:
            if index == len(needed):
                yield []
                return
            x = needed[index]
            for y in range(x + 1, x + top + 1):
                read = Read(table, x, y - x)
                if not self.plain(read):
                    break
                if y - 1 not in needed or not self.whole(read):
                    continue
                rest = bisect.bisect_left(needed, y)
                for tail in extend(rest):
                    yield [read, *tail]

        yield from extend(0)

    def least_cost(self, table: Table) -> float:
        """Shortest path over every candidate read of one table (exhaustive, memoised)."""
        needed = self.needed(table)
        wanted = set(needed)
        top = self.limit(table, -1)
        timing = self.limits.timing

        @functools.cache
        def best(index: int) -> float:
            if index == len(needed):
                return 0.0
            x, found = needed[index], math.inf
            for y in range(x + 1, min(x + top, needed[-1] + 1) + 1):
                read = Read(table, x, y - x)
                if not self.plain(read):
                    break
                if y - 1 in wanted and self.whole(read):
                    rest = bisect.bisect_left(needed, y)
                    found = min(found, timing.read_cost(read) + best(rest))
            return found

        return best(0)

    def check(self, plan: Plan) -> None:
        """Every invariant a plan must hold."""
        assert set(plan.unplannable) == self.lost
        assert list(plan.unplannable) == sorted(plan.unplannable)
        keys = [(r.table, r.address) for r in plan.reads]
        assert keys == sorted(keys)
        for read in plan.reads:
            assert read.count >= 1
            assert self.valid(read), read
            needed = self.needed(read.table)
            assert read.address in needed and read.address + read.count - 1 in needed
        for table in {r.table for r in plan.reads} | set(self.tables()):
            covered = [a for r in plan.reads if r.table is table for a in r.span]
            assert len(covered) == len(set(covered)), "two reads overlap"
            assert set(self.needed(table)) <= set(covered)
        for table, addresses, _ in self.atoms:
            holding = [r for r in plan.reads if r.table is table and set(r.span) & addresses]
            if not self.oversize(table, addresses):
                assert len(holding) == 1 and addresses <= set(holding[0].span)

    def one_block_per_atom(self) -> list[Read]:
        reads = []
        for table, addresses, _ in self.atoms:
            limit = self.limit(table, self.region(table, min(addresses)))
            low, high = min(addresses), max(addresses) + 1
            reads += [Read(table, a, min(limit, high - a)) for a in range(low, high, limit)]
        return reads


def check_optimal(points: Sequence[Point], limits: ReadLimits, *, enumerate_all: bool) -> Plan:
    plan = plan_reads(points, limits)
    ref = _Reference(points, limits)
    ref.check(plan)
    timing = limits.timing
    if enumerate_all:
        least = sum(
            min(cost_of(candidate, timing) for candidate in ref.all_plans(table))
            for table in ref.tables()
        )
    else:
        least = sum(ref.least_cost(table) for table in ref.tables())
    assert cost_of(plan, timing) == pytest.approx(least, abs=TIE)
    assert cost_of(plan, timing) <= cost_of(ref.one_block_per_atom(), timing) + TIE
    assert cost_of(plan, timing) <= cost_of(one_read_per_entity(points, limits), timing) + TIE
    return plan


# --- timing -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("timing", "read", "asked", "answered"),
    [
        (RTU, Read(H, 0, 10), 8, 25),
        (RTU, Read(H, 0, 1), 8, 7),
        (RTU, Read(C, 0, 79), 8, 15),
        (RTU, Read(C, 0, 8), 8, 6),
        (LinkTiming(mode="ascii"), Read(H, 0, 10), 17, 51),
        (LinkTiming(mode="ascii"), Read(Table.DISCRETE, 0, 9), 17, 15),
        (LinkTiming(mode="tcp"), Read(IN, 0, 10), 12, 29),
    ],
)
def test_frame_sizes(timing: LinkTiming, read: Read, asked: int, answered: int) -> None:
    assert timing.request_bytes(read) == asked
    assert timing.response_bytes(read) == answered
    assert timing.read_bytes(read) == asked + answered


def test_rtu_read_cost_is_characters_plus_two_silences_plus_turnaround() -> None:
    read = Read(H, 0, 10)
    assert RTU.char_time == pytest.approx(CHAR)
    assert RTU.silence == pytest.approx(3.5 * CHAR)
    assert RTU.read_cost(read) == pytest.approx((8 + 25 + 7) * CHAR)
    slow = replace(RTU, turnaround=0.02)
    assert slow.read_cost(read) == pytest.approx((8 + 25 + 7) * CHAR + 0.02)


def test_silence_is_fixed_above_19200_baud() -> None:
    assert LinkTiming(baudrate=19200).silence == pytest.approx(3.5 * 10 / 19200)
    assert LinkTiming(baudrate=38400).silence == 0.00175
    fast = LinkTiming(baudrate=115200)
    assert fast.read_cost(Read(H, 0, 1)) == pytest.approx(15 * 10 / 115200 + 2 * 0.00175)


def test_ascii_gap_is_one_character() -> None:
    link = LinkTiming(mode="ascii", baudrate=9600, bits_per_char=10)
    assert link.silence == pytest.approx(CHAR)
    assert link.read_cost(Read(H, 0, 10)) == pytest.approx((17 + 51 + 2) * CHAR)


def test_tcp_costs_one_round_trip_whatever_the_size() -> None:
    link = LinkTiming(mode="tcp", tcp_round_trip=0.004, turnaround=0.001)
    assert link.silence == 0.0
    assert link.read_cost(Read(H, 0, 1)) == link.read_cost(Read(H, 0, 125)) == pytest.approx(0.005)
    assert link.write_cost(Write(16, H, 0, (1, 2))) == pytest.approx(0.005)


@pytest.mark.parametrize(
    ("args", "bits"),
    [
        ((9600, "N", 1, 8), 10),
        ((9600, "E", 1, 8), 11),
        ((9600, "N", 2, 8), 11),
        ((9600, "O", 2, 8), 12),
        ((9600, "E", 1, 7), 10),
    ],
)
def test_for_serial_counts_start_data_parity_and_stop_bits(args: Any, bits: int) -> None:
    link = LinkTiming.for_serial(*args)
    assert (link.mode, link.baudrate, link.bits_per_char) == ("rtu", 9600, bits)
    assert LinkTiming.for_serial(19200, mode="ascii").mode == "ascii"


@pytest.mark.parametrize(
    ("write", "asked"),
    [
        (Write(5, C, 3, (0xFF00,)), 8),
        (Write(6, H, 0x1000, (5000,)), 8),
        (Write(15, C, 0, (1,) * 10), 11),
        (Write(16, H, 0x102A, (0, 0)), 13),
    ],
)
def test_write_sizes_and_cost(write: Write, asked: int) -> None:
    assert RTU.write_bytes(write) == asked + 8
    assert RTU.write_cost(write) == pytest.approx((asked + 8 + 7) * CHAR)


def test_write_cost_refuses_a_read_function() -> None:
    with pytest.raises(ValueError, match="not a write"):
        RTU.write_cost(Write(3, H, 0, (1,)))


@pytest.mark.parametrize(
    "fields", [{"baudrate": 0}, {"bits_per_char": 0}, {"turnaround": -1.0}, {"tcp_round_trip": -1}]
)
def test_link_timing_refuses_impossible_numbers(fields: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=r"must be positive|cannot be negative"):
        LinkTiming(**fields)


# --- plan_reads by hand --------------------------------------------------------------------------


def test_nothing_to_read_plans_nothing() -> None:
    assert plan_reads([], ReadLimits()) == Plan((), ())
    assert plan_reads([pt("cmd", 5, access="w")], ReadLimits()) == Plan((), ())


def test_points_sharing_registers_are_read_once() -> None:
    points = [pt("word", 10), pt("bit0", 10, "bit0"), pt("bit3", 10, "bit3"), pt("again", 10)]
    assert spans(plan_reads(points, ReadLimits())) == [("holding", 10, 1)]


@pytest.mark.parametrize(
    ("hole", "merged"),
    # RTU: a hole of h registers costs 2h characters; a second read costs 8 + 5 + 7 = 20.
    [(1, True), (9, True), (10, True), (11, False), (30, False)],
)
def test_a_hole_is_read_through_only_when_cheaper(hole: int, merged: bool) -> None:
    points = [pt("a", 100), pt("b", 101 + hole)]
    plan = plan_reads(points, ReadLimits())
    expected = (
        [("holding", 100, hole + 2)]
        if merged
        else [("holding", 100, 1), ("holding", 101 + hole, 1)]
    )
    assert spans(plan) == expected  # at 10 the costs tie: fewer reads win


def test_tcp_merges_everything_within_the_limit() -> None:
    limits = ReadLimits(max_registers=50, timing=LinkTiming(mode="tcp"))
    points = [pt("a", 0), pt("b", 40), pt("c", 49), pt("d", 60)]
    assert spans(plan_reads(points, limits)) == [("holding", 0, 50), ("holding", 60, 1)]


def test_faster_baud_or_latency_changes_where_holes_pay() -> None:
    points = [pt("a", 0), pt("b", 20)]  # a hole of 19 registers
    assert len(plan_reads(points, ReadLimits()).reads) == 2
    slow_device = ReadLimits(timing=LinkTiming(turnaround=0.05))
    assert spans(plan_reads(points, slow_device)) == [("holding", 0, 21)]
    fast_line = ReadLimits(timing=LinkTiming(baudrate=115200))  # silences fixed at 1.75 ms
    assert len(plan_reads(points, fast_line).reads) == 1


def test_no_readable_gaps_means_only_defined_addresses() -> None:
    points = [pt("a", 0), pt("b", 2)]
    strict = ReadLimits(readable_gaps=False)
    assert spans(plan_reads(points, strict)) == [("holding", 0, 1), ("holding", 2, 1)]
    defined = replace(strict, defined=frozenset({(H, 1)}))
    assert spans(plan_reads(points, defined)) == [("holding", 0, 3)]


def test_unreadable_addresses_split_blocks_and_drop_points() -> None:
    points = [pt("a", 0), pt("b", 2), pt("big", 4, "u32"), pt("bit", 5, "bit0")]
    limits = ReadLimits(unreadable=frozenset({(H, 1), (H, 4)}))
    plan = plan_reads(points, limits)
    assert spans(plan) == [("holding", 0, 1), ("holding", 2, 1), ("holding", 5, 1)]
    assert plan.unplannable == ("big",)  # the bit field of register 5 is still read


def test_blocks_never_cross_a_segment_and_keep_its_max() -> None:
    segments = (WireSegment(H, 10, 19, max_count=4), WireSegment(H, 20, 29))
    limits = ReadLimits(max_registers=8, segments=segments)
    points = [pt(f"r{a}", a) for a in (8, 9, 10, 11, 12, 13, 14, 19, 20, 21, 30)]
    assert spans(plan_reads(points, limits)) == [
        ("holding", 8, 2),
        ("holding", 10, 4),
        ("holding", 14, 1),
        ("holding", 19, 1),
        ("holding", 20, 2),
        ("holding", 30, 1),
    ]


def test_outside_segments_a_hole_may_not_contain_a_segment() -> None:
    limits = ReadLimits(segments=(WireSegment(H, 3, 4),), timing=LinkTiming(mode="tcp"))
    assert spans(plan_reads([pt("a", 0), pt("b", 8)], limits)) == [
        ("holding", 0, 1),
        ("holding", 8, 1),
    ]


def test_a_value_across_a_segment_boundary_is_unplannable() -> None:
    limits = ReadLimits(segments=(WireSegment(H, 10, 19), WireSegment(C, 0, 5)))
    plan = plan_reads([pt("torn", 19, "u32"), pt("ok", 18), pt("coil", 7, table=C)], limits)
    assert plan == Plan((Read(C, 7, 1), Read(H, 18, 1)), ("torn",))


@pytest.mark.parametrize(
    ("limit", "expected"),
    [
        (1, [(40, 1), (41, 1), (42, 1), (43, 1), (44, 1), (45, 1)]),
        (4, [(40, 4), (44, 2)]),
        (6, [(40, 6)]),
    ],
)
def test_a_value_longer_than_the_limit_is_read_in_limit_sized_chunks(
    limit: int, expected: list[tuple[int, int]]
) -> None:
    plan = plan_reads([pt("mac", 40, "ascii6")], ReadLimits(max_registers=limit))
    assert [(r.address, r.count) for r in plan.reads] == expected


def test_chunks_of_a_long_value_group_with_their_neighbours() -> None:
    points = [pt("mac", 41, "ascii3"), pt("before", 40), pt("after", 44)]
    plan = plan_reads(points, ReadLimits(max_registers=2))
    assert spans(plan) == [("holding", 40, 2), ("holding", 42, 2), ("holding", 44, 1)]


def test_a_u32_is_never_torn_when_it_fits() -> None:
    points = [pt("a", 9), pt("u32", 10, "u32"), pt("b", 12)]
    plan = plan_reads(points, ReadLimits(max_registers=2))
    assert spans(plan) == [("holding", 9, 1), ("holding", 10, 2), ("holding", 12, 1)]


def test_bit_tables_use_the_bit_limit_and_byte_packing() -> None:
    points = [pt(f"c{a}", a, table=C) for a in range(0, 20)] + [pt("i", 0, table=IN)]
    plan = plan_reads(points, ReadLimits(max_bits=16))
    assert spans(plan) == [("coil", 0, 16), ("coil", 16, 4), ("input", 0, 1)]
    # a hole of up to 8 bits costs at most one byte: always worth reading through
    assert spans(plan_reads([pt("a", 0, table=C), pt("b", 60, table=C)], ReadLimits())) == [
        ("coil", 0, 61)
    ]


def test_equal_cost_prefers_fewer_reads_then_a_long_first_block() -> None:
    points = [pt(f"r{a}", a) for a in range(13)]
    assert [r.count for r in plan_reads(points, ReadLimits(max_registers=6)).reads] == [6, 6, 1]


def test_plan_is_independent_of_input_order() -> None:
    points = [pt("a", 5), pt("b", 5, "bit2"), pt("c", 9, "u32"), pt("d", 3, table=C), pt("e", 30)]
    limits = ReadLimits(max_registers=4)
    first = plan_reads(points, limits)
    for order in itertools.permutations(points):
        assert plan_reads(order, limits) == first


# --- limits_for --------------------------------------------------------------------------------


def test_limits_of_the_p2_drive() -> None:
    limits = limits_for(shipped("p2_vfd"))
    assert (limits.max_registers, limits.max_bits, limits.readable_gaps) == (16, 2000, False)
    assert limits.unreadable == {(H, a) for a in (0x100C, 0x100D, 0x100E, 0x100F, 0x1013, 0x1014)}
    assert (H, 0x0004) in limits.defined  # an entity of a non-default option value
    assert (H, 0x2000) not in limits.defined  # the command word is write-only
    assert limits.segments == ()
    assert limits.timing == RTU


def test_limits_of_the_vacon_board_are_in_wire_addresses() -> None:
    limits = limits_for(shipped("vacon_nx"))
    assert limits.segments == (
        WireSegment(H, 0, 98, 30),
        WireSegment(H, 100, 1998, 30),
        WireSegment(H, 2000, 2010, 11),
        WireSegment(H, 2100, 2110, 11),
    )
    assert limits.unreadable == {(H, 99), (H, 1999), (H, 2099)}


def test_limits_for_takes_device_overrides_refusals_and_timing() -> None:
    mapping = shipped("nastec_vasco")
    link = LinkTiming.for_serial(19200, "E")
    refused = frozenset({(H, 0x40)})
    limits = limits_for(mapping, max_registers=16, max_bits=8, refused=refused, timing=link)
    assert (limits.max_registers, limits.max_bits, limits.timing) == (16, 8, link)
    assert (H, 0x40) in limits.unreadable and (H, 0x31) in limits.unreadable
    assert (H, 0xFFFF) in limits.unreadable  # reserved up to printed 0x10000


@pytest.mark.parametrize(
    ("field", "value"), [("max_registers", 0), ("max_registers", 126), ("max_bits", 2001)]
)
def test_limits_for_refuses_counts_beyond_the_modbus_limits(field: str, value: int) -> None:
    with pytest.raises(ValueError, match=field):
        limits_for(shipped("vacon_nx"), **{field: value})


# --- the shipped mappings, exactly ------------------------------------------------------------


def _plan(
    name: str, options: dict[str, str] | None = None, poll: set[PollClass] | None = None
) -> Plan:
    mapping = shipped(name)
    points = [
        p for p in mapping.points(options).values() if poll is None or p.entity.poll_class in poll
    ]
    return check_optimal(points, limits_for(mapping), enumerate_all=False)


def test_p2_fast_points_are_the_manuals_block_reads() -> None:
    plan = _plan("p2_vfd", poll={PollClass.FAST})
    assert spans(plan) == [
        ("holding", 0x1001, 11),
        ("holding", 0x1010, 3),
        ("holding", 0x1015, 1),
        ("holding", 0x3000, 1),
        ("holding", 0x8000, 1),
    ]
    frames = [head(read) for read in plan.reads]
    assert frames[0] == "01 03 10 01 00 0B"  # D12: 01 03 10 01 00 0B 51 0D
    assert frames[1] == "01 03 10 10 00 03"  # D13: 01 03 10 10 00 03 00 CE
    assert frames[3] == "01 03 30 00 00 01"  # D10
    assert frames[4] == "01 03 80 00 00 01"  # D11


def test_p2_full_scan_adds_the_set_value_and_parameters() -> None:
    plan = _plan("p2_vfd")
    assert spans(plan) == [
        ("holding", 0x1000, 12),  # 1000H read back too (rw), merged with D12's block
        ("holding", 0x1010, 3),
        ("holding", 0x1015, 2),
        ("holding", 0x3000, 1),
        ("holding", 0x8000, 1),
        ("holding", 0xF001, 2),
        ("holding", 0xF008, 1),
        ("holding", 0xF507, 1),
        ("holding", 0xF905, 1),
    ]
    assert head(plan.reads[2]) == "01 03 10 15 00 02"  # D14: 01 03 10 15 00 02 D1 0F


def test_vacon_process_data_out_in_one_read_of_eleven() -> None:
    assert spans(_plan("vacon_nx")) == [
        ("holding", 0, 9),
        ("holding", 24, 1),
        ("holding", 98, 1),
        ("holding", 732, 2),
        ("holding", 2000, 11),  # IDs 2001-2011
        ("holding", 2100, 11),  # IDs 2101-2111
    ]


def test_nastec_reads_one_register_per_request() -> None:
    mapping = shipped("nastec_vasco")
    plan = _plan("nastec_vasco")
    registers = sorted({a for p in mapping.points().values() for a in p.span})
    assert spans(plan) == [("holding", a, 1) for a in registers]
    assert [r.address for r in plan.reads if 0xBC <= r.address <= 0xC1] == list(range(0xBC, 0xC2))


def test_smartgen_reads_its_alarm_bits_in_one_fc01_read() -> None:
    assert spans(_plan("smartgen_hgm6100")) == [
        ("coil", 0, 79),
        ("holding", 0, 56),
        ("holding", 70, 28),  # clock, model, date 70-81 and the phase angles 92-97
    ]
    can = _plan("smartgen_hgm6100", {"can": "yes"})
    assert spans(can)[0] == ("coil", 0, 82)
    assert head(can.reads[0]) == "01 01 00 00 00 52"
    assert spans(can)[1:] == [("holding", 0, 56), ("holding", 56, 56), ("holding", 112, 13)]


def test_soft_starter_stays_within_six_and_off_the_reserved_rows() -> None:
    plan = _plan("soft_starter")
    assert spans(plan) == [
        ("holding", 0x1001, 6),
        ("holding", 0x1007, 6),
        ("holding", 0x100D, 6),
        ("holding", 0x1013, 6),
        ("holding", 0x1019, 6),
        ("holding", 0x101F, 6),
        ("holding", 0x1025, 1),
        ("holding", 0x102A, 4),  # the two run-time u32 values
        ("holding", 0x1030, 1),  # 102EH/102FH are write-only: not defined, not read
        ("holding", 0x1031, 6),
    ]
    assert not any(set(r.span) & set(range(0x1026, 0x102A)) for r in plan.reads)


def _option_sets(mapping: Mapping) -> list[dict[str, str]]:
    names = list(mapping.options)
    combos = itertools.product(*(mapping.options[n].choices for n in names))
    return [dict(zip(names, combo, strict=True)) for combo in combos]


@pytest.mark.parametrize(
    "name", ["nastec_vasco", "p2_vfd", "smartgen_hgm6100", "soft_starter", "vacon_nx"]
)
def test_every_option_set_of_every_mapping_plans_optimally(name: str) -> None:
    mapping = shipped(name)
    seen: set[frozenset[tuple[str, int, int]]] = set()
    for options in _option_sets(mapping):
        points = list(mapping.points(options).values())
        shape = frozenset((p.key, p.address, p.count) for p in points if p.entity.readable)
        if shape in seen:  # options that change only scales or names plan alike
            continue
        seen.add(shape)
        for max_registers in (None, 16):
            limits = limits_for(mapping, max_registers=max_registers)
            assert check_optimal(points, limits, enumerate_all=False).unplannable == ()


# --- random point sets ----------------------------------------------------------------------------

KINDS = ["u16", "u16", "u32", "bit0", "bit4", "ascii3", "coil"]


@st.composite
def point_sets(draw: st.DrawFn, *, size: int, span: int, count_max: int = 3) -> list[Point]:
    points = []
    for index in range(draw(st.integers(0, size))):
        kind = draw(st.sampled_from(KINDS))
        if kind == "ascii3":
            kind = f"ascii{draw(st.integers(1, count_max))}"
        table = C if kind == "coil" else H
        access = draw(st.sampled_from(["r", "r", "r", "rw", "w"]))
        if table is H and access != "r" and kind.startswith("bit"):
            access = "r"
        points.append(pt(f"p{index}", draw(st.integers(0, span)), kind, table, access))
    return points


@st.composite
def limit_sets(draw: st.DrawFn, *, span: int, max_top: int) -> ReadLimits:
    addresses = st.tuples(st.sampled_from([H, C]), st.integers(0, span + 3))
    segments = []
    for _ in range(draw(st.integers(0, 2))):
        first = draw(st.integers(0, span))
        last = draw(st.integers(first, span + 3))
        segments.append(
            WireSegment(
                draw(st.sampled_from([H, C])),
                first,
                last,
                draw(st.none() | st.integers(1, max_top)),
            )
        )
    timing = draw(
        st.sampled_from(
            [
                RTU,
                LinkTiming(baudrate=38400, turnaround=0.002),
                LinkTiming(mode="ascii", bits_per_char=10),
                LinkTiming(mode="tcp"),
            ]
        )
    )
    return ReadLimits(
        max_registers=draw(st.integers(1, max_top)),
        max_bits=draw(st.integers(1, max_top * 2)),
        readable_gaps=draw(st.booleans()),
        unreadable=frozenset(draw(st.lists(addresses, max_size=3))),
        defined=frozenset(draw(st.lists(addresses, max_size=8))),
        segments=tuple(segments),
        timing=timing,
    )


RANDOM = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@RANDOM
@given(points=point_sets(size=6, span=20), limits=limit_sets(span=20, max_top=6))
def test_plan_equals_the_best_of_all_plans_enumerated(
    points: list[Point], limits: ReadLimits
) -> None:
    check_optimal(points, limits, enumerate_all=True)


@RANDOM
@given(points=point_sets(size=30, span=80, count_max=8), limits=limit_sets(span=80, max_top=20))
def test_large_random_plans_hold_every_invariant(points: list[Point], limits: ReadLimits) -> None:
    plan = check_optimal(points, limits, enumerate_all=False)
    assert plan_reads(reversed(points), limits) == plan


# --- baselines, costs, refusals ----------------------------------------------------------------


def test_one_read_per_entity_is_what_home_assistant_polls() -> None:
    points = [
        pt("w", 0),
        pt("b", 0, "bit1"),
        pt("mac", 4, "ascii3"),
        pt("cmd", 9, access="w"),
        pt("x", 20),
    ]
    assert spans(one_read_per_entity(points)) == [
        ("holding", 0, 1),
        ("holding", 0, 1),
        ("holding", 4, 3),
        ("holding", 20, 1),
    ]
    limits = ReadLimits(max_registers=2, unreadable=frozenset({(H, 20)}))
    assert spans(one_read_per_entity(points, limits)) == [
        ("holding", 0, 1),
        ("holding", 0, 1),
        ("holding", 4, 2),
        ("holding", 6, 1),
    ]
    torn = ReadLimits(segments=(WireSegment(H, 5, 9),))
    assert spans(one_read_per_entity([pt("mac", 4, "ascii3")], torn)) == []


def test_cost_of_sums_read_costs() -> None:
    reads = (Read(H, 0, 10), Read(C, 0, 8))
    expected = (8 + 25 + 7 + 8 + 6 + 7) * CHAR
    assert cost_of(Plan(reads), RTU) == pytest.approx(expected)
    assert cost_of(list(reads), RTU) == pytest.approx(expected)
    assert cost_of(Plan(()), RTU) == 0.0


def test_split_read_halves_a_refused_block_at_an_atom_boundary() -> None:
    points = [
        pt("a", 0),
        pt("a_bit", 0, "bit1"),
        pt("u32", 2, "u32"),
        pt("c", 6),
        pt("d", 8),
        pt("cmd", 9, access="w"),
        pt("other", 7, table=C),
    ]
    block = Read(H, 0, 9)
    halves = split_read(block, points, halves=True)
    assert spans(halves) == [("holding", 0, 4), ("holding", 6, 3)]
    assert unread(block, halves) == {(H, 4), (H, 5)}
    atoms = split_read(block, points)
    assert spans(atoms) == [
        ("holding", 0, 1),
        ("holding", 2, 2),
        ("holding", 6, 1),
        ("holding", 8, 1),
    ]
    assert unread(block, atoms) == holes(block, points) == {(H, 1), (H, 4), (H, 5), (H, 7)}
    assert split_read(Read(H, 2, 2), points, halves=True) == ()
    assert split_read(Read(H, 3, 1), points) == ()  # part of one atom: nothing smaller
    assert unread(Read(H, 0, 2), [Read(H, 0, 2)]) == frozenset()
    assert addresses_of(Read(H, 2, 2)) == {(H, 2), (H, 3)}


def test_split_read_clips_a_chunked_value_to_the_block() -> None:
    points = [pt("mac", 0, "ascii6"), pt("next", 6)]
    assert spans(split_read(Read(H, 4, 3), points)) == [("holding", 4, 2), ("holding", 6, 1)]


Learnt = frozenset[tuple[Table, int]]


def _learn(
    points: list[Point], mapping: Mapping, device_refuses: set[tuple[Table, int]]
) -> tuple[Learnt, int]:
    """The engine's search (bridge/core/refusal.py) against a device refusing some
    addresses: what it remembers and how many extra reads it spent."""
    learnt: set[tuple[Table, int]] = set()
    spent = 0
    for block in plan_reads(points, limits_for(mapping)).reads:
        if addresses_of(block) & device_refuses:
            search = refusal_search(block, points)
            found = run_search(search, lambda part: not addresses_of(part) & device_refuses)
            learnt |= found.refused
            spent += found.reads
    return frozenset(learnt), spent


def test_learning_a_refused_register_inside_a_block() -> None:
    mapping = shipped("vacon_nx")
    points = list(mapping.points().values())
    learnt, spent = _learn(points, mapping, {(H, 5)})
    assert (learnt, spent) == ({(H, 5)}, 6)  # 0-8 -> 4-8 -> 4-5 -> 5: three pairs of reads
    plan = check_optimal(points, limits_for(mapping, refused=learnt), enumerate_all=False)
    assert spans(plan)[:2] == [("holding", 0, 5), ("holding", 6, 3)]
    assert plan.unplannable == ("monitor_motor_voltage",)


def test_learning_a_refused_hole_keeps_every_point() -> None:
    mapping = shipped("smartgen_hgm6100")
    points = list(mapping.points().values())
    learnt, _ = _learn(points, mapping, {(H, 32), (C, 5)})
    assert learnt == {(H, 32), (H, 33), (C, 5)}
    plan = check_optimal(points, limits_for(mapping, refused=learnt), enumerate_all=False)
    assert plan.unplannable == ()
    assert spans(plan) == [
        ("coil", 0, 5),
        ("coil", 6, 73),
        ("holding", 0, 32),
        ("holding", 34, 22),
        ("holding", 70, 28),
    ]


def test_a_refused_quantity_leaves_nothing_to_blame() -> None:
    mapping = shipped("p2_vfd")
    points = list(mapping.points().values())
    block = plan_reads(points, limits_for(mapping)).reads[0]
    assert unread(block, split_read(block, points, halves=True)) == frozenset()
    assert holes(block, points) == frozenset()
