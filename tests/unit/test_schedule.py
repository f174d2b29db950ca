"""Poll intervals per entity (bridge/core/schedule.py): what an entity's interval is, when
each interval is due (a fake clock), and the plans of intervals due together
(bridge/core/device_state.py)."""

from __future__ import annotations

import math
from collections import Counter
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bridge.core.device_state import DeviceState
from bridge.core.discovery_entity import ComponentContext
from bridge.core.entity import Entity, PollClass, Table
from bridge.core.mapping import load_mapping
from bridge.core.planner import cost_of
from bridge.core.schedule import ONCE, PollRule, Schedule, parse_poll
from bridge.core.timing import LinkTiming
from bridge.core.topics import Topics
from bridge.errors import MappingError
from tests.factory import make_mapping

H = Table.HOLDING
TIMING = LinkTiming()


@pytest.mark.parametrize(
    ("given_", "expected"),
    [
        ("fast", PollClass.FAST),
        ("once", PollClass.ONCE),
        (10, 10.0),
        (2.5, 2.5),
        ("10s", 10.0),
        ("1m", 60.0),
        ("1h", 3600.0),
        ("500ms", 0.5),
        (0.1, 0.1),
        (86400, 86400.0),
    ],
)
def test_a_poll_is_a_class_or_an_interval(given_: object, expected: object) -> None:
    assert parse_poll(given_) == expected


