"""ESPHome's modbus_controller YAML imported: the documentation's examples and ESPHome's
own test convert, values decode as ESPHome reads them, code and filters are reported."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.cli import main
from bridge.config import load_config
from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import Mapping
from bridge.importer.esphome import import_esphome
from bridge.importer.source import load_source

DATA = Path(__file__).parent / "data" / "esphome"


def test_the_documentation_example_converts_with_every_key_accounted_for() -> None:
    result = import_esphome(load_source(DATA / "docs_example.yaml"), "docs_example.yaml")
    assert result.buses == [
        {
            "id": "epever",
            "transport": "rtu",
            "port": "/dev/ttyUSB0",
            "timeout": 0.25,
            "baudrate": 115200,
            "parity": "N",
            "stopbits": 1,
            "bytesize": 8,
        },
    ]
    (device,) = result.devices
    assert device.config == {
        "id": "modbus_device",
        "name": "Modbus device",
        "bus": "epever",
        "unit": 1,
        "poll": {"fast": 60.0, "slow": 3660.0},
    }
    entities = device.mapping["entities"]
    assert list(entities) == [
        "battery_capacity",
        "array_rated_voltage",
        "array_rated_power",
        "alarm_bit0",
        "alarm_bit10",
        "alarm_bit15",
        "reset_to_factory_default",
    ]
    assert entities["array_rated_power"] == {
        "name": "array_rated_power",
        "address": 0x3002,
        "table": "input",
        "type": "u32",
        "word_order": "little",
        "scale": 0.01,
        "offset": 0.0,
        "unit": "W",
        "poll": "fast",
        "ha": {"entity_id": "epever_array_rated_power", "display_precision": 1},
    }
    assert entities["reset_to_factory_default"]["dangerous"] is True
    assert [(n.where.line, n.key, n.partly) for n in result.notes] == [
        (8, "uart", True),
        (13, "modbus.flow_control_pin", False),
        (67, "rtc_clock.internal", False),
        (71, "rtc_clock.raw_encode", False),
        (55, "Reset to Factory Default", True),
        (20, "modbus_device.setup_priority", False),
    ]


def test_values_decode_as_esphome_reads_them() -> None:
    result = import_esphome(load_source(DATA / "docs_example.yaml"), "docs_example.yaml")
    points = Mapping.model_validate(result.devices[0].mapping).points()
    # U_DWORD_R: low word first; multiply 0.01
    image = {(Table.INPUT, 0x3002): 0x5678, (Table.INPUT, 0x3003): 0x0001}
    assert decode(points["array_rated_power"], image) == pytest.approx(0x15678 * 0.01)
    # the documentation's register 15 holding 12288: bits 12 and 13
    image = {(Table.INPUT, 15): 12288}
    assert [decode(points[k], image) for k in ("alarm_bit0", "alarm_bit10", "alarm_bit15")] == [
        False,
        False,
        False,
    ]
    image = {(Table.INPUT, 15): 0x8401}
    assert [decode(points[k], image) for k in ("alarm_bit0", "alarm_bit10", "alarm_bit15")] == [
        True,
        True,
        True,
    ]


def test_esphomes_own_test_has_nothing_usable_and_says_why(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        ["import", "esphome", str(DATA / "tests_common.yaml"), "--out", str(tmp_path / "o")]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert (
        "tests_common.yaml:36: modbus_controller2: not converted: a Modbus server on the ESP" in err
    )
    assert "tests_common.yaml:29: modbus_controller1: not converted: no entity converted" in err


def test_lambdas_and_other_filters_are_reported_not_guessed(tmp_path: Path) -> None:
    path = tmp_path / "node.yaml"
    path.write_text(
        """\
esphome: {name: meter}
uart: {baud_rate: 9600, parity: EVEN, stop_bits: 2}
modbus: {id: bus}
modbus_controller: [{id: sdm, address: 2, update_interval: 10s, command_throttle: 100ms}]
sensor:
  - platform: modbus_controller
    name: Power
    address: 12
    register_type: read
    value_type: FP32
    filters:
      - offset: 2
      - multiply: 10
      - sliding_window_moving_average: {window_size: 5}
  - platform: modbus_controller
    name: Energy
    custom_command: [0x2, 0x4, 0x1, 0x56, 0x00, 0x02]
    lambda: return 1;
