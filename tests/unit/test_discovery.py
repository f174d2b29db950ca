"""Home Assistant discovery payloads: one test per rule, then exact snapshots.

Snapshots live in tests/golden/discovery/ (pretty-printed, sorted keys). After an
intended change, rewrite them with ``UPDATE_SNAPSHOTS=1 pytest tests/unit/test_discovery.py``
and read the diff. ``tools/check_ha_discovery.py`` validates them with Home Assistant's
own schemas (run by hand in a Home Assistant virtualenv, not by the test suite).
"""

from __future__ import annotations

import difflib
import json
import os
import re
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

import bridge
from bridge.core.codec import limits_of, unit_of
from bridge.core.discovery import (
    BUS_HEALTH_SENSORS,
    DEVICE_HEALTH_SENSORS,
    DeviceInfo,
    Origin,
    Publish,
    build_bridge_discovery,
    build_device_discovery,
    build_discovery,
    removal,
)
from bridge.core.discovery_alarms import alarm_names
from bridge.core.discovery_entity import admitted, shown_readings
from bridge.core.entity import Table
from bridge.core.health_report import BusSnapshot, DeviceSnapshot, Snapshot, build_health_report
from bridge.core.mapping import (
    Mapping,
    builtin_mapping_names,
    builtin_mapping_path,
    format_validation_errors,
    load_mapping,
)
from bridge.core.simulation import initial_image
from bridge.core.topics import Topics
from bridge.sunspec.image import build_image
from bridge.sunspec.mapping import build_mapping
from tests.factory import make_mapping
from tests.library.layout import has_no_status
from tests.sunspec_devices import every_image
from tests.sunspec_reference import walked
from tests.unit.test_shared_register import ENTITIES, MODE

TOPICS = Topics("modbus", "homeassistant")
ORIGIN = Origin(sw_version="test")
GOLDEN = Path(__file__).resolve().parent.parent / "golden" / "discovery"
SUNSPEC_IMAGES = every_image()
STATE = "modbus/dev"
AVAILABILITY = [{"topic": "modbus/bridge/state"}, {"topic": "modbus/dev/availability"}]


def _device(mapping: Mapping, **fields: Any) -> DeviceInfo:
    values: dict[str, Any] = {
        "id": "dev",
        "name": "Test device",
        "mapping": mapping,
        "options": {},
        "bus": "rs485",
        "unit": 1,
        "allow_dangerous_writes": False,
        "fast_interval": 2.0,
        "slow_interval": 60.0,
    } | fields
    return DeviceInfo(**values)


def _cmps(entities: dict[str, dict[str, Any]], **kwargs: Any) -> dict[str, Any]:
    """The components built for a mapping of ``entities`` (kwargs: DeviceInfo fields,
    units, limits, state_refresh, or mapping top-level fields prefixed ``mapping_``)."""
    top = {k.removeprefix("mapping_"): v for k, v in kwargs.items() if k.startswith("mapping_")}
    build = {
        k: kwargs.pop(k) for k in ("units", "limits", "readings", "state_refresh") if k in kwargs
    }
    fields = {k: v for k, v in kwargs.items() if not k.startswith("mapping_")}
    device = _device(make_mapping(entities, **top), **fields)
    payload = build_device_discovery(device, TOPICS, ORIGIN, **build)
    return dict(payload["cmps"])


def _one(entity: dict[str, Any], **kwargs: Any) -> dict[str, Any] | None:
    entity = {"name": "Value", "address": 0} | entity
    return _cmps({"value": entity}, **kwargs).get("value")


def _ids(platform: str, key: str = "value") -> dict[str, Any]:
    return {
        "platform": platform,
        "unique_id": f"modbus_dev_{key}",
        "default_entity_id": f"{platform}.dev_{key}",
        "qos": 1,
    }


def _state(key: str = "value") -> dict[str, Any]:
    return {"state_topic": STATE, "value_template": f"{{{{ value_json.{key} }}}}"}


# --- the device payload -----------------------------------------------------------------


def test_device_payload_whole() -> None:
    mapping = make_mapping({"level": {"name": "Level", "address": 0, "unit": "m"}})
    payload = build_device_discovery(_device(mapping), TOPICS, ORIGIN)
    assert payload == {
        "device": {
            "identifiers": ["modbus_dev"],
            "manufacturer": "Test",
            "model": "T1",
            "name": "Test device",
            "via_device": "modbus_bridge",
        },
        "origin": {
            "name": "modbus-mqtt-bridge",
            "sw_version": "test",
            "support_url": "https://github.com/modbus-mqtt-bridge/modbus-mqtt-bridge",
        },
        "availability": AVAILABILITY,
        "availability_mode": "all",
        "cmps": {
            "level": _ids("sensor", "level")
            | {"name": "Level", "enabled_by_default": True}
            | _state("level")
            | {"unit_of_measurement": "m", "suggested_display_precision": 0}
            | {"expire_after": 602},
        },
    }


def test_origin_defaults_to_the_package_version() -> None:
    assert Origin().sw_version == bridge.__version__
    assert Origin().name == "modbus-mqtt-bridge"


def test_device_mode_is_one_retained_message_of_the_payload() -> None:
    device = _device(make_mapping({"level": {"name": "Level", "address": 0}}))
    [message] = build_discovery(device, TOPICS, ORIGIN, mode="device")
    assert message.topic == "homeassistant/device/dev/config"
    assert message.retain is True
    assert json.loads(message.payload) == build_device_discovery(device, TOPICS, ORIGIN)
    celsius = _device(make_mapping({"t": {"name": "T", "address": 0, "unit": "°C"}}))
    [message] = build_discovery(celsius, TOPICS, ORIGIN, mode="device")
    assert '"unit_of_measurement":"°C"' in message.payload  # UTF-8 as is, compact


def test_removal_is_an_empty_retained_message() -> None:
    assert removal("homeassistant/device/dev/config") == Publish(
        "homeassistant/device/dev/config", "", retain=True
    )


def test_default_entity_id_is_a_slug_of_the_device_id() -> None:
    config = _one({}, id="borehole-pump")
    assert config is not None
    assert config["default_entity_id"] == "sensor.borehole_pump_value"
    assert config["unique_id"] == "modbus_borehole-pump_value"
    assert "object_id" not in config


