"""Simulated counter faults (bridge/core/simulation_counter.py) and counters rolling over."""

from __future__ import annotations

import random

import pytest

from bridge.core.codec import decode
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.core.simulation import Mover, advance, words_for
from bridge.core.simulation_counter import (
    REBOOT_READS,
    CounterFault,
    check_counter,
    counter_fault,
    fault_image,
    fault_reads,
)
from bridge.errors import ValueRejectedError

GENSET = load_mapping(builtin_mapping_path("smartgen_hgm6100")).points({"can": "yes"})
NASTEC = load_mapping(builtin_mapping_path("nastec_vasco")).points({})
STARTER = load_mapping(builtin_mapping_path("soft_starter")).points({})


def at(point_key: str, points: dict, value: float) -> dict:
    point = points[point_key]
    return words_for(point, value, {})


def read(points: dict, key: str, image: dict, answer: dict) -> object:
    return decode(points[key], image | answer)


@pytest.mark.parametrize(
    ("fault", "reads"),
    [
        (CounterFault.ZERO, [0]),
        (CounterFault.REBOOT, [0] * REBOOT_READS),
        (CounterFault.JITTER, [19998]),
        (CounterFault.TEAR, [10000]),  # 1 * 10000 + 9999 read with the low word at 0
        (CounterFault.WRAP, []),
        (CounterFault.RESET, []),
    ],
)
def test_what_the_next_reads_answer(fault: CounterFault, reads: list[float]) -> None:
    image = at("energy", GENSET, 19999)
    answers = fault_reads(GENSET["energy"], fault, image)
    assert [read(GENSET, "energy", image, a) for a in answers] == reads


def test_a_tear_of_a_little_endian_pair_zeroes_its_lower_address() -> None:
    point = STARTER["cumulative_run_time"]  # minutes at the lower address, radix 60
    image = words_for(point, 3 * 60 + 59, {})
    (answer,) = fault_reads(point, CounterFault.TEAR, image)
    assert decode(point, image | answer) == 180
    assert answer[(point.table, point.address)] == 0


def test_a_reset_clears_the_count_and_a_wrap_puts_it_two_below_the_width() -> None:
    point = NASTEC["motor_life"]
    image = words_for(point, 5000, {})
    assert decode(point, image | fault_image(point, CounterFault.RESET, image)) == 0
    assert decode(point, image | fault_image(point, CounterFault.WRAP, image)) == 2**32 - 2


def test_a_counter_past_its_width_rolls_over() -> None:
    point = NASTEC["motor_life"]
    image = words_for(point, 2**32 - 2, {})
    mover = Mover(point, 0, 2**32, 1, counter=True, per_hour=3600 * 5)
    image |= advance((mover,), image, random.Random(0), seconds=1.0)
    assert decode(point, image) == 3


def test_faults_are_refused_on_what_is_not_a_counter_or_cannot_do_them() -> None:
    with pytest.raises(ValueRejectedError, match="not a counter"):
        check_counter(GENSET["oil_pressure"])
    with pytest.raises(ValueRejectedError, match="one of zero, reboot"):
        counter_fault("melt")
    hours = GENSET["ecu_engine_hours"]  # one register, scale 0.1
    image = words_for(hours, 100.0, {})
    with pytest.raises(ValueRejectedError, match="one register"):
        fault_reads(hours, CounterFault.TEAR, image)
    fuel = GENSET["ecu_fuel_total"]
    assert decode(fuel, image | fault_image(fuel, CounterFault.WRAP, image)) == 2**32 - 2
