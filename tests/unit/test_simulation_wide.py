"""The simulator holds half floats and 64-bit values like any number: a plausible start
within the type's range, values stored and read back whole, counters that count on."""

from __future__ import annotations

import random

import pytest

from bridge.core.codec import decode
from bridge.core.simulation import advance, build_movers, initial_image, number_range, words_for
from tests.factory import make_mapping

ENTITIES = {
    "energy": {
        "name": "Energy",
        "address": 0,
        "type": "u64",
        "unit": "Wh",
        "ha": {"device_class": "energy", "state_class": "total_increasing"},
    },
    "balance": {"name": "Balance", "address": 4, "type": "s64", "scale": 0.01, "unit": "kWh"},
    "voltage": {
        "name": "Voltage",
        "address": 8,
        "type": "f64",
        "unit": "V",
        "ha": {"device_class": "voltage"},
    },
    "temperature": {
        "name": "Temperature",
        "address": 12,
        "type": "f16",
        "unit": "°C",
        "ha": {"device_class": "temperature"},
    },
    "setpoint": {"name": "Setpoint", "address": 13, "type": "f16", "access": "rw"},
    "limit": {
        "name": "Limit",
        "address": 14,
        "type": "u64",
        "access": "rw",
        "word_order": "little",
    },
}
MAPPING = make_mapping(ENTITIES)
POINTS = MAPPING.points()


@pytest.mark.parametrize("key", list(ENTITIES))
def test_each_starts_at_a_plausible_number_within_its_range(key: str) -> None:
    image = initial_image(MAPPING, POINTS)
    value = decode(POINTS[key], image)
    low, high = number_range(POINTS[key])
    assert isinstance(value, int | float)
    assert low <= value <= high
    assert high <= 65504 or POINTS[key].entity.data_type.value != "f16"


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("limit", (1 << 64) - 5),
        ("balance", -123456789012.34),
        ("setpoint", 42.5),
        ("voltage", 231.125),
    ],
)
def test_a_value_is_stored_whole_and_reads_back(key: str, value: float) -> None:
    image = initial_image(MAPPING, POINTS)
    image |= words_for(POINTS[key], value, image)
    assert decode(POINTS[key], image) == value


def test_a_64_bit_counter_counts_on() -> None:
    image = initial_image(MAPPING, POINTS)
    before = decode(POINTS["energy"], image)
    movers = build_movers(POINTS, image)
    image |= advance(movers, image, random.Random(1), seconds=3600.0)
    after = decode(POINTS["energy"], image)
    assert isinstance(before, int) and isinstance(after, int)
    assert after > before
