"""The shape of an independent source's register definitions, transcribed as data.

Facts only (address, type, word order, scale, unit): no text or code of the source.
"""

from __future__ import annotations

from dataclasses import dataclass

TABLES = frozenset({"input", "holding"})
# "f64" is added to lib37's list: one community source reads an ORNO counter as float64
TYPES = frozenset({"f32", "f64", "u16", "s16", "u32", "s32", "u64", "s64"})
WORD_ORDERS = frozenset({"big", "little"})
# "°" (phase angle) and "kVAh" (apparent energy) are added to lib37's list; temperatures,
# durations, pressures, flows and milli-units for the inverters, chargers and heat pumps
UNITS = frozenset(
    {
        "V",
        "A",
        "W",
        "kW",
        "VA",
        "kVA",
        "var",
        "kvar",
        "Hz",
        "kWh",
        "Wh",
        "kvarh",
        "kVAh",
        "%",
        "",
        "°",
        "°C",
        "K",
        "Ah",
        "mA",
        "mV",
        "h",
        "min",
        "s",
        "bar",
        "l/min",
    }
)
_WIDTHS = {"u16": 1, "s16": 1, "f32": 2, "u32": 2, "s32": 2, "u64": 4, "s64": 4, "f64": 4}


@dataclass(frozen=True, slots=True)
class SourcePoint:
    """One register point as a source reads it."""

    key: str  # the library mapping's entity key this point corresponds to
    table: str  # "input" | "holding"
    address: int  # 0-based wire address as sent in the Modbus PDU
    type: str  # "f32" | "f64" | "u16" | "s16" | "u32" | "s32" | "u64" | "s64"
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


def overlaps(definition: SourceDefinition) -> list[tuple[str, str, int]]:
    """(first key, second key, wire address) for every register two points share."""
    owner: dict[tuple[str, int], str] = {}
    found: list[tuple[str, str, int]] = []
    for p in definition.points:
        for address in registers(p):
            other = owner.setdefault((p.table, address), p.key)
            if other != p.key:
                found.append((other, p.key, address))
    return found


# factor from a unit to its base unit, for comparing scales across sources
_BASE = {"kW": ("W", 1000.0), "kVA": ("VA", 1000.0), "kvar": ("var", 1000.0), "Wh": ("kWh", 0.001)}
FIELDS = ("table", "address", "type", "word_order", "scale", "key")


@dataclass(frozen=True, slots=True)
class Disagreement:
    """Sources of one device that read one entity key differently in one field."""

    device: str
    key: str  # the entity key; for field "key", the start address read under several keys
    field: str  # one of FIELDS
    values: tuple[tuple[str, str], ...]  # (source, value as text), in definition order


def base_scale(point: SourcePoint) -> tuple[str, float]:
    """The point's unit and scale expressed in the base unit (kW -> W, Wh -> kWh)."""
    unit, factor = _BASE.get(point.unit, (point.unit, 1.0))
    return unit, point.scale * factor


def _field(point: SourcePoint, field: str) -> str:
    if field == "scale":
        unit, scale = base_scale(point)
        return f"{scale:.6g} {unit}".rstrip()
    if field == "address":
        return f"{point.address:#06x}"
    if field == "word_order" and width(point) == 1:
        return "-"  # one register has no word order
    return str(getattr(point, field))


def disagreements(definitions: tuple[SourceDefinition, ...]) -> list[Disagreement]:
    """Every (key, field) that two or more of one device's definitions read differently.

    Field "key" lists a start address that sources read under different entity keys.
    """
    found: list[Disagreement] = []
    keys = dict.fromkeys(p.key for d in definitions for p in d.points)
    for key in keys:
        readers = [(d, points_by_key(d)[key]) for d in definitions if key in points_by_key(d)]
        for field in FIELDS[:-1]:
            values = tuple((d.source, _field(p, field)) for d, p in readers)
            if len({v for _, v in values}) > 1:
                found.append(Disagreement(definitions[0].device, key, field, values))
    addresses = sorted({p.address for d in definitions for p in d.points})
    for address in addresses:
        values = tuple(
            (d.source, p.key) for d in definitions for p in d.points if p.address == address
        )
        if len({v for _, v in values}) > 1:
            found.append(Disagreement(definitions[0].device, f"{address:#06x}", "key", values))
    return found
