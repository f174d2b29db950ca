"""The entities of one SunSpec point (``point_entities``): its type, sentinel, scale,
unit and Home Assistant presentation, from the model definition. Pure; ``mapping`` calls
it for every placed point of every model of a chain.

Not-implemented values (SunSpec's, as pysunspec2's ``mb.py`` has them) are sentinels:
0x8000 int16 and sunssf, 0xFFFF uint16/count/enum16/bitfield16, 0x80000000 int32,
0xFFFFFFFF uint32/enum32/bitfield32, the lowest int64, the highest uint64, 0 for the
accumulators and an ipaddr, NaN for floats (the codec reads any NaN as unknown; the
sentinel states it), every register 0 for a string. A bit of a bitfield32 is taken from
the register that holds it, whose sentinel is 0xFFFF: a word of 16 set bits reads unknown
(as the whole 0xFFFFFFFF does), where pysunspec2 would still read the other word's bits.
"""

from __future__ import annotations

from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass, replace
from typing import Any

from bridge.sunspec.models import HEADER, ModelDef, PlacedPoint, PointDef, Symbol, scale_factor
from bridge.sunspec.naming import group_label, key_of, presentation, sentence, snake, symbol_label
from bridge.sunspec.walk import ChainModel

NOT_IMPLEMENTED = "not implemented"
PADDING = "padding"
Path = tuple[tuple[str, int], ...]

_TYPES = {
    "int16": "s16", "uint16": "u16", "count": "u16", "acc16": "u16", "enum16": "u16",
    "bitfield16": "u16", "sunssf": "s16", "int32": "s32", "uint32": "u32", "acc32": "u32",
    "enum32": "u32", "bitfield32": "u32", "ipaddr": "u32", "int64": "s64", "uint64": "u64",
    "acc64": "u64", "float32": "f32", "float64": "f64", "string": "ascii",
}  # fmt: skip
_UNIMPLEMENTED = {
    "int16": 0x8000, "sunssf": 0x8000, "uint16": 0xFFFF, "count": 0xFFFF,
    "enum16": 0xFFFF, "bitfield16": 0xFFFF, "int32": 0x80000000, "uint32": 0xFFFFFFFF,
    "enum32": 0xFFFFFFFF, "bitfield32": 0xFFFFFFFF, "int64": 1 << 63,
    "uint64": (1 << 64) - 1, "acc16": 0, "acc32": 0, "acc64": 0, "ipaddr": 0,
    "float32": 0x7FC00000, "float64": 0x7FF8000000000000, "string": 0,
}  # fmt: skip
_LEFT_OUT = {
    "pad": PADDING,
    "eui48": "an EUI-48 (MAC) address: no entity type shows it",
    "ipv6addr": "an IPv6 address: no entity type shows it",
}
_CHARGE_STATES = frozenset({"SoC", "ChaState"})  # 802's and 124's state of charge
_ACCUMULATORS = frozenset({"acc16", "acc32", "acc64"})
_ALARM_WORDS = ("Evt", "Alrm", "Alm")  # event and alarm bitfields (Evt1, DCAlrm, GlblAlm)


@dataclass(frozen=True, slots=True)
class Source:
    """What an entity reads: the point ``point`` of the chain's ``model``-th model (its
    ``model_id``), in the group instances ``path``; ``bit`` for one bit of a bitfield."""

    model: int
    model_id: int
    path: Path
    point: str
    bit: int | None = None


@dataclass(frozen=True, slots=True)
class ModelContext:
    """One model of the chain being built: where it is, its placed points, how its
    groups are named, and the names already given (to keep them unique)."""

    index: int
    model: ChainModel
    definition: ModelDef
    prefix: str
    placed: tuple[PlacedPoint, ...]
    group_labels: AnyMapping[str, str]
    ids: AnyMapping[Path, str]
    read_limit: int
    names: set[str]

    def key(self, placed: PlacedPoint) -> str:
        return key_of(self.prefix, placed.path, placed.point.name)

    def name(self, path: Path, label: str) -> str:
        """A unique human name: the groups' (a module's IDStr, else its label and index),
        then ``label``; the model's label added when another model has it."""
        parts: list[str] = []
        for depth, (group, index) in enumerate(path):
            own = self.ids.get(path[: depth + 1]) if index else None
            shown = self.group_labels.get(group, group)
            if index:
                parts.append(own or f"{group_label(shown)} {index}")
            elif shown.casefold() not in label.casefold():
                parts.append(shown)
        name = sentence(" ".join([*parts, label]))
        if name in self.names:
            name = f"{name} ({self.definition.label or self.definition.name})"
        base, n = name, 2
        while name in self.names:
            name, n = f"{base} {n}", n + 1
        self.names.add(name)
        return name


Built = dict[str, tuple[dict[str, Any], Source]]


