"""The simulator's plausible ranges: the table by unit and device class, the mapping's
``simulate:`` hints over it, energy counted by the power, the count-on-read quirk."""

from __future__ import annotations

import random
from typing import Any

import pytest
from pydantic import ValidationError

from bridge.core.codec import decode
from bridge.core.simulation import advance, build_movers, count_once, initial_image, words_for
from bridge.core.simulation_range import Plausible, energy_source, plausible
from tests.factory import make_mapping


def points_of(entities: dict[str, dict[str, Any]]) -> Any:
    mapping = make_mapping(entities)
    return mapping, mapping.points()


def reading(address: int, **fields: Any) -> dict[str, Any]:
    return {"name": f"Reading {address}", "address": address} | fields


@pytest.mark.parametrize(
    ("key", "fields", "expected"),
    [
        ("battery_voltage", {"unit": "V", "ha": {"state_class": "measurement"}}, 26.8),
        ("voltage_uab", {"unit": "V", "ha": {"state_class": "measurement"}}, 400),
        ("phase_angle_ub", {"unit": "°", "ha": {"state_class": "measurement_angle"}}, 120),
        ("start_count", {"ha": {"state_class": "total_increasing"}}, 420),
        ("raw_word", {"ha": {"state_class": "measurement"}}, None),  # nothing known
        ("rated_voltage", {"unit": "V"}, None),  # a rating, not a reading
        ("level", {"simulate": {"min": 1, "max": 3}}, 2),  # a hint alone: its middle
        ("floor", {"simulate": {"min": 1}}, 1),
        (
            "pressure",
            {"unit": "bar", "ha": {"state_class": "measurement"}, "simulate": {"max": 2.5}},
            2.5,
        ),
    ],
)
def test_the_typical_value_by_unit_words_and_hint(
    key: str, fields: dict[str, Any], expected: float | None
) -> None:
    _, points = points_of({key: reading(1, scale=0.1, **fields)})
    found = plausible(points[key])
    assert (None if found is None else found.typical) == expected


def test_a_hint_out_of_order_is_refused() -> None:
    with pytest.raises(ValidationError, match="min <= typical <= max"):
        points_of({"level": reading(1, simulate={"min": 3, "max": 1})})


def test_energy_counts_by_the_total_power_and_count_once_steps_every_counter() -> None:
    power = {"unit": "kW", "ha": {"device_class": "power", "state_class": "measurement"}}
    mapping, points = points_of(
        {
            "power_a": reading(1, **power),
            "power": reading(2, **power),
            "energy": reading(3, unit="kWh", ha={"state_class": "total_increasing"}),
        }
    )
    source = energy_source(points["energy"], points)
    assert source == (points["power"], 1.0)
    image = initial_image(mapping, points)
    image |= words_for(points["power"], 0, image)  # stopped: no energy
    movers = tuple(m for m in build_movers(points, image) if m.counter)
    start = decode(points["energy"], image)
    assert advance(movers, image, random.Random(0), 3600) == {}
    assert decode(points["energy"], image | count_once(movers, image)) == start + 1
    assert plausible(points["energy"]) == Plausible(0, 1e12, 15000, 15)
