"""The words the web page shows for values and alarms: Home Assistant's, never the keys."""

from __future__ import annotations

import re
from typing import Any

import pytest

from bridge.core.codec import unknown_code
from bridge.core.discovery_alarms import in_words
from bridge.core.entity import Entity
from bridge.core.hass import BINARY_SENSOR_CLASSES, BINARY_SENSOR_STATES, binary_sensor_class
from bridge.core.mapping import Mapping, builtin_mapping_path, load_mapping
from bridge.core.state import active_alarms
from bridge.core.wording import (
    UNKNOWN,
    alarm_texts,
    label_text,
    number_text,
    unit_sources,
    value_text,
)

SEEDS = ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100")
KEY = re.compile(r"^[a-z][a-z0-9_]*$")  # a label written as a key


def seed(name: str) -> Mapping:
    return load_mapping(builtin_mapping_path(name))


def entity(**fields: Any) -> Entity:
    return Entity.model_validate({"name": "x", "address": 1} | fields)


@pytest.mark.parametrize("name", SEEDS)
def test_every_label_of_a_seed_reads_in_words_and_never_as_its_key(name: str) -> None:
    mapping = seed(name)
    units = unit_sources(mapping.points())
    enums = {k: e for k, e in mapping.entities.items() if e.enum is not None}
    assert enums
    for key, each in enums.items():
        for label in (each.enum or {}).values():
            text = value_text(each, label, None, False, key in units)
            if key in units or not KEY.match(label):  # bar, 2.5 kHz: already words
                assert text == label, (key, label)
            else:
                assert text == in_words(label) and text != label, (key, label)
                assert "_" not in text and text[0].isupper(), (key, label)


@pytest.mark.parametrize("name", SEEDS)
def test_each_seed_status_reads_as_home_assistant_shows_it(name: str) -> None:
    mapping = seed(name)
    assert mapping.status is not None
    status = mapping.entities[mapping.status]
    if status.enum is not None:
        shown = {value_text(status, label, None, False) for label in status.enum.values()}
        assert not shown & set(status.enum.values())  # no key shown as it is
    else:  # the Vacon's "Running": a binary sensor of class running
        assert status.ha.device_class == "running"
        assert value_text(status, True, None, False) == "Running"
        assert value_text(status, False, None, False) == "Not running"
    assert value_text(status, None, None, False) == UNKNOWN


def test_the_p2_status_and_fault_read_as_their_labels_in_words() -> None:
    p2 = seed("p2_vfd")
    status, fault = p2.entities["status"], p2.entities["fault_code"]
    assert value_text(status, "running_forward", None, False) == "Running forward"
    assert value_text(fault, "no_fault", None, False) == "No fault"
    assert value_text(fault, "dc_bus_undervoltage", None, False) == "Dc bus undervoltage"


def test_a_code_the_mapping_has_no_label_for_says_so() -> None:
    status = seed("p2_vfd").entities["status"]
    assert value_text(status, unknown_code(9), None, False) == "Unknown code 9"
    unit = seed("nastec_vasco").entities["unit"]
    assert value_text(unit, unknown_code(77), None, False, units=True) == "Unknown code 77"
    assert label_text(entity(type="ascii", count=2), "code_1") == "code_1"  # text as it is


def test_every_binary_sensor_class_has_home_assistants_words() -> None:
    assert set(BINARY_SENSOR_STATES) == BINARY_SENSOR_CLASSES | {None}
    for device_class in BINARY_SENSOR_CLASSES:
        sensor = entity(table="discrete", ha={"device_class": device_class})
        off, on = BINARY_SENSOR_STATES[device_class]
        assert value_text(sensor, True, None, False) == on != off
        assert value_text(sensor, False, None, False) == off


def test_booleans_read_as_the_platform_they_are_published_as() -> None:
    plain = entity(table="discrete")
    assert [value_text(plain, v, None, False) for v in (True, False)] == ["On", "Off"]
    alarm = entity(table="discrete", alarm=True)  # published with class problem
    assert binary_sensor_class(alarm) == "problem"
    assert [value_text(alarm, v, None, False) for v in (True, False)] == ["Problem", "OK"]
    switch = entity(type="bool", access="rw", ha={"device_class": "switch"})
    assert binary_sensor_class(switch) is None  # a switch's class is no binary sensor's
    assert [value_text(switch, v, None, False) for v in (True, False)] == ["On", "Off"]
    # a guarded switch is shown read-only (a binary sensor) until the device allows it
    guarded = entity(type="bool", access="rw", dangerous=True, alarm=True)
    assert value_text(guarded, True, None, False) == "Problem"
    assert value_text(guarded, True, None, True) == "On"


@pytest.mark.parametrize(
    ("value", "decimals", "text"),
    [
        (12.345, 1, "12.3"),
        (5, 2, "5.00"),
        (100, 0, "100"),
        (-0.04, 1, "0.0"),
        (-0.0, 0, "0"),
        (-1.26, 1, "-1.3"),
        (0.1 + 0.2, None, "0.30000000000000004"),  # decimals not known yet: as it is
        (1500, None, "1500"),
    ],
)
def test_numbers_read_with_their_decimals(value: float, decimals: int | None, text: str) -> None:
    assert number_text(value, decimals) == text
    assert value_text(entity(), value, decimals, False) == text


def test_text_values_read_as_they_are() -> None:
    text = entity(type="ascii", count=4)
    assert value_text(text, "running_forward", None, False) == "running_forward"


def test_active_alarms_read_as_the_names_home_assistant_shows() -> None:
    points = seed("nastec_vasco").points()
    values: dict[str, Any] = {"alarm_dry_running": True}
    keys = active_alarms(points, values)
    assert alarm_texts(points, keys, "Pump") == ["Dry running"]
    p2 = seed("p2_vfd").points()
    for values, names in (
        ({"fault_code": "overcurrent_accel"}, ["Overcurrent accel"]),
        ({"fault_code": unknown_code(99)}, ["Fault code 99"]),  # as the alarms sensor does
        ({"fault_code": "no_fault"}, []),
    ):
        assert alarm_texts(p2, active_alarms(p2, values), "Fan drive") == names
