"""A mapping built from a walked SunSpec device: one entity per implemented point.

``build_mapping(chain, registers)`` returns a ``BuiltMapping``: the mapping document (the
dict a mapping YAML file holds, validated by ``bridge.core.mapping.Mapping``), what each
entity reads (``sources``) and the points left out with the reason (``skipped``). It is
pure: ``registers`` (wire address -> word, what the caller has read of the device) gives
the values a layout needs (the count points of the 7xx curves) and the module names
(model 160's ``IDStr``); without them a model whose layout depends on a count is left
out, and repeating groups are named by their index.

Per point type (``entities``): numbers as ``s16``/``u16``/``s32``/``u32``/``s64``/
``u64``/``f32``/``f64``; ``acc16/32/64`` as ``u16/u32/u64`` counters
(``total_increasing``); ``enum16/32`` as enums of the model's symbols; ``bitfield16/32``
as the raw word (diagnostic) and one boolean per symbol (an alarm for the event and
alarm words); ``string`` as ``ascii``; ``sunssf`` as a diagnostic ``s16`` that the points
it scales name in ``scale_by``; ``ipaddr`` as a diagnostic ``u32``; ``pad``, ``eui48`` and
``ipv6addr`` left out. "Not implemented" values are sentinels. Addresses are the wire
addresses the walk read (offset 0).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping as AnyMapping
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

import yaml

from bridge.core.mapping import Mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.sunspec.entities import PADDING, Built, ModelContext, Source, point_entities
from bridge.sunspec.models import (
    GroupDef,
    ModelDef,
    ModelDefinitionError,
    PlacedPoint,
    layout,
    load_model,
)
from bridge.sunspec.naming import snake
from bridge.sunspec.walk import BASES, Chain, ChainModel, Read, WalkLimits, read_chain, text, walk

_Dumper: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

STATUS_POINTS = ("St", "State")  # an inverter's or a battery's operating state


@dataclass(frozen=True, slots=True)
class Skipped:
    """A point (or a whole model: ``point`` empty) left out of the mapping, and why."""

    model: int
    address: int
    point: str
    reason: str


@dataclass(frozen=True, slots=True)
class BuiltMapping:
    """The mapping document, each entity's ``Source`` and what was left out."""

    document: dict[str, Any]
    sources: dict[str, Source]
    skipped: tuple[Skipped, ...] = field(default=())

    def mapping(self) -> Mapping:
        """The document validated (pydantic's ValidationError if the builder erred)."""
        return Mapping.model_validate(self.document)

    def yaml(self) -> str:
        """The document as a mapping file (``load_mapping`` reads it back), with what was
        left out in its header's comments."""
        lines = [
            "# Built by modbus-mqtt-bridge from the SunSpec model definitions of the device's",
            "# model chain (bridge/sunspec/mapping.py). Left out:",
            *(
                f"# - model {s.model} at {s.address}{' ' + s.point if s.point else ''}: {s.reason}"
                for s in self.skipped
                if s.reason != PADDING
            ),
        ]
        if len(lines) == 2:
            lines[-1] = lines[-1].removesuffix(" Left out:")
        body = yaml.dump(
            self.document, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100
        )
        return "\n".join(lines) + "\n" + body


async def build_from_device(
    read: Read, bases: Sequence[int] = BASES, limits: WalkLimits | None = None
) -> tuple[Chain, BuiltMapping]:
    """Walk a device (``walk``), read its models (``read_chain``) and build its mapping:
    ``read(address, count)`` reads holding registers of the unit, within
    ``limits.read_limit``. The walk's errors as they are (NotSunSpecError: no marker)."""
    limits = limits or WalkLimits()
    chain = await walk(read, bases, limits)
    registers = await read_chain(read, chain, limits.read_limit)
    return chain, build_mapping(chain, registers, read_limit=limits.read_limit)


def build_mapping(
    chain: Chain,
    registers: AnyMapping[int, int] | None = None,
    *,
    read_limit: int = 125,
) -> BuiltMapping:
    """The mapping of a walked device (see the module's docstring)."""
    words = registers or {}
    found = _Found()
    seen: Counter[int] = Counter()
    names: set[str] = set()
    for index, model in enumerate(chain.models):
        seen[model.id] += 1
        try:
            definition = load_model(model.id)
            placed = layout(definition, model.length, _counts(definition, model, words))
        except ModelDefinitionError as e:
            found.skipped.append(Skipped(model.id, model.address, "", str(e)))
            continue
        prefix = snake(definition.name) + (f"_{seen[model.id]}" if seen[model.id] > 1 else "")
        context = ModelContext(
            index=index,
            model=model,
            definition=definition,
            prefix=prefix,
            placed=placed,
            group_labels=_group_labels(definition.group),
            ids=_module_ids(model, placed, words),
            read_limit=read_limit,
            names=names,
        )
        before = len(found.entities)
        for point in placed:
            found.add(model, point, *point_entities(context, point))
        if len(found.entities) == before:
            reason = f"none of its points (L {model.length}) is an entity"
            found.skipped.append(Skipped(model.id, model.address, "", reason))
    for key in _unplannable(_header(chain, found.entities, read_limit)):
        found.drop(key, f"no read of {read_limit} registers can fetch it")
    document = _header(chain, found.entities, read_limit)
    status = next((k for k, s in found.sources.items() if _is_status(s, found.entities[k])), None)
    if status is not None:
        document["status"] = status
    return BuiltMapping(document, found.sources, tuple(found.skipped))


