"""bridge.errors.first_of: the error inside the ExceptionGroups task groups raise."""

from __future__ import annotations

from bridge.errors import BridgeError, BusError, first_of


def test_first_of_searches_nested_groups_in_order() -> None:
    wanted, later = BusError("gateway unplugged"), BridgeError("later")
    group = ExceptionGroup(
        "outer",
        [
            ExceptionGroup("no match inside", [ValueError("a")]),
            ValueError("b"),
            ExceptionGroup("match inside", [KeyError("c"), wanted]),
            later,
        ],
    )
    assert first_of(group, BridgeError) is wanted
    assert first_of(group, LookupError) is group.exceptions[2].exceptions[0]  # type: ignore[attr-defined]
    assert first_of(group, OSError) is None