def point_entities(context: ModelContext, placed: PlacedPoint) -> tuple[Built, str]:
    """The entities of one point (key -> entity, source) and, when it has none, why."""
    point = placed.point
    if not placed.path and placed.offset < HEADER:
        return {}, ""  # the model's ID and L: the walk's
    if point.type in _LEFT_OUT:
        return {}, _LEFT_OUT[point.type]
    if point.size > context.read_limit:
        return {}, f"{point.size} registers: longer than one read of {context.read_limit}"
    key = context.key(placed)
    source = Source(context.index, context.model.id, placed.path, point.name)
    entity: dict[str, Any] = {
        "name": context.name(placed.path, point.label or point.name),
        "address": context.model.address + placed.offset,
        "type": _TYPES[point.type],
        "sentinels": {_UNIMPLEMENTED[point.type]: NOT_IMPLEMENTED},
        "note": f"SunSpec model {context.model.id} point {point.name}",
    }
    if point.type == "string":
        entity |= {"count": point.size, "poll": "once", "ha": {"entity_category": "diagnostic"}}
    elif point.type in ("sunssf", "ipaddr"):
        # a scale factor is read with every value it scales, whenever they are due
        entity |= {"poll": "slow", "ha": {"entity_category": "diagnostic"}}
    elif point.type.startswith("enum") and point.symbols:
        entity["enum"] = _labels(point.symbols, _UNIMPLEMENTED[point.type])
    elif point.type.startswith("bitfield"):
        entity["ha"] = {"entity_category": "diagnostic"}
        bits = _bits(context, placed, key, source)
        _writable(entity, point)
        return {key: (entity, source)} | bits, ""
    else:
        reason = _number(context, placed, entity)
        if reason:
            context.names.discard(entity["name"])
            return {}, reason
    if point.static and "poll" not in entity:
        entity["poll"] = "slow"  # the definition says it does not change (a rating)
    _writable(entity, point)
    return {key: (entity, source)}, ""


def _number(context: ModelContext, placed: PlacedPoint, entity: dict[str, Any]) -> str:
    """A number's scale, unit and classes (the reason when it is left out: none now; a
    point too far from its scale factor for one read is read bracketed, bridge/core/
    bracket.py)."""
    point = placed.point
    factor = scale_factor(placed, context.placed)
    if isinstance(factor, int):
        entity["scale"] = 10.0**factor
    elif factor is not None:
        entity["scale_by"] = context.key(factor)
    counter = point.type in _ACCUMULATORS or (
        point.name.startswith("Tot") and point.units.strip().lower() in ("wh", "varh", "vah")
    )
    shown = presentation(point.units, counter=counter, number=True)
    if shown.unit is not None:
        entity["unit"] = shown.unit
    ha: dict[str, Any] = {}
    if shown.device_class is not None:
        ha["device_class"] = shown.device_class
    elif point.name in _CHARGE_STATES and shown.unit == "%":
        ha["device_class"] = "battery"  # a battery's state of charge
    if shown.state_class is not None and point.access != "RW":
        ha["state_class"] = shown.state_class
    if ha:
        entity["ha"] = ha
    return ""


def _writable(entity: dict[str, Any], point: PointDef) -> None:
    """A point the model marks RW: a command, dangerous (SunSpec marks none as safe),
    a setting in Home Assistant; its range is its type's and its enum's (the models give
    no other)."""
    if point.access != "RW" or point.type == "sunssf":
        return
    entity["access"] = "rw"
    entity["dangerous"] = True
    entity["ha"] = {k: v for k, v in entity.get("ha", {}).items() if k != "state_class"} | {
        "entity_category": "config"
    }


def _labels(symbols: tuple[Symbol, ...], unimplemented: int) -> dict[int, str]:
    """An enum's labels: the symbols' names in snake case, unique."""
    labels: dict[int, str] = {}
    for s in symbols:
        if s.value == unimplemented or s.value in labels:
            continue
        label = snake(s.name)
        if label.startswith("code_") or label in labels.values():
            label = f"{label}_{s.value}"
        labels[s.value] = label
    return labels


def _bits(context: ModelContext, placed: PlacedPoint, key: str, source: Source) -> Built:
    """One read-only boolean per symbol of a bitfield: an alarm for event and alarm words,
    else a diagnostic one."""
    point = placed.point
    wide = point.type == "bitfield32"
    alarm = any(word in point.name for word in _ALARM_WORDS)
    built: Built = {}
    for s in point.symbols:
        if not 0 <= s.value < (32 if wide else 16) or s.name.upper().startswith("RESERVED"):
            continue
        word = 0 if not wide or s.value >= 16 else 1  # big-endian: the high word first
        label = s.label or symbol_label(s.name)
        entity: dict[str, Any] = {
            "name": context.name(placed.path, f"{point.label or point.name}: {label}"),
            "address": context.model.address + placed.offset + word,
            "bit": s.value % 16,
            "sentinels": {0xFFFF: NOT_IMPLEMENTED},
            "note": f"SunSpec model {context.model.id} point {point.name} bit {s.value}",
        }
        if alarm:
            entity |= {"alarm": True, "ha": {"device_class": "problem"}}
        else:  # a capability or a mode flag: there to look at, not on the dashboard
            entity["ha"] = {"entity_category": "diagnostic"}
        bit_key = f"{key}_{snake(s.name)}"
        while bit_key in built:
            bit_key += f"_{s.value}"
        built[bit_key] = (entity, replace(source, bit=s.value))
    return built
