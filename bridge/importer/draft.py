"""A mapping entity being made by an importer, its checks, and a device's mapping document.

An importer makes ``Draft``s (fields of a mapping entity, where they came from);
``validated`` checks one as the mapping would (a Home Assistant device class the mapping
refuses is dropped, and noted), ``whole`` the entities of one device together (overlaps,
references), ``mapping_document`` is the mapping file's text as data.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError

from bridge.core.entity import MAX_INTERVAL, MIN_INTERVAL, Entity
from bridge.core.hass import presentation_problems
from bridge.core.mapping import Mapping, format_validation_errors
from bridge.importer.result import Import
from bridge.importer.source import Node, Where

_GUARDED = re.compile(r"reset|factory|default|password|passw|baud|parity|address|unit id", re.I)


@dataclass(slots=True)
class Draft:
    """A mapping entity being made, with the scan interval it was polled at."""

    name: str
    fields: dict[str, Any]
    scan_interval: int
    node: Node
    ha: dict[str, Any] = field(default_factory=dict)


def validated(draft: Draft, fields: dict[str, Any], result: Import) -> dict[str, Any] | None:
    """``fields`` as the mapping takes them: a Home Assistant state or device class the
    mapping refuses (a unit the class does not take, a class unknown to the bridge, an
    energy reading without a summing state class) is dropped (noted), as Home Assistant
    shows the value all the same; None (noted) when they still do not validate. A
    writable entity whose name speaks of a reset, a password or the line's settings is
    marked ``dangerous`` (written only where the config allows it), and noted."""
    error = ""
    if fields.get("access", "r") != "r" and _GUARDED.search(draft.name):
        fields = fields | {"dangerous": True}
        reason = "marked dangerous: the device's allow_dangerous_writes permits its writes"
        result.note(draft.node.where, draft.name, reason, partly=True)
    for drop in ((), ("state_class",), ("device_class",), ("state_class", "device_class")):
        trial = fields | {"ha": {k: v for k, v in fields["ha"].items() if k not in drop}}
        try:
            problems = presentation_problems(Entity.model_validate(trial))
        except ValidationError as exc:
            error = "; ".join(format_validation_errors(exc))
            continue
        if problems:
            error = "; ".join(f"ha: {problem}" for problem in problems)
            continue
        for key in drop:
            if key in fields["ha"]:
                result.note(draft.node.at(key), f"{draft.name}.{key}", f"refused: {error}")
        return trial
    result.note(draft.node.where, draft.name, f"not converted: {error}")
    return None


def mapping_document(
    model: str, description: str, transport: str, entities: dict[str, Any], result: Import
) -> dict[str, Any]:
    """A device's mapping as data, headed by where it came from."""
    return {
        "manufacturer": "Imported",
        "model": model,
        "description": description,
        "source": {"title": f"imported from {result.source}"},
        "protocol": {"transports": [transport]},
        "entities": entities,
    }


def whole(entities: dict[str, Any], drafts: list[Draft], result: Import) -> dict[str, Any]:
    """The entities that pass the checks across entities (overlaps...); the rest noted: the
    entity an error is about (``entities.<key>.``: the second of two values that cross), else
    the entities it names, else all."""
    where = {d.name: d.node.where for d in drafts}
    for _ in range(len(entities) + 1):
        if not entities:
            return entities
        document = {"manufacturer": "x", "model": "x", "description": "x"}
        try:
            Mapping.model_validate(document | {"source": {"title": "x"}, "entities": entities})
        except ValidationError as exc:
            rows = list(format_validation_errors(exc))
        else:
            return entities
        named = [k for k in entities if any(r.startswith(f"entities.{k}.") for r in rows)]
        named = named or [k for k in entities if any(f"'{k}'" in r for r in rows)]
        for key in named or list(entities):
            name = entities.pop(key)["name"]
            own = [r for r in rows if r.startswith(f"entities.{key}.") or f"'{key}'" in r]
            result.note(where.get(name, Where(result.source, 1)), name, "; ".join(own or rows))
    return entities


def entity_poll(seconds: float, named: dict[float, str]) -> str | float:
    """An entity's ``poll``: the name of ``seconds`` in ``named`` (``{0: "once", 15:
    "fast"}``), else ``seconds`` itself within the bounds a mapping takes."""
    if seconds in named:
        return named[seconds]
    return min(max(seconds, MIN_INTERVAL), MAX_INTERVAL)
