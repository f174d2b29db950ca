"""The exception tree of the bridge.

    BridgeError                 base of everything the bridge raises on purpose
    ├── InputError              a file the user wrote is invalid (config or mapping)
    │   ├── ConfigError         the config file; ``issues`` lists ``path: message`` rows
    │   └── MappingError        a mapping file; rows name the entity key and the field
    ├── CodecError              a value cannot be decoded or encoded
    │   ├── MissingDataError    a register the value needs has not been read yet
    │   └── ValueRejectedError  a command value is refused (not writable, type, range,
    │                           enum label, sentinel, guard); nothing is written
    ├── CommandExpiredError     a command could not be sent before its expiry: dropped
    └── ModbusError             a transaction did not succeed
        ├── BusError            the port or gateway is not reachable (unplugged, refused)
        ├── DeviceTimeoutError  the unit did not answer in time
        ├── DeviceExceptionError the unit answered with an exception code; ``action`` says
        │                       what the device means by it (fail, retry, busy, refused,
        │                       locked) and ``meaning`` its name in the device's manual
        └── FrameError          a frame could not be built or parsed (CRC, length)

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


class CommandExpiredError(BridgeError):
    """A command could not be sent before its expiry; it was dropped, never sent late."""


class ModbusError(BridgeError):
    """A Modbus transaction did not succeed."""


class BusError(ModbusError):
    """The serial port or TCP gateway is not reachable."""


class DeviceTimeoutError(ModbusError):
    """The unit did not answer in time."""


class DeviceExceptionError(ModbusError):
    """The unit answered with an exception code."""

    def __init__(self, code: int, meaning: str, action: str) -> None:
        self.code = code
        self.meaning = meaning
        self.action = action
        super().__init__(f"exception {code:02X}h: {meaning}")


class FrameError(ModbusError):
    """A frame could not be built or parsed (bad CRC/LRC, truncated, unknown function)."""