def test_an_entity_asks_for_its_own_entity_id_when_it_names_one() -> None:
    """An imported entity keeps the id Home Assistant's modbus gave it (``ha.entity_id``);
    its unique id stays the bridge's, and a read-only fallback asks for the same id."""
    config = _one({"ha": {"entity_id": "water_temperature"}}, id="boiler")
    assert config is not None
    assert config["default_entity_id"] == "sensor.water_temperature"
    assert config["unique_id"] == "modbus_boiler_value"
    guarded = {"access": "rw", "dangerous": True, "ha": {"entity_id": "setpoint"}}
    shown = _one(guarded, id="boiler")
    assert shown is not None
    assert (shown["platform"], shown["default_entity_id"]) == ("sensor", "sensor.setpoint")


def test_a_switch_with_its_own_words_is_discovered_as_any_switch() -> None:
    """``words`` are what the bridge writes and reads on the wire: Home Assistant still
    sends ON/OFF and reads true/false, so the payload is the plain switch's, whole."""
    plain = {"type": "bool", "access": "rw"}
    worded = plain | {"words": {"write_on": 0x0100, "write_off": 0x0200, "read_on": [0x0100, 3]}}
    payload = _one(worded)
    assert payload == _one(plain)
    assert payload is not None
    assert (payload["platform"], payload["payload_on"], payload["payload_off"]) == (
        "switch",
        "ON",
        "OFF",
    )


# --- read-only platforms ------------------------------------------------------------------


def test_numeric_sensor() -> None:
    entity = {
        "scale": 0.1,
        "unit": "bar",
        "ha": {"device_class": "pressure", "state_class": "measurement", "icon": "mdi:gauge"},
    }
    assert _one(entity) == _ids("sensor") | {
        "name": "Value",
        "enabled_by_default": True,
        "icon": "mdi:gauge",
    } | _state() | {
        "device_class": "pressure",
        "state_class": "measurement",
        "unit_of_measurement": "bar",
        "suggested_display_precision": 1,
        "expire_after": 602,
    }


@pytest.mark.parametrize(
    ("entity", "precision"),
    [
        ({"scale": 0.01}, 2),
        ({"precision": 3}, 3),
        ({"scale": 0.01, "ha": {"display_precision": 1}}, 1),
        ({"type": "f32"}, None),
        ({"type": "f32", "ha": {"display_precision": 2}}, 2),
    ],
)
def test_display_precision(entity: dict[str, Any], precision: int | None) -> None:
    config = _one(entity)
    assert config is not None
    assert config.get("suggested_display_precision") == precision


def test_unit_read_from_a_register() -> None:
    entities = {
        "unit": {"name": "Unit", "address": 1, "enum": {0: "bar", 1: "psi"}},
        "value": {"name": "Value", "address": 0, "unit_from": "unit", "scale": 0.1},
    }
    assert "unit_of_measurement" not in _cmps(entities)["value"]
    assert _cmps(entities, units={"value": "psi"})["value"]["unit_of_measurement"] == "psi"


def test_enum_sensor_has_options_and_no_unit_or_state_class() -> None:
    config = _one({"enum": {0: "off", 1: "on", 7: "fault"}})
    assert config == _ids("sensor") | {"name": "Value", "enabled_by_default": True} | _state() | {
        "device_class": "enum",
        "options": ["off", "on", "fault"],
        "expire_after": 602,
    }


def test_text_sensor() -> None:
    config = _one({"type": "ascii", "count": 4, "poll": "once"})
    assert config == _ids("sensor") | {"name": "Value", "enabled_by_default": True} | _state() | {
        "expire_after": 660
    }


def test_binary_sensor_alarm_is_a_problem() -> None:
    config = _one({"bit": 3, "alarm": True})
    assert config == _ids("binary_sensor") | {
        "name": "Value",
        "enabled_by_default": True,
    } | _state() | {"payload_on": "True", "payload_off": "False", "device_class": "problem"} | {
        "expire_after": 602
    }


def test_binary_sensor_keeps_its_device_class() -> None:
    config = _one({"bit": 0, "ha": {"device_class": "running"}})
    assert config is not None
    assert config["device_class"] == "running"
    plain = _one({"bit": 0})
    assert plain is not None
    assert "device_class" not in plain


@pytest.mark.parametrize(
    ("entity", "expire"),
    [
        ({}, 602),  # fast: 2 * 300 + 2
        ({"poll": "slow"}, 660),
        ({"poll": "once"}, 660),
    ],
)
def test_expire_after_outlives_two_state_refreshes(entity: dict[str, Any], expire: int) -> None:
    config = _one(entity)
    assert config is not None
    assert config["expire_after"] == expire
    refreshed = _one(entity, state_refresh=60.0, fast_interval=1.0, slow_interval=30.0)
    assert refreshed is not None
    assert refreshed["expire_after"] == {602: 121, 660: 150}[expire]


def test_expire_after_of_an_entitys_own_interval() -> None:
    """Issue 35: an interval of its own (the mapping's, or as the device config resolved it)."""
    assert (_one({"poll": "10m"}) or {})["expire_after"] == 1200  # 2 * 300 + 600
    assert (_one({}, intervals={"value": 30.0}) or {})["expire_after"] == 630


def test_entity_category_and_enabled_by_default() -> None:
    diagnostic = _one({"ha": {"entity_category": "diagnostic"}})
    assert diagnostic is not None
    assert (diagnostic["entity_category"], diagnostic["enabled_by_default"]) == (
        "diagnostic",
        False,
    )
    low = _one({"confidence": "low", "ha": {"enabled": False}})
    assert low is not None
    assert "entity_category" not in low
    assert low["enabled_by_default"] is False


# --- commanding platforms -----------------------------------------------------------------


def test_number() -> None:
    entity = {
        "access": "rw",
        "scale": 0.1,
        "min": 0.5,
        "max": 10,
        "unit": "bar",
        "ha": {"device_class": "pressure", "entity_category": "config"},
    }
    assert _one(entity) == _ids("number") | {
        "name": "Value",
        "entity_category": "config",
        "enabled_by_default": True,
        "command_topic": "modbus/dev/value/set",
    } | _state() | {
        "min": 0.5,
        "max": 10.0,
        "step": 0.1,
        "mode": "box",
        "unit_of_measurement": "bar",
        "device_class": "pressure",
    }


