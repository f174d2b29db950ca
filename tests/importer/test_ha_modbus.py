"""Home Assistant's modbus YAML imported: values decode as Home Assistant shows them, every
key not converted is reported with file and line, and the written files pass `check`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.core.codec import decode, encode
from bridge.core.entity import Table
from bridge.core.mapping import Mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Write
from bridge.importer import ha_modbus
from bridge.importer.ha_modbus import import_ha
from bridge.importer.result import Import
from bridge.importer.source import load_source

DATA = Path(__file__).parent / "data"
CASES = yaml.safe_load((DATA / "ha_sensor_values.yaml").read_text())["cases"]

WHOLE = """\
homeassistant:
  name: Home
modbus:
  - name: Solar inverter
    type: rtuovertcp
    host: 192.0.2.7
    port: 8899
    timeout: 5
    message_wait_milliseconds: 40
    sensors:
      - {name: PV power, address: 10, slave: 3, data_type: uint32, swap: word, scale: 0.1,
         unit_of_measurement: W, device_class: power, state_class: measurement,
         unique_id: pv_power, scan_interval: 10}
      - {name: Grid voltage, address: 20, slave: 3, input_type: input, virtual_count: 2,
         scale: 0.1, precision: 1, unit_of_measurement: V, device_class: voltage,
         scan_interval: 60}
    binary_sensors:
      - {name: Fault, address: 4, slave: 3, input_type: discrete_input, device_class: problem}
      - {name: Running, address: 30, slave: 3, input_type: holding}
    switches:
      - {name: Export limit, address: 200, slave: 3, verify: {}}
      - {name: Relay, address: 7, slave: 4, write_type: coil}
  - name: Heat pump
    type: serial
    method: rtu
    port: /dev/ttyUSB0
    baudrate: 19200
    bytesize: 8
    parity: E
    stopbits: 1
    sensors:
      - {name: Flow temperature, address: 1, slave: 1, scale: 0.1,
         unit_of_measurement: "°C", device_class: temperature}
"""
EVERY_KEY = """\
modbus:
  - name: hub
    type: tcp
    host: 127.0.0.1
    port: 502
    delay: 3
    retries: 3
    sensors:
      - name: Energy
        address: 1
        slave: 1
        data_type: float64
      - name: Power
        address: 5
        slave: 1
        zero_suppress: 2
        min_value: 0
        lazy_error_count: 3
    switches:
      - {name: Mode, address: 9, slave: 1, command_on: 0xFF, command_off: 0}
    climates:
      - {name: Room, address: 1, slave: 1, target_temp_register: 2}
    covers:
      - {name: Shutter, address: 3, slave: 1}
  - name: far
    type: udp
    host: 192.0.2.1
    port: 502
    sensors:
      - {name: Lost, address: 1, slave: 1}
