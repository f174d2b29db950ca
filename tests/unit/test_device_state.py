"""What one device knows, without a bus (bridge/core/device_state.py): the image a read
leaves, the values decoded from what was read fresh, the plans around learnt refusals."""

from __future__ import annotations

from bridge.core.device_state import DeviceState
from bridge.core.entity import PollClass, Table
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.request import Read, Write
from bridge.core.timing import LinkTiming
from tests.factory import make_mapping

H, C = Table.HOLDING, Table.COIL
RECHECK = 60.0
MAPPING = make_mapping(
    {
        "speed": {"name": "Speed", "address": 1, "poll": "fast", "scale": 0.1},
        "current": {"name": "Current", "address": 2, "poll": "fast"},
        "energy": {"name": "Energy", "address": 3, "type": "u32", "poll": "fast"},
        "mode": {"name": "Mode", "address": 11, "poll": "slow", "enum": {0: "off", 1: "on"}},
        "command": {"name": "Command", "address": 21, "access": "w", "poll": "slow"},
        "reset": {"name": "Reset", "address": 31, "access": "rw", "dangerous": True},
        "relay": {"name": "Relay", "address": 6, "table": "coil", "access": "rw"},
    },
    protocol={"addressing": {"offset": -1}},
)


def state(guard: Guard = UNGUARDED) -> DeviceState:
    return DeviceState(MAPPING, {}, timing=LinkTiming(), recheck=RECHECK, guard=guard)


def fast_read(device: DeviceState) -> Read:
    (read,) = device.plan([PollClass.FAST])
    return read


def test_a_poll_class_is_planned_once_and_its_reads_kept() -> None:
    device = state()
    plan = device.plan([PollClass.FAST])
    assert plan == (Read(H, 0, 4),)  # wire addresses: printed minus one
    assert device.plan([PollClass.FAST]) is plan  # planned once per set of due intervals
    assert device.plan([2.0]) is plan  # fast is the default 2 s
    both = device.plan([PollClass.SLOW, PollClass.FAST])  # one plan for the union
    assert device.plan([PollClass.FAST, PollClass.SLOW]) is both
    words = [(r.table, a) for r in both for a in r.span]
    assert len(words) == len(set(words))  # no register read twice in one pass
    assert {a for r in plan + device.plan([PollClass.SLOW]) for a in r.span} <= {
        a for r in both for a in r.span
    }
    device.forget_plans()
    assert device.plan([PollClass.FAST]) is not plan  # planned again when limits change


def test_keep_puts_the_answer_in_the_image_and_in_fresh() -> None:
    device = state()
    fresh: set[tuple[Table, int]] = set()
    back = device.keep(Read(H, 0, 4), (215, 7, 1, 2), fresh)
    assert back == frozenset()
    assert device.image == {(H, 0): 215, (H, 1): 7, (H, 2): 1, (H, 3): 2}
    assert fresh == {(H, 0), (H, 1), (H, 2), (H, 3)}


def test_only_what_was_read_fresh_is_decoded_and_only_changes_are_returned() -> None:
    device = state()
    fresh: set[tuple[Table, int]] = set()
    device.keep(Read(H, 0, 2), (215, 7), fresh)
    keys = ["speed", "current", "energy", "command"]
    assert device.decode_fresh(keys, fresh) == {"speed", "current"}
    assert device.values == {"speed": 21.5, "current": 7}  # energy not read, command write-only
    assert device.decode_fresh(keys, fresh) == frozenset()  # the same values again
    device.keep(Read(H, 1, 3), (8, 0, 9), fresh)
    assert device.decode_fresh(keys, fresh) == {"current", "energy"}
    assert device.values == {"speed": 21.5, "current": 8, "energy": 9}


def test_a_value_partly_read_keeps_its_last_value() -> None:
    device = state()
    device.values["energy"] = 5
    fresh: set[tuple[Table, int]] = set()
    device.keep(Read(H, 2, 1), (1,), fresh)  # the high word only
    assert device.decode_fresh(["energy"], fresh) == frozenset()
    assert device.values["energy"] == 5


def test_a_refused_value_becomes_none() -> None:
    device = state()
    device.values["current"] = 7
    assert device.avoid({(H, 1)}, now=0.0) == {(H, 1)}
    assert device.decode_fresh(["current"], set()) == {"current"}
    assert device.values["current"] is None


def test_learnt_refusals_are_planned_around_until_answered_again() -> None:
    device = state()
    before = device.plan([PollClass.FAST])
    assert device.avoid({(H, 1)}, now=0.0) == {(H, 1)}
    assert device.refused == {(H, 1)}
    around = device.plan([PollClass.FAST])
    assert around != before
    assert all((H, 1) not in {(r.table, a) for a in r.span} for r in around)
    assert device.avoid({(H, 1)}, now=1.0) == frozenset()  # not news the second time
    back = device.keep(Read(H, 1, 1), (3,), set())
    assert back == {(H, 1)}
    assert device.refused == frozenset()
    assert device.plan([PollClass.FAST]) == before


def test_a_refusal_is_read_again_at_its_recheck() -> None:
    device = state()
    before = device.plan([PollClass.FAST])
    device.avoid({(H, 1)}, now=100.0)
    assert device.recheck(now=100.0 + RECHECK - 1) == frozenset()
    assert device.refused == {(H, 1)}
    assert device.recheck(now=100.0 + RECHECK) == {(H, 1)}
    assert device.refused == frozenset()
    assert device.plan([PollClass.FAST]) == before