@pytest.mark.parametrize(
    ("entity", "limits", "bounds"),
    [
        ({"min": 10, "max": 50}, {}, (10.0, 50.0)),
        ({"min": 10, "max": 50}, {"value": (20.0, 40.0)}, (20.0, 40.0)),
        ({"min": 10, "max": 50}, {"value": (None, 40.0)}, (10.0, 40.0)),
        ({"min": 10, "max": 50}, {"value": (45.0, 30.0)}, (10.0, 50.0)),  # contradictory
        ({}, {}, (0, 65535)),
        ({"scale": 0.1}, {}, (0.0, 6553.5)),
        ({"type": "s16", "scale": 0.01}, {}, (-327.68, 327.67)),
        ({"scale": -1}, {}, (-65535, 0)),
        ({"bit": 4, "width": 4}, {}, (0, 15)),
    ],
)
def test_number_range(
    entity: dict[str, Any], limits: dict[str, Any], bounds: tuple[float, float]
) -> None:
    config = _one({"access": "rw"} | entity, limits=limits)
    assert config is not None
    assert (config["min"], config["max"]) == bounds


def test_number_range_offers_no_guarded_value_until_dangerous_writes_are_allowed() -> None:
    """A negative speed reference (reverse) is guarded: Home Assistant does not offer it
    until the device allows dangerous writes."""
    entity = {"access": "rw", "type": "s16", "scale": 0.01, "min": -100, "max": 100}
    guarded = entity | {"dangerous_below": 0}
    assert _bounds(_one(entity)) == (-100.0, 100.0)
    assert _bounds(_one(guarded)) == (0.0, 100.0)
    assert _bounds(_one(guarded, allow_dangerous_writes=True)) == (-100.0, 100.0)
    above = entity | {"dangerous_below": -200}  # guards nothing in the range
    assert _bounds(_one(above)) == (-100.0, 100.0)


def _bounds(config: dict[str, Any] | None) -> tuple[float, float]:
    assert config is not None
    return config["min"], config["max"]


def test_number_range_with_a_sign_bit() -> None:
    entities = {
        "sign": {"name": "Sign", "address": 1, "bit": 0, "access": "rw"},
        "value": {"name": "Value", "address": 0, "access": "rw", "sign_from": "sign"},
    }
    config = _cmps(entities)["value"]
    assert (config["min"], config["max"]) == (-65535, 65535)


def test_number_step_and_mode() -> None:
    config = _one({"access": "rw", "scale": 0.5, "step": 2, "ha": {"mode": "slider"}})
    assert config is not None
    assert (config["step"], config["mode"]) == (2.0, "slider")
    assert "expire_after" not in config


def test_select() -> None:
    config = _one({"access": "rw", "enum": {0: "auto", 1: "manual"}})
    assert config == _ids("select") | {
        "name": "Value",
        "enabled_by_default": True,
        "command_topic": "modbus/dev/value/set",
    } | _state() | {"options": ["auto", "manual"]}


def test_switch() -> None:
    config = _one({"access": "rw", "type": "bool", "ha": {"device_class": "outlet"}})
    assert config == _ids("switch") | {
        "name": "Value",
        "enabled_by_default": True,
        "command_topic": "modbus/dev/value/set",
    } | _state() | {
        "payload_on": "ON",
        "payload_off": "OFF",
        "state_on": "True",
        "state_off": "False",
        "device_class": "outlet",
    }


def test_button() -> None:
    config = _one({"access": "w", "press": 1, "ha": {"device_class": "restart"}})
    assert config == _ids("button") | {
        "name": "Value",
        "enabled_by_default": True,
        "command_topic": "modbus/dev/value/set",
        "payload_press": "PRESS",
        "device_class": "restart",
    }


def test_text() -> None:
    config = _one({"access": "rw", "type": "ascii", "count": 5})
    assert config == _ids("text") | {
        "name": "Value",
        "enabled_by_default": True,
        "command_topic": "modbus/dev/value/set",
        "state_topic": STATE,
        "value_template": "{{ value_json.value if value_json.value is not none else '' }}",
        "max": 10,
        "mode": "text",
    }


@pytest.mark.parametrize(
    ("entity", "platform", "extra"),
    [
        ({"min": 0, "max": 9}, "number", {"min": 0.0, "max": 9.0, "step": 1.0, "mode": "box"}),
        ({"type": "bool"}, "switch", {"payload_on": "ON", "payload_off": "OFF"}),
        ({"type": "ascii", "count": 2}, "text", {"max": 4, "mode": "text"}),
    ],
)
def test_write_only_entities_have_no_state(
    entity: dict[str, Any], platform: str, extra: dict[str, Any]
) -> None:
    config = _one({"access": "w"} | entity)
    assert (
        config
        == _ids(platform)
        | {
            "name": "Value",
            "enabled_by_default": True,
            "command_topic": "modbus/dev/value/set",
        }
        | extra
    )


COMMAND = {"address": 9, "access": "w", "enum": {1: "run", 2: "stop", 3: "reset"}}
DRIVE_STATE = {"name": "State", "address": 10, "enum": {1: "running", 2: "standby", 3: "fault"}}


def test_a_write_only_select_shows_no_remembered_state() -> None:
    """Without a state topic Home Assistant runs a select optimistic: it would show the
    last option chosen (run) after the device stopped or tripped. A rendered None is its
    unknown state."""
    config = _one(COMMAND)
    assert config == _ids("select") | {
        "name": "Value",
        "enabled_by_default": True,
        "command_topic": "modbus/dev/value/set",
        "options": ["run", "stop", "reset"],
        "state_topic": STATE,
        "value_template": "{{ none }}",
    }


def test_a_write_only_select_shows_the_state_it_is_linked_to() -> None:
    link = {"entity": "state", "labels": {"running": "run", "standby": "stop"}}
    cmps = _cmps(
        {"command": COMMAND | {"name": "Command", "state_from": link}, "state": DRIVE_STATE}
    )
    assert cmps["command"]["state_topic"] == STATE
    assert cmps["command"]["value_template"] == (
        '{% set s = value_json.state %}{{ {"running": "run", "standby": "stop"}.get(s) }}'
    )


