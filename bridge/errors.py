"""The exception tree of the bridge.

    BridgeError                 base of everything the bridge raises on purpose
    ├── InputError              a file the user wrote is invalid (config or mapping)
    │   ├── ConfigError         the config file; ``issues`` lists ``path: message`` rows
    │   └── MappingError        a mapping file; rows name the entity key and the field
    └── CodecError              a value cannot be decoded or encoded
        ├── MissingDataError    a register the value needs has not been read yet
        └── ValueRejectedError  a command value is refused (not writable, type, range,
                                enum label, sentinel, guard); nothing is written

Every error carries a message a user can act on; none is raised for a device fault
(devices report through health counters, never by stopping the bridge).
"""

from __future__ import annotations

from collections.abc import Sequence


class BridgeError(Exception):
    """Base class of every error the bridge raises on purpose."""


class InputError(BridgeError):
    """A user-written file is invalid; ``issues`` holds one ``location: message`` row each."""

    def __init__(self, source: str, issues: Sequence[str]) -> None:
        self.source = source
        self.issues = tuple(issues)
        lines = "\n".join(f"  {issue}" for issue in self.issues)
        super().__init__(f"{source}: {len(self.issues)} error(s)\n{lines}")


class ConfigError(InputError):
    """The config file is invalid."""


class MappingError(InputError):
    """A mapping file is invalid."""


class CodecError(BridgeError):
    """A value cannot be decoded from or encoded to registers."""


class MissingDataError(CodecError):
    """A register needed to decode or encode a value is not in the register image."""


class ValueRejectedError(CodecError):
    """A command value is refused before anything reaches the wire."""
