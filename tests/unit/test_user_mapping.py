"""A device's override file: written with comments kept, atomically, and taken by the
loader as the device's mapping only when it extends the mapping the device names."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.config import load_config
from bridge.config.user_mapping import entity_added, override_path, restore, write_atomic
from bridge.errors import ConfigError

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
