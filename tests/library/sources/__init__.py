"""Every independent source definition, by library device name."""

from __future__ import annotations

from tests.library.source import SourceDefinition
from tests.library.sources import abb, eastron

_MODULES = (eastron, abb)

SOURCES: dict[str, tuple[SourceDefinition, ...]] = {
    device: definitions for module in _MODULES for device, definitions in module.DEFINITIONS.items()
}
