"""What an import answers: the config, the mappings, and a note for everything left out.

Nothing is silent: every key of the source that did not become part of the bridge's
config or a mapping is a ``Note`` with its file, line and reason; a key converted only
in part (a value kept, a behaviour not) is a note too, marked ``partly``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from bridge.importer.source import Where

MAX_ENTITIES = 10_000  # entities one import converts, at most


@dataclass(frozen=True, slots=True)
class Note:
    """A key not converted (or converted in part), where it was written, and why."""

    where: Where
    key: str
    reason: str
    partly: bool = False

    def __str__(self) -> str:
        kind = "partly converted" if self.partly else "not converted"
        return f"{self.where}: {self.key}: {kind}: {self.reason}"


@dataclass(frozen=True, slots=True)
class ImportedDevice:
    """One device of the config and its mapping (a plain mapping document)."""

    config: dict[str, Any]
    mapping: dict[str, Any]

    @property
    def id(self) -> str:
        return str(self.config["id"])


@dataclass(slots=True)
class Import:
    """The bridge config (buses; the devices come from ``devices``) and the notes."""

    source: str
    buses: list[dict[str, Any]] = field(default_factory=list)
    devices: list[ImportedDevice] = field(default_factory=list)
    notes: list[Note] = field(default_factory=list)
    entities: int = 0

    def note(self, where: Where, key: str, reason: str, *, partly: bool = False) -> None:
        self.notes.append(Note(where, key, reason, partly))

    @property
    def usable(self) -> bool:
        """True when at least one device with an entity came out."""
        return any(device.mapping.get("entities") for device in self.devices)

    def config(self, mapping_ref: dict[str, str]) -> dict[str, Any]:
        """The config document; ``mapping_ref``: device id -> the path its mapping is at."""
        used = {device.config["bus"] for device in self.devices}
        return {
            "mqtt": {"url": "mqtt://127.0.0.1:1883"},
            "buses": [bus for bus in self.buses if bus["id"] in used],
            "devices": [
                device.config | {"mapping": mapping_ref[device.id]} for device in self.devices
            ],
        }
