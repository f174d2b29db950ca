"""Every independent source definition, by library device name."""

from __future__ import annotations

from tests.library.source import SourceDefinition

SOURCES: dict[str, tuple[SourceDefinition, ...]] = {}