@pytest.mark.parametrize(
    ("link", "row"),
    [
        (
            {"entity": "state", "labels": {"fault": "halt"}},
            "entities.command: state_from.labels: 'halt' is not one of the options",
        ),
        (
            {"entity": "state", "labels": {"tripped": "stop"}},
            "entities.command.state_from.labels: 'tripped' is not one of 'state''s labels",
        ),
        (
            {"entity": "speed", "labels": {"running": "run"}},
            "entities.command.state_from.entity: 'speed' must be a readable enum",
        ),
        (
            {"entity": "nothing", "labels": {"running": "run"}},
            "entities.command.state_from.entity: 'nothing' must be a readable enum",
        ),
    ],
)
def test_a_state_link_names_an_enum_and_labels_both_have(link: dict[str, Any], row: str) -> None:
    entities = {
        "command": COMMAND | {"name": "Command", "state_from": link},
        "state": DRIVE_STATE,
        "speed": {"name": "Speed", "address": 11},
    }
    with pytest.raises(ValidationError) as caught:
        make_mapping(entities)
    assert list(format_validation_errors(caught.value)) == [row]


@pytest.mark.parametrize(
    ("fields", "row"),
    [
        ({"access": "rw"}, "entities.command: state_from is for a write-only select"),
        ({"press": 1, "enum": None}, "entities.command: state_from is for a write-only select"),
    ],
)
def test_a_state_link_is_for_a_write_only_select(fields: dict[str, Any], row: str) -> None:
    link = {"entity": "state", "labels": {"running": "run"}}
    command = {k: v for k, v in (COMMAND | fields).items() if v is not None}
    entities = {"command": command | {"name": "Command", "state_from": link}, "state": DRIVE_STATE}
    with pytest.raises(ValidationError) as caught:
        make_mapping(entities)
    assert next(iter(format_validation_errors(caught.value))).startswith(row)


# --- what is published ---------------------------------------------------------------------


@pytest.mark.parametrize("access", ["r", "rw", "w"])
def test_secret_entities_are_never_published(access: str) -> None:
    assert _one({"access": access, "secret": True}) is None


def test_dangerous_writable_entity_is_read_only_unless_allowed() -> None:
    entity = {
        "access": "rw",
        "dangerous": True,
        "unit": "Hz",
        "min": 10,
        "max": 60,
        "poll": "slow",
        "ha": {"device_class": "frequency", "entity_category": "config"},
    }
    assert _one(entity) == _ids("sensor") | {
        "name": "Value",
        "entity_category": "diagnostic",  # Home Assistant refuses config on sensors
        "enabled_by_default": False,  # a commissioning setting
    } | _state() | {
        "device_class": "frequency",
        "unit_of_measurement": "Hz",
        "suggested_display_precision": 0,
        "expire_after": 660,
    }
    allowed = _one(entity, allow_dangerous_writes=True)
    assert allowed is not None
    assert (allowed["platform"], allowed["unique_id"]) == ("number", "modbus_dev_value")
    assert (allowed["entity_category"], allowed["enabled_by_default"]) == ("config", False)


def test_dangerous_switch_shown_read_only_drops_the_switch_device_class() -> None:
    config = _one(
        {"access": "rw", "type": "bool", "dangerous": True, "ha": {"device_class": "switch"}}
    )
    assert config is not None
    assert config["platform"] == "binary_sensor"
    assert "device_class" not in config


def test_dangerous_select_shown_read_only_is_an_enum_sensor() -> None:
    config = _one({"access": "rw", "enum": {0: "a", 1: "b"}, "dangerous": True})
    assert config is not None
    assert (config["platform"], config["device_class"], config["options"]) == (
        "sensor",
        "enum",
        ["a", "b"],
    )


def test_dangerous_write_only_entity_is_omitted_unless_allowed() -> None:
    entity = {"access": "w", "press": 1, "dangerous": True}
    assert _one(entity) is None
    allowed = _one(entity, allow_dangerous_writes=True)
    assert allowed is not None
    assert allowed["platform"] == "button"


def test_entities_follow_the_device_options() -> None:
    entities = {
        "base": {"name": "Base", "address": 0},
        "solar": {"name": "Solar", "address": 1, "when": {"pv": "present"}},
        "freq": {
            "name": "Frequency",
            "address": 2,
            "scale": 0.1,
            "variants": [{"when": {"pv": "present"}, "scale": 0.01}],
        },
    }
    options = {
        "pv": {"description": "PV input", "choices": ["absent", "present"], "default": "absent"}
    }
    plain = _cmps(entities, mapping_options=options)
    assert sorted(plain) == ["base", "freq"]
    assert plain["freq"]["suggested_display_precision"] == 1
    solar = _cmps(entities, mapping_options=options, options={"pv": "present"})
    assert sorted(solar) == ["base", "freq", "solar"]
    assert solar["freq"]["suggested_display_precision"] == 2


# --- status and alarms ------------------------------------------------------------------


def test_the_status_entity_is_published_once_as_itself() -> None:
    """A status keyed otherwise (the Smartgen's genset_status) is its own component, not
    also a second, identical "Status" sensor; the alarms component joins the alarms."""
    entities = {
        "state": {"name": "State", "address": 0, "enum": {0: "stop", 1: "run"}},
        "trip": {"name": "Trip", "address": 1, "bit": 0, "alarm": True},
    }
    cmps = _cmps(entities, mapping_status="state")
    assert list(cmps) == [
        "state",
        "trip",
        "alarms",
        "alarm_events",  # the alarm's events and device triggers (test_alarm_events.py)
        "trip_raised_trigger",
        "trip_cleared_trigger",
    ]
    assert cmps["state"] == _ids("sensor", "state") | {
        "name": "State",
        "enabled_by_default": True,
    } | _state("state") | {
        "device_class": "enum",
        "options": ["stop", "run"],
        "expire_after": 602,
    }
    assert cmps["alarms"] == _ids("sensor", "alarms") | {
        "name": "Active alarms",
        "enabled_by_default": True,
        "icon": "mdi:alert",
        "state_topic": STATE,
        "value_template": (
            '{% set n = {"trip":"Trip"} %}{% set text %}{% for k in value_json.alarms %}'
            "{{ n.get(k, k | replace('_', ' ') | capitalize) }}"
            "{{ ', ' if not loop.last else '' }}{% endfor %}{% endset %}"
            "{{ (text or 'none')[:255] }}"
        ),
        "json_attributes_topic": STATE,
        "json_attributes_template": "{{ {'keys': value_json.alarms} | tojson }}",
        "expire_after": 602,
    }


