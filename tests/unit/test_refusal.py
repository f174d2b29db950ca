"""The refusal search against model devices: refused registers, holes and quantities."""

from __future__ import annotations

from bridge.core.entity import Table
from bridge.core.planner import addresses_of
from bridge.core.refusal import Refusal, refusal_search, run_search
from bridge.core.request import Read
from tests.factory import make_mapping

H = Table.HOLDING


def points(*spans: tuple[int, str]) -> list:
    entities = {
        f"p{address}": {"name": f"P{address}", "address": address, "type": kind}
        for address, kind in spans
    }
    return list(make_mapping(entities).points().values())


def strict(refused: set[int], max_count: int = 125):
    def answers(read: Read) -> bool:
        return read.count <= max_count and not {a for _, a in addresses_of(read)} & refused

    return answers


def test_a_refused_register_is_found_by_bisection() -> None:
    pts = points(*((a, "u16") for a in range(8)))
    found = run_search(refusal_search(Read(H, 0, 8), pts), strict({5}))
    assert found == Refusal(frozenset({(H, 5)}), None, 6)


def test_a_refused_hole_is_blamed_when_the_parts_answer() -> None:
    pts = points((0, "u16"), (1, "u16"), (4, "u16"), (5, "u16"))
    found = run_search(refusal_search(Read(H, 0, 6), pts), strict({2, 3}))
    assert found.refused == {(H, 2), (H, 3)}
    assert found.max_count is None


def test_a_refused_quantity_gives_a_lower_read_limit() -> None:
    pts = points(*((a, "u16") for a in range(8)))
    found = run_search(refusal_search(Read(H, 0, 8), pts), strict(set(), max_count=4))
    assert found == Refusal(frozenset(), 4, 2)


def test_a_long_value_is_halved_by_count() -> None:
    pts = points((0, "u32"))
    found = run_search(refusal_search(Read(H, 0, 2), pts), strict(set(), max_count=1))
    assert found == Refusal(frozenset(), 1, 2)


def test_a_single_refused_register_is_remembered_without_reads() -> None:
    pts = points((7, "u16"))
    found = run_search(refusal_search(Read(H, 7, 1), pts), strict({7}))
    assert found == Refusal(frozenset({(H, 7)}), None, 0)


def test_atom_by_atom_costs_more_reads_than_bisection() -> None:
    pts = points(*((a, "u16") for a in range(16)))
    block = Read(H, 0, 16)
    bisect = run_search(refusal_search(block, pts), strict({11}))
    one_by_one = run_search(refusal_search(block, pts, halves=False), strict({11}))
    assert bisect.refused == one_by_one.refused == {(H, 11)}
    assert bisect.reads < one_by_one.reads == 16
