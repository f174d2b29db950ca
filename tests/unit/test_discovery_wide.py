"""Discovery of half floats and 64-bit values: a 64-bit counter is a sensor of whole numbers,
a float has no fixed decimals, and a writable float offers its type's whole range (not
0..0), scaled, never infinite."""

from __future__ import annotations

import json
import sys
from typing import Any

import pytest

from tests.unit.test_discovery import _one


def test_a_64_bit_counter_is_a_number_of_whole_units() -> None:
    config = _one({"type": "u64", "unit": "Wh", "ha": {"state_class": "total_increasing"}})
    assert config is not None
    assert (config["platform"], config["state_class"]) == ("sensor", "total_increasing")
    assert config["suggested_display_precision"] == 0


@pytest.mark.parametrize("kind", ["f16", "f64"])
def test_a_float_has_no_fixed_decimals(kind: str) -> None:
    config = _one({"type": kind})
    assert config is not None
    assert "suggested_display_precision" not in config


@pytest.mark.parametrize(
    ("entity", "low", "high"),
    [
        ({"type": "f16"}, -65504.0, 65504.0),
        ({"type": "f16", "scale": 0.1}, -6550.4, 6550.4),
        ({"type": "f32"}, -3.4028234663852886e38, 3.4028234663852886e38),
        ({"type": "f64", "scale": 10}, -sys.float_info.max, sys.float_info.max),
        ({"type": "f64", "min": 0, "max": 5}, 0, 5),
        ({"type": "u64"}, 0, (1 << 64) - 1),
        ({"type": "s64"}, -(1 << 63), (1 << 63) - 1),
    ],
)
def test_a_writable_number_offers_its_type_s_range(
    entity: dict[str, Any], low: float, high: float
) -> None:
    config = _one(entity | {"access": "rw"})
    assert config is not None
    assert config["min"] == pytest.approx(low)
    assert config["max"] == pytest.approx(high)
    json.dumps(config, allow_nan=False)  # finite: Home Assistant's JSON takes it
