"""Reads split to a device's limit (raw reads of commissioning and management)."""

from __future__ import annotations

import pytest

from bridge.core.entity import Table
from bridge.core.request import Read, split_read


@pytest.mark.parametrize(
    ("count", "limit", "parts"),
    [
        (2, 1, [(151, 1), (152, 1)]),
        (5, 2, [(151, 2), (153, 2), (155, 1)]),
        (4, 4, [(151, 4)]),
        (3, 125, [(151, 3)]),
    ],
)
def test_split_read_covers_the_read_in_order_within_the_limit(
    count: int, limit: int, parts: list[tuple[int, int]]
) -> None:
    split = split_read(Read(Table.HOLDING, 151, count), limit)
    assert [(r.address, r.count) for r in split] == parts
    assert all(r.table is Table.HOLDING for r in split)


def test_a_limit_below_one_is_a_bug() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        split_read(Read(Table.COIL, 0, 3), 0)
