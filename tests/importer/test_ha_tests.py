"""Home Assistant's own modbus test configurations (tests/importer/data/ha_tests/), each
converted: every entity converted (by its key) or reported (by its name), and the states
Home Assistant's tests read decoded by the imported mapping to the same state."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import Mapping
from bridge.importer.ha_modbus import import_ha
from bridge.importer.result import Import
from bridge.importer.source import load_source

DATA = Path(__file__).parent / "data" / "ha_tests"
FILES = sorted(DATA.glob("*.yaml"))
HUB = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502}
STATE = {"on": True, "off": False, None: None}


def configs() -> list[tuple[str, dict[str, Any]]]:
    return [
        (f"{path.stem}::{config['test']}", config)
        for path in FILES
        for config in yaml.safe_load(path.read_text(encoding="utf-8"))["configs"]
    ]


def convert(tmp_path: Path, hub: dict[str, Any]) -> Import:
    path = tmp_path / "configuration.yaml"
    path.write_text(yaml.safe_dump({"modbus": [hub]}, sort_keys=False), encoding="utf-8")
    return import_ha(load_source(path), path.name)


def hub_of(config: dict[str, Any]) -> dict[str, Any]:
    """A hub with the test's entities (a test's own hub settings, when it has them)."""
    entities = {k: v for k, v in config.items() if k not in ("test", "expect", "hub")}
    return config.get("hub", HUB) | entities


def test_every_home_assistant_test_file_is_here() -> None:
    assert [path.stem for path in FILES] == [
        "test_binary_sensor",
        "test_climate",
        "test_cover",
        "test_fan",
        "test_init",
        "test_light",
        "test_switch",
    ]


@pytest.mark.parametrize(("test", "config"), configs(), ids=[t for t, _ in configs()])
def test_each_entity_is_converted_or_reported_by_name(
    tmp_path: Path, test: str, config: dict[str, Any]
) -> None:
    result = convert(tmp_path, hub_of(config))
    expect = config["expect"]
    converted = [key for device in result.devices for key in device.mapping["entities"]]
    for device in result.devices:
        Mapping.model_validate(device.mapping)  # each mapping loads as the bridge loads it
    whole = {n.key for n in result.notes if not n.partly}
    partly = {n.key for n in result.notes if n.partly}
    assert sorted(converted) == sorted(expect.get("converted", []))
    assert set(expect.get("reported", [])) <= whole, result.notes
    assert set(expect.get("partly", [])) <= partly, result.notes
    assert not {n.key for n in result.notes} & set(expect.get("quiet", [])), result.notes
    entities = {k: e for device in result.devices for k, e in device.mapping["entities"].items()}
    for key, fields in expect.get("fields", {}).items():
        assert {f: entities[key].get(f) for f in fields} == fields
    for field, value in expect.get("bus", {}).items():
        assert result.buses[0][field] == value
    for field, value in expect.get("device", {}).items():
        assert result.devices[0].config[field] == value


def _states() -> list[dict[str, Any]]:
    data = yaml.safe_load((DATA / "test_switch.yaml").read_text(encoding="utf-8"))
    return list(data["states"])


@pytest.mark.parametrize("case", _states(), ids=lambda c: f"{c['write_type']}-{c['words']}")
def test_home_assistant_switch_states_read_the_same(tmp_path: Path, case: dict[str, Any]) -> None:
    switch = {"name": "Test entity", "address": 1234, "slave": 1, "write_type": case["write_type"]}
    result = convert(tmp_path, HUB | {"switches": [switch | case["addon"]]})
    (device,) = result.devices
    point = Mapping.model_validate(device.mapping).points()["test_entity"]
    word = case["words"][0]
    if point.table is Table.COIL:
        word &= 1  # a coil read answers bits: the first is bit 0 of what the test returns
    shown = case["bridge"] if "bridge" in case else STATE[case["expected"]]
    assert decode(point, {(point.table, 1234): word}) is shown


def _binary_states() -> list[dict[str, Any]]:
    data = yaml.safe_load((DATA / "test_binary_sensor.yaml").read_text(encoding="utf-8"))
    return list(data["states"])


@pytest.mark.parametrize(
    "case", _binary_states(), ids=lambda c: f"{c['input_type']}-{c['words'][:2]}"
)
def test_home_assistant_binary_sensor_states_read_the_same(
    tmp_path: Path, case: dict[str, Any]
) -> None:
    sensor = {"name": "Test entity", "address": 51, "input_type": case["input_type"]}
    (device,) = convert(tmp_path, HUB | {"binary_sensors": [sensor]}).devices
    point = Mapping.model_validate(device.mapping).points()["test_entity"]
    word = case["words"][0]
    if point.table.is_bits:
        word &= 1  # a bit read: the first bit is bit 0 of what the test returns
    assert decode(point, {(point.table, 51): word}) is STATE[case["expected"]]
