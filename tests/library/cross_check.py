"""Decode one register image with a library mapping and with an independent source's
definition, point by point. Pure: the test (test_cross_check.py) and docs/library.md
(tools/library_doc.py) both read its ``Comparison``.

A point of the source whose key the mapping has is *shared*. A shared point the source
places elsewhere (table, address, type, word order) or reads in a unit the mapping's
cannot be converted to is a *disagreement* without decoding; every other shared point is
decoded from a random image (each source point's registers holding a plausible value,
seeded by device and source) both ways, converted to the mapping's unit, and differs
only as a disagreement too (a scale, a sign). The mapping lists each disagreement in its
``library.disagreements`` with the choice made.
"""

from __future__ import annotations

import math
import random
import struct
from dataclasses import dataclass

from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import Mapping, Point
from tests.library.source import SourceDefinition, SourcePoint, width

# the range a plausible engineering value is drawn from, by the source's unit
_PLAUSIBLE = {
    "V": (180.0, 420.0),
    "A": (0.0, 63.0),
    "W": (-23000.0, 23000.0),
    "kW": (-23.0, 23.0),
    "VA": (0.0, 23000.0),
    "kVA": (0.0, 23.0),
    "var": (-9000.0, 9000.0),
    "kvar": (-9.0, 9.0),
    "Hz": (45.0, 55.0),
    "kWh": (0.0, 1e6),
    "Wh": (0.0, 1e9),
    "kvarh": (0.0, 1e6),
    "kVAh": (0.0, 1e6),
    "%": (0.0, 100.0),
    "": (-1.0, 1.0),
    "°": (-180.0, 180.0),
    "°C": (-20.0, 80.0),
    "K": (0.0, 30.0),
    "Ah": (0.0, 300.0),
    "mA": (0.0, 63000.0),
    "mV": (0.0, 60000.0),
    "h": (0.0, 50000.0),
    "min": (0.0, 1440.0),
    "s": (0.0, 86400.0),
    "bar": (0.0, 6.0),
    "l/min": (0.0, 60.0),
}
# (source unit, mapping unit) -> factor; the same unit is 1
_FACTORS = {
    ("kW", "W"): 1e3,
    ("W", "kW"): 1e-3,
    ("kVA", "VA"): 1e3,
    ("VA", "kVA"): 1e-3,
    ("kvar", "var"): 1e3,
    ("var", "kvar"): 1e-3,
    ("kWh", "Wh"): 1e3,
    ("Wh", "kWh"): 1e-3,
    ("kWh", "MWh"): 1e-3,
    ("kvarh", "varh"): 1e3,
    ("varh", "kvarh"): 1e-3,
    ("mA", "A"): 1e-3,
    ("A", "mA"): 1e3,
    ("mV", "V"): 1e-3,
    ("V", "mV"): 1e3,
    ("h", "min"): 60.0,
    ("min", "h"): 1 / 60,
    ("min", "s"): 60.0,
    ("s", "min"): 1 / 60,
}
_FLOATS = {"f32": ">f", "f64": ">d"}  # struct formats, high byte first
_INTEGERS = {"u16": (0, 0xFFFF), "s16": (-0x8000, 0x7FFF), "u32": (0, 0xFFFFFFFF)}
_INTEGERS |= {"s32": (-(1 << 31), (1 << 31) - 1), "u64": (0, (1 << 64) - 1)}
_INTEGERS |= {"s64": (-(1 << 63), (1 << 63) - 1)}


@dataclass(frozen=True, slots=True)
class Difference:
    """One shared point the source and the mapping do not agree on."""

    key: str
    what: str


@dataclass(frozen=True, slots=True)
class Comparison:
    """One mapping against one source definition."""

    device: str
    source: str
    ref: str
    agreed: tuple[str, ...]  # shared keys decoded to the same value
    differences: tuple[Difference, ...]
    unshared: tuple[str, ...]  # source keys the mapping has no entity for

    @property
    def compared(self) -> int:
        return len(self.agreed) + len(self.differences)


