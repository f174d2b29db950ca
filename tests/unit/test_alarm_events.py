"""Alarm events (bridge/core/alarm_events.py): each raise and clear once, nothing else."""

from __future__ import annotations

from typing import Any

import pytest

from bridge.core.alarm_events import AlarmEvent, alarm_events, event_document, reported
from bridge.core.discovery import build_device_discovery
from bridge.core.discovery_alarms import alarm_names
from bridge.core.mapping import builtin_mapping_names, builtin_mapping_path, load_mapping
from tests.factory import make_mapping
from tests.library.layout import has_no_status
from tests.unit.test_discovery import ORIGIN, TOPICS, _device

POINTS = make_mapping(
    {
        "dry_running": {"name": "Dry running", "address": 1, "bit": 0, "alarm": True},
        "overheat": {"name": "Overheat", "address": 1, "bit": 1, "alarm": True},
        "fault": {
            "name": "Fault",
            "address": 2,
            "alarm": True,
            "enum": {0: "none", 3: "overload", 7: "earth_fault"},
        },
        "speed": {"name": "Speed", "address": 3},
    }
).points()


def run(before: frozenset[str], **values: Any) -> tuple[list[tuple[str, str]], frozenset[str]]:
    events, after = alarm_events(POINTS, values, before)
    return [(e.alarm, e.state) for e in events], after


NONE = frozenset[str]()
QUIET = {"dry_running": False, "overheat": False, "fault": "none", "speed": 5}


def test_a_raise_and_a_clear_are_said_once_each() -> None:
    events, after = run(NONE, **QUIET | {"dry_running": True})
    assert events == [("dry_running", "raised")] and after == {"dry_running"}
    assert run(after, **QUIET | {"dry_running": True, "speed": 7}) == ([], after)
    assert run(after, **QUIET) == ([("dry_running", "cleared")], NONE)


def test_a_fault_code_changing_is_one_clear_and_one_raise() -> None:
    _, after = run(NONE, **QUIET | {"fault": "overload"})
    events, after = run(after, **QUIET | {"fault": "earth_fault"})
    assert events == [("overload", "cleared"), ("earth_fault", "raised")]
    assert after == {"earth_fault"}


def test_an_entity_without_a_value_keeps_its_alarms() -> None:
    """Offline, refused, or not read yet after a reload: not a clear."""
    before = frozenset({"dry_running", "overload"})
    assert run(before, speed=5) == ([], before)
    assert run(before, dry_running=None, overheat=None, fault=None) == ([], before)
    assert run(before, **QUIET | {"fault": None}) == ([("dry_running", "cleared")], {"overload"})


def test_alarms_active_at_the_first_poll_are_raised_unless_published_before() -> None:
    values = QUIET | {"dry_running": True, "fault": "overload"}
    assert run(NONE, **values)[0] == [("dry_running", "raised"), ("overload", "raised")]
    assert run(frozenset({"dry_running"}), **values)[0] == [("overload", "raised")]


def test_a_code_without_a_label_is_an_alarm_of_its_entity() -> None:
    events, after = alarm_events(POINTS, QUIET | {"fault": "code_23"}, NONE)
    assert events == [AlarmEvent("fault_23", True, "fault", 23, labelled=False)]
    assert events[0].event_type == "fault_other_raised"
    (cleared,), _ = alarm_events(POINTS, QUIET, after)
    assert (cleared.alarm, cleared.state, cleared.code) == ("fault_23", "cleared", 23)


def test_a_name_seeded_that_no_entity_reports_is_kept_quietly() -> None:
    before = frozenset({"gone_from_the_mapping"})
    assert run(before, **QUIET) == ([], before)


def test_the_event_document() -> None:
    event = AlarmEvent("overload", True, "fault", 3)
    assert event_document(event, "Overload", "2026-11-27T22:00:00.000+00:00") == {
        "event_type": "overload_raised",
        "alarm": "overload",
        "name": "Overload",
        "transition": "raised",
        "entity": "fault",
        "code": 3,
        "time": "2026-11-27T22:00:00.000+00:00",
    }


@pytest.mark.parametrize("name", builtin_mapping_names())
def test_every_alarm_of_every_shipped_mapping_has_its_triggers_and_event_types(
    name: str,
) -> None:
    """A new alarm in a mapping cannot lack its device triggers."""
    mapping = load_mapping(builtin_mapping_path(name))
    payload = build_device_discovery(_device(mapping), TOPICS, ORIGIN)
    components = payload["cmps"]
    names = alarm_names(mapping.active({}), "Test device")
    if has_no_status(mapping):
        assert not names and "alarm_events" not in components
        return
    assert names, "every shipped device but a meter reports alarms"
    events = components["alarm_events"]
    triggers = {
        c["payload"]: c for c in components.values() if c["platform"] == "device_automation"
    }
    for alarm, shown in names.items():
        for state in ("raised", "cleared"):
            assert f"{alarm}_{state}" in events["event_types"]
            trigger = triggers[f"{alarm}_{state}"]
            assert (trigger["type"], trigger["subtype"]) == (state, shown)
            assert trigger["topic"] == events["state_topic"] == "modbus/dev/event"
    assert set(triggers) <= set(events["event_types"])


def test_only_names_an_entity_reports_are_taken_from_a_document() -> None:
    names = ["dry_running", "overload", "fault_23", "fault_x", "speed", "nothing", "x" * 200]
    assert reported(names, POINTS) == {"dry_running", "overload", "fault_23"}
