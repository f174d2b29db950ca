"""Community Home Assistant modbus packages (``community.PACKAGES``, pinned commits)
imported whole: no entity is left out but those the mapping model cannot express, and
every converted sensor decodes as Home Assistant's modbus integration shows it.

``ha_value`` is Home Assistant's sensor decode written from its behaviour (homeassistant/
components/modbus: registers swapped per ``swap``, unpacked by ``data_type`` or
``structure``, a raw ``nan_value`` (or its negative) unknown, then ``scale * raw +
offset``, ``min_value``/``max_value``, ``zero_suppress``, and the state rounded to
``precision`` places, an integer at 0); the bridge keeps full precision, so a state is
compared to within half its last place.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from bridge.core.codec import decode
from bridge.core.mapping import Mapping, Point
from bridge.importer.ha_modbus import find_hubs, import_ha
from bridge.importer.result import Import
from bridge.importer.source import load_source
from tests.importer.community import PACKAGES, Package

_PLATFORMS = ("sensors", "binary_sensors", "switches", "climates", "covers", "fans", "lights")
_STRUCT = {"int16": "h", "uint16": "H", "int32": "i", "uint32": "I", "float32": "f"}
_STRUCT |= {"int64": "q", "uint64": "Q", "float64": "d", "float16": "e"}
_WORDS = (  # register images tried on each sensor: small, high bits, all ones, sentinels
    (0x0001, 0x0002, 0x0003, 0x0004),
    (0x89AB, 0xCDEF, 0x0123, 0x4567),
    (0xFFFF, 0xFFFF, 0xFFFF, 0xFFFF),
    (0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF),
    (0xFFFF, 0x7FFF, 0xFFFF, 0xFFFF),
    (0x8000, 0x0000, 0x0000, 0x0000),
    (0x0000, 0x8000, 0x0000, 0x0000),
    (0x0000, 0x0000, 0x0000, 0x0000),
)


def imported(package: Package, tmp_path: Path) -> tuple[Any, Import]:
    path = package.write(tmp_path)
    data = load_source(path)
    return data, import_ha(data, path.name)


def source_entities(data: Any) -> dict[str, list[dict[str, Any]]]:
    """The package's modbus entities by platform, as written."""
    found: dict[str, list[dict[str, Any]]] = {}
    for hub in find_hubs(data, Import("x")):
        for platform in _PLATFORMS:
            found.setdefault(platform, []).extend(hub.get(platform) or [])
    return {platform: items for platform, items in found.items() if items}


def dropped(data: Any, result: Import) -> dict[str, list[str]]:
    """Each entity of the source that is in no imported mapping, with the notes that say
    why (a name given twice counts twice)."""
    written = Counter(
        entity["name"]
        for device in result.devices
        for entity in device.mapping.get("entities", {}).values()
    )
    wanted = Counter(str(e.get("name")) for items in source_entities(data).values() for e in items)
    missing = wanted - written
    return {
        name: [
            f"{note.key}: {note.reason}"
            for note in result.notes
            if not note.partly and (note.key == name or note.key.startswith(f"{name}."))
        ]
        for name in missing
    }


@pytest.mark.parametrize("package", PACKAGES, ids=[p.id for p in PACKAGES])
def test_a_community_package_imports_with_nothing_dropped_the_model_can_express(
    package: Package, tmp_path: Path
) -> None:
    data, result = imported(package, tmp_path)
    counts = {platform: len(items) for platform, items in source_entities(data).items()}
    assert counts == package.entities  # the file is the one described
    left_out = dropped(data, result)
    unexpected = {
        name: reasons
        for name, reasons in left_out.items()
        if not any(package.dropped.get(name, "\0") in reason for reason in reasons)
    }
    assert unexpected == {}
    assert sorted(left_out) == sorted(package.dropped)  # each allowed drop is still needed


@pytest.mark.parametrize("package", PACKAGES, ids=[p.id for p in PACKAGES])
def test_a_community_packages_sensors_decode_as_home_assistant_shows_them(
    package: Package, tmp_path: Path
) -> None:
    data, result = imported(package, tmp_path)
    points = {
        point.entity.name: point
        for device in result.devices
        for point in Mapping.model_validate(device.mapping).points().values()
        if not point.entity.writable  # a switch may share a sensor's name (Sungrow's)
    }
    compared = 0
    for sensor in source_entities(data)["sensors"]:
        point = points.get(str(sensor["name"]))
        if point is None or point.entity.name in package.dropped:
            continue  # left out: the test above says why
        for words in _images(point):
            expected = ha_value(sensor, words)
            shown = decode(
                point, {(point.table, point.address + i): w for i, w in enumerate(words)}
            )
            assert _same(shown, expected, sensor.get("precision", 0)), (sensor["name"], words)
            compared += 1
    assert compared >= 8 * 40  # at least 40 sensors each package


def _images(point: Point) -> list[tuple[int, ...]]:
    if point.entity.data_type.value == "ascii":
        return [tuple(0x4142 + 0x0202 * (i % 12) for i in range(point.count))]
    return [words[: point.count] for words in _WORDS]


def ha_value(sensor: dict[str, Any], words: tuple[int, ...]) -> float | str | None:
    """The value Home Assistant's modbus sensor computes for these register words, before
    it rounds the state to ``precision`` places (an integer at 0)."""
    registers = list(words)
    swap = sensor.get("swap", "none")
    if swap in ("byte", "word_byte"):
        registers = [((w & 0xFF) << 8) | (w >> 8) for w in registers]
    if swap in ("word", "word_byte"):
        registers.reverse()
    raw = b"".join(w.to_bytes(2, "big") for w in registers)
    data_type = sensor.get("data_type", "int16")
    if data_type == "string":
        return raw.decode()
    structure = sensor["structure"] if data_type == "custom" else f">{_STRUCT[data_type]}"
    (entry,) = struct.unpack(structure, raw)
    if isinstance(entry, bytes):
        return entry.decode()
    nan = sensor.get("nan_value")
    nan = int(nan, 0) if isinstance(nan, str) else nan
    if (nan is not None and entry in (nan, -nan)) or entry != entry:
        return None
    value = sensor.get("scale", 1) * entry + sensor.get("offset", 0)
    if sensor.get("min_value") is not None and value < sensor["min_value"]:
        value = sensor["min_value"]
    if sensor.get("max_value") is not None and value > sensor["max_value"]:
        value = sensor["max_value"]
    if sensor.get("zero_suppress") is not None and abs(value) <= sensor["zero_suppress"]:
        return 0
    return float(value)


def _same(shown: object, expected: float | str | None, precision: int) -> bool:
    """The bridge's value is Home Assistant's rounded to the places Home Assistant shows
    (the bridge rounds the exact decimal value, Home Assistant the binary float: at an
    exact tie, 65.535 to 2 places, the last digit may differ by one)."""
    if not isinstance(expected, float) or not isinstance(shown, int | float):
        return shown == expected
    return math.isclose(float(shown), expected, abs_tol=0.5 * 10**-precision + 1e-9)