def compare(mapping: Mapping, definition: SourceDefinition) -> Comparison:
    """Every shared point of ``definition`` decoded both ways from one seeded image."""
    points = mapping.points()
    rng = random.Random(f"{definition.device}/{definition.source}")
    image = {}
    for source_point in definition.points:
        image |= source_words(source_point, plausible_raw(source_point, rng))
    agreed, differences = [], []
    for source_point in definition.points:
        point = points.get(source_point.key)
        if point is None:
            continue
        what = placement_difference(point, source_point) or value_difference(
            point, source_point, image
        )
        if what:
            differences.append(Difference(source_point.key, what))
        else:
            agreed.append(source_point.key)
    unshared = tuple(p.key for p in definition.points if p.key not in points)
    return Comparison(
        definition.device,
        definition.source,
        definition.ref,
        tuple(agreed),
        tuple(differences),
        unshared,
    )


def placement_difference(point: Point, source: SourcePoint) -> str:
    """Where the source reads the point differently: table, address, type, word order."""
    entity = point.entity
    mine = (entity.table.value, point.address, entity.data_type.value, point.count)
    theirs = (source.table, source.address, source.type, width(source))
    if mine != theirs:
        return f"the mapping reads {_where(*mine)}, the source {_where(*theirs)}"
    if point.count > 1 and entity.word_order.value != source.word_order:
        return f"word order {entity.word_order.value} here, {source.word_order} in the source"
    return ""


def value_difference(point: Point, source: SourcePoint, image: dict[tuple[Table, int], int]) -> str:
    """How the two decodings of the same registers differ (scale, unit, sign), or ''."""
    unit = point.entity.unit or ""
    factor = 1.0 if source.unit == unit else _FACTORS.get((source.unit, unit))
    if factor is None:
        return f"unit {source.unit!r} in the source, {unit!r} here"
    theirs = source_value(source, image) * factor
    mine = decode(point, image)
    if not isinstance(mine, int | float) or isinstance(mine, bool):
        return f"the mapping decodes {mine!r}, the source {theirs!r}"
    step = abs(point.entity.scale) if not point.entity.data_type.is_float else 0.0
    if not math.isclose(float(mine), theirs, rel_tol=1e-6, abs_tol=step / 2 + 1e-9):
        return f"the mapping decodes {mine!r} {unit}, the source {theirs!r} {unit}"
    return ""


def _where(table: str, address: int, kind: str, count: int) -> str:
    return f"{table} 0x{address:04X} as {kind} ({count} registers)"


def plausible_raw(point: SourcePoint, rng: random.Random) -> float | int:
    """A raw value (before the source's scale) whose engineering value is plausible."""
    low, high = _PLAUSIBLE[point.unit]
    value = rng.uniform(low, high)
    if point.type in _FLOATS:
        return value / point.scale
    least, most = _INTEGERS[point.type]
    return max(least, min(most, round(value / point.scale)))


def source_words(point: SourcePoint, raw: float | int) -> dict[tuple[Table, int], int]:
    """The registers holding ``raw`` as the source lays it out."""
    if point.type in _FLOATS:
        data = struct.pack(_FLOATS[point.type], raw)
    else:
        signed = point.type.startswith("s")
        data = int(raw).to_bytes(2 * width(point), "big", signed=signed)
    words = [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
    if point.word_order == "little":
        words.reverse()
    table = Table(point.table)
    return {(table, point.address + i): word for i, word in enumerate(words)}


def source_value(point: SourcePoint, image: dict[tuple[Table, int], int]) -> float:
    """The engineering value the source reads from ``image`` (raw x scale, its unit)."""
    table = Table(point.table)
    words = [image[(table, point.address + i)] for i in range(width(point))]
    if point.word_order == "little":
        words.reverse()
    data = b"".join(word.to_bytes(2, "big") for word in words)
    if point.type in _FLOATS:
        raw: float = struct.unpack(_FLOATS[point.type], data)[0]
    else:
        raw = int.from_bytes(data, "big", signed=point.type.startswith("s"))
    return raw * point.scale
