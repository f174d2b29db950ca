"""Learnt refusals: holes are learnt and re-checked, a device refusing everything is a fault."""

from __future__ import annotations

import pytest

from bridge.core.entity import Table
from bridge.core.planner import Address
from bridge.core.refusal_memory import RefusalMemory, Verdict

H = Table.HOLDING


def cells(*addresses: int) -> frozenset[Address]:
    return frozenset((H, a) for a in addresses)


def memory(answered: frozenset[Address] = frozenset(), recheck: float = 60.0) -> RefusalMemory:
    remembered = RefusalMemory(recheck)
    remembered.answer(answered)
    return remembered


@pytest.mark.parametrize(
    ("case", "answered_before", "answered", "blocks", "verdict"),
    [
        ("a hole in a new block, the rest answered", cells(), 10, [cells(0, 1, 2)], Verdict.LEARN),
        ("nothing answered, never seen", cells(), 0, [cells(0, 1), cells(5)], Verdict.SEARCH),
        ("a storm: every block it answered before", cells(0, 1, 5), 0, [cells(0, 1), cells(5)], Verdict.FAULT),
        ("one known block refused, nothing answered", cells(5), 0, [cells(5)], Verdict.FAULT),
        ("a forgotten hole merged into known blocks", cells(0, 2), 0, [cells(0, 1, 2)], Verdict.SEARCH),
        ("a known block refused, more answered", cells(0, 1), 3, [cells(0, 1)], Verdict.LEARN),
        ("a known block refused, as much answered", cells(0, 1), 2, [cells(0, 1)], Verdict.LEARN),
        ("more refused than answered, all known", cells(0, 1, 2), 2, [cells(0, 1, 2)], Verdict.FAULT),
        ("more refused than answered, all new", cells(), 2, [cells(0, 1, 2)], Verdict.LEARN),
        ("known blocks count, mixed ones do not", cells(0, 1), 2, [cells(0, 1), cells(3, 4)], Verdict.LEARN),
    ],
)  # fmt: skip
def test_a_pass_is_judged_by_what_the_device_answered_before(
    case: str,
    answered_before: frozenset[Address],
    answered: int,
    blocks: list[frozenset[Address]],
    verdict: Verdict,
) -> None:
    assert memory(answered_before).judge(answered, blocks) is verdict, case


@pytest.mark.parametrize(
    ("case", "refused_before", "found", "explained"),
    [
        ("a learnt hole refused again", cells(7), cells(7), True),
        ("learnt holes, all refused again", cells(7, 9), cells(7), True),
        ("a new address among them", cells(7), cells(7, 8), False),
        ("never refused before", cells(), cells(7), False),
        ("nothing found", cells(7), cells(), False),
    ],
)
def test_a_search_answering_nothing_is_explained_only_by_holes_learnt_before(
    case: str, refused_before: frozenset[Address], found: frozenset[Address], explained: bool
) -> None:
    remembered = memory()
    remembered.learn(refused_before, 0.0)
    remembered.expire(1e9)  # re-checked: forgotten, still known as refused before
    assert remembered.explains(found) is explained, case


def test_learnt_refusals_are_forgotten_after_the_recheck_interval() -> None:
    remembered = memory(recheck=60.0)
    assert remembered.learn(cells(5), 100.0) == cells(5)
    assert remembered.learn(cells(9), 130.0) == cells(9)
    assert remembered.refused == cells(5, 9)
    assert remembered.expire(159.9) == cells()
    assert remembered.expire(160.0) == cells(5)
    assert remembered.refused == cells(9)
    assert remembered.expire(190.0) == cells(9)
    assert remembered.refused == cells()


def test_a_refusal_refused_again_is_learnt_again_quietly() -> None:
    remembered = memory(recheck=60.0)
    remembered.learn(cells(5), 0.0)
    remembered.expire(60.0)
    assert remembered.learn(cells(5, 6), 61.0) == cells(6)  # only 6 is news
    assert remembered.refused == cells(5, 6)
    assert remembered.expire(120.0) == cells()  # the clock restarted at 61
    assert remembered.expire(121.0) == cells(5, 6)


def test_an_address_answered_again_is_no_longer_refused() -> None:
    remembered = memory()
    remembered.learn(cells(5, 6), 0.0)
    assert remembered.answer(cells(4, 5)) == cells(5)
    assert remembered.refused == cells(6)
    assert remembered.answer(cells(5)) == cells()  # news once
    assert remembered.learn(cells(5), 1.0) == cells(5)  # refused after answering: news again


def test_a_learnt_address_is_no_longer_one_it_answered() -> None:
    remembered = memory(cells(0, 1, 2))
    remembered.learn(cells(1), 0.0)
    remembered.expire(1e9)
    assert remembered.judge(0, [cells(0, 1, 2)]) is Verdict.SEARCH  # 1 may be the hole
    assert remembered.judge(0, [cells(0, 2)]) is Verdict.FAULT