def test_reads_are_limited_only_downwards() -> None:
    device = state()
    assert fast_read(device).count == 4
    assert device.limit_reads(2)
    assert device.max_read == 2
    assert all(r.count <= 2 for r in device.plan([PollClass.FAST]))
    assert device.limits().max_registers == 2
    assert not device.limit_reads(3)  # more than it takes now: not learnt
    assert not device.limit_reads(2)
    assert device.max_read == 2
    assert device.limit_reads(1)
    assert all(r.count == 1 for r in device.plan([PollClass.FAST]))


def test_reads_for_chosen_points_follow_the_limits_learnt() -> None:
    device = state()
    wanted = [device.points["speed"], device.points["energy"]]
    assert device.reads_for(wanted) == (Read(H, 0, 4),)  # the gap is cheaper read through
    device.limit_reads(2)
    assert device.reads_for(wanted) == (Read(H, 0, 1), Read(H, 2, 2))


def test_a_register_write_is_stored_a_coil_command_is_not() -> None:
    device = state()
    device.store(Write(16, H, 2, (1, 2)))
    device.store(Write(5, C, 4, (0xFF00,)))
    assert device.image == {(H, 2): 1, (H, 3): 2}


def test_the_guard_joins_this_mapping_with_the_earlier_ones() -> None:
    own = state().guard
    assert (H, 30) in own.dangerous  # reset, printed 31
    earlier = Guard.of(
        make_mapping({"wipe": {"name": "Wipe", "address": 100, "access": "w", "dangerous": True}})
        .points()
        .values()
    )
    joined = state(guard=earlier).guard
    assert set(joined.dangerous) == set(own.dangerous) | {(H, 100)}


def test_addresses_are_shown_as_printed_and_as_sent() -> None:
    device = state()
    shown = device.shown({(H, 40), (H, 3), (H, 0)})  # the low word of energy; a hole
    assert shown == "holding 0x0001 (wire 0), holding 0x0004 (wire 3), holding 0x0029 (wire 40)"


COUNTING = make_mapping(
    {
        "energy": {
            "name": "Energy",
            "address": 1,
            "type": "u32",
            "unit": "kWh",
            "ha": {"device_class": "energy", "state_class": "total_increasing"},
        },
        "hours": {
            "name": "Hours",
            "address": 3,
            "scale": 0.1,
            "unit": "h",
            "confirm_reset": 1,
            "ha": {"device_class": "duration", "state_class": "total_increasing"},
        },
    },
)


def counted(device: DeviceState, energy: int, hours: int) -> frozenset[str]:
    fresh: set[tuple[Table, int]] = set()
    device.keep(Read(H, 1, 3), (energy >> 16, energy & 0xFFFF, hours), fresh)
    return device.decode_fresh(["energy", "hours"], fresh)


def test_a_counter_read_lower_keeps_its_value_and_says_so() -> None:
    device = DeviceState(COUNTING, {}, timing=LinkTiming(), recheck=RECHECK)
    assert counted(device, 19930, 1000) == {"energy", "hours"}
    assert device.take_counter_news() == []
    assert counted(device, 0, 1001) == {"hours"}  # energy held
    assert device.values == {"energy": 19930, "hours": 100.1}
    ((key, reading),) = device.take_counter_news()
    assert (key, reading.kind, reading.reason, reading.read) == ("energy", "held", "zero", 0)
    assert counted(device, 19931, 5) == {"energy", "hours"}  # hours: confirm_reset 1
    assert device.values == {"energy": 19931, "hours": 0.5}
    assert [(k, r.kind) for k, r in device.take_counter_news()] == [("hours", "reset")]


def test_a_rollover_is_published_in_the_type_it_was_read_in() -> None:
    device = DeviceState(COUNTING, {}, timing=LinkTiming(), recheck=RECHECK)
    counted(device, 0xFFFFFFF0, 65530)
    counted(device, 3, 2)
    assert device.values == {"energy": 2**32 + 3, "hours": 6553.8}
    assert isinstance(device.values["energy"], int)


def test_seeds_are_what_a_lower_first_reading_is_held_against() -> None:
    device = DeviceState(COUNTING, {}, timing=LinkTiming(), recheck=RECHECK)
    changed = device.seed_counters(
        {"energy": 19930, "hours": "x", "last_reset": {"energy": "2026-01-01T00:00:00+00:00"}}
    )
    assert changed == {"energy"} and device.values == {"energy": 19930}
    assert device.last_reset == {"energy": "2026-01-01T00:00:00+00:00"}
    counted(device, 0, 7)
    assert device.values == {"energy": 19930, "hours": 0.7}
    assert device.seed_counters({"energy": 100}) == frozenset()


def test_a_reload_carries_the_counters_published() -> None:
    earlier = DeviceState(COUNTING, {}, timing=LinkTiming(), recheck=RECHECK)
    counted(earlier, 19930, 1000)
    earlier.last_reset["hours"] = "2026-11-27T10:00:00+00:00"
    device = DeviceState(COUNTING, {}, timing=LinkTiming(), recheck=RECHECK)
    assert device.carry_counters(earlier) == {"energy", "hours"}
    assert device.last_reset == {"hours": "2026-11-27T10:00:00+00:00"}
    counted(device, 0, 1001)  # a misread right after the reload is held like any other
    assert device.values == {"energy": 19930, "hours": 100.1}


def test_a_seeded_last_reset_must_be_a_time() -> None:
    device = DeviceState(COUNTING, {}, timing=LinkTiming(), recheck=RECHECK)
    device.seed_counters({"last_reset": {"energy": "soon", "hours": "2026-11-27T10:00:00"}})
    assert device.last_reset == {}  # no time, and a time without its offset
    device.seed_counters({"last_reset": {"hours": "2026-11-27T10:00:00+00:00"}})
    assert device.last_reset == {"hours": "2026-11-27T10:00:00+00:00"}