def test_active_alarms_are_shown_by_name() -> None:
    """The state document lists keys and fault labels; Home Assistant shows names (the
    device's name taken off) and fault labels in words, not a normal code's label."""
    entities = {
        "alarm_dry_running": {"name": "Dry running", "address": 0, "bit": 0, "alarm": True},
        "common_shutdown": {"name": "Pump shutdown", "address": 0, "bit": 1, "alarm": True},
        "fault": {
            "name": "Fault",
            "address": 1,
            "alarm": True,
            "enum": {0: "no_fault", 1: "dc_bus_undervoltage", 2: "ok_too"},
            "normal": [0, 2],
        },
        "level": {"name": "Level", "address": 2},
    }
    mapping = make_mapping(entities)
    assert alarm_names(mapping.active(), "Pump") == {
        "alarm_dry_running": "Dry running",
        "common_shutdown": "Shutdown",
        "dc_bus_undervoltage": "Dc bus undervoltage",
    }
    template = _cmps(entities, name="Pump")["alarms"]["value_template"]
    assert template.startswith(
        '{% set n = {"alarm_dry_running":"Dry running","common_shutdown":"Shutdown",'
    )


def test_a_boolean_status_is_its_own_binary_sensor_only() -> None:
    entities = {"running": {"name": "Running", "address": 0, "bit": 1, "poll": "slow"}}
    cmps = _cmps(entities, mapping_status="running")
    assert list(cmps) == ["running"]
    assert cmps["running"]["platform"] == "binary_sensor"


@pytest.mark.parametrize("name", builtin_mapping_names())
def test_no_shipped_device_shows_its_status_twice(name: str) -> None:
    """The status entity has one component: its own (named by the mapping)."""
    mapping = load_mapping(builtin_mapping_path(name))
    cmps = build_device_discovery(_device(mapping), TOPICS, ORIGIN)["cmps"]
    assert mapping.status in cmps or has_no_status(mapping)
    readers = [k for k, c in cmps.items() if c.get("value_template", "").endswith(".status }}")]
    assert readers == (["status"] if mapping.status == "status" else [])


def test_an_entity_keyed_status_is_the_status_component() -> None:
    entities = {"status": {"name": "Drive state", "address": 0, "enum": {0: "a", 1: "b"}}}
    cmps = _cmps(entities, mapping_status="status")
    assert list(cmps) == ["status"]
    assert cmps["status"]["name"] == "Drive state"


def test_no_alarms_component_without_alarm_entities() -> None:
    assert list(_cmps({"level": {"name": "Level", "address": 0}})) == ["level"]


# --- entity mode and the bridge ---------------------------------------------------------


def test_entity_mode_inlines_the_shared_options() -> None:
    entities = {
        "level": {"name": "Level", "address": 0},
        "speed": {"name": "Speed", "address": 1, "access": "rw", "min": 0, "max": 5},
    }
    device = _device(make_mapping(entities))
    messages = build_discovery(device, TOPICS, ORIGIN, mode="entity")
    payload = build_device_discovery(device, TOPICS, ORIGIN)
    shared = {k: v for k, v in payload.items() if k != "cmps"}
    assert [m.topic for m in messages] == [
        "homeassistant/sensor/dev/level/config",
        "homeassistant/number/dev/speed/config",
    ]
    for message, (key, component) in zip(messages, payload["cmps"].items(), strict=True):
        expected = {k: v for k, v in component.items() if k != "platform"} | shared
        assert json.loads(message.payload) == expected, key
        assert message.retain


def test_bridge_device() -> None:
    [message] = build_bridge_discovery(TOPICS, ORIGIN, "modbus_bridge")
    assert message.topic == "homeassistant/device/modbus_bridge/config"
    assert json.loads(message.payload) == {
        "device": {
            "identifiers": ["modbus_bridge"],
            "manufacturer": "modbus-mqtt-bridge",
            "model": "Modbus MQTT bridge",
            "name": "Modbus MQTT bridge",
            "sw_version": "test",
        },
        "origin": ORIGIN.as_dict(),
        "cmps": {
            "connection_state": {
                "platform": "binary_sensor",
                "unique_id": "modbus_bridge_connection_state",
                "default_entity_id": "binary_sensor.modbus_bridge_connection_state",
                "name": "Connection state",
                "qos": 1,
                "entity_category": "diagnostic",
                "enabled_by_default": True,
                "device_class": "connectivity",
                "state_topic": "modbus/bridge/state",
                "payload_on": "online",
                "payload_off": "offline",
            }
        },
    }
    [entity] = build_bridge_discovery(TOPICS, ORIGIN, "modbus_bridge", mode="entity")
    assert entity.topic == "homeassistant/binary_sensor/modbus_bridge/connection_state/config"
    assert "platform" not in json.loads(entity.payload)


def _health_cmps(buses: tuple[str, ...] = (), devices: tuple[str, ...] = ()) -> dict[str, Any]:
    """The health sensors of the bridge's ``buses`` and of ``devices`` (on each device)."""
    [message] = build_bridge_discovery(TOPICS, ORIGIN, "modbus", buses=buses)
    cmps: dict[str, Any] = json.loads(message.payload)["cmps"]
    mapping = make_mapping({"x": {"name": "X", "address": 0}})
    for device_id in devices:
        payload = build_device_discovery(
            _device(mapping, id=device_id), TOPICS, ORIGIN, health=True
        )
        cmps |= {k: v for k, v in payload["cmps"].items() if k != "x"}
    return {k: v for k, v in cmps.items() if k != "connection_state"}


def test_bridge_health_sensors_per_bus_and_device() -> None:
    cmps = _health_cmps(buses=("rs485", "gw"), devices=("pump", "meter"))
    assert list(cmps) == [
        f"{kind}_{item}_{suffix}"
        for kind, items, suffixes in (
            ("bus", ("rs485", "gw"), ("request_rate", "utilisation", "timeouts", "frame_errors")),
            ("device", ("pump", "meter"), ("state", "latency_p95", "errors", "requests")),
        )
        for item in items
        for suffix in suffixes
    ]
    assert cmps["bus_gw_timeouts"] == {
        "platform": "sensor",
        "unique_id": "modbus_bridge_bus_gw_timeouts",
        "default_entity_id": "sensor.modbus_bus_gw_timeouts",
        "name": "Bus gw timeouts",
        "qos": 1,
        "entity_category": "diagnostic",
        "enabled_by_default": True,
        "state_topic": "modbus/bridge/health",
        "availability_topic": "modbus/bridge/state",
        "value_template": "{{ value_json.get('buses', {}).get('gw', {}).get('timeouts') }}",
        "state_class": "total_increasing",
        "icon": "mdi:timer-alert",
    }
    assert cmps["bus_gw_utilisation"]["value_template"] == (
        "{% set v = value_json.get('buses', {}).get('gw', {}).get('utilisation') %}"
        "{{ none if v is none else (v * 100) | round(1) }}"
    )
    assert cmps["bus_gw_utilisation"]["unit_of_measurement"] == "%"
    assert cmps["device_meter_state"]["options"] == ["online", "offline", "unknown"]
    for key, component in cmps.items():
        assert component["platform"] == "sensor", key
        assert component["entity_category"] == "diagnostic", key
        assert component["state_topic"] == "modbus/bridge/health", key
    unique_ids = [c["unique_id"] for c in cmps.values()]
    assert len(set(unique_ids)) == len(unique_ids)


