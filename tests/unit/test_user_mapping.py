"""A device's override file: written with comments kept, atomically, and taken by the
loader as the device's mapping only when it extends the mapping the device names."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.config import DeviceConfig, load_config
from bridge.config.user_mapping import (
    entity_added,
    override_path,
    propose,
    restore,
    write_atomic,
)
from bridge.core.mapping import builtin_mapping_path
from bridge.errors import ConfigError, MappingError

CONFIG = """\
mqtt: {url: mqtt://127.0.0.1:1883}
buses:
  - {id: rs485, transport: rtu, port: /dev/ttyUSB0}
devices:
  - {id: pump, bus: rs485, unit: 1, mapping: nastec_vasco}
  - {id: drive, bus: rs485, unit: 2, mapping: p2_vfd}
"""
SPARE = {"name": "Spare voltage", "address": 0x62, "scale": 0.1, "unit": "V"}


def config(tmp_path: Path) -> Path:
    path = tmp_path / "config.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return path


def test_a_new_override_extends_the_device_mapping(tmp_path: Path) -> None:
    path = override_path(tmp_path / "state", "pump")
    write_atomic(path, entity_added(None, "nastec_vasco", "spare", SPARE))
    loaded = load_config(config(tmp_path))
    assert loaded.mappings["pump"].entities["spare"].unit == "V"
    assert "spare" not in loaded.mappings["drive"].entities  # another device: its own
    assert [p.name for p in path.parent.iterdir()] == ["pump.yaml"]  # no temp file left


def test_an_edit_keeps_the_users_comments_and_order(tmp_path: Path) -> None:
    text = (
        "# my pump's extras\n"
        "extends: nastec_vasco  # the shipped one\n"
        "entities:\n"
        "  # a word the manual forgot\n"
        "  spare:\n"
        "    name: Spare voltage\n"
        "    address: 0x62\n"
    )
    edited = entity_added(text, "ignored", "spare2", {"name": "Spare 2", "address": 0x63})
    assert edited == text + "  spare2:\n    name: Spare 2\n    address: 99\n"


@pytest.mark.parametrize(
    "text", ["- a list\n", "entities: {}\n", "extends: [a]\n", "extends: x\nentities: [1]\n"]
)
def test_a_file_that_is_no_override_is_not_edited(text: str) -> None:
    with pytest.raises(ValueError, match="override file"):
        entity_added(text, "nastec_vasco", "spare", SPARE)


def test_an_override_of_another_mapping_is_an_error_naming_both(tmp_path: Path) -> None:
    path = override_path(tmp_path / "state", "drive")
    write_atomic(path, entity_added(None, "nastec_vasco", "spare", SPARE))
    with pytest.raises(ConfigError) as caught:
        load_config(config(tmp_path))
    assert caught.value.issues == (
        f"devices.drive.mapping: {path}: extends 'nastec_vasco', not the device's mapping "
        "'p2_vfd': remove the file or make it extend the device's mapping",
    )


def test_restore_puts_the_file_back(tmp_path: Path) -> None:
    path = override_path(tmp_path, "pump")
    restore(path, None)
    assert not path.exists()
    write_atomic(path, "one")
    write_atomic(path, "two")
    restore(path, "one")
    assert path.read_text(encoding="utf-8") == "one"
    restore(path, None)
    assert not path.exists()


def device(mapping: str) -> DeviceConfig:
    return DeviceConfig.model_validate(
        {"id": "pump", "bus": "rs485", "unit": 1, "mapping": mapping}
    )


def test_propose_extends_a_file_by_its_absolute_path(tmp_path: Path) -> None:
    (tmp_path / "mine.yaml").write_text(
        builtin_mapping_path("nastec_vasco").read_text(encoding="utf-8"), encoding="utf-8"
    )
    proposed = propose(device("mine.yaml"), tmp_path, tmp_path / "state", "spare", SPARE)
    assert proposed.before is None
    assert f"extends: {(tmp_path / 'mine.yaml').resolve()}" in proposed.text
    assert proposed.mapping.entities["spare"].scale == 0.1


def test_propose_adds_to_the_override_a_device_names(tmp_path: Path) -> None:
    state = tmp_path / "state"
    path = override_path(state, "pump")
    write_atomic(path, entity_added(None, "nastec_vasco", "spare", SPARE))
    named = device(str(path))
    second = {"name": "Spare 2", "address": 0x63}
    proposed = propose(named, tmp_path, state, "spare_2", second)
    assert set(proposed.mapping.entities) >= {"spare", "spare_2"}
    assert proposed.text.startswith(proposed.before or "-")


@pytest.mark.parametrize(
    ("mapping", "key", "row"),
    [
        ("nastec_vasco", "power", "entities.power: the mapping has this entity already"),
        ("sunspec", "x", "mapping: a SunSpec device's mapping is built, not edited"),
    ],
)
def test_propose_refuses_a_taken_key_and_a_built_mapping(
    tmp_path: Path, mapping: str, key: str, row: str
) -> None:
    with pytest.raises(MappingError) as caught:
        propose(device(mapping), tmp_path, tmp_path / "state", key, SPARE)
    assert caught.value.issues == (row,)
    assert not (tmp_path / "state").exists()
