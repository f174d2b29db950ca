"""Home Assistant's float16 and 64-bit sensors, and ESPHome's QWORDs, imported: each decodes
the registers as they do. Home Assistant unpacks the registers with Python's struct after
its swap (``byte``: the bytes of each register; ``word``: the registers in reverse), so
the expected values below are struct's reading of the swapped words."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import Mapping
from bridge.importer.esphome import import_esphome
from bridge.importer.ha_modbus import import_ha
from bridge.importer.source import load_source

WORDS = [0x89AB, 0xCDEF, 0x0123, 0x4567]
HUB = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502}


def ha_reading(form: str, words: list[int], swap: str) -> float | int:
    """What Home Assistant's sensor unpacks: ``form`` after ``swap``."""
    swapped = list(words)
    if swap in ("byte", "word_byte"):
        swapped = [((w & 0xFF) << 8) | (w >> 8) for w in swapped]
    if swap in ("word", "word_byte"):
        swapped.reverse()
    value: float | int = struct.unpack(form, b"".join(w.to_bytes(2, "big") for w in swapped))[0]
    return value


def imported_point(tmp_path: Path, sensor: dict[str, Any]) -> Any:
    path = tmp_path / "configuration.yaml"
    entity = {"name": "Test", "address": 51, "slave": 1} | sensor
    path.write_text(yaml.safe_dump({"modbus": [HUB | {"sensors": [entity]}]}), encoding="utf-8")
    result = import_ha(load_source(path), path.name)
    assert [n for n in result.notes if "data_type" in n.key or "swap" in n.key] == []
    (device,) = result.devices
    return Mapping.model_validate(device.mapping).points()["test"]


CASES = [
    ({"data_type": "uint64"}, ">Q", WORDS),
    ({"data_type": "int64"}, ">q", WORDS),
    ({"data_type": "float64"}, ">d", [0x4009, 0x21FB, 0x5444, 0x2D18]),
    ({"data_type": "float16"}, ">e", [0x4248]),
    ({"data_type": "custom", "structure": ">q", "count": 4}, ">q", WORDS),
    ({"data_type": "custom", "structure": ">e", "count": 1}, ">e", [0xC500]),
]
SWAPS = {1: ("none", "byte"), 4: ("none", "byte", "word", "word_byte")}


@pytest.mark.parametrize(
    ("sensor", "form", "words", "swap"),
    [(s, f, w, swap) for s, f, w in CASES for swap in SWAPS[len(w)]],
    ids=lambda v: str(v) if isinstance(v, str) else None,
)
def test_home_assistant_types_decode_as_home_assistant_unpacks_them(
    tmp_path: Path, sensor: dict[str, Any], form: str, words: list[int], swap: str
) -> None:
    point = imported_point(tmp_path, sensor | {"swap": swap, "precision": 0})
    value = decode(point, {(Table.HOLDING, 51 + i): w for i, w in enumerate(words)})
    expected = ha_reading(form, words, swap)
    if isinstance(expected, float):
        assert struct.pack(form, value) == struct.pack(form, expected)  # the same float
    else:
        assert value == expected


def test_a_little_endian_structure_reverses_every_byte(tmp_path: Path) -> None:
    point = imported_point(tmp_path, {"data_type": "custom", "structure": "<Q", "count": 4})
    value = decode(point, {(Table.HOLDING, 51 + i): w for i, w in enumerate(WORDS)})
    assert value == struct.unpack("<Q", b"".join(w.to_bytes(2, "big") for w in WORDS))[0]


def test_a_64_bit_nan_value_is_a_sentinel(tmp_path: Path) -> None:
    point = imported_point(tmp_path, {"data_type": "int64", "nan_value": -1})
    assert point.entity.sentinels == {(1 << 64) - 1: "nan_value"}
    assert decode(point, {(Table.HOLDING, 51 + i): 0xFFFF for i in range(4)}) is None


def test_word_swap_of_a_half_float_is_refused_as_home_assistant_does(tmp_path: Path) -> None:
    path = tmp_path / "configuration.yaml"
    entity = {"name": "Test", "address": 51, "slave": 1, "data_type": "float16", "swap": "word"}
    path.write_text(yaml.safe_dump({"modbus": [HUB | {"sensors": [entity]}]}), encoding="utf-8")
    result = import_ha(load_source(path), path.name)
    assert [str(n) for n in result.notes] == [
        "configuration.yaml:10: Test.swap: not converted: word swap of one number",
        "configuration.yaml:2: hub unit 1: not converted: no entity converted: the device is "
        "not written",
    ]


@pytest.mark.parametrize(
    ("value_type", "words", "expected"),
    [
        ("U_QWORD", WORDS, 0x89ABCDEF01234567),
        ("S_QWORD", WORDS, 0x89ABCDEF01234567 - (1 << 64)),
        ("U_QWORD_R", WORDS, 0x45670123CDEF89AB),  # ESPHome: the four words reversed
        ("S_QWORD_R", [0xFFFE, 0xFFFF, 0xFFFF, 0xFFFF], -2),
    ],
)
def test_esphome_qwords(tmp_path: Path, value_type: str, words: list[int], expected: int) -> None:
    path = tmp_path / "node.yaml"
    path.write_text(
        "esphome: {name: meter}\nmodbus_controller: [{id: m, address: 1}]\n"
        "sensor:\n  - {platform: modbus_controller, modbus_controller_id: m, name: Energy,\n"
        f"     address: 3, register_type: holding, value_type: {value_type}}}\n",
        encoding="utf-8",
    )
    result = import_esphome(load_source(path), path.name)
    assert [n for n in result.notes if "value_type" in n.key] == []
    (device,) = result.devices
    point = Mapping.model_validate(device.mapping).points()["energy"]
    assert decode(point, {(Table.HOLDING, 3 + i): w for i, w in enumerate(words)}) == expected