def test_a_device_shows_its_own_health_with_the_ids_it_had_on_the_bridge() -> None:
    """The sensors moved from the bridge device to the device: same unique ids and entity
    ids (history stays), named for what they show; available whenever the bridge is,
    so that an offline device shows 'offline', not 'unavailable'."""
    payload = build_device_discovery(
        _device(make_mapping({"x": {"name": "X", "address": 0}}), id="pump"),
        TOPICS,
        ORIGIN,
        health=True,
    )
    assert payload["cmps"]["device_pump_latency_p95"] == {
        "platform": "sensor",
        "unique_id": "modbus_bridge_device_pump_latency_p95",
        "default_entity_id": "sensor.modbus_device_pump_latency_p95",
        "name": "Modbus latency p95",
        "qos": 1,
        "entity_category": "diagnostic",
        "enabled_by_default": False,
        "state_topic": "modbus/bridge/health",
        "availability": [{"topic": "modbus/bridge/state"}],
        "value_template": "{{ value_json.get('devices', {}).get('pump', {}).get('latency_p95_ms') }}",
        "unit_of_measurement": "ms",
        "device_class": "duration",
        "state_class": "measurement",
    }
    enabled = [k for k, c in payload["cmps"].items() if k != "x" and c["enabled_by_default"]]
    assert enabled == ["device_pump_state", "device_pump_errors"]
    without = build_device_discovery(
        _device(make_mapping({"x": {"name": "X", "address": 0}}), id="pump"), TOPICS, ORIGIN
    )
    assert list(without["cmps"]) == ["x"]


def test_an_enabled_health_sensor_says_why() -> None:
    for sensor in (*BUS_HEALTH_SENSORS, *DEVICE_HEALTH_SENSORS):
        assert sensor.enabled_reason is None or sensor.enabled_reason.strip(), sensor


def test_bridge_health_sensors_read_fields_of_the_health_document() -> None:
    """Each template names a field the report builder writes, with a value the sensor
    accepts (a number, or one of an enum's options)."""
    snapshot = Snapshot(
        wall=0.0,
        monotonic=10.0,
        uptime=10.0,
        buses=(BusSnapshot("rs485", "rtu", connected=True, requests=5, busy_seconds=1.0),),
        devices=(DeviceSnapshot("pump-1", "rs485", 1, online=True, latency_p95=0.02),),
    )
    document = build_health_report(snapshot)
    pattern = re.compile(
        r"value_json\.get\('(buses|devices)', \{\}\)\.get\('([^']+)', \{\}\)\.get\('(\w+)'\)"
    )
    for key, component in _health_cmps(buses=("rs485",), devices=("pump-1",)).items():
        match = pattern.search(component["value_template"])
        assert match is not None, key
        section, item, field = match.groups()
        value = document[section][item][field]
        if "options" in component:
            assert value in component["options"], key
        else:
            assert isinstance(value, int | float), key


def test_bridge_health_sensor_entity_ids_are_slugs() -> None:
    cmps = _health_cmps(buses=("line-A",))
    component = cmps["bus_line-A_timeouts"]
    assert component["unique_id"] == "modbus_bridge_bus_line-A_timeouts"
    assert component["default_entity_id"] == "sensor.modbus_bus_line_a_timeouts"
    assert (
        component["value_template"]
        == "{{ value_json.get('buses', {}).get('line-A', {}).get('timeouts') }}"
    )


def test_bridge_health_sensors_in_entity_mode() -> None:
    messages = build_bridge_discovery(
        TOPICS, ORIGIN, "modbus_bridge", mode="entity", buses=("rs485",)
    )
    topics = [m.topic for m in messages]
    assert len(topics) == 1 + 4
    assert "homeassistant/sensor/modbus_bridge/bus_rs485_request_rate/config" in topics
    device = _device(make_mapping({"x": {"name": "X", "address": 0}}), id="pump")
    messages = build_discovery(device, TOPICS, ORIGIN, mode="entity", health=True)
    assert "homeassistant/sensor/pump/device_pump_state/config" in [m.topic for m in messages]


@pytest.mark.parametrize(
    ("device_name", "name", "shown"),
    [
        ("Genset", "Genset status", "Status"),
        ("Genset", "genset status", "Status"),
        ("Borehole pump", "Borehole pump run time", "Run time"),
        ("Genset", "Genset", "Genset"),  # nothing left: kept
        ("Gen", "Genset status", "Genset status"),  # a word, not a prefix of one
        ("Pump", "Main pump speed", "Main pump speed"),
    ],
)
def test_an_entity_name_does_not_repeat_the_device_name(
    device_name: str, name: str, shown: str
) -> None:
    config = _one({"name": name}, name=device_name)
    assert config is not None
    assert config["name"] == shown


