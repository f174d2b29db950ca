"""Durations as written in configs and mappings (bridge/core/duration.py)."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from bridge.core.duration import parse_duration
from bridge.core.protocol import Keepalive


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("500ms", 0.5),
        ("2s", 2.0),
        ("1.5m", 90.0),
        ("2min", 120.0),
        ("1h", 3600.0),
        (" 3 s ", 3.0),
        ("4", 4.0),
        (7, 7.0),
        (0.25, 0.25),
        (0, 0.0),
    ],
)
def test_accepted_forms(text: object, seconds: float) -> None:
    assert parse_duration(text) == seconds


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (True, "a number of seconds"),
        ("2 days", "use e.g. 500ms"),
        ("-1s", "use e.g. 500ms"),
        (-1, "cannot be negative"),
        (math.nan, "finite"),
        (math.inf, "finite"),
        ("1e999", "use e.g. 500ms"),
        (None, "invalid duration"),
    ],
)
def test_refused_with_the_accepted_forms(value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_duration(value)


def test_a_keepalive_of_zero_is_refused() -> None:
    """Its reads come every half interval: zero would never let the event loop rest."""
    with pytest.raises(ValidationError, match="greater than 0"):
        Keepalive(interval=0)
    assert Keepalive.model_validate({"interval": "20s"}).interval == 20.0