"""


def convert(tmp_path: Path, text: str, name: str = "configuration.yaml") -> Import:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return import_ha(load_source(path), name)


def hub_with(sensor: dict[str, Any]) -> str:
    hub = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502}
    return yaml.safe_dump({"modbus": [hub | {"sensors": [sensor]}]})


def only_mapping(result: Import) -> Mapping:
    (device,) = result.devices
    return Mapping.model_validate(device.mapping)


@pytest.mark.parametrize("case", CASES, ids=[str(c["addon"]) for c in CASES])
def test_home_assistant_sensor_cases_decode_to_the_same_state(
    tmp_path: Path, case: dict[str, Any]
) -> None:
    sensor = {"name": "Test", "address": 51, "slave": 1, "scan_interval": 1} | case["addon"]
    result = convert(tmp_path, hub_with(sensor))
    noted = {note.key.split(".")[-1]: note for note in result.notes}
    if "not_converted" in case:
        assert not result.usable
        assert noted[case["not_converted"]].where.line == 7  # the data_type line
        return
    point = only_mapping(result).points()["test"]
    table = Table(point.table)
    image = {(table, 51 + i): word for i, word in enumerate(case["words"])}
    value = decode(point, image)
    shown = case.get("bridge", case["expected"])
    if "partly" in case:
        assert case["partly"] in noted
    if shown is None or isinstance(value, str):
        assert value == shown
    elif isinstance(value, int) and not isinstance(value, bool):
        assert str(value) == shown  # exact: a 64-bit integer is not a float's 53 bits
    else:
        decimals = case["addon"].get("precision", 0)
        assert math.isclose(float(value), float(shown), abs_tol=0.5 * 10**-decimals)  # type: ignore[arg-type]


def test_a_whole_configuration_becomes_buses_devices_and_mappings(tmp_path: Path) -> None:
    text = WHOLE
    result = convert(tmp_path, text)
    assert result.buses == [
        {
            "id": "solar_inverter",
            "timeout": 5,
            "transport": "rtu-over-tcp",
            "host": "192.0.2.7",
            "tcp_port": 8899,
        },
        {
            "id": "heat_pump",
            "timeout": 3,
            "transport": "rtu",
            "port": "/dev/ttyUSB0",
            "bytesize": 8,
            "baudrate": 19200,
            "parity": "E",
            "stopbits": 1,
        },
    ]
    devices = {d.id: d for d in result.devices}
    assert sorted(devices) == ["heat_pump", "solar_inverter_unit_3", "solar_inverter_unit_4"]
    inverter = devices["solar_inverter_unit_3"]
    assert inverter.config == {
        "id": "solar_inverter_unit_3",
        "name": "Solar inverter unit 3",
        "bus": "solar_inverter",
        "unit": 3,
        "poll": {"fast": 10, "slow": 60},
        "protocol": {"min_request_interval": 0.04},
    }
    entities = inverter.mapping["entities"]
    assert list(entities) == [
        "pv_power",
        "grid_voltage",
        "grid_voltage_1",
        "grid_voltage_2",
        "fault",
        "running",
        "export_limit",
    ]
    assert entities["pv_power"] == {
        "name": "PV power",
        "address": 10,
        "note": "Home Assistant modbus unique_id pv_power",
        "table": "holding",
        "type": "u32",
        "word_order": "little",
        "scale": 0.1,
        "offset": 0.0,
        "unit": "W",
        "poll": "fast",
        "ha": {"entity_id": "pv_power", "device_class": "power", "state_class": "measurement"},
    }
    assert entities["grid_voltage_2"]["address"] == 22
    assert entities["grid_voltage_2"]["ha"]["entity_id"] == "grid_voltage_2"
    assert entities["running"] | {} == {
        "name": "Running",
        "address": 30,
        "table": "holding",
        "bit": 0,
        "poll": 15,  # Home Assistant's default scan interval, kept exactly
        "ha": {"entity_id": "running"},
    }
    assert entities["export_limit"] == {
        "name": "Export limit",
        "address": 200,
        "table": "holding",
        "type": "bool",
        "write_function": 6,
        "access": "rw",
        "words": {"write_on": 1, "write_off": 0},  # 2 reads unknown, as Home Assistant's verify
        "poll": 15,
        "ha": {"entity_id": "export_limit", "component": "switch"},
    }
    relay = devices["solar_inverter_unit_4"].mapping["entities"]["relay"]
    assert (relay["table"], relay["access"], relay["write_function"]) == ("coil", "w", 5)
    mapping = Mapping.model_validate(inverter.mapping)
    assert mapping.points()["pv_power"].address == 10
    # 15 s (the default) between the device's fast (10 s) and slow (60 s): kept exactly
    assert entities["fault"]["poll"] == 15
    assert result.notes == []


def test_every_key_left_out_is_reported_with_its_line(tmp_path: Path) -> None:
    text = EVERY_KEY
    result = convert(tmp_path, text)
    assert [(n.where.line, n.key, n.partly) for n in result.notes] == [
        (7, "hub.retries", False),
        (22, "Room", False),
        (24, "Shutter", False),
        (18, "Power.lazy_error_count", True),  # Energy and Mode count 0: they differ
        (26, "far.type", False),
        (30, "Lost", False),
    ]
    (device,) = result.devices
    assert list(device.mapping["entities"]) == ["energy", "power", "mode"]
    assert device.mapping["entities"]["energy"]["type"] == "f64"
    assert result.buses[0]["connect_delay"] == 3  # the hub's delay
    assert device.config["offline_after"] == 4  # unavailable at the 4th failed read


def test_unit_0_is_written_disabled_and_reported(tmp_path: Path) -> None:
    fixture = DATA / "ha_fixtures" / "configuration.yaml"
    result = import_ha(load_source(fixture), fixture.name)
    (device,) = result.devices
    assert (device.config["unit"], device.config["enabled"]) == (1, False)
    assert [n.key for n in result.notes] == ["testModbus unit 0"]


def test_nothing_usable_is_not_usable(tmp_path: Path) -> None:
    result = convert(tmp_path, "homeassistant:\n  name: Home\n")
    assert not result.usable
    assert [str(n) for n in result.notes] == [
        "configuration.yaml:1: modbus: not converted: no modbus hub found"
    ]


def test_the_number_of_entities_is_bounded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ha_modbus, "MAX_ENTITIES", 3)
    sensors = [{"name": f"S{n}", "address": n, "slave": 1} for n in range(5)]
    hub = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502, "sensors": sensors}
    result = convert(tmp_path, yaml.safe_dump({"modbus": [hub]}))
    assert list(result.devices[0].mapping["entities"]) == ["s0", "s1", "s2"]
    assert [n.reason for n in result.notes] == ["more than 3 entities: not converted"] * 2


SHAPED = """\
modbus:
  - name: hub
    type: tcp
    host: 127.0.0.1
    port: 502
    sensors:
      - {name: Flow, address: 1, slave: 1, scale: 0.1, min_value: "-5", max_value: 50,
         zero_suppress: 0.5}
      - {name: Label, address: 2, slave: 1, data_type: string, count: 2, min_value: 1}
      - {name: Odd, address: 4, slave: 1, zero_suppress: -1}
    switches:
      - {name: Relay, address: 9, slave: 1, command_on: 0x0100, command_off: 0x0200,
         verify: {state_on: [0x0100, 0x0101], state_off: 0x0200}}
      - {name: Mode, address: 10, slave: 1, command_on: 0xFF, command_off: 0}
      - {name: Same, address: 11, slave: 1, command_on: 3, command_off: 3}
      - {name: Coil, address: 12, slave: 1, write_type: coil, command_on: 0, command_off: 1}
      - {name: Big, address: 13, slave: 1, command_on: 0x10000}
      - {name: Both, address: 14, slave: 1, verify: {state_on: [1, 2], state_off: [0, 2]}}
