"""ESPHome ``modbus_controller`` YAML as a bridge config and mappings (not yet)."""

from __future__ import annotations

from typing import Any

from bridge.importer.result import Import
from bridge.importer.source import Node, Where


def import_esphome(data: Any, source: str) -> Import:
    result = Import(source)
    where = data.where if isinstance(data, Node) else Where(source, 1)
    result.note(where, "modbus_controller", "the ESPHome import is not written yet")
    return result
