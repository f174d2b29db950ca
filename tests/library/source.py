"""The shape of an independent source's register definitions, transcribed as data.

Facts only (address, type, word order, scale, unit): no text or code of the source.
"""

from __future__ import annotations

from dataclasses import dataclass

TABLES = frozenset({"input", "holding"})
TYPES = frozenset({"f32", "u16", "s16", "u32", "s32", "u64", "s64"})
WORD_ORDERS = frozenset({"big", "little"})
# "°" (phase angle) is added to lib37's list: mbmd reads SDM phase angles in degrees
UNITS = frozenset(
    {"V", "A", "W", "kW", "VA", "kVA", "var", "kvar", "Hz", "kWh", "Wh", "kvarh", "%", "", "°"}
)
_WIDTHS = {"u16": 1, "s16": 1, "f32": 2, "u32": 2, "s32": 2, "u64": 4, "s64": 4}


@dataclass(frozen=True, slots=True)
class SourcePoint:
    """One register point as a source reads it."""

    key: str  # the library mapping's entity key this point corresponds to
    table: str  # "input" | "holding"
    address: int  # 0-based wire address as sent in the Modbus PDU
    type: str  # "f32" | "u16" | "s16" | "u32" | "s32" | "u64" | "s64"
    unit: str  # the unit of raw*scale
    scale: float = 1.0  # engineering value = raw * scale (before unit conversion)
    word_order: str = "big"  # "big" (high word first) | "little"
    name: str = ""  # the source's own name for it, for the table


@dataclass(frozen=True, slots=True)
class SourceDefinition:
    """One source's definition of one device."""

    device: str  # library mapping name, e.g. "eastron_sdm630"
    source: str  # "mbmd" | "evcc" | "ha-community:<repo>" | "vendor"
    ref: str  # "owner/repo@<commit>:<path>" or document title+version
    points: tuple[SourcePoint, ...]
    notes: tuple[str, ...] = ()  # what the source says that matters


def width(point: SourcePoint) -> int:
    """Number of 16-bit registers the point spans."""
    return _WIDTHS[point.type]


def registers(point: SourcePoint) -> range:
    """The wire addresses the point occupies."""
    return range(point.address, point.address + width(point))


def points_by_key(definition: SourceDefinition) -> dict[str, SourcePoint]:
    """The definition's points keyed by entity key."""
    return {p.key: p for p in definition.points}
