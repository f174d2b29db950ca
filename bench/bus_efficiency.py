"""Bus efficiency of the poll planner on the shipped mappings.

Run: ``.venv/bin/python bench/bus_efficiency.py``

Per mapping (default options, Modbus RTU at 9600 8N1, turnaround 0) one full scan of every
readable point, three ways:

* plan: ``plan_reads`` with ``limits_for(mapping)``;
* minimum: the least-bus-time plan found by an independent exhaustive search, which shares
  no code with ``plan_reads``: a shortest path, address by address, over every candidate
  read (every start and end register of a needed address) that the device rules allow;
* per entity: one read per readable entity, as Home Assistant's modbus integration polls
  (chunked to the device's max count where an entity is longer: otherwise the device
  refuses it).

The second table simulates a strict device that refuses a few addresses inside merged
blocks (a hole where the block has one, else its middle register): the engine meets each
refusal, bisects the block (``split_read(..., halves=True)``; the column in brackets counts
the reads one read per atom would take instead), remembers what was refused
(``addresses_of``, ``unread``) and plans again with ``limits_for(mapping, refused=...)``.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from bridge.core.entity import Table
from bridge.core.mapping import (
    Mapping,
    Point,
    builtin_mapping_names,
    builtin_mapping_path,
    load_mapping,
)
from bridge.core.planner import (
    ReadLimits,
    addresses_of,
    holes,
    limits_for,
    one_read_per_entity,
    plan_reads,
    split_read,
)
from bridge.core.refusal import refusal_search, run_search
from bridge.core.request import Read
from bridge.core.timing import LinkTiming

TIMING = LinkTiming.for_serial(9600, "N", 1, 8)
Address = tuple[Table, int]


@dataclass(frozen=True)
class Figures:
    reads: int
    wire_bytes: int
    seconds: float

    @classmethod
    def of(cls, reads: Sequence[Read]) -> Figures:
        return cls(
            len(reads),
            sum(TIMING.read_bytes(r) for r in reads),
            sum(TIMING.read_cost(r) for r in reads),
        )


# --- the independent exhaustive search ----------------------------------------------------


class Exhaustive:
    """Least bus time over every valid plan, from the device rules stated address by address."""

    def __init__(self, points: Iterable[Point], limits: ReadLimits) -> None:
        self.limits = limits
        readable = [p for p in points if p.entity.readable]
        self.defined = limits.defined | {(p.table, a) for p in readable for a in p.span}
        kept = [p for p in readable if not any((p.table, a) in limits.unreadable for a in p.span)]
        spans: dict[Address, set[int]] = {}
        for p in kept:  # registers shared by points form one group (union of spans)
            group = set(p.span)
            for a in p.span:
                group |= spans.get((p.table, a), set())
            for a in group:
                spans[(p.table, a)] = group
        self.owner: dict[Address, frozenset[int]] = {
            (table, address): frozenset(group)
            for (table, address), group in spans.items()
            if len({self.region(table, a) for a in group}) == 1
        }
        self.lost = {p.key for p in readable if (p.table, p.address) not in self.owner}

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

    def allowed(self, read: Read) -> bool:
        """Region, length, unreadable and defined rules (monotone in the read's length)."""
        table = read.table
        regions = {self.region(table, a) for a in read.span}
        if len(regions) != 1 or read.count > self.limit(table, regions.pop()):
            return False
        if any((table, a) in self.limits.unreadable for a in read.span):
            return False
        return self.limits.readable_gaps or all((table, a) in self.defined for a in read.span)

    def whole(self, read: Read) -> bool:
        """No group of shared registers cut, unless it is longer than any read allows."""
        span = set(read.span)
        for a in span:
            group = self.owner.get((read.table, a))
            too_long = group and len(group) > self.limit(read.table, self.region(read.table, a))
            if group and not group <= span and not too_long:
                return False
        return True

    def best(self) -> list[Read]:
        plan: list[Read] = []
        for table in sorted({t for t, _ in self.owner}):
            plan += self._best_of(table)
        return plan

    def _best_of(self, table: Table) -> list[Read]:
        needed = sorted(a for t, a in self.owner if t is table)
        wanted = set(needed)

        @functools.cache
        def path(index: int) -> tuple[float, int, tuple[Read, ...]]:
            if index == len(needed):
                return 0.0, 0, ()
            x = needed[index]
            found: tuple[float, int, tuple[Read, ...]] = (math.inf, 0, ())
            for y in range(x + 1, needed[-1] + 2):
                read = Read(table, x, y - x)
                if not self.allowed(read):
                    break
                if y - 1 not in wanted or not self.whole(read):
                    continue
                cost, count, rest = path(bisect.bisect_left(needed, y))
                option = (cost + TIMING.read_cost(read), count + 1, (read, *rest))
                tie = abs(option[0] - found[0]) <= 1e-9
                if option[0] < found[0] - 1e-9 or (tie and option[1] < found[1]):
                    found = option
            return found

        return list(path(0)[2])


# --- the strict device -------------------------------------------------------------------------


def refusals(plan: Sequence[Read], points: Sequence[Point]) -> set[Address]:
    """Up to three addresses in merged blocks: a hole if the block has one, else its middle."""
    chosen: set[Address] = set()
    for block in plan:
        if len(chosen) == 3 or not split_read(block, points):
            continue
        gaps = sorted(holes(block, points))
        chosen.add(
            gaps[len(gaps) // 2] if gaps else (block.table, block.address + block.count // 2)
        )
    return chosen


def learn(
    plan: Sequence[Read], points: Sequence[Point], device_refuses: set[Address], *, halves: bool
) -> tuple[frozenset[Address], int]:
    """The engine's search (bridge/core/refusal.py) meeting the refusals, by bisection
    (``halves``) or atom by atom: what it remembers, and the extra reads it spent."""
    learnt: set[Address] = set()
    spent = 0
    for block in plan:
        if addresses_of(block) & device_refuses:
            search = refusal_search(block, points, halves=halves)
            found = run_search(search, lambda part: not addresses_of(part) & device_refuses)
            learnt |= found.refused
            spent += found.reads
    return frozenset(learnt), spent


# --- report ----------------------------------------------------------------------------------


def cells(f: Figures) -> list[str]:
    return [str(f.reads), str(f.wire_bytes), f"{f.seconds * 1000:.1f}"]


def row(values: Iterable[str]) -> str:
    return "| " + " | ".join(values) + " |"


def wire(addresses: Iterable[Address]) -> str:
    return ", ".join(f"{t.value[0]}{a:04X}" for t, a in sorted(addresses)) or "-"


def measure(label: str, mapping: Mapping, max_registers: int | None = None) -> tuple[str, str]:
    """The two table rows of one mapping: the full scan, and the strict device."""
    points = [p for p in mapping.points().values() if p.entity.readable]
    limits = limits_for(mapping, max_registers=max_registers, timing=TIMING)
    plan = plan_reads(points, limits).reads
    least = Figures.of(Exhaustive(points, limits).best())
    mine = Figures.of(plan)
    baseline = Figures.of(one_read_per_entity(points, limits))
    ratio = f"{mine.seconds / least.seconds:.2f}"
    scan = row([label, str(len(points)), *cells(mine), *cells(least), *cells(baseline), ratio])

    device = refusals(plan, points)
    learnt, spent = learn(plan, points, device, halves=True)
    _, one_by_one = learn(plan, points, device, halves=False)
    relimited = limits_for(mapping, max_registers=max_registers, refused=learnt, timing=TIMING)
    after = plan_reads(points, relimited)
    search = Exhaustive(points, relimited)
    least_after = Figures.of(search.best())
    assert set(after.unplannable) == search.lost
    got = Figures.of(after.reads)
    strict = row(
        [
            *(label, wire(device), wire(learnt), str(spent), str(one_by_one), *cells(got)),
            f"{least_after.seconds * 1000:.1f}",
            f"{got.seconds / least_after.seconds:.2f}",
            ", ".join(after.unplannable) or "-",
        ]
    )
    return scan, strict


def main() -> None:
    cases = [(name, name, None) for name in builtin_mapping_names()]
    cases.append(("nastec_vasco, max 16", "nastec_vasco", 16))  # a device config raising it
    rows = [
        measure(label, load_mapping(builtin_mapping_path(name)), top) for label, name, top in cases
    ]
    print(f"Full scan of all readable points, default options, RTU {TIMING.baudrate} 8N1.")
    print("Bytes = request + response on the wire; ms = bus time incl. two t3.5 silences.\n")
    header = [
        *("mapping", "points", "plan reads", "plan bytes", "plan ms"),
        *("min reads", "min bytes", "min ms"),
        *("per-entity reads", "per-entity bytes", "per-entity ms", "plan/min"),
    ]
    print(row(header))
    print(row(["---"] + ["---:"] * 11))
    print("\n".join(scan for scan, _ in rows))
    print("\nStrict device: refuses the listed addresses; the engine learns, then plans again.\n")
    header = [
        *("mapping", "device refuses", "learnt", "learning reads", "(atom by atom)"),
        "reads after",
        *("bytes after", "ms after", "min ms after", "plan/min", "unplannable"),
    ]
    print(row(header))
    print(row(["---"] * 3 + ["---:"] * 7 + ["---"]))
    print("\n".join(strict for _, strict in rows))


if __name__ == "__main__":
    main()
