"""Command topics and payloads, state documents, duplicate detection."""

from __future__ import annotations

import json
import math

import pytest

from bridge.core.commands import Command, RecentMessages, parse_get, parse_set, past_deadline
from bridge.core.state import active_alarms, plain_payload, state_document
from bridge.core.topics import Action, CommandTopic, Topics
from bridge.errors import ValueRejectedError
from tests.factory import make_mapping

TOPICS = Topics("modbus", "homeassistant")


@pytest.mark.parametrize(
    ("topic", "parsed"),
    [
        ("modbus/pump/set", CommandTopic("pump", None, Action.SET)),
        ("modbus/pump/set_value/set", CommandTopic("pump", "set_value", Action.SET)),
        ("modbus/pump/get", CommandTopic("pump", None, Action.GET)),
        ("modbus/pump", None),
        ("modbus/pump/set_value", None),
        ("modbus/pump/set_value/get", None),
        ("modbus/bridge/set", None),
        ("modbus//set", None),
        ("other/pump/set", None),
        ("modbus/pump/a/b/set", None),
    ],
)
def test_parse_command_topics(topic: str, parsed: CommandTopic | None) -> None:
    assert TOPICS.parse_command(topic) == parsed


def test_topic_names() -> None:
    assert TOPICS.bridge_state == "modbus/bridge/state"
    assert TOPICS.device("pump") == "modbus/pump"
    assert TOPICS.value("pump", "actual_value") == "modbus/pump/actual_value"
    assert TOPICS.availability("pump") == "modbus/pump/availability"
    assert TOPICS.set("pump", "x") == "modbus/pump/x/set"
    assert TOPICS.error("pump") == "modbus/pump/error"
    assert TOPICS.device_config("pump") == "homeassistant/device/pump/config"
    assert TOPICS.entity_config("sensor", "pump", "x") == "homeassistant/sensor/pump/x/config"
    assert TOPICS.command_filters() == (
        "modbus/+/set",
        "modbus/+/+/set",
        "modbus/+/get",
    )


@pytest.mark.parametrize(
    ("payload", "key", "parsed"),
    [
        (b'{"set_value": 4.5, "run": "ON"}', None, {"set_value": 4.5, "run": "ON"}),
        (b"4.5", "set_value", {"set_value": 4.5}),
        (b" 45 ", "set_value", {"set_value": 45}),
        (b"ON", "run", {"run": "ON"}),
        (b"true", "run", {"run": True}),
        (b"no_water", "mode", {"mode": "no_water"}),
        (b'"Fix speed"', "mode", {"mode": "Fix speed"}),
        (b"Fix speed", "mode", {"mode": "Fix speed"}),
        (b"PRESS", "reset", {"reset": "PRESS"}),
    ],
)
def test_parse_set(payload: bytes, key: str | None, parsed: dict[str, object]) -> None:
    assert parse_set(payload, key) == parsed


@pytest.mark.parametrize(
    ("payload", "key", "message"),
    [
        (b"4.5", None, "JSON object"),
        (b"[1]", None, "non-empty JSON object"),
        (b"{}", None, "non-empty JSON object"),
        (b"", "x", "empty payload"),
        (b'{"a": 1}', "x", "one plain value"),
        (b"\xff\xfe", "x", "not UTF-8"),
        (b"1" * 70000, "x", "at most 65536 bytes"),
        (json.dumps({f"k{i}": 1 for i in range(101)}).encode(), None, "at most 100"),
    ],
)
def test_parse_set_refuses(payload: bytes, key: str | None, message: str) -> None:
    with pytest.raises(ValueRejectedError, match=message):
        parse_set(payload, key)


def test_parse_get() -> None:
    assert parse_get(b"") is None
    assert parse_get(b'{"actual_value": ""}') == ["actual_value"]
    assert parse_get(b'["a", "b"]') == ["a", "b"]
    for bad in (b"x", b"[1]", b"{}", b"3"):
        with pytest.raises(ValueRejectedError):
            parse_get(bad)


def test_commands_expire() -> None:
    command = Command("pump", {"set_value": 4.5}, received=10.0, expires=15.0)
    assert not command.expired(15.0)
    assert command.expired(15.1)