"""


def test_clamp_zero_suppress_and_a_switchs_words_are_converted(tmp_path: Path) -> None:
    result = convert(tmp_path, SHAPED)
    entities = only_mapping(result).model_dump()["entities"]
    flow = entities["flow"]
    assert (flow["clamp"], flow["zero_suppress"]) == ({"min": -5.0, "max": 50.0}, 0.5)
    assert entities["relay"]["words"] == {
        "write_on": 0x0100,
        "write_off": 0x0200,
        "read_on": (0x0100, 0x0101),
        "read_off": None,
    }
    assert (entities["mode"]["access"], entities["mode"]["words"]["write_on"]) == ("w", 0xFF)
    # a word in both lists reads on, as Home Assistant looks in state_on first: off is 0 only
    assert (entities["both"]["words"]["read_on"], entities["both"]["words"]["read_off"]) == (
        (1, 2),
        None,
    )
    assert sorted(entities) == ["both", "flow", "mode", "relay"]
    assert [(n.where.line, n.key) for n in result.notes] == [
        (9, "Label.min_value"),
        (10, "Odd.zero_suppress"),
        (15, "Same.command_on"),
        (16, "Coil.command_on"),
        (17, "Big.command_on"),
    ]


PACKAGE = DATA / "ha_fixtures" / "hybrid_inverter_package.yaml"
# switch key -> (address, command_on, command_off, words read as on, as off), as Home
# Assistant's modbus switch writes (write_register, FC06) and reads them back (verify)
PACKAGE_SWITCHES = {
    "inverter_work_mode_backup": (3000, 1, 0, (1,), (0, 2)),
    "inverter_export_limit": (3010, 1, 0, (1,), (0,)),
    "inverter_backup_mode": (3020, 0x55AA, 0xAA55, (0x55AA, 0x55AB), (0xAA55,)),
    "inverter_fan": (3040, 3, 0, (3,), (0,)),
    "inverter_light": (3041, 1, 0, (1,), (0,)),
}


def test_a_packages_switches_on_its_sensors_registers_are_all_converted() -> None:
    """A raw work-mode sensor and a switch on one register, an export-limit switch on a
    register a sensor reads, a backup-mode switch with its own words and verify, a fan and
    a light on registers sensors read: nothing is dropped, and each switch writes and reads
    the words Home Assistant's modbus does."""
    result = import_ha(load_source(PACKAGE), PACKAGE.name)
    assert [n.key for n in result.notes if not n.partly] == []  # nothing dropped
    assert {n.key for n in result.notes} == {"Inverter fan", "Inverter light"}  # now switches
    mapping = only_mapping(result)
    points = mapping.points({})
    assert len(points) == 7 + 5
    for key, (address, on, off, read_on, read_off) in PACKAGE_SWITCHES.items():
        point = points[key]
        assert (point.address, point.write_address) == (address, address)
        assert encode(point, "ON", {}) == (Write(6, Table.HOLDING, address, (on,)),)
        assert encode(point, "OFF", {}) == (Write(6, Table.HOLDING, address, (off,)),)
        for word, state in [(w, True) for w in read_on] + [(w, False) for w in read_off]:
            assert decode(point, {(Table.HOLDING, address): word}) is state
        assert decode(point, {(Table.HOLDING, address): 0x1234}) is None  # neither: unknown
    shared = {points["inverter_work_mode_raw"].address, points["inverter_export_limit_raw"].address}
    reads = plan_reads(list(points.values()), limits_for(mapping)).reads
    assert all(sum(a in r.span for r in reads) == 1 for a in shared)  # one read serves both


