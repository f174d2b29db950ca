"""Build small mappings in tests without YAML files."""

from __future__ import annotations

from typing import Any

from bridge.core.mapping import Mapping, Point


def make_mapping(entities: dict[str, dict[str, Any]], **top: Any) -> Mapping:
    data: dict[str, Any] = {
        "manufacturer": "Test",
        "model": "T1",
        "description": "test device",
        "source": {"title": "test manual"},
        "entities": entities,
    }
    data.update(top)
    return Mapping.model_validate(data)


def make_point(key: str = "value", **fields: Any) -> Point:
    """One point named ``key``; ``fields`` are its entity fields (address defaults to 0)."""
    fields.setdefault("name", key.replace("_", " ").capitalize())
    fields.setdefault("address", 0)
    return make_mapping({key: fields}).points()[key]