def test_a_command_is_in_time_at_its_expiry_and_expired_just_after() -> None:
    command = Command("pump", {"set_value": 4.5}, received=10.0, expires=15.0)
    assert not command.expired(10.0)  # the clock is passed in: no wall time is read
    assert not command.expired(15.0)
    assert command.expired(math.nextafter(15.0, math.inf))


@pytest.mark.parametrize(
    ("expiry", "message_expiry", "expires"),
    [
        (5.0, None, 105.0),  # no message expiry: the bridge's command_expiry
        (5.0, 2.0, 102.0),  # the publisher's is sooner: it wins
        (5.0, 60.0, 105.0),  # the publisher's is later: the bridge's still holds
        (5.0, 5.0, 105.0),
        (5.0, 0.0, 100.0),  # no time left: in time at its arrival only
    ],
)
def test_a_command_is_in_time_from_its_arrival(
    expiry: float, message_expiry: float | None, expires: float
) -> None:
    items: dict[str, object] = {"start": "PRESS", "speed": 40}
    command = Command.arrived("pump", items, 100.0, expiry, message_expiry)
    assert command == Command("pump", items, received=100.0, expires=expires)
    assert not command.expired(expires)
    assert command.expired(math.nextafter(expires, math.inf))


@pytest.mark.parametrize(
    ("deadline", "now", "past"),
    [
        (None, 0.0, False),  # no deadline (a poll, a raw write): never past
        (None, 1e12, False),
        (15.0, 14.9, False),
        (15.0, 15.0, False),  # at the deadline: still in time
        (15.0, math.nextafter(15.0, math.inf), True),
        (15.0, 16.0, True),
    ],
)
def test_past_deadline(deadline: float | None, now: float, past: bool) -> None:
    assert past_deadline(deadline, now) is past


def test_redelivered_duplicates_are_recognised() -> None:
    recent = RecentMessages(window=10)
    assert not recent.is_duplicate("t", b"1", 7, False, now=0.0)
    assert recent.is_duplicate("t", b"1", 7, True, now=1.0)  # redelivery, DUP set
    assert not recent.is_duplicate("t", b"1", 8, False, now=2.0)  # a new message
    assert not recent.is_duplicate("t", b"2", 7, True, now=3.0)  # other payload
    assert not recent.is_duplicate("t", b"1", 7, True, now=20.0)  # outside the window
    assert not recent.is_duplicate("t", b"1", None, True, now=21.0)  # QoS 0: no packet id


MAPPING = make_mapping(
    {
        "state": {"name": "State", "address": 1, "enum": {0: "off", 6: "running"}},
        "fault": {
            "name": "Fault",
            "address": 2,
            "enum": {0: "none", 4: "overcurrent"},
            "alarm": True,
        },
        "dry_running": {"name": "Dry running", "address": 3, "bit": 3, "alarm": True},
        "level": {"name": "Level", "address": 4, "scale": 0.1},
        "password": {
            "name": "Password",
            "address": 5,
            "access": "rw",
            "secret": True,
            "dangerous": True,
        },
        "reset": {"name": "Reset", "address": 6, "access": "w", "press": 1},
    },
    status="state",
)


def test_state_document_and_alarms() -> None:
    points = MAPPING.points()
    values = {
        "state": "running",
        "fault": "overcurrent",
        "dry_running": True,
        "level": None,
        "password": 123,
    }
    assert state_document(MAPPING, points, values) == {
        "state": "running",
        "fault": "overcurrent",
        "dry_running": True,
        "level": None,
        "status": "running",
        "alarms": ["overcurrent", "dry_running"],
    }
    assert active_alarms(points, {"fault": "none", "dry_running": False}) == []


def test_a_fault_code_without_a_label_is_still_an_active_alarm() -> None:
    points = MAPPING.points()
    assert active_alarms(points, {"fault": "code_23", "dry_running": False}) == ["fault_23"]


@pytest.mark.parametrize(
    ("value", "payload"),
    [(4.5, "4.5"), (45, "45"), (True, "true"), (None, "null"), ("running", "running")],
)
def test_plain_payloads(value: object, payload: str) -> None:
    assert plain_payload(value) == payload  # type: ignore[arg-type]
