"""The simulator stores a discrete input's value in the discrete table (an imported Home
Assistant binary sensor on a discrete input read 0 whatever it was set to)."""

from __future__ import annotations

from bridge.core.entity import Table
from bridge.core.mapping import Mapping
from bridge.core.simulation import words_for


def test_a_discrete_input_is_stored_in_the_discrete_table() -> None:
    mapping = Mapping.model_validate(
        {
            "manufacturer": "x",
            "model": "x",
            "description": "x",
            "source": {"title": "x"},
            "entities": {
                "fault": {"name": "Fault", "address": 4, "table": "discrete"},
                "relay": {"name": "Relay", "address": 4, "table": "coil", "access": "rw"},
            },
        }
    )
    points = mapping.points()
    assert words_for(points["fault"], True, {}) == {(Table.DISCRETE, 4): 1}
    assert words_for(points["relay"], True, {}) == {(Table.COIL, 4): 1}
