"""``scale_by`` through the planner, the device state, the write plan, discovery, counters
and the simulator: a value is read, decoded and written with its exponent of the same
request, never another's."""

from __future__ import annotations

from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.core.bracket import Bracket
from bridge.core.codec import decimals_of, decode
from bridge.core.counters import CounterRule
from bridge.core.device_state import DeviceState
from bridge.core.entity import PollClass, Table
from bridge.core.mapping import Mapping, Point
from bridge.core.planner import limits_for, plan_reads, split_read
from bridge.core.request import Read, Write
from bridge.core.simulation import initial_image
from bridge.core.timing import LinkTiming
from bridge.core.write_plan import dependencies
from tests.factory import make_mapping
from tests.unit.test_discovery import _cmps

H = Table.HOLDING


def inverter(**top: Any) -> Mapping:
    """Three values scaled by one exponent at 40, an unscaled value between, a value
    scaled by another exponent at 60 (a SunSpec model's layout, shortened)."""
    return make_mapping(
        {
            "a": {"name": "A", "address": 0, "scale_by": "a_sf"},
            "b": {"name": "B", "address": 1, "type": "s16", "scale_by": "a_sf"},
            "c": {"name": "C", "address": 2, "type": "u32", "scale_by": "a_sf"},
            "mid": {"name": "Middle", "address": 20},
            "a_sf": {"name": "A scale", "address": 40, "type": "s16"},
            "w": {"name": "W", "address": 50, "scale_by": "w_sf", "poll": "slow"},
            "w_sf": {"name": "W scale", "address": 60, "type": "s16", "poll": "fast"},
        },
        **top,
    )


def reads_of(mapping: Mapping, keys: list[str] | None = None, **limits: Any) -> Any:
    points = mapping.points()
    chosen = [points[k] for k in keys] if keys is not None else list(points.values())
    return plan_reads(chosen, limits_for(mapping, **limits))


def holding(read: Read, point: Point) -> bool:
    return all(cell in {(read.table, a) for a in read.span} for cell in point.footprint)


def test_points_sharing_one_exponent_are_read_with_it_in_one_read() -> None:
    plan = reads_of(inverter())
    assert plan.unplannable == ()
    points = inverter().points()
    for key in ("a", "b", "c", "w"):
        assert any(holding(read, points[key]) for read in plan.reads), key


def test_a_value_due_alone_reads_its_exponent_too() -> None:
    plan = reads_of(inverter(), ["w"])
    assert plan.reads == (Read(H, 50, 11),)


A_SF, W_SF = Read(H, 40, 1), Read(H, 60, 1)


def test_a_value_too_far_from_its_exponent_for_the_limit_is_read_bracketed() -> None:
    plan = reads_of(inverter(), max_registers=30)  # 0..40 needs 41, 50..60 needs 11
    assert plan.unplannable == ()
    # a, b, c are read before the plan's read of a_sf: a dedicated read of it goes first
    assert plan.bracketed == (Bracket(A_SF, ("a", "b", "c"), before=True, after=False),)
    covered = {a for read in plan.reads for a in read.span}
    assert {0, 1, 2, 3, 20, 40, 50, 60} <= covered
    plan = reads_of(inverter(), max_registers=10)
    assert plan.unplannable == ()
    assert [(b.exponent, b.keys) for b in plan.bracketed] == [
        (A_SF, ("a", "b", "c")),
        (W_SF, ("w",)),
    ]


def test_an_unreadable_register_between_a_value_and_its_exponent_brackets_it() -> None:
    mapping = inverter()
    limits = limits_for(mapping, refused=frozenset({(H, 30)}))
    plan = plan_reads(mapping.points().values(), limits)
    assert plan.unplannable == ()
    assert [b.keys for b in plan.bracketed] == [("a", "b", "c")]
    assert all(30 not in read.span for read in plan.reads)


def test_an_unreadable_exponent_still_makes_its_far_values_unplannable() -> None:
    mapping = inverter()
    limits = limits_for(mapping, max_registers=30, refused=frozenset({(H, 40)}))
    plan = plan_reads(mapping.points().values(), limits)
    assert plan.unplannable == ("a", "a_sf", "b", "c")
    assert plan.bracketed == ()