PRESENTED = """\
modbus:
  - name: hub
    type: tcp
    host: 127.0.0.1
    port: 502
    sensors:
      - {name: Yield, address: 1, slave: 1, data_type: uint32, device_class: energy,
         unit_of_measurement: Wh}
      - {name: Reactive, address: 3, slave: 1, device_class: reactive_power,
         unit_of_measurement: VAr, state_class: measurement}
      - {name: Signal, address: 4, slave: 1, device_class: signal_strength,
         unit_of_measurement: dBm, scale: -1}
      - {name: Label, address: 5, slave: 1, data_type: custom, structure: ">6s", count: 3}
      - {name: Schedule, address: 8, slave: 1, data_type: custom, structure: ">HHh", count: 3}
"""


def test_a_class_the_bridge_refuses_is_dropped_and_the_entity_kept(tmp_path: Path) -> None:
    """Home Assistant shows an energy reading without a state class, or a 'VAr' reactive
    power, all the same (it only warns): the entity comes over without the device class,
    and the report says so; text in a custom structure is a text; a structure of several
    values (a comma-joined text in Home Assistant) is reported."""
    result = convert(tmp_path, PRESENTED)
    entities = only_mapping(result).model_dump()["entities"]
    assert sorted(entities) == ["label", "reactive", "signal", "yield"]
    assert entities["yield"]["ha"]["device_class"] is None
    assert (entities["reactive"]["ha"]["device_class"], entities["reactive"]["unit"]) == (
        None,
        "VAr",
    )
    assert entities["signal"]["ha"]["device_class"] == "signal_strength"
    assert (entities["label"]["type"], entities["label"]["count"]) == ("ascii", 3)
    label = only_mapping(result).points()["label"]
    words = (0x4142, 0x3132, 0x6364)  # Home Assistant: struct ">6s" decoded, "AB12cd"
    assert decode(label, {(Table.HOLDING, 5 + i): w for i, w in enumerate(words)}) == "AB12cd"
    assert [(n.where.line, n.key) for n in result.notes] == [
        (14, "Schedule.structure"),
        (7, "Yield.device_class"),
        (9, "Reactive.device_class"),  # its state class stays
    ]
    assert entities["reactive"]["ha"]["state_class"] == "measurement"


def test_an_entity_left_out_by_the_checks_across_entities_is_told_its_own_reason(
    tmp_path: Path,
) -> None:
    """Two entities dropped from one device each get the row about them, not every row of
    the device (a package with three such switches read each note three times over)."""
    sensors = [
        {"name": "Grid code", "address": 1, "slave": 1, "data_type": "uint32"},
        {"name": "Grid signed", "address": 2, "slave": 1, "data_type": "int32"},  # crosses
        {"name": "Mode code", "address": 7, "slave": 1, "data_type": "uint32"},
        {"name": "Mode signed", "address": 8, "slave": 1, "data_type": "int32"},  # crosses
    ]
    hub = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502, "sensors": sensors}
    result = convert(tmp_path, yaml.safe_dump({"modbus": [hub]}))
    kept = set(result.devices[0].mapping["entities"]) if result.devices else set()
    reasons = {n.key: n.reason for n in result.notes if n.key in ("Grid signed", "Mode signed")}
    assert kept == {"grid_code", "mode_code"}
    assert set(reasons) == {"Grid signed", "Mode signed"}
    assert all(("'grid_code'" in r) != ("'mode_code'" in r) for r in reasons.values())


def test_every_scan_interval_is_kept_exactly(tmp_path: Path) -> None:
    sensors = [
        {"slave": 1} | sensor
        for sensor in [
            {"name": "Power", "address": 1, "scan_interval": 10},
            {"name": "Temperature", "address": 2, "scan_interval": 60},
            {"name": "Energy", "address": 3, "scan_interval": 600},
            {"name": "Serial", "address": 4, "scan_interval": 0},
            {"name": "Lifetime", "address": 5, "scan_interval": 200000},
            {"name": "Mode", "address": 6},
        ]
    ]
    hub = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502}
    result = convert(tmp_path, yaml.safe_dump({"modbus": [hub | {"sensors": sensors}]}))
    (device,) = result.devices
    assert device.config["poll"] == {"fast": 10, "slow": 200000}
    polls = {key: entity["poll"] for key, entity in device.mapping["entities"].items()}
    assert polls == {
        "power": "fast",
        "temperature": 60,
        "energy": 600,
        "serial": "once",
        "lifetime": "slow",  # the longest: the device's slow poll, over a day
        "mode": 15,  # Home Assistant's default
    }
    assert result.notes == []
    only_mapping(result)  # it validates
