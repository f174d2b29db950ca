"""Every shipped mapping, simulated for an hour: its readings look real.

Each reading with a plausible range (bridge/core/simulation_range.py, or the entity's
``simulate:`` hint) starts and stays inside it, counters never fall and rise at their
rate (run hours by the hour, starts rarely, energy by the simulated power), and a value
that follows another (the pump's set value in use) shows it, also after a write.
"""

from __future__ import annotations

import random

import pytest

from bridge.core.codec import Value, decode
from bridge.core.mapping import builtin_mapping_names, builtin_mapping_path, load_mapping
from bridge.core.simulation import (
    advance,
    build_movers,
    initial_image,
    number_range,
    words_for,
)
from bridge.core.simulation_range import plausible

TICK = 10.0  # seconds
HOUR = int(3600 / TICK)


def number(value: Value) -> float:
    assert isinstance(value, int | float) and not isinstance(value, bool), value
    return float(value)


@pytest.mark.parametrize("name", builtin_mapping_names())
def test_an_hour_of_simulated_readings_stays_plausible(name: str) -> None:
    mapping = load_mapping(builtin_mapping_path(name))
    points = mapping.points(mapping.default_options())
    image = initial_image(mapping, points)
    movers = build_movers(points, image)
    rng = random.Random(1)
    ranged = {}
    for key, point in points.items():
        found = plausible(point)
        if found is not None and point.entity.readable and point.sign is None:
            low, high = number_range(point)
            ranged[key] = (max(found.low, low), min(found.high, high), found)
    counters = [m for m in movers if m.counter]
    start = {m.point.key: number(decode(m.point, image)) for m in counters}
    for _ in range(HOUR):
        before = {m.point.key: number(decode(m.point, image)) for m in counters}
        for key, (low, high, found) in ranged.items():
            if found.per_hour:
                continue
            value = number(decode(points[key], image))
            step = abs(points[key].entity.scale)
            assert low - step <= value <= high + step, f"{name}.{key}: {value} not in {low}..{high}"
        image |= advance(movers, image, rng, TICK)
        for mover in counters:
            key = mover.point.key
            assert number(decode(mover.point, image)) >= before[key], f"{name}.{key} fell"
    for mover in counters:
        key, step = mover.point.key, abs(mover.point.entity.scale)
        rose = number(decode(mover.point, image)) - start[key]
        found = plausible(mover.point)
        assert found is not None, f"{name}.{key}: a counter without a plausible rate"
        most = 25.0 if mover.rate_source is not None else found.per_hour  # the power's top
        assert rose <= most * 1.5 + 2 * step, f"{name}.{key} rose {rose} in an hour"
        if found.per_hour >= 1:
            assert rose > 0, f"{name}.{key} did not count in an hour"


def test_the_genset_reads_like_a_genset() -> None:
    """The values of issue 22: a 24 V battery and charger, phase angles 0/120/240°,
    counters apart (starts, energy and run hours are not one number)."""
    mapping = load_mapping(builtin_mapping_path("smartgen_hgm6100"))
    points = mapping.points(mapping.default_options())
    image = initial_image(mapping, points)
    keys = ["battery_voltage", "charger_voltage", "start_count", "energy", "run_hours"]
    keys += [f"generator_phase_angle_u{p}" for p in "abc"]
    read = {key: decode(points[key], image) for key in keys}
    assert 24 <= number(read["battery_voltage"]) <= 28.8
    assert 24 <= number(read["charger_voltage"]) <= 28.8
    angles = [number(read[f"generator_phase_angle_u{p}"]) for p in "abc"]
    assert angles == [0, 120, 240]
    counts = {number(read[key]) for key in ("start_count", "energy", "run_hours")}
    assert len(counts) == 3
    assert number(read["start_count"]) < number(read["run_hours"]) < number(read["energy"])


def test_the_set_value_in_use_follows_the_set_value() -> None:
    mapping = load_mapping(builtin_mapping_path("nastec_vasco"))
    points = mapping.points(mapping.default_options())
    image = initial_image(mapping, points)
    assert decode(points["set_value"], image) == decode(points["set_value_active"], image) != 0
    movers = build_movers(points, image)
    image |= words_for(points["set_value"], 5.5, image)  # a write
    image |= advance(movers, image, random.Random(0))
    assert decode(points["set_value_active"], image) == 5.5
