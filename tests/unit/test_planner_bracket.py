"""Bracketed reads (bridge/core/bracket.py): a ``scale_by`` value too far from its exponent
for one read is read with its exponent read before and after it, and decoded only when
every reading of the exponent around it agrees. Pure: the planner, the verdict and the
device state, fed as the bus would answer."""

from __future__ import annotations

from typing import Any

from bridge.core.bracket import Bracket, Verdict, brackets_of, needs_after, verdict
from bridge.core.device_state import DeviceState
from bridge.core.entity import PollClass, Table
from bridge.core.mapping import Mapping
from bridge.core.planner import cost_of, limits_for, plan_reads
from bridge.core.request import Read
from bridge.core.timing import LinkTiming
from tests.factory import make_mapping

H = Table.HOLDING
DUE = [PollClass.FAST, PollClass.SLOW]


def curve(**top: Any) -> Mapping:
    """SunSpec's layout: factors at a model's top, curve points 300 registers on (two of
    them share one factor), a value near its own factor, a plain value."""
    return make_mapping(
        {
            "v_sf": {"name": "V scale", "address": 0, "type": "s16"},
            "w_sf": {"name": "W scale", "address": 1, "type": "s16"},
            "near": {"name": "Near", "address": 2, "scale_by": "w_sf"},
            "plain": {"name": "Plain", "address": 3},
            "v1": {"name": "V1", "address": 300, "scale_by": "v_sf"},
            "v2": {"name": "V2", "address": 301, "type": "s16", "scale_by": "v_sf"},
        },
        **top,
    )


def plan_of(mapping: Mapping, **limits: Any) -> Any:
    return plan_reads(mapping.points().values(), limits_for(mapping, **limits))


# --- the planner ------------------------------------------------------------------------------


def test_a_value_300_registers_from_its_exponent_gets_a_bracketed_plan() -> None:
    plan = plan_of(curve())  # max 125 registers a read
    assert plan.unplannable == ()
    assert plan.reads == (Read(H, 0, 4), Read(H, 300, 2))
    # the plan's read of v_sf (first) serves before the values; one read after them
    assert plan.bracketed == (Bracket(Read(H, 0, 1), ("v1", "v2"), before=False, after=True),)


def test_two_values_of_one_exponent_share_its_reads() -> None:
    plan = plan_of(curve())
    assert len(plan.bracketed) == 1
    assert plan.extra == (Read(H, 0, 1),)  # one extra read a pass for both values


def test_values_near_their_exponent_are_planned_as_before() -> None:
    near = make_mapping(
        {
            "w_sf": {"name": "W scale", "address": 1, "type": "s16"},
            "near": {"name": "Near", "address": 2, "scale_by": "w_sf"},
            "plain": {"name": "Plain", "address": 3},
        }
    )
    plan = plan_of(near)
    assert plan.reads == (Read(H, 1, 3),)
    assert plan.bracketed == () and plan.extra == ()


def test_the_cost_of_a_plan_counts_its_bracket_reads() -> None:
    timing = LinkTiming()
    plan = plan_of(curve())
    assert cost_of(plan, timing) == sum(timing.read_cost(r) for r in (*plan.reads, *plan.extra))
    assert cost_of(plan, timing) > cost_of(plan.reads, timing)


def test_a_value_due_alone_has_its_far_exponent_planned() -> None:
    mapping = curve()
    points = mapping.points()
    plan = plan_reads([points["v1"]], limits_for(mapping))
    assert plan.reads == (Read(H, 0, 1), Read(H, 300, 1))
    assert plan.bracketed == (Bracket(Read(H, 0, 1), ("v1",), before=False, after=True),)