def test_an_entity_id_does_not_repeat_the_device_id() -> None:
    """Key genset_status on the device genset asks for sensor.genset_status (its unique
    id stays the key's: Home Assistant keeps an existing entity's id and history); the
    repeat stays where the shorter id is another key's, and for a key that is only the
    device id."""
    entities = {
        "genset_status": {"name": "Status", "address": 0},
        "genset_mode": {"name": "Mode", "address": 1},
        "mode": {"name": "Mode code", "address": 2},
        "genset": {"name": "Genset", "address": 3},
        "trip": {"name": "Trip", "address": 4, "bit": 0, "alarm": True},
        "genset_alarms": {"name": "Alarm word", "address": 5},
    }
    cmps = _cmps(entities, id="genset", name="Standby genset")
    ids = {
        key: (c["unique_id"], c["default_entity_id"])
        for key, c in cmps.items()
        if c["platform"] != "device_automation"  # a trigger is no entity: no ids
    }
    assert ids == {
        "genset_status": ("modbus_genset_genset_status", "sensor.genset_status"),
        "genset_mode": ("modbus_genset_genset_mode", "sensor.genset_genset_mode"),
        "mode": ("modbus_genset_mode", "sensor.genset_mode"),
        "genset": ("modbus_genset_genset", "sensor.genset_genset"),
        "trip": ("modbus_genset_trip", "binary_sensor.genset_trip"),
        "genset_alarms": ("modbus_genset_genset_alarms", "sensor.genset_genset_alarms"),
        "alarms": ("modbus_genset_alarms", "sensor.genset_alarms"),
        "alarm_events": ("modbus_genset_alarm_events", "event.genset_alarm_events"),
    }
    dashed = _cmps({"main_drive_speed": {"name": "Speed", "address": 0}}, id="main-drive")
    assert dashed["main_drive_speed"]["default_entity_id"] == "sensor.main_drive_speed"


def test_every_device_points_to_the_bridge() -> None:
    [bridge_message] = build_bridge_discovery(TOPICS, ORIGIN, "modbus_bridge")
    bridge_ids = json.loads(bridge_message.payload)["device"]["identifiers"]
    device = build_device_discovery(
        _device(make_mapping({"x": {"name": "X", "address": 0}})), TOPICS, ORIGIN
    )
    assert device["device"]["via_device"] in bridge_ids


# --- exact snapshots --------------------------------------------------------------------