def test_without_readable_gaps_a_hole_between_them_brackets_it() -> None:
    plan = reads_of(inverter(protocol={"readable_gaps": False}))
    assert plan.unplannable == ()
    assert [b.keys for b in plan.bracketed] == [("a", "b", "c"), ("w",)]
    dense = make_mapping(
        {
            "v": {"name": "V", "address": 0, "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 1, "type": "s16"},
        },
        protocol={"readable_gaps": False},
    )
    assert reads_of(dense).reads == (Read(H, 0, 2),)


def test_a_long_atom_holding_a_scaled_value_is_not_cut() -> None:
    mapping = make_mapping(
        {
            "text": {"name": "Text", "address": 0, "type": "ascii", "count": 8},
            "v": {"name": "V", "address": 2, "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 3, "type": "s16"},
        }
    )
    plan = reads_of(mapping, max_registers=4)  # v is freed from sf, the text cut in 4s
    assert plan.unplannable == ()
    assert plan.reads == (Read(H, 0, 4), Read(H, 4, 4))
    assert plan.bracketed == ()  # v and sf land in one read after all: read as any value


def test_a_refused_block_is_split_never_between_a_value_and_its_exponent() -> None:
    points = list(inverter().points().values())
    parts = split_read(Read(H, 0, 61), points)
    assert Read(H, 0, 41) in parts
    assert Read(H, 50, 11) in parts


@settings(max_examples=200, deadline=None)
@given(
    sf_address=st.integers(0, 30),
    values=st.lists(st.integers(0, 30), min_size=1, max_size=5, unique=True),
    limit=st.integers(1, 31),
)
def test_every_planned_value_is_read_with_its_exponent(
    sf_address: int, values: list[int], limit: int
) -> None:
    entities: dict[str, dict[str, Any]] = {
        "sf": {"name": "Scale", "address": sf_address, "type": "s16"}
    }
    for index, address in enumerate(a for a in values if a != sf_address):
        entities[f"v{index}"] = {"name": f"V{index}", "address": address, "scale_by": "sf"}
    mapping = make_mapping(entities)
    points = mapping.points()
    plan = reads_of(mapping, max_registers=limit)
    assert plan.unplannable == ()
    scaled = [p for p in points.values() if p.scale_source is not None]
    bracketed = {key for b in plan.bracketed for key in b.keys}
    assert all(b.exponent == Read(H, sf_address, 1) for b in plan.bracketed)
    for point in scaled:  # with its exponent in one read, or bracketed: never both, never none
        together = sum(holding(read, point) for read in plan.reads) == 1
        assert together != (point.key in bracketed), point.key
        if len(point.extent) > limit:
            assert point.key in bracketed
    assert sum(1 for r in plan.reads for a in r.span if a == sf_address) == 1


# --- the device state -----------------------------------------------------------------------


def state(mapping: Mapping | None = None) -> DeviceState:
    return DeviceState(mapping or inverter(), {}, timing=LinkTiming(), recheck=60.0)


def answer(device: DeviceState, words: dict[int, int]) -> set[tuple[Table, int]]:
    fresh: set[tuple[Table, int]] = set()
    for read in device.plan([PollClass.FAST, PollClass.SLOW]):
        device.keep(read, tuple(words.get(a, 0) for a in read.span), fresh)
    return fresh


def test_a_poll_decodes_the_value_with_the_exponent_of_the_same_read() -> None:
    device = state()
    fresh = answer(device, {0: 1234, 40: 0xFFFE, 50: 7, 60: 3})
    device.decode_fresh(device.keys_of([PollClass.FAST, PollClass.SLOW]), fresh)
    assert device.values["a"] == 12.34
    assert device.values["w"] == 7000


def test_a_value_whose_exponent_was_not_read_fresh_keeps_its_value() -> None:
    device = state()
    fresh = answer(device, {0: 1234, 40: 0xFFFE})
    device.decode_fresh(["a"], fresh)
    device.image[(H, 0)] = 99  # the value word alone, read again (never with an old exponent)
    assert device.decode_fresh(["a"], {(H, 0)}) == frozenset()
    assert device.values["a"] == 12.34


def test_a_refused_exponent_makes_its_values_unknown() -> None:
    device = state()
    fresh = answer(device, {0: 1234, 40: 0xFFFE})
    device.decode_fresh(["a"], fresh)
    device.avoid({(H, 40)}, 0.0)
    assert device.decode_fresh(["a"], fresh) == frozenset({"a"})
    assert device.values["a"] is None


def test_a_scaled_value_not_due_is_decoded_only_when_its_exponent_was_read() -> None:
    device = state()
    assert "w" not in device.keys_of([PollClass.FAST])  # w_sf alone is read
    assert "w_sf" in device.keys_of([PollClass.SLOW])  # read with w


def test_a_read_on_request_reads_the_exponent() -> None:
    device = state()
    points = device.points
    assert device.reads_for([points["b"]]) == (Read(H, 1, 40),)


# --- writes, discovery, counters, simulation -------------------------------------------------


def test_a_write_reads_the_exponent_first() -> None:
    mapping = make_mapping(
        {
            "limit": {"name": "Limit", "address": 0, "access": "rw", "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 3, "type": "s16"},
        }
    )
    assert dependencies(mapping.points()["limit"], []) == [Read(H, 3, 1)]


def test_discovery_leaves_the_precision_of_a_scaled_value_to_home_assistant() -> None:
    sf = {"name": "Scale", "address": 9, "type": "s16"}
    plain = _cmps({"v": {"name": "Power", "address": 0, "scale_by": "sf"}, "sf": sf})
    assert "suggested_display_precision" not in plain["v"]
    fixed = _cmps(
        {"v": {"name": "Power", "address": 0, "scale_by": "sf", "precision": 2}, "sf": sf}
    )
    assert fixed["v"]["suggested_display_precision"] == 2


def test_discovery_of_a_scaled_setting_offers_every_value_it_may_take() -> None:
    sf = {"name": "Scale", "address": 9, "type": "s16"}
    entities = {"v": {"name": "Limit", "address": 0, "scale_by": "sf", "access": "rw"}, "sf": sf}
    config = _cmps(entities)["v"]
    assert config["step"] == 0.001
    assert config["min"] == 0
    assert config["max"] == 65535 * 10**10
    with_precision = entities | {"v": entities["v"] | {"precision": 1, "max": 100}}
    config = _cmps(with_precision)["v"]
    assert (config["step"], config["max"]) == (0.1, 100)


def test_a_scaled_counter_does_not_continue_rollovers() -> None:
    mapping = make_mapping(
        {
            "wh": {"name": "Energy", "address": 0, "type": "u32", "scale_by": "sf"},
            "sf": {"name": "Scale", "address": 2, "type": "s16"},
        }
    )
    assert CounterRule.of(mapping.points()["wh"]).wrap is None


def test_the_simulator_holds_exponent_zero_and_plain_values() -> None:
    mapping = inverter()
    points = mapping.points()
    image = initial_image(mapping, points)
    assert image[(H, 40)] == 0
    for key in ("a", "b", "c", "w"):
        assert isinstance(decode(points[key], image), int)


def test_a_value_and_its_exponent_from_two_requests_are_never_decoded_together() -> None:
    device = state()
    fresh: set[tuple[Table, int]] = set()
    device.keep(Read(H, 0, 1), (1234,), fresh)  # a read plan that cut them apart
    device.keep(Read(H, 40, 1), (0xFFFE,), fresh)
    assert device.decode_fresh(["a"], fresh) == frozenset()
    assert "a" not in device.values
    device.keep(Read(H, 0, 41), (1234,) + (0,) * 39 + (0xFFFD,), fresh)
    assert device.decode_fresh(["a"], fresh) == frozenset({"a"})
    assert device.values["a"] == 1.234


def test_a_written_value_waits_for_its_read_back_with_the_exponent() -> None:
    device = state()
    fresh = answer(device, {0: 1234, 40: 0xFFFE})
    device.decode_fresh(["a"], fresh)
    device.store(Write(6, H, 0, (5,)))
    assert device.decode_fresh(["a"], {(H, 0), (H, 40)}) == frozenset()
    assert device.values["a"] == 12.34


def test_a_scaled_counter_reset_keeps_the_decimals_of_its_exponent() -> None:
    mapping = make_mapping(
        {
            "wh": {
                "name": "Energy",
                "address": 0,
                "type": "u32",
                "scale_by": "sf",
                "ha": {"state_class": "total_increasing", "device_class": "energy"},
                "unit": "kWh",
            },
            "sf": {"name": "Scale", "address": 2, "type": "s16"},
        }
    )
    device = state(mapping)
    for raw in (1234, 123, 123, 123):
        fresh: set[tuple[Table, int]] = set()
        device.keep(Read(H, 0, 3), (0, raw, 0xFFFE), fresh)
        device.decode_fresh(["wh"], fresh)
    assert device.values["wh"] == 1.23  # the reset, confirmed, with the exponent's decimals


def test_the_decimals_shown_follow_the_exponent_read() -> None:
    points = inverter().points()
    assert decimals_of(points["a"], {(H, 40): 0xFFFD}) == 3
    assert decimals_of(points["a"], {(H, 40): 2}) == 0
    assert decimals_of(points["a"], {(H, 40): 0x8000}) is None
    assert decimals_of(points["a"], {}) is None
    assert decimals_of(points["mid"], {}) == 0
    fixed = make_mapping(
        {
            "v": {"name": "V", "address": 0, "scale_by": "sf", "precision": 1},
            "sf": {"name": "Scale", "address": 1, "type": "s16"},
        }
    )
    assert decimals_of(fixed.points()["v"], {(H, 1): 0xFFFD}) == 1