@dataclass(slots=True)
class _Found:
    """The entities built so far, what each reads, and what was left out."""

    entities: dict[str, dict[str, Any]] = field(default_factory=dict)
    sources: dict[str, Source] = field(default_factory=dict)
    skipped: list[Skipped] = field(default_factory=list)

    def add(self, model: ChainModel, point: PlacedPoint, built: Built, reason: str) -> None:
        if reason:
            where = _where(point.path, point.point.name)
            self.skipped.append(Skipped(model.id, model.address + point.offset, where, reason))
        for key, (entity, source) in built.items():
            if key in self.entities:  # two points, one key (no bundled definition has it)
                self.skipped.append(Skipped(model.id, entity["address"], key, "its key is taken"))
                continue
            self.entities[key] = entity
            self.sources[key] = source

    def drop(self, key: str, reason: str) -> None:
        source = self.sources.pop(key)
        address = self.entities.pop(key)["address"]
        where = _where(source.path, source.point)
        self.skipped.append(Skipped(source.model_id, address, where, reason))


def _where(path: tuple[tuple[str, int], ...], name: str) -> str:
    """A point's place in its model: ``module[2]/DCW``."""
    return "/".join([*(f"{group}[{index}]" if index else group for group, index in path), name])


def _unplannable(document: dict[str, Any]) -> tuple[str, ...]:
    """The keys the planner cannot read (none from a walked image as the bundled models
    lay out: a value too far from its scale factor is read bracketed, bridge/core/
    bracket.py); the full set of entities is the most any poll reads."""
    if not document["entities"]:
        return ()
    mapping = Mapping.model_validate(document)
    return plan_reads(mapping.points().values(), limits_for(mapping)).unplannable


def _header(chain: Chain, entities: dict[str, dict[str, Any]], read_limit: int) -> dict[str, Any]:
    common = chain.common
    models = ", ".join(str(i) for i in chain.model_ids) or "none"
    document: dict[str, Any] = {
        "manufacturer": (common.manufacturer if common else None) or "Generic",
        "model": (common.model if common else None) or "SunSpec device",
        "description": f"A SunSpec device (models {models} from {chain.base}), its entities "
        "built from the SunSpec model definitions",
        "source": {
            "title": "SunSpec information models (pysunspec2 "
            f"{metadata.version('pysunspec2')} model JSON)",
            "document": "bridge/sunspec/mapping.py",
        },
        "protocol": {
            "addressing": {"offset": 0, "display": "dec"},
            "function_codes": [3, 6, 16],
            "max_read_registers": read_limit,
            "readable_gaps": True,
            "transports": ["tcp", "rtu", "rtu-over-tcp"],
        },
        "entities": entities,
    }
    return document


def _is_status(source: Source, entity: dict[str, Any]) -> bool:
    """The device's status: the first operating state (a model's top-level enum St or
    State: an inverter's, a battery's)."""
    return "enum" in entity and not source.path and source.point in STATUS_POINTS


def _counts(definition: ModelDef, model: ChainModel, words: AnyMapping[int, int]) -> dict[str, int]:
    """The values of the top-level points that count a model's repeating groups."""
    counts: dict[str, int] = {}
    for name in definition.count_points:
        address = model.address + definition.group.point(name).offset
        if address not in words:
            raise ModelDefinitionError(
                f"SunSpec model {model.id} at {model.address}: its layout needs point {name} "
                f"(register {address}) read"
            )
        counts[name] = words[address]
    return counts


def _group_labels(group: GroupDef) -> dict[str, str]:
    labels = {group.name: group.label or group.name}
    for child in group.groups:
        labels |= _group_labels(child)
    return labels


def _module_ids(
    model: ChainModel, placed: tuple[PlacedPoint, ...], words: AnyMapping[int, int]
) -> dict[tuple[tuple[str, int], ...], str]:
    """A repeating group instance's own name, its ``IDStr`` (model 160's modules), where
    the caller read it."""
    ids: dict[tuple[tuple[str, int], ...], str] = {}
    for p in placed:
        if p.point.name != "IDStr" or not p.path or not p.path[-1][1]:
            continue
        span = range(model.address + p.offset, model.address + p.offset + p.point.size)
        if all(a in words for a in span):
            found = text([words[a] for a in span])
            if found and found.isprintable():  # else named by its index
                ids[p.path] = found
    return ids


__all__ = ["BuiltMapping", "Skipped", "Source", "build_from_device", "build_mapping"]
