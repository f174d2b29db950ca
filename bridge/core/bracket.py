"""Bracketed reads: a ``scale_by`` value read apart from its exponent. Pure.

A value and its exponent are read in one request wherever a read can hold both
(bridge/core/planner.py). Where none can (SunSpec model 129's third and fourth curves, the
7xx DER curves: more than 125 registers from their factors), the value is read
*bracketed*: its exponent is read before the value's read and again after it, and the
value is decoded only when every reading of the exponent from the one before to the one
after is the same (the factor did not change while the value was read: as far as a master
can know, the value was produced under it). Otherwise it is not decoded this pass: it
keeps its last value (not unknown), and the device counts it (``scaled_values_held``).

The plan says where (``Bracket``): the exponent's one-register read and the values it
brackets. The plan's own read of the exponent serves as the reading before (it precedes
every read of the values, the usual layout: a model's factors at its top) or after (it
follows them); a side it cannot serve gets a dedicated one-register read, before the pass
or after it. The exponent's reads are shared by every far value it scales: one extra read
per exponent and pass in the usual layout, two when far values lie on both sides of it;
exponents side by side (SunSpec's factors) are read in one (``planner.join_reads``).

What the bus answered is judged by ``verdict``: the exponent's readings of this pass
(request number, word), and the request numbers the value's words came in.
"""

from __future__ import annotations

import enum
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass

from bridge.core.entity import Table
from bridge.core.request import Read

Observation = tuple[int, int]  # (request number, word): one reading of an exponent register


@dataclass(frozen=True, slots=True)
class Bracket:
    """The values ``keys`` read apart from their exponent ``exponent`` (a one-register read):
    ``before``/``after``: a dedicated read of it before/after the pass (the plan's own
    read of it cannot serve that side)."""

    exponent: Read
    keys: tuple[str, ...]
    before: bool
    after: bool


class Verdict(enum.Enum):
    SAME = "same"  # read before and after the value, every reading equal: decode
    CHANGED = "changed"  # readings differ: the value is held this pass (and counted)
    UNCHECKED = "unchecked"  # no reading before or after the value: held, not counted


def brackets_of(
    far: Iterable[tuple[str, Table, range, int]], reads: Sequence[Read]
) -> tuple[Bracket, ...]:
    """The brackets of ``far`` values (key, table, registers, exponent's wire address) under
    ``reads`` (the plan's, in the order a pass sends them; each value and exponent in one)."""
    grouped: dict[tuple[Table, int], list[tuple[str, range]]] = {}
    for key, table, span, exponent in far:
        grouped.setdefault((table, exponent), []).append((key, span))
    found: list[Bracket] = []
    for (table, exponent), values in sorted(grouped.items()):
        own = _index(reads, table, exponent)
        apart = {
            key: {_index(reads, table, a) for a in span}
            for key, span in values
            if any(_index(reads, table, a) != own for a in span)
        }  # (a value the plan reads with its exponent after all is read as any other)
        if not apart:
            continue
        indices = set().union(*apart.values())
        found.append(
            Bracket(
                Read(table, exponent, 1),
                tuple(sorted(apart)),
                before=not own < min(indices),
                after=not own > max(indices),
            )
        )
    return tuple(found)


def _index(reads: Sequence[Read], table: Table, address: int) -> int:
    return next(i for i, r in enumerate(reads) if r.table is table and address in r.span)


def verdict(readings: Iterable[Observation], value_requests: Collection[int]) -> Verdict:
    """Judge a value's words (the request numbers they came in) by its exponent's readings
    of the same pass: the last reading before the value's first word, the first after its
    last word, and every reading between them, must exist and agree."""
    first, last = min(value_requests), max(value_requests)
    ordered = sorted(readings)
    before = [r for r in ordered if r[0] < first]
    after = [r for r in ordered if r[0] > last]
    if not before or not after:
        return Verdict.UNCHECKED
    window = [r for r in ordered if before[-1][0] <= r[0] <= after[0][0]]
    return Verdict.SAME if len({word for _, word in window}) == 1 else Verdict.CHANGED


def needs_after(readings: Iterable[Observation], value_requests: Collection[int]) -> bool:
    """No reading of the exponent after the value's last word yet: read it again."""
    last = max(value_requests, default=0)
    return not any(number > last for number, _ in readings)