@pytest.mark.parametrize(
    ("given_", "message"),
    [
        (0, "within 0.1 s and 2678400 s"),
        (0.05, "within 0.1 s"),
        ("2d", "poll must be fast, slow, once or an interval"),
        (2678401, "(31 days), not 2678401 s"),
        (-5, "cannot be negative"),
        (True, "poll must be"),
        ("Fast", "poll must be"),
        (float("nan"), "finite"),
        (None, "poll must be"),
    ],
)
def test_a_bad_poll_is_refused_with_the_accepted_forms(given_: object, message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_poll(given_)


def test_a_bad_interval_in_a_mapping_names_file_entity_and_field(tmp_path: Path) -> None:
    path = tmp_path / "pump.yaml"
    path.write_text(
        "manufacturer: Test\nmodel: T1\ndescription: test\nsource: {title: manual}\n"
        "entities:\n  speed: {name: Speed, address: 1, poll: 10ms}\n"
    )
    with pytest.raises(MappingError) as caught:
        load_mapping(path)
    assert caught.value.source == str(path)
    (issue,) = caught.value.issues
    assert issue.startswith("entities.speed.poll: ")
    assert "a poll interval must be within 0.1 s and 2678400 s (31 days), not 0.01 s" in issue


def test_an_entity_interval_of_its_own_is_kept_and_has_no_class() -> None:
    entity = Entity.model_validate({"name": "T", "address": 1, "poll": "10s"})
    assert (entity.poll, entity.poll_spec, entity.poll_class) == (10.0, 10.0, None)
    writable = Entity.model_validate({"name": "S", "address": 1, "access": "rw"})
    assert (writable.poll_spec, writable.poll_class) == (PollClass.SLOW, PollClass.SLOW)


ENTITIES = {
    "grid_voltage": {"name": "Grid voltage", "address": 1},
    "grid_current": {"name": "Grid current", "address": 2, "poll": "slow"},
    "temperature": {"name": "Temperature", "address": 3, "poll": 30},
    "serial": {"name": "Serial", "address": 4, "poll": "once"},
    "setpoint": {"name": "Setpoint", "address": 5, "access": "rw"},
}


def test_the_device_config_wins_an_exact_key_over_a_glob_then_the_first_glob() -> None:
    entities = make_mapping(ENTITIES).entities
    rule = PollRule(
        fast=2.0,
        slow=60.0,
        entities=(("grid_*", 5.0), ("grid_current", PollClass.FAST), ("*", 600.0)),
    )
    assert rule.intervals(entities) == {
        "grid_voltage": 5.0,  # the first glob
        "grid_current": 2.0,  # its key, though a glob before it matches
        "temperature": 600.0,
        "serial": 600.0,
        "setpoint": 600.0,
    }
    assert PollRule(3.0, 90.0).intervals(entities) == {
        "grid_voltage": 3.0,
        "grid_current": 90.0,
        "temperature": 30.0,  # the mapping's own
        "serial": ONCE,
        "setpoint": 90.0,
    }
    assert rule.unmatched(entities) == []
    assert PollRule(entities=(("grid_volts", 5.0), ("x*", 1.0))).unmatched(entities) == [
        "grid_volts",
        "x*",
    ]


# --- the schedule, on a fake clock ------------------------------------------------------------


def test_multiples_fall_on_one_tick_and_missed_ticks_are_skipped() -> None:
    schedule = Schedule.of([5.0, 60.0, ONCE], origin=100.0)
    assert schedule.due(100.0) == {5.0, 60.0, ONCE}
    schedule.served([5.0, 60.0, ONCE], ended=100.2)
    assert schedule.next_due == {5.0: 105.0, 60.0: 160.0, ONCE: math.inf}
    schedule.served([5.0], ended=157.0)  # a pass that ran late: 110..155 are skipped
    assert schedule.next_due[5.0] == 160.0
    assert schedule.due(160.0) == {5.0, 60.0}  # together, in one pass
    schedule.retry(ONCE, 130.0)
    assert schedule.wake() == 130.0


@given(
    origin=st.floats(0, 1e6),
    interval=st.sampled_from([0.1, 0.5, 2.0, 5.0, 10.0, 60.0, 600.0, 86400.0]),
    late=st.floats(0, 1e5),
)
def test_the_next_tick_is_after_the_pass_and_on_the_grid(
    origin: float, interval: float, late: float
) -> None:
    schedule = Schedule.of([interval], origin)
    ended = origin + late
    tick = schedule.tick_after(interval, ended)
    assert ended < tick <= ended + interval * (1 + 1e-9)
    steps = (tick - origin) / interval
    assert abs(steps - round(steps)) < 1e-6


# a mapping of 5 s, 60 s and 600 s entities on neighbouring registers
SIMULATED = make_mapping(
    {
        **{f"power_{i}": {"name": f"Power {i}", "address": i, "poll": 5} for i in range(1, 5)},
        **{f"energy_{i}": {"name": f"Energy {i}", "address": 4 + i, "poll": "1m"} for i in (1, 2)},
        "temperature": {"name": "Temperature", "address": 8, "poll": "60s"},
        "fault": {"name": "Fault", "address": 20, "poll": 5},
        "lifetime": {"name": "Lifetime", "address": 21, "type": "u32", "poll": "10m"},
        "firmware": {"name": "Firmware", "address": 40, "poll": "once"},
        "limit": {"name": "Limit", "address": 9, "access": "rw"},  # slow: 60 s
    }
)


def simulate(state: DeviceState, minutes: float) -> tuple[dict[str, list[float]], list[Any]]:
    """Run the poll loop on a fake clock, each pass taking its plan's bus time: the times
    each key was decoded, and the plans of the passes."""
    now = 0.0
    schedule = Schedule.of(set(state.intervals.values()), now)
    decoded: dict[str, list[float]] = {key: [] for key in state.points}
    passes = []
    while now < minutes * 60:
        due = schedule.due(now)
        plan = state.plan(due)
        passes.append((due, plan))
        for key in state.keys_of(due):
            decoded[key].append(now)
        now += cost_of(plan, TIMING)
        schedule.served(due, now)
        now = max(now, schedule.wake())
    return decoded, passes


def test_over_half_an_hour_each_interval_is_kept_within_ten_percent() -> None:
    state = DeviceState(SIMULATED, {}, timing=TIMING, recheck=60.0)
    decoded, passes = simulate(state, 30)
    for key, times in decoded.items():
        nominal = state.intervals[key]
        if nominal == ONCE:
            assert times[0] == 0.0
            continue
        gaps = [b - a for a, b in pairwise(times)]
        assert len(times) >= 30 * 60 / nominal
        # read along in a hole can only come sooner; never later than 10 % over
        assert all(gap <= nominal * 1.1 for gap in gaps), (key, max(gaps))
    for key in ("power_1", "energy_1", "lifetime"):
        nominal = state.intervals[key]
        gaps = [b - a for a, b in pairwise(decoded[key])]
        assert all(abs(gap - nominal) <= 0.1 * nominal for gap in gaps), key
    mixed = [(due, plan) for due, plan in passes if len(due - {ONCE}) > 1]
    assert len(mixed) == 30  # at 0, 60, .. 1740 s: 5 s and 60 s (and 600 s) in one pass
    for _, plan in passes:  # no register read twice in a pass
        words = Counter((read.table, a) for read in plan for a in read.span)
        assert max(words.values()) == 1


def test_intervals_due_together_share_reads_and_cost_no_more_than_apart() -> None:
    state = DeviceState(SIMULATED, {}, timing=TIMING, recheck=60.0)
    together = state.plan([5.0, 60.0])
    apart = state.plan([5.0]) + state.plan([60.0])
    assert len(together) < len(apart)  # registers 1..9: one read, not two
    assert cost_of(together, TIMING) <= cost_of(apart, TIMING)
    assert state.plan([60.0, 5.0]) is together  # one plan per set of due intervals
    state.forget_plans()
    assert state.plan([5.0, 60.0]) is not together


def test_an_entity_not_due_in_a_hole_read_through_is_decoded_too() -> None:
    mapping = make_mapping(
        {
            "a": {"name": "A", "address": 1, "poll": 5},
            "b": {"name": "B", "address": 2, "poll": 600},
            "c": {"name": "C", "address": 3, "poll": 5},
            "far": {"name": "Far", "address": 90, "poll": 600},
        }
    )
    state = DeviceState(mapping, {}, timing=TIMING, recheck=60.0)
    (read,) = state.plan([5.0])  # 1..3 in one read: cheaper than two
    assert (read.address, read.count) == (1, 3)
    assert state.keys_of([5.0]) == ("a", "b", "c")  # b is read along: decoded, fresh
    assert state.keys_of([600.0]) == ("b", "far")
    fresh: set[tuple[Table, int]] = set()
    state.keep(read, (10, 20, 30), fresh)
    assert state.decode_fresh(state.keys_of([5.0]), fresh) == {"a", "b", "c"}
    assert state.values == {"a": 10, "b": 20, "c": 30}


def test_the_device_config_moves_an_entity_between_plans() -> None:
    rule = PollRule(2.0, 60.0, (("temperature", 5.0), ("energy_*", PollClass.FAST)))
    state = DeviceState(SIMULATED, {}, timing=TIMING, recheck=60.0, poll=rule)
    assert state.intervals["temperature"] == 5.0
    assert state.intervals["energy_1"] == 2.0
    assert "temperature" in state.keys_of([5.0])
    assert state.plan([PollClass.FAST]) == state.plan([2.0])


# --- expire_after -------------------------------------------------------------------------------


def context(**fields: Any) -> ComponentContext:
    values: dict[str, Any] = {
        "topics": Topics("modbus"),
        "device_id": "dev",
        "allow_dangerous_writes": False,
        "fast_interval": 2.0,
        "slow_interval": 60.0,
        "state_refresh": 300.0,
        "units": {},
        "limits": {},
    }
    return ComponentContext(**(values | fields))


@pytest.mark.parametrize(
    ("poll", "key", "intervals", "expected"),
    [
        (PollClass.FAST, "", {}, 602),  # today's rule: two refreshes and one poll
        (PollClass.SLOW, "", {}, 660),
        (PollClass.ONCE, "", {}, 660),
        (600.0, "", {}, 1200),  # the mapping's own interval
        (PollClass.FAST, "t", {"t": 3600.0}, 4200),  # as the device config resolved it
        (PollClass.FAST, "t", {"t": ONCE}, 660),
    ],
)
def test_expire_after_outlives_the_entitys_own_interval(
    poll: PollClass | float, key: str, intervals: dict[str, float], expected: int
) -> None:
    got = context(intervals=intervals).expire_after(poll, key)
    assert got == expected
    interval = intervals.get(key, poll if isinstance(poll, float) else 60.0)
    assert got > (interval if math.isfinite(interval) else 0)  # Home Assistant needs more
