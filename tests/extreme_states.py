"""Each shipped mapping's discovery with its states at the extremes (issue 12, item 13).

For every shipped mapping, its default options and each other option choice alone, with
and without ``allow_dangerous_writes``, the register image is filled five ways: every
register 0 (``raw 0``), every bit set (``raw max``: 0xFFFF, -1 for a signed register),
0x8000 (the most negative s16), and every entity at the ``min`` and at the ``max`` of the
manual's range. Each image gives the state document the bridge publishes and the
discovery payload it publishes with it (admitting the values read, as the running bridge
does: ``shown_readings``).

tests/unit/test_extreme_states.py checks every case with the bridge's reading of Home
Assistant's rules; ``tools/check_ha_discovery.py --states`` checks them with Home
Assistant's own schemas and state handling. Run as ``python -m tests.extreme_states`` it
prints the cases as JSON (what the tool reads, from the bridge's virtualenv).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from bridge.core.codec import Image, Value, decode
from bridge.core.discovery import DeviceInfo, Origin, build_device_discovery
from bridge.core.discovery_entity import shown_readings
from bridge.core.entity import Table
from bridge.core.mapping import (
    Mapping,
    Point,
    builtin_mapping_names,
    builtin_mapping_path,
    load_mapping,
)
from bridge.core.simulation import words_for
from bridge.core.state import state_document
from bridge.core.topics import Topics
from bridge.errors import MissingDataError, ValueRejectedError

TOPICS = Topics("modbus", "homeassistant")
ORIGIN = Origin(sw_version="extremes")
FILLS = {"raw 0": 0x0000, "raw max": 0xFFFF, "raw 0x8000": 0x8000}


@dataclass(frozen=True, slots=True)
class Case:
    """One state document of one device, with the discovery payload published with it."""

    name: str  # mapping, options, dangerous writes, extreme
    discovery: dict[str, Any]
    state: dict[str, Any]

    def as_json(self) -> dict[str, Any]:
        return {"name": self.name, "discovery": self.discovery, "state": self.state}


def option_sets(mapping: Mapping) -> list[dict[str, str]]:
    """The default options, then each other choice of one option alone."""
    sets = [mapping.default_options()]
    for name, spec in mapping.options.items():
        sets += [{name: choice} for choice in spec.choices if choice != spec.default]
    return sets


def images(points: dict[str, Point]) -> dict[str, Image]:
    """The five register images of the extremes."""
    cells = {(p.table, a) for p in points.values() if p.entity.readable for a in p.span}
    result: dict[str, Image] = {}
    for label, word in FILLS.items():
        result[label] = {c: (1 if word else 0) if c[0].is_bits else word for c in cells}
    for label in ("min", "max"):
        image: dict[tuple[Table, int], int] = dict.fromkeys(cells, 0)
        for point in points.values():
            limit = getattr(point.entity, label)
            if limit is None or not point.entity.readable:
                continue
            try:
                image |= words_for(point, limit, image)
            except ValueRejectedError:
                continue  # a limit that is the device's "unknown" marker
        result[label] = image
    return result


def values_of(points: dict[str, Point], image: Image) -> dict[str, Value]:
    values: dict[str, Value] = {}
    for key, point in points.items():
        if not point.entity.readable:
            continue
        try:
            values[key] = decode(point, image)
        except MissingDataError:
            values[key] = None
    return values


def cases(name: str) -> Iterator[Case]:
    """Every case of one shipped mapping."""
    mapping = load_mapping(builtin_mapping_path(name))
    for options in option_sets(mapping):
        points = mapping.points(options)
        for dangerous in (False, True):
            device = DeviceInfo(
                id=name,
                name=name,
                mapping=mapping,
                options=options,
                bus="rs485",
                unit=1,
                allow_dangerous_writes=dangerous,
                fast_interval=2.0,
                slow_interval=60.0,
            )
            for label, image in images(points).items():
                values = values_of(points, image)
                readings = shown_readings(points, values, image)
                discovery = build_device_discovery(device, TOPICS, ORIGIN, readings=readings)
                state = state_document(mapping, points, values)
                chosen = ",".join(f"{k}={v}" for k, v in sorted(options.items()))
                yield Case(f"{name}[{chosen}][dangerous={dangerous}] {label}", discovery, state)


def every_case() -> Iterator[Case]:
    for name in builtin_mapping_names():
        yield from cases(name)


if __name__ == "__main__":
    json.dump([case.as_json() for case in every_case()], sys.stdout, ensure_ascii=False)