def test_an_exponent_after_its_values_is_read_again_before_them() -> None:
    mapping = make_mapping(
        {
            "v": {"name": "V", "address": 0, "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 200, "type": "s16"},
        }
    )
    plan = plan_of(mapping)
    assert plan.bracketed == (Bracket(Read(H, 200, 1), ("v",), before=True, after=False),)


def test_values_on_both_sides_of_their_exponent_cost_two_reads() -> None:
    mapping = make_mapping(
        {
            "low": {"name": "Low", "address": 0, "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 200, "type": "s16"},
            "high": {"name": "High", "address": 400, "scale_by": "sf"},
        }
    )
    plan = plan_of(mapping)
    assert plan.bracketed == (Bracket(Read(H, 200, 1), ("high", "low"), before=True, after=True),)
    assert len(plan.extra) == 2


def test_brackets_of_reads_the_order_of_the_plan() -> None:
    reads = [Read(H, 0, 10), Read(H, 100, 10)]
    assert brackets_of([("v", H, range(100, 101), 5)], reads) == (
        Bracket(Read(H, 5, 1), ("v",), before=False, after=True),
    )
    assert brackets_of([("v", H, range(5, 6), 3)], reads) == ()  # one read holds both


# --- the verdict ------------------------------------------------------------------------------


def test_the_verdict_needs_one_reading_before_and_one_after() -> None:
    assert verdict([(1, 0xFFFE), (5, 0xFFFE)], {3}) is Verdict.SAME
    assert verdict([(1, 0xFFFE), (5, 0xFFFD)], {3}) is Verdict.CHANGED
    assert verdict([(1, 0xFFFE)], {3}) is Verdict.UNCHECKED
    assert verdict([(5, 0xFFFE)], {3}) is Verdict.UNCHECKED
    # a reading between, different, is a change even when the two ends agree
    assert verdict([(1, 2), (3, 1), (6, 2)], {2, 4}) is Verdict.CHANGED
    # readings long before or after the bracket do not count
    assert verdict([(1, 9), (2, 2), (4, 2), (8, 7)], {3}) is Verdict.SAME


def test_an_exponent_read_after_the_values_needs_no_other_read() -> None:
    assert needs_after([(1, 2)], {3})
    assert not needs_after([(1, 2), (4, 2)], {3})


# --- the device state: what the bus answered ----------------------------------------------------


def answer_pass(device: DeviceState, words: dict[int, int], after: dict[int, int]) -> Any:
    """Answer a poll of ``device`` as the bus would: the dedicated reads before, the plan,
    then the reads ``unconfirmed`` asks for (answered from ``after``, the device's words by
    then); return (fresh, since)."""
    fresh: set[tuple[Table, int]] = set()
    since = device.requests
    brackets = device.brackets(DUE)
    for read in device.exponents_before(brackets):
        device.keep(read, tuple(words[a] for a in read.span), fresh)
    for read in device.plan(DUE):
        device.keep(read, tuple(words.get(a, 0) for a in read.span), fresh)
    for read in device.unconfirmed(brackets, since):
        device.keep(read, tuple(after.get(a, words.get(a, 0)) for a in read.span), fresh)
    return fresh, since


def test_a_bracketed_value_is_decoded_with_the_factor_that_held() -> None:
    device = DeviceState(curve(), {}, timing=LinkTiming(), recheck=60.0)
    words = {0: 0xFFFE, 1: 0xFFFF, 2: 1234, 300: 2301, 301: 0xFFFF}
    fresh, since = answer_pass(device, words, after={})
    assert device.requests == since + 3  # two plan reads and one exponent read after
    device.decode_fresh(device.keys_of(DUE), fresh, since)
    assert device.values["v1"] == 23.01
    assert device.values["v2"] == -0.01
    assert device.values["near"] == 123.4
    assert device.scaled_values_held == 0


def test_a_factor_changed_between_the_two_reads_publishes_nothing_scaled_by_it() -> None:
    device = DeviceState(curve(), {}, timing=LinkTiming(), recheck=60.0)
    words = {0: 0xFFFE, 1: 0xFFFF, 2: 1234, 300: 2301, 301: 5}
    fresh, since = answer_pass(device, words, after={})
    device.decode_fresh(device.keys_of(DUE), fresh, since)
    assert device.values["v1"] == 23.01
    # the device moves its factor from -2 to -1 after the value was read: 2301 was meant
    # at -2 (or at -1: a master cannot know), so neither 230.1 nor 23.01 goes out
    words[300] = 231
    fresh, since = answer_pass(device, words, after={0: 0xFFFF})
    changed = device.decode_fresh(device.keys_of(DUE), fresh, since)
    assert "v1" not in changed and "v2" not in changed
    assert device.values["v1"] == 23.01  # its last value, not unknown
    assert device.scaled_values_held == 2
    # the next pass, the factor steady at -1: published with it
    words[0] = 0xFFFF
    fresh, since = answer_pass(device, words, after={})
    device.decode_fresh(device.keys_of(DUE), fresh, since)
    assert device.values["v1"] == 23.1


def test_without_since_a_bracketed_value_is_not_decoded() -> None:
    device = DeviceState(curve(), {}, timing=LinkTiming(), recheck=60.0)
    fresh, _ = answer_pass(device, {0: 0xFFFE, 300: 1}, after={})
    device.decode_fresh(["v1", "near"], fresh)
    assert "v1" not in device.values and "near" in device.values


def test_a_value_read_before_its_exponent_uses_the_factor_of_its_bracket() -> None:
    mapping = make_mapping(
        {
            "v": {"name": "V", "address": 0, "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 200, "type": "s16"},
        }
    )
    device = DeviceState(mapping, {}, timing=LinkTiming(), recheck=60.0)
    fresh, since = answer_pass(device, {0: 5, 200: 2}, after={})
    assert device.requests == since + 3  # sf, v, sf (the plan's own read of it after v)
    device.decode_fresh(["v"], fresh, since)
    assert device.values["v"] == 500


def shared() -> Mapping:
    """One exponent scaling a value beside it and a value 300 registers on."""
    return make_mapping(
        {
            "sf": {"name": "Scale", "address": 0, "type": "s16"},
            "near": {"name": "Near", "address": 1, "scale_by": "sf"},
            "far": {"name": "Far", "address": 300, "scale_by": "sf"},
        }
    )


def test_a_value_read_with_its_exponent_keeps_that_reading_when_it_is_read_again() -> None:
    device = DeviceState(shared(), {}, timing=LinkTiming(), recheck=60.0)
    # sf -1 with near and far; sf is -2 by the read after far: far held, near as read
    fresh, since = answer_pass(device, {0: 0xFFFF, 1: 123, 300: 456}, after={0: 0xFFFE})
    assert device.image[(H, 0)] == 0xFFFE
    device.decode_fresh(["near", "far"], fresh, since)
    assert device.values["near"] == 12.3  # at -1, the exponent of its own request
    assert "far" not in device.values
    assert device.scaled_values_held == 1


def test_a_bracket_the_bus_did_not_close_is_held_and_not_counted() -> None:
    device = DeviceState(shared(), {}, timing=LinkTiming(), recheck=60.0)
    fresh: set[tuple[Table, int]] = set()
    since = device.requests
    for read in device.plan(DUE):  # the exponent read after them failed
        device.keep(read, tuple(0xFFFF if a == 0 else 5 for a in read.span), fresh)
    assert device.unconfirmed(device.brackets(DUE), since) == (Read(H, 0, 1),)
    device.decode_fresh(["near", "far"], fresh, since)
    assert device.values == {"near": 0.5}
    assert device.scaled_values_held == 0


def test_no_exponent_read_is_asked_for_values_the_pass_did_not_read() -> None:
    device = DeviceState(shared(), {}, timing=LinkTiming(), recheck=60.0)
    since = device.requests
    device.keep(Read(H, 0, 2), (0xFFFF, 5), set())  # the far value's read failed
    assert device.unconfirmed(device.brackets(DUE), since) == ()


def factors_side_by_side(**top: Any) -> Mapping:
    return make_mapping(
        {
            "v_sf": {"name": "V scale", "address": 0, "type": "s16"},
            "w_sf": {"name": "W scale", "address": 1, "type": "s16"},
            "v": {"name": "V", "address": 300, "scale_by": "v_sf"},
            "w": {"name": "W", "address": 301, "scale_by": "w_sf"},
        },
        **top,
    )


def test_factors_side_by_side_are_read_again_in_one_read() -> None:
    plan = plan_of(factors_side_by_side())
    assert [b.exponent for b in plan.bracketed] == [Read(H, 0, 1), Read(H, 1, 1)]
    assert plan.extra == (Read(H, 0, 2),)
    device = DeviceState(factors_side_by_side(), {}, timing=LinkTiming(), recheck=60.0)
    fresh, since = answer_pass(device, {0: 0xFFFF, 1: 2, 300: 2301, 301: 7}, after={})
    assert device.requests == since + 3  # 0..1, 300..301, then 0..1 again
    device.decode_fresh(["v", "w"], fresh, since)
    assert device.values == {"v": 230.1, "w": 700}


def test_factors_are_joined_only_within_a_read_and_a_segment() -> None:
    assert plan_of(factors_side_by_side(), max_registers=1).extra == (
        Read(H, 0, 1),
        Read(H, 1, 1),
    )
    segments = [{"name": "a", "start": 0, "end": 0}, {"name": "b", "start": 1, "end": 400}]
    plan = plan_of(factors_side_by_side(protocol={"segments": segments}))
    assert plan.extra == (Read(H, 0, 1), Read(H, 1, 1))
