"""The page's JSON documents speak as Home Assistant does: the demo's five seed devices (not
running, holding what the simulator starts with) through ``bridge.web.views``."""

from __future__ import annotations

from typing import Any

from bridge.app import Bridge
from bridge.core.codec import unknown_code
from bridge.core.discovery import DeviceInfo, Origin, build_device_discovery
from bridge.core.discovery_alarms import in_words
from bridge.core.discovery_entity import shown_name
from bridge.core.hass import BINARY_SENSOR_STATES
from bridge.core.state import published
from bridge.core.topics import Topics
from bridge.modbus.poller import DevicePoller
from bridge.web.views import changed_values, device_document, summary
from tests.unit.test_demo_view import demo_bridge


def poller(bridge: Bridge, device_id: str) -> DevicePoller:
    return bridge.engine.devices[device_id]


def test_each_device_status_is_its_label_in_words_with_the_key_beside_it() -> None:
    bridge = demo_bridge()
    for each in bridge.engine.devices.values():
        row = summary(each, {})
        key = each.mapping.status
        assert key is not None and row["status"] == each.values[key]
        status = each.points[key].entity
        if status.enum is not None:
            assert row["status_text"] == in_words(row["status"]) != row["status"], row
        else:
            assert row["status_text"] in ("Running", "Not running"), row
    fan = summary(poller(bridge, "fan_drive"), {})
    assert (fan["status"], fan["status_text"]) == ("running_forward", "Running forward")
    vacon = poller(bridge, "main_drive")
    vacon.values["running"] = False
    assert summary(vacon, {})["status_text"] == "Not running"
    vacon.values["running"] = None
    assert summary(vacon, {})["status_text"] == "Unknown"


def test_every_value_row_carries_the_name_and_words_home_assistant_shows() -> None:
    bridge = demo_bridge()
    for each in bridge.engine.devices.values():
        document = device_document(each, {}, "modbus/x")
        rows = {row["key"]: row for row in document["values"]}
        assert list(rows) == published(each.points)
        for key, row in rows.items():
            entity = each.points[key].entity
            assert row["name"] == shown_name(entity.name, each.device.display_name)
            value = row["value"]
            if entity.enum is not None and isinstance(value, str) and "_" in value:
                assert row["text"] != value, (each.device.id, key)  # never the key
            if isinstance(value, bool):
                assert row["text"] in _BOOLEAN_WORDS, (each.device.id, key, row["text"])
    genset = device_document(poller(bridge, "genset"), {}, "modbus/genset")
    names = [row["name"] for row in genset["values"]]
    assert "Genset status" not in names and "Status" in names  # as Home Assistant shows it


_BOOLEAN_WORDS = {word for words in BINARY_SENSOR_STATES.values() for word in words}


def test_numbers_carry_their_decimals_and_units() -> None:
    fan = poller(demo_bridge(), "fan_drive")
    rows = {row["key"]: row for row in device_document(fan, {}, "t")["values"]}
    frequency = rows["max_output_frequency"]
    assert frequency["unit"] == "Hz" and frequency["decimals"] == 2
    assert frequency["text"] == f"{frequency['value']:.2f}"


def test_an_alarm_and_an_unknown_code_read_clearly_and_keep_their_keys() -> None:
    bridge = demo_bridge()
    fan = poller(bridge, "fan_drive")
    fan.values["fault_code"] = unknown_code(99)
    row = summary(fan, {})
    assert row["alarms"] == ["fault_code_99"] and row["alarm_names"] == ["Fault code 99"]
    fan.values["status"] = unknown_code(7)
    assert summary(fan, {})["status_text"] == "Unknown code 7"
    values = changed_values(fan, {"fault_code", "status"})
    assert values["values"]["fault_code"]["text"] == "Unknown code 99"
    assert values["alarm_names"] == ["Fault code 99"] and values["status"] == "code_7"

    pump = poller(bridge, "borehole_pump")
    pump.values["alarm_dry_running"] = True
    change: dict[str, Any] = changed_values(pump, {"alarm_dry_running", "no_such_key"})
    assert list(change["values"]) == ["alarm_dry_running"]
    dry = change["values"]["alarm_dry_running"]
    assert (dry["value"], dry["text"], dry["alarm"]) == (True, "Problem", True)
    assert change["alarms"] == ["alarm_dry_running"]
    assert change["alarm_names"] == ["Dry running"]
    assert change["status_text"] == summary(pump, {})["status_text"]


def test_a_unit_register_reads_its_unit_as_it_is() -> None:
    pump = poller(demo_bridge(), "borehole_pump")
    rows = {row["key"]: row for row in device_document(pump, {}, "t")["values"]}
    unit = rows["unit"]
    assert unit["text"] == unit["value"], unit  # bar, not Bar


def test_the_page_names_and_words_are_those_of_the_discovery_payload() -> None:
    """Each value under the ``name`` its discovery component gives Home Assistant, a binary
    sensor in the words of the ``device_class`` it is published with, an enum's value one
    of the ``options`` Home Assistant takes."""
    bridge = demo_bridge()
    for each in bridge.engine.devices.values():
        info = DeviceInfo(
            id=each.device.id,
            name=each.device.display_name,
            mapping=each.mapping,
            options=dict(each.device.options),
            bus=each.device.bus,
            unit=each.device.unit,
            allow_dangerous_writes=each.device.allow_dangerous_writes,
            fast_interval=2.0,
            slow_interval=60.0,
        )
        cmps = build_device_discovery(info, Topics("modbus", "homeassistant"), Origin())["cmps"]
        rows = device_document(each, {}, "t")["values"]
        for row in rows:
            component = cmps[row["key"]]  # every value the page shows is an entity in HA
            assert row["name"] == component["name"], row["key"]
            if component["platform"] == "binary_sensor" and row["value"] is not None:
                words = BINARY_SENSOR_STATES[component.get("device_class")]
                assert row["text"] == words[row["value"]], row
            if "options" in component and row["value"] is not None:
                assert row["value"] in component["options"], row
