"""The exception tree of the bridge.

    BridgeError                 base of everything the bridge raises on purpose
    ├── InputError              a file the user wrote is invalid (config or mapping)
    │   ├── ConfigError         the config file; ``issues`` lists ``path: message`` rows
    │   ├── MappingError        a mapping file; rows name the entity key and the field
    │   └── ConfigEditError     an edit of the config file is refused (bridge/config/store.py);
    │       │                   ``field`` names where (``devices.pump.unit``); nothing written
    │       ├── ConfigConflictError  the file changed on disk since it was read; ``diff``
    │       │                   shows how (secrets hidden)
    │       ├── ConfigReadOnlyError  the config is not a file the bridge may write (the
    │       │                   add-on's options, a config given as data)
    │       └── ConfigWriteError the file or its backup could not be written (disk, rights)
    ├── CodecError              a value cannot be decoded or encoded
    │   ├── MissingDataError    a register the value needs has not been read yet
    │   └── ValueRejectedError  a command value is refused (type, range, enum label,
    │       │                   sentinel); nothing is written. ``forbidden`` is False
    │       ├── WriteForbiddenError  the key may not be written, whatever the value (not
    │       │                   writable, unknown, guarded, a lock, its conditions unmet,
    │       │                   EEPROM or toggle spacing); ``forbidden`` is True
    │       └── CommandRejectedError  keys of a multi-key command were refused; ``refused``
    │                           maps each to its reason; nothing of the command is written;
    │                           ``forbidden`` when any key's refusal was
    ├── CommandExpiredError     a command could not be sent before its expiry: dropped
    ├── SunSpecError            a SunSpec walk found no chain it can use
    │   ├── NotSunSpecError     no ``SunS`` marker at any base tried: not a SunSpec device
    │   └── SunSpecChainError   the model chain is malformed (runs past 65535, too many
    │                           models or registers, a short answer, a model id 0)
    └── ModbusError             a transaction did not succeed
        ├── BusError            the port or gateway is not reachable (unplugged, refused)
        ├── DeviceTimeoutError  the unit did not answer in time
        ├── DeviceExceptionError the unit answered with an exception code; ``action`` says
        │                       what the device means by it (fail, retry, busy, refused,
        │                       locked) and ``meaning`` its name in the device's manual
        ├── FrameError          a frame could not be built or parsed (CRC, length)
        └── PartialWriteError   a compound write failed after its first frame: ``done`` of
                                ``total`` frames were written, ``restored`` says whether the
                                frames done were undone; ``cause`` is the failure

Every error carries a message a user can act on; none is raised for a device fault
(devices report through health counters, never by stopping the bridge). Task groups wrap
what ended them in (nested) ExceptionGroups: ``first_of`` finds the error inside.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TypeVar

_E = TypeVar("_E", bound=BaseException)


def first_of(group: BaseExceptionGroup[BaseException], kind: type[_E]) -> _E | None:
    """The first exception of type ``kind`` in ``group`` (nested groups searched in
    order), else None."""
    for exc in group.exceptions:
        found = first_of(exc, kind) if isinstance(exc, BaseExceptionGroup) else exc
        if isinstance(found, kind):
            return found
    return None


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


class ConfigEditError(InputError):
    """An edit of the config file is refused and nothing is written: ``field`` names where
    (``devices.pump.unit``, empty when it is the whole edit), ``message`` says why, and
    ``issues`` holds every ``field: message`` row."""

    def __init__(self, message: str, field: str = "", issues: Sequence[str] = ()) -> None:
        self.message = message
        self.field = field
        super().__init__("config edit", issues or [f"{field}: {message}" if field else message])


class ConfigConflictError(ConfigEditError):
    """The config file changed on disk since it was read: ``diff`` (unified, secrets
    hidden) goes from what was read to what is on disk now; nothing is written."""

    def __init__(self, source: str, diff: str) -> None:
        self.diff = diff
        super().__init__(f"{source} changed on disk since it was read; reload it and redo the edit")


class ConfigReadOnlyError(ConfigEditError):
    """The config is not a file the bridge may write (the add-on's options, data)."""


class ConfigWriteError(ConfigEditError):
    """The config file or its backup could not be written; the file is as it was."""


class CodecError(BridgeError):
    """A value cannot be decoded from or encoded to registers."""


class MissingDataError(CodecError):
    """A register needed to decode or encode a value is not in the register image."""


class ValueRejectedError(CodecError):
    """A command value is refused before anything reaches the wire."""

    forbidden = False  # True: the key may not be written whatever the value


class WriteForbiddenError(ValueRejectedError):
    """A command is refused for what it writes, not for its value: an entity that is not
    writable or unknown, a guarded register, a lock, conditions the device does not meet
    now, a write sooner than its spacing. The gateway answers 0x01 (the value: 0x03)."""

    forbidden = True


class CommandRejectedError(ValueRejectedError):
    """Some keys of a command were refused, so none of its keys is written."""

    def __init__(self, refused: Mapping[str, ValueRejectedError], keys: Sequence[str]) -> None:
        self.refused = {key: str(error) for key, error in refused.items()}
        self.forbidden = any(error.forbidden for error in refused.values())
        self.keys = tuple(keys)
        others = [k for k in self.keys if k not in self.refused]
        reasons = "; ".join(self.refused.values())
        nothing = f"; nothing written (also not {', '.join(others)})" if others else ""
        super().__init__(reasons + nothing)

    def reason(self, key: str) -> str:
        """Why ``key`` was not written: its own refusal, or the refusal of the others."""
        if key in self.refused:
            others = len(self.keys) > 1
            return self.refused[key] + ("; nothing of this command was written" if others else "")
        return f"not written: the same command had refused keys ({', '.join(self.refused)})"


class CommandExpiredError(BridgeError):
    """A command could not be sent before its expiry; it was dropped, never sent late.
    ``sent``: an earlier attempt went out and was not answered (the device may have acted
    on it); only its resend was dropped."""

    def __init__(self, message: str, *, sent: bool = False) -> None:
        super().__init__(message)
        self.sent = sent


class SunSpecError(BridgeError):
    """A SunSpec walk found no model chain it can use."""


class NotSunSpecError(SunSpecError):
    """No ``SunS`` marker at any base address tried."""


class SunSpecChainError(SunSpecError):
    """The model chain is malformed or larger than the walk's bounds; ``base``: where the
    marker was found (set by the walk)."""

    base: int | None = None


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
        super().__init__(f"exception {code} ({meaning})")


class FrameError(ModbusError):
    """A frame could not be built or parsed (bad CRC/LRC, truncated, unknown function)."""


class PartialWriteError(ModbusError):
    """A compound write failed after some of its frames were written."""

    def __init__(
        self,
        done: int,
        total: int,
        *,
        restored: bool,
        cause: ModbusError,
        now: str | None = None,
    ) -> None:
        self.done = done
        self.total = total
        self.restored = restored
        self.cause = cause
        undone = "undone again" if restored else "NOT undone"
        message = (
            f"written only in part: frame {done + 1} of {total} failed ({cause}); "
            f"the {done} frame(s) before it were {undone}"
        )
        super().__init__(message if now is None else f"{message}; the device now reads {now}")