def _pretty(data: Any) -> str:
    return json.dumps(data, indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def _check_snapshot(name: str, data: Any) -> None:
    path = GOLDEN / f"{name}.json"
    text = _pretty(data)
    if os.environ.get("UPDATE_SNAPSHOTS") == "1":
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        return
    if not path.is_file():
        pytest.fail(f"no snapshot {path}: run UPDATE_SNAPSHOTS=1 pytest {__file__}")
    stored = path.read_text(encoding="utf-8")
    if stored != text:
        diff = difflib.unified_diff(
            stored.splitlines(), text.splitlines(), str(path), "built now", lineterm=""
        )
        pytest.fail("discovery differs from the snapshot:\n" + "\n".join(diff), pytrace=False)


def _shipped(name: str) -> DeviceInfo:
    return DeviceInfo(
        id=name,
        name=name,
        mapping=load_mapping(builtin_mapping_path(name)),
        options={},
        bus="rs485",
        unit=1,
        allow_dangerous_writes=False,
        fast_interval=2.0,
        slow_interval=60.0,
    )


def _as_read(device: DeviceInfo) -> dict[str, Any]:
    """Units and limits as the bridge has them when it first publishes a device: read
    from its registers (here: what a simulated unit holds at start)."""
    points = device.mapping.points(device.options)
    image = initial_image(device.mapping, points)
    units = {k: unit_of(p, image) for k, p in points.items() if p.unit_source is not None}
    limits = {
        k: limits_of(p, image)
        for k, p in points.items()
        if p.min_source is not None or p.max_source is not None
    }
    return {"units": units, "limits": limits}


@pytest.mark.parametrize("name", builtin_mapping_names())
def test_shipped_mapping_snapshot(name: str) -> None:
    """What Home Assistant gets for each shipped mapping: one config, once, with the units
    and limits read from the device (bridge/discovery_publisher.py waits for them)."""
    device = _shipped(name)
    payload = build_device_discovery(device, TOPICS, ORIGIN, health=True, **_as_read(device))
    _check_snapshot(name, payload)


SUNSPEC_SNAPSHOTS = ("inverter_mppt", "meter", "battery", "device_1547")


@pytest.mark.parametrize("name", SUNSPEC_SNAPSHOTS)
def test_sunspec_device_snapshot(name: str) -> None:
    """What Home Assistant gets for a SunSpec device's built mapping (an inverter with four
    MPPTs, a meter, a battery, pysunspec2's 1547 device), dangerous writes allowed so its
    settings are offered too: ``make test-ha`` checks each against both Home Assistant
    versions (tools/check_ha_discovery.py)."""
    image = build_image(SUNSPEC_IMAGES[name], 40000, name)
    built = build_mapping(walked(image), image.registers)
    device = DeviceInfo(
        id=f"sunspec_{name}",
        name=f"SunSpec {name}",
        mapping=built.mapping(),
        options={},
        bus="rs485",
        unit=1,
        allow_dangerous_writes=True,
        fast_interval=2.0,
        slow_interval=60.0,
    )
    payload = build_device_discovery(device, TOPICS, ORIGIN, health=True, **_as_read(device))
    _check_snapshot(f"sunspec_{name}", payload)


def test_bridge_snapshot() -> None:
    [message] = build_bridge_discovery(TOPICS, ORIGIN, "modbus_bridge", buses=("rs485",))
    _check_snapshot("bridge", json.loads(message.payload))


SAMPLE_ENTITIES: dict[str, dict[str, Any]] = {
    "pressure": {
        "name": "Pressure",
        "address": 0,
        "scale": 0.1,
        "unit": "bar",
        "ha": {"device_class": "pressure", "state_class": "measurement"},
    },
    "state": {"name": "State", "address": 1, "enum": {0: "stopped", 1: "running"}},
    "overload": {"name": "Overload", "address": 2, "bit": 0, "alarm": True},
    "serial": {
        "name": "Serial number",
        "address": 3,
        "type": "ascii",
        "count": 4,
        "poll": "once",
        "ha": {"entity_category": "diagnostic"},
    },
    "setpoint": {
        "name": "Setpoint",
        "address": 10,
        "access": "rw",
        "scale": 0.1,
        "min": 0,
        "max": 16,
        "unit": "bar",
        "ha": {"device_class": "pressure", "entity_category": "config"},
    },
    "mode": {"name": "Mode", "address": 11, "access": "rw", "enum": {0: "auto", 1: "manual"}},
    "run": {"name": "Run", "address": 12, "access": "rw", "type": "bool"},
    "label": {"name": "Label", "address": 13, "access": "rw", "type": "ascii", "count": 4},
    "command": {"name": "Command", "address": 20, "access": "w", "enum": {1: "start", 2: "stop"}},
    "reset": {"name": "Reset", "address": 21, "access": "w", "press": 1},
    "baudrate": {
        "name": "Baud rate",
        "address": 22,
        "access": "rw",
        "dangerous": True,
        "enum": {0: "9600", 1: "19200"},
        "ha": {"entity_category": "config"},
    },
}


def test_entity_mode_snapshot() -> None:
    mapping = make_mapping(SAMPLE_ENTITIES, status="state")
    messages = build_discovery(
        _device(mapping, id="sample", name="Sample"), TOPICS, ORIGIN, mode="entity"
    )
    _check_snapshot(
        "entity_mode_sample",
        [
            {"topic": m.topic, "retain": m.retain, "payload": json.loads(m.payload)}
            for m in messages
        ],
    )


# --- a value read is never dropped: the payload admits what the device holds (issue 12) ------


def test_an_enum_code_without_a_label_becomes_an_option_while_it_is_read() -> None:
    entities = {
        "mode": {"name": "Mode", "address": 0, "enum": {0: "auto", 1: "manual"}},
        "speed": {"name": "Speed", "address": 1, "access": "rw", "enum": {0: "low", 1: "high"}},
    }
    readings = {"mode": "code_23", "speed": "code_7"}
    cmps = _cmps(entities, mapping_status="mode", readings=readings)
    assert cmps["mode"]["options"] == ["auto", "manual", "code_23"]
    assert cmps["mode"]["device_class"] == "enum"
    assert cmps["speed"]["options"] == ["low", "high", "code_7"]
    plain = _cmps(entities, mapping_status="mode", readings={"mode": "manual"})
    assert plain["mode"]["options"] == ["auto", "manual"]


def test_the_status_component_admits_the_status_entity_s_unknown_code() -> None:
    entities = {"state": {"name": "State", "address": 0, "enum": {0: "off", 1: "on"}}}
    mapping = make_mapping(entities, status="state")
    image = {(Table.HOLDING, 0): 9}
    values = {"state": "code_9"}
    shown = shown_readings(mapping.points(), values, image)
    assert shown == {"state": "code_9"}
    cmps = _cmps(entities, mapping_status="state", readings=shown)
    assert "status" not in cmps  # the status entity is published once, as itself
    assert cmps["state"]["options"] == ["off", "on", "code_9"]


@pytest.mark.parametrize(
    ("entity", "reading", "bounds"),
    [
        ({"min": 1, "max": 9999}, 0, (0, 9999)),  # an unconfigured parameter reads 0
        ({"min": 1, "max": 9999}, 12000, (1, 12000)),
        ({"min": 1, "max": 9999}, 50, (1, 9999)),
        ({"type": "s16", "scale": 0.01, "min": -100, "max": 100, "dangerous_below": 0}, -5.5,
         (-5.5, 100)),  # a negative reference read is shown, though not offered for writing
    ],
)  # fmt: skip
def test_a_number_range_covers_the_value_the_device_reads(
    entity: dict[str, Any], reading: float, bounds: tuple[float, float]
) -> None:
    config = _one({"access": "rw"} | entity, readings={"value": reading})
    assert _bounds(config) == bounds


def test_shown_readings_are_the_values_home_assistant_would_drop() -> None:
    entities = {
        "ramp": {"name": "Ramp", "address": 0, "access": "rw", "min": 1, "max": 300},
        "low": {"name": "Low", "address": 1, "access": "rw", "max": 50},
        "freq": {"name": "Freq", "address": 2, "access": "rw", "min_from": "low"},
        "temp": {"name": "Temp", "address": 3, "ha": {"state_class": "measurement"}},
        "mode": {"name": "Mode", "address": 4, "enum": {0: "a"}},
        "ref": {"name": "Ref", "address": 5, "access": "rw", "type": "s16",
                "dangerous_below": 0},
    }  # fmt: skip
    points = make_mapping(entities).points()
    image = {(Table.HOLDING, a): 0 for a in range(6)} | {(Table.HOLDING, 1): 20}
    values = {"ramp": 0, "low": 20, "freq": 10, "temp": 99999, "mode": "a", "ref": -3}
    assert shown_readings(points, values, image) == {"ramp": 0, "freq": 10, "ref": -3}
    values |= {"ramp": 5, "freq": 25, "mode": "code_4", "ref": 0}
    assert shown_readings(points, values, image) == {"mode": "code_4"}
    del image[(Table.HOLDING, 1)]  # the limit register not read yet: the static limits
    assert shown_readings(points, values | {"freq": 10}, image) == {"mode": "code_4"}


def test_a_payload_admits_the_readings_inside_the_range_its_reading_widened() -> None:
    """A setting read below its limits widened the range sent: readings between it and the
    limits need no new payload; one further out, or a new unknown code, does."""
    entities = {
        "ramp": {"name": "Ramp", "address": 0, "access": "rw", "min": 1, "max": 300},
        "ref": {"name": "Ref", "address": 1, "access": "rw", "type": "s16", "max": 50,
                "dangerous_below": 0},
        "mode": {"name": "Mode", "address": 2, "enum": {0: "a"}},
    }  # fmt: skip
    points = make_mapping(entities).points()
    image = {(Table.HOLDING, a): 0 for a in range(3)}
    sent = {"ramp": 0, "ref": -10, "mode": "code_4"}
    assert admitted(points, sent, sent, image)
    assert admitted(points, sent, {"ref": -3}, image)  # back towards the floor
    assert admitted(points, sent, {}, image)  # back in range: the wider payload still shows it
    assert not admitted(points, sent, {"ref": -11}, image)  # further out
    assert not admitted(points, sent, {"ramp": 301}, image)  # out on the other side
    assert not admitted(points, sent, {"mode": "code_5"}, image)  # another unknown code
    assert not admitted(points, {}, {"ramp": 0}, image)  # nothing widened yet
    assert not admitted(points, sent, {"other": "code_4"}, image)  # not sent for that key


def test_entities_on_one_register_are_each_their_own_component() -> None:
    """A raw word, a select, a switch, a view and a bit of one register: one component
    each, with its own unique id and platform (nothing is keyed by address)."""
    cmps = _cmps({k: v for k, v in ENTITIES.items() if k in MODE})
    platforms = {key: cmps[key]["platform"] for key in MODE}
    assert platforms == {
        "mode_raw": "number",
        "mode": "select",
        "backup": "switch",
        "feeding_in": "binary_sensor",
        "bit_0": "switch",
    }
    assert {cmps[key]["unique_id"] for key in MODE} == {f"modbus_dev_{key}" for key in MODE}
