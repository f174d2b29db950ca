"""Tear-free 32-bit values read one register at a time (Nastec life counters)."""

from __future__ import annotations

from collections.abc import Generator

import pytest

from bridge.core.entity import Table
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Read
from bridge.core.tearing import Torn, torn_values, untear
from tests.factory import make_mapping

H = Table.HOLDING
NASTEC = load_mapping(builtin_mapping_path("nastec_vasco"))


def run(
    check: Generator[Read, int, tuple[int, int] | None], answers: list[int]
) -> tuple[list[Read], tuple[int, int] | None]:
    """Drive ``check`` with ``answers``; the reads it asked for and its result."""
    asked: list[Read] = []
    feed = iter(answers)
    try:
        read = next(check)
        while True:
            asked.append(read)
            read = check.send(next(feed))
    except StopIteration as done:
        return asked, done.value


def test_the_nastec_life_and_band_counters_are_torn_by_one_register_reads() -> None:
    points = NASTEC.points()
    reads = plan_reads(list(points.values()), limits_for(NASTEC)).reads
    torn = {t.point.key: t for t in torn_values(points.values(), reads)}
    counters = ["electric_life", "inverter_life", "motor_life"] + [
        f"frequency_range_{n}_time" for n in range(1, 5)
    ]
    assert sorted(torn) == sorted(counters)
    life = torn["electric_life"]
    assert (life.high, life.low, life.high_first) == (0xAA, 0xAB, True)  # idx 0xAB/0xAC
    wide = plan_reads(list(points.values()), limits_for(NASTEC, max_registers=2)).reads
    assert "electric_life" not in {t.point.key for t in torn_values(points.values(), wide)}


BIG = Torn(NASTEC.points()["electric_life"], high=0xAA, low=0xAB)
LITTLE = Torn(NASTEC.points()["electric_life"], high=0xAB, low=0xAA)  # low word first


@pytest.mark.parametrize(
    ("torn", "read", "answers", "asked", "result"),
    [
        # the high word did not move: the pair read stands, one extra read
        (BIG, (0, 0xFFFE), [0], ["high"], (0, 0xFFFE)),
        # rolled over between high and low (0x0000FFFF -> 0x00010000): low and high again
        (BIG, (0, 0x0000), [1, 0x0003, 1], ["high", "low", "high"], (1, 0x0003)),
        # still moving: given up after three rounds
        (BIG, (0, 0), [1, 0, 2, 0, 3], ["high"] + ["low", "high"] * 2, None),
        # word_order little: the low word was read first, so low and high again
        (LITTLE, (7, 0xFFFF), [0x0002, 7], ["low", "high"], (7, 0x0002)),
    ],
)
def test_untear_reads_high_low_high_until_the_high_word_stands_still(
    torn: Torn,
    read: tuple[int, int],
    answers: list[int],
    asked: list[str],
    result: tuple[int, int] | None,
) -> None:
    reads, words = run(untear(torn, *read), answers)
    where = {torn.high: "high", torn.low: "low"}
    assert [where[r.address] for r in reads] == asked
    assert all((r.table, r.count) == (H, 1) for r in reads)
    assert words == result


def test_only_two_register_numbers_split_across_reads_are_torn() -> None:
    mapping = make_mapping(
        {
            "counter": {"name": "C", "address": 0, "type": "u32"},
            "total": {"name": "T", "address": 2, "type": "s32", "word_order": "little"},
            "label": {"name": "L", "address": 4, "type": "ascii", "count": 2},
            "word": {"name": "W", "address": 6},
        }
    )
    points = mapping.points()
    one_by_one = [Read(H, a, 1) for a in range(7)]
    torn = torn_values(points.values(), one_by_one)
    assert [(t.point.key, t.high, t.low) for t in torn] == [("counter", 0, 1), ("total", 3, 2)]
    assert torn_values(points.values(), [Read(H, 0, 7)]) == []
    partial = [Read(H, 0, 2), Read(H, 2, 1)]  # total's second word in no read: unplannable
    assert torn_values(points.values(), partial) == []
