"""Counters never go backwards by accident (bridge/core/counters.py)."""

from __future__ import annotations

import pytest

from bridge.core.counters import (
    CONFIRM,
    Counter,
    CounterRule,
    Kind,
    counters_of,
    is_counter,
)
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.core.state import NEVER_RESET, state_document

U16 = CounterRule(wrap=65536.0)


def run(counter: Counter, readings: list[object]) -> list[tuple[Kind, float | None]]:
    return [(r.kind, r.value) for r in map(counter.read, readings)]


def test_rises_are_published_as_read() -> None:
    assert run(Counter(U16), [5, 5, 6, 100]) == [
        (Kind.FIRST, 5),
        (Kind.RISE, 5),
        (Kind.RISE, 6),
        (Kind.RISE, 100),
    ]


@pytest.mark.parametrize(
    ("readings", "reason"),
    [
        ([19930, 0, 19940], "zero"),  # one read of 0 after a reconnect
        ([19999, 10000, 20000], "lower"),  # a torn read
        ([19940, 19939, 19941], "jitter"),  # -1 LSB
        ([19940, None, 19941], "not a number"),  # a failed read
        ([19940, "sensor open", 19941], "not a number"),  # a sentinel
        ([19940, float("nan"), 19941], "not a number"),
    ],
)
def test_a_single_bad_reading_is_held_and_the_count_goes_on(
    readings: list[object], reason: str
) -> None:
    counter = Counter(CounterRule())
    first, bad, after = map(counter.read, readings)
    assert bad.kind is Kind.HELD and bad.value == first.value and bad.reason == reason
    assert after.kind is Kind.RISE and after.value == readings[2]


def test_a_decrease_is_a_reset_once_confirmed_and_said_once() -> None:
    counter = Counter(CounterRule())
    outcomes = run(counter, [500, 7, 7, 7, 7, 8])
    assert outcomes == [
        (Kind.FIRST, 500),
        (Kind.HELD, 500),
        (Kind.HELD, 500),
        (Kind.RESET, 7),
        (Kind.RISE, 7),
        (Kind.RISE, 8),
    ]


def test_a_new_count_rising_from_the_reset_confirms_it_too() -> None:
    """A run-time counter cleared at a start counts on while it is being confirmed."""
    counter = Counter(CounterRule())
    assert run(counter, [500, 0, 1, 2]) == [
        (Kind.FIRST, 500),
        (Kind.HELD, 500),
        (Kind.HELD, 500),
        (Kind.RESET, 2),
    ]
    assert counter.read(2).kind is Kind.RISE


def test_lower_readings_that_fall_again_start_the_confirmation_over() -> None:
    counter = Counter(CounterRule())
    assert run(counter, [500, 9, 8, 8, 8]) == [
        (Kind.FIRST, 500),
        (Kind.HELD, 500),
        (Kind.HELD, 500),  # 8 < 9: a new run of one
        (Kind.HELD, 500),
        (Kind.RESET, 8),
    ]


def test_a_good_reading_between_bad_ones_ends_their_run() -> None:
    counter = Counter(CounterRule())
    kinds = [k for k, _ in run(counter, [500, 0, 0, 501, 0, 0, 502])]
    assert Kind.RESET not in kinds


def test_jitter_never_becomes_a_reset_however_long_it_lasts() -> None:
    counter = Counter(CounterRule(lsb=0.1))
    outcomes = run(counter, [100.0] + [99.7] * 10 + [100.1])
    assert {k for k, _ in outcomes[1:-1]} == {Kind.HELD}
    assert {v for _, v in outcomes[1:-1]} == {100.0}
    assert outcomes[-1] == (Kind.RISE, 100.1)


def test_a_decrease_just_over_the_jitter_is_confirmed_like_any_other() -> None:
    counter = Counter(CounterRule(lsb=0.1, confirm=2))
    assert run(counter, [100.0, 99.6, 99.6]) == [
        (Kind.FIRST, 100.0),
        (Kind.HELD, 100.0),
        (Kind.RESET, 99.6),
    ]


@pytest.mark.parametrize("confirm", [1, 2, 5])
def test_confirm_is_the_number_of_lower_readings(confirm: int) -> None:
    counter = Counter(CounterRule(confirm=confirm))
    kinds = [k for k, _ in run(counter, [1000] + [10] * confirm)]
    assert kinds == [Kind.FIRST] + [Kind.HELD] * (confirm - 1) + [Kind.RESET]


