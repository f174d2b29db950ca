"""Finding out what a device refused in a read, as a pure search the caller drives.

``refusal_search(block, points)`` is a generator: it yields the reads to try, is sent
``True`` when the device answered a read and ``False`` when it refused it, and returns a
``Refusal``: the addresses to avoid from now on and, when every part answered and nothing
lay between them, the smaller read limit the device showed. The engine drives it with
real transactions; the bench and the tests drive it with a model of a strict device.

The search bisects at atom boundaries (about 2·log2(n) reads find one refused atom or
hole among n), or with ``halves=False`` tries the atoms one by one. A single value longer
than the device allows is halved by count.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass

from bridge.core.mapping import Point
from bridge.core.planner import Address, addresses_of, split_read, unread
from bridge.core.request import Read

Search = Generator[Read, bool, "Refusal"]


@dataclass(frozen=True, slots=True)
class Refusal:
    refused: frozenset[Address]
    max_count: int | None  # a lower read limit, when only the quantity was refused
    reads: int  # reads spent finding out


def refusal_search(block: Read, points: Sequence[Point], *, halves: bool = True) -> Search:
    """Locate what the device refused in ``block`` (which it refused whole)."""
    refused: set[Address] = set()
    limits: list[int] = []
    spent = 0

    def locate(read: Read) -> Generator[Read, bool, None]:
        nonlocal spent
        parts = split_read(read, points, halves=halves)
        if not parts and read.count > 1:  # one value longer than the device allows per read
            half = read.count // 2
            parts = (
                Read(read.table, read.address, half),
                Read(read.table, read.address + half, read.count - half),
            )
        if not parts:
            refused.update(addresses_of(read))
            return
        answered = []
        for part in parts:
            spent += 1
            answered.append((yield part))
        for part, ok in zip(parts, answered, strict=True):
            if not ok:
                yield from locate(part)
        if all(answered):
            between = unread(read, parts)
            if between:
                refused.update(between)
            else:
                limits.append(max(part.count for part in parts))

    yield from locate(block)
    return Refusal(frozenset(refused), min(limits) if limits else None, spent)


def run_search(search: Search, answers: Callable[[Read], bool]) -> Refusal:
    """Drive a search synchronously (a model device, in benches and tests)."""
    try:
        read = next(search)
        while True:
            read = search.send(answers(read))
    except StopIteration as done:
        return done.value  # type: ignore[no-any-return]