number:
  - platform: modbus_controller
    name: Set point
    address: 40
    value_type: S_WORD
    multiply: 10
    min_value: -5
    max_value: 50
select:
  - platform: modbus_controller
    name: Mode
    address: 41
    value_type: U_WORD
    optionsmap: {"Off": 0, "Auto": 2}
""",
        encoding="utf-8",
    )
    result = import_esphome(load_source(path), "node.yaml")
    entities = result.devices[0].mapping["entities"]
    assert (entities["power"]["scale"], entities["power"]["offset"]) == (10.0, 20.0)
    assert entities["set_point"] | {} == {
        "name": "Set point",
        "address": 40,
        "table": "holding",
        "type": "s16",
        "access": "rw",
        "min": -5,
        "max": 50,
        "scale": 0.1,
        "offset": 0.0,
        "poll": "fast",
        "ha": {"entity_id": "meter_set_point"},
    }
    assert entities["mode"]["enum"] == {0: "Off", 2: "Auto"}
    assert result.devices[0].config["protocol"] == {"min_request_interval": 0.1}
    assert result.buses[0] | {} == {
        "id": "meter",
        "transport": "rtu",
        "port": "/dev/ttyUSB0",
        "timeout": 0.25,
        "baudrate": 9600,
        "parity": "E",
        "stopbits": 2,
        "bytesize": 8,
    }
    assert [(n.where.line, n.key) for n in result.notes] == [
        (2, "uart"),
        (14, "Power.filters.sliding_window_moving_average"),
        (18, "Energy.lambda"),
    ]
    out = tmp_path / "out"
    assert main(["import", "esphome", str(path), "--out", str(out)]) == 0
    loaded = load_config(out / "config.yaml")
    assert sorted(loaded.mappings["sdm"].entities) == ["mode", "power", "set_point"]


def test_entities_inside_a_controller_are_reported_with_where_they_belong(tmp_path: Path) -> None:
    """ESPHome's modbus_controller schema has no entity keys (esphome/components/
    modbus_controller/__init__.py): a node with them does not compile, so nothing is guessed."""
    path = tmp_path / "node.yaml"
    path.write_text(
        """\
esphome: {name: meter}
uart: {baud_rate: 9600}
modbus: {id: bus}
modbus_controller:
  - id: sdm
    address: 2
    sensors:
      - {name: Voltage, address: 0, register_type: read, value_type: FP32}
    switch:
      - {name: Relay, address: 1, register_type: coil}
sensor:
  - {platform: modbus_controller, name: Power, address: 12, register_type: read,
     value_type: FP32}
""",
        encoding="utf-8",
    )
    result = import_esphome(load_source(path), "node.yaml")
    assert sorted(result.devices[0].mapping["entities"]) == ["power"]
    inline = [(n.where.line, n.key, n.partly) for n in result.notes if "inside" in n.reason]
    assert inline == [(7, "sdm.sensors", False), (9, "sdm.switch", False)]
    assert "- platform: modbus_controller" in result.notes[-1].reason


def test_skip_updates_is_kept_exactly_as_each_entitys_interval(tmp_path: Path) -> None:
    path = tmp_path / "node.yaml"
    path.write_text(
        """\
esphome: {name: meter}
uart: {baud_rate: 9600}
modbus: {id: bus}
modbus_controller: [{id: sdm, address: 2, update_interval: 5s}]
sensor:
  - {platform: modbus_controller, name: Power, address: 1, register_type: read}
  - {platform: modbus_controller, name: Voltage, address: 2, register_type: read, skip_updates: 11}
  - {platform: modbus_controller, name: Energy, address: 3, register_type: read, skip_updates: 1}
  - {platform: modbus_controller, name: Hours, address: 4, register_type: read, skip_updates: 119}
"""
    )
    result = import_esphome(load_source(path), "node.yaml")
    (device,) = result.devices
    assert device.config["poll"] == {"fast": 5.0, "slow": 600.0}  # 5 s x (119 + 1)
    polls = {key: entity["poll"] for key, entity in device.mapping["entities"].items()}
    # every (skip_updates + 1)-th update of 5 s: 60 s and 10 s their own, exactly
    assert polls == {"power": "fast", "voltage": 60.0, "energy": 10.0, "hours": "slow"}
    assert not [n for n in result.notes if "skip_updates" in n.key]
    points = Mapping.model_validate(device.mapping).points()
    assert points["voltage"].entity.poll_spec == 60.0