def test_a_u16_rollover_is_a_continuation() -> None:
    counter = Counter(U16)
    assert run(counter, [65530, 65535, 3, 10]) == [
        (Kind.FIRST, 65530),
        (Kind.RISE, 65535),
        (Kind.WRAP, 65539),
        (Kind.RISE, 65546),
    ]
    assert run(counter, [65000, 2]) == [(Kind.RISE, 130536), (Kind.WRAP, 131074)]


def test_a_zero_at_the_top_of_the_width_is_held_not_taken_for_a_wrap() -> None:
    counter = Counter(U16)
    assert run(counter, [65530, 0, 4]) == [
        (Kind.FIRST, 65530),
        (Kind.HELD, 65530),
        (Kind.WRAP, 65540),
    ]


def test_a_drop_from_the_middle_of_the_width_is_no_wrap() -> None:
    counter = Counter(U16)
    assert run(counter, [30000, 3]) == [(Kind.FIRST, 30000), (Kind.HELD, 30000)]


def test_a_reset_after_wraps_starts_from_the_value_read() -> None:
    counter = Counter(CounterRule(wrap=65536.0, confirm=1))
    run(counter, [65535, 1, 20000])
    assert counter.read(5) == counter.read(5).__class__(Kind.RESET, 5, 85536)
    assert counter.read(6).value == 6


def test_a_seed_is_what_the_first_reading_is_checked_against() -> None:
    counter = Counter(CounterRule())
    assert counter.seed(19930)
    assert run(counter, [0, 19931]) == [(Kind.HELD, 19930), (Kind.RISE, 19931)]


def test_a_seed_below_what_was_read_since_changes_nothing() -> None:
    counter = Counter(CounterRule())
    counter.read(200)
    assert not counter.seed(150)
    assert not counter.seed(None)  # type: ignore[arg-type]
    assert counter.published == 200


def test_a_seed_above_what_was_read_since_wins() -> None:
    counter = Counter(CounterRule())
    counter.read(0)  # read while the broker was away
    assert counter.seed(19930)
    assert counter.read(19935).value == 19935


def test_a_seed_past_the_width_keeps_the_wraps() -> None:
    counter = Counter(U16)
    counter.seed(65536 + 100)
    assert run(counter, [150, 60]) == [(Kind.RISE, 65686), (Kind.HELD, 65686)]


def test_the_rule_of_a_point_follows_its_type_scale_and_option() -> None:
    points = load_mapping(builtin_mapping_path("smartgen_hgm6100")).points({"can": "yes"})
    energy = CounterRule.of(points["energy"])
    assert energy == CounterRule(confirm=CONFIRM, wrap=65536 * 10000, lsb=1.0)
    hours = CounterRule.of(points["ecu_engine_hours"], confirm=5)
    assert hours.wrap == pytest.approx(6553.6) and hours.lsb == 0.1 and hours.confirm == 5


def test_every_counter_of_the_shipped_mappings_is_found() -> None:
    found = {}
    for name, options in [
        ("smartgen_hgm6100", {"can": "yes"}),
        ("nastec_vasco", {}),
        ("soft_starter", {}),
    ]:
        points = list(load_mapping(builtin_mapping_path(name)).points(options).values())
        found[name] = sorted(counters_of(points))
        assert all(is_counter(p) == (p.key in found[name]) for p in points)
    assert found["smartgen_hgm6100"] == [
        "ecu_engine_hours",
        "ecu_fuel_total",
        "energy",
        "run_hours",
        "start_count",
    ]
    assert len(found["nastec_vasco"]) == 7
    assert found["soft_starter"] == ["cumulative_run_time", "current_run_time"]


def test_a_total_counter_carries_its_last_reset_in_the_document() -> None:
    mapping = load_mapping(builtin_mapping_path("soft_starter"))
    points = mapping.points({})
    values = {"current_run_time": 12, "cumulative_run_time": 3400}
    document = state_document(mapping, points, values)
    assert document["last_reset"] == {"current_run_time": NEVER_RESET}
    later = {"current_run_time": "2026-11-27T22:00:00+00:00"}
    assert state_document(mapping, points, values, later)["last_reset"] == later
    genset = load_mapping(builtin_mapping_path("smartgen_hgm6100"))
    assert "last_reset" not in state_document(genset, genset.points({}), {})


@pytest.mark.parametrize("seed", [10**400, float("inf"), float("nan"), True, "19930", None])
def test_a_seed_that_is_no_number_a_float_holds_is_ignored(seed: object) -> None:
    counter = Counter(CounterRule(wrap=65536.0))
    assert not counter.seed(seed)  # type: ignore[arg-type]
    assert counter.read(10**400).kind is Kind.HELD  # and a reading neither ends anything
    assert counter.read(5).value == 5
