"""The changes the config store makes to a config file, as typed values, and how each is
made to a document (plain data or the round-trip YAML: both are dicts and lists).

    AddDevice(device={...})              a device appended to ``devices``
    EditDevice(id=..., set={...})        fields of one device set (``"poll.fast": "5s"``), a
                                         ``None`` value removes the key (its default applies);
                                         a new ``id`` renames the gateway's references too
    RemoveDevice(id=...)                 the device's entry removed
    AddBus(bus={...})                    a serial or TCP bus appended to ``buses``

Every field is bounded before anything reads it (ids 64 characters, a name 100, any text
1024 and no control character, a few hundred items, four levels deep); what the values
mean is checked by the loader, as ``check`` does. A secret left out of an edit, or given
as ``SECRET_MARK`` (what the store's view shows), keeps the file's value. ``parse_change``
reads one from JSON data.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, MutableMapping
from typing import Annotated, Any, Literal, NoReturn

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    TypeAdapter,
    ValidationError,
    field_validator,
)

from bridge.config.model import DeviceConfig, SerialBus, TcpBus
from bridge.errors import ConfigEditError

MAX_ID = 64  # characters of a device or bus id (they become MQTT topic levels)
MAX_NAME = 100  # characters of a device's name
MAX_TEXT = 1024  # characters of any other text (a path, a host, an option)
MAX_ITEMS = 256  # entries of one list or mapping
MAX_NODES = 2000  # values in one change
MAX_DEPTH = 4  # levels of nesting under a field
SECRET_MARK = "**********"  # noqa: S105 - a secret's place in views; given back, the secret is kept
SECRET_KEYS = frozenset(
    f"{name}{suffix}" for name in ("password", "token") for suffix in ("", "_file", "_env")
)
"""Keys that hold a secret or say where one is: never shown, kept unless given anew."""

_DEVICE_FIELDS = frozenset(DeviceConfig.model_fields)
_BUS_FIELDS = frozenset(SerialBus.model_fields) | frozenset(TcpBus.model_fields)
_LIMITS = {"id": MAX_ID, "bus": MAX_ID, "name": MAX_NAME}
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_PATH = re.compile(r"^[a-z_]+(\.[^.\s]{1,200}){0,3}$")

Id = Annotated[str, StringConstraints(min_length=1, max_length=MAX_ID)]
Make = Callable[[Any, Any], Any]  # (plain value, its sibling or None) -> a document node


def _bounded(value: Any, section: str) -> None:
    """ValueError naming the place of the first value past a bound (walked breadth first,
    each container's size checked before its entries, so a huge input stops early)."""
    queue: list[tuple[Any, str, int]] = [(value, section, 0)]
    for item, where, depth in queue:
        if len(queue) > MAX_NODES:
            raise ValueError(f"{section}: more than {MAX_NODES} values")
        if depth > MAX_DEPTH:
            raise ValueError(f"{where}: nested more than {MAX_DEPTH} levels")
        if isinstance(item, list | dict) and len(item) > MAX_ITEMS:
            raise ValueError(f"{where}: at most {MAX_ITEMS} entries (got {len(item)})")
        if isinstance(item, dict):
            for key in item:
                if not _scalar_key(key):
                    raise ValueError(f"{where}: keys are text of at most 200 characters or numbers")
            queue += [(v, f"{where}.{k}", depth + 1) for k, v in item.items()]
        elif isinstance(item, list):
            queue += [(v, f"{where}.{i}", depth + 1) for i, v in enumerate(item)]
        else:
            _check_scalar(item, where, depth)


def _scalar_key(key: object) -> bool:
    if isinstance(key, str):
        return len(key) <= 200 and not _CONTROL.search(key)
    return isinstance(key, int) and not isinstance(key, bool) and abs(key) < 2**63


def _check_scalar(value: object, where: str, depth: int) -> None:
    if isinstance(value, str):
        limit = _LIMITS.get(where.rsplit(".", 1)[-1], MAX_TEXT) if depth <= 1 else MAX_TEXT
        if len(value) > limit:
            raise ValueError(f"{where}: at most {limit} characters (got {len(value)})")
        if _CONTROL.search(value):
            raise ValueError(f"{where}: no control characters (line breaks, tabs, NUL)")
    elif isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{where}: not a finite number")
    elif isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 2**63:
        raise ValueError(f"{where}: a number beyond 64 bits")
    elif value is not None and not isinstance(value, bool | int | float | str):
        raise ValueError(f"{where}: {type(value).__name__} is not a config value")


def _fields(value: dict[str, Any], known: frozenset[str], section: str) -> dict[str, Any]:
    unknown = sorted(set(value) - known)
    if unknown:
        raise ValueError(f"{section}.{unknown[0][:MAX_ID]}: not a field (have {sorted(known)})")
    _bounded(value, section)
    return value


class _Change(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class AddDevice(_Change):
    """A device appended to ``devices`` (its fields as in the config file)."""

    kind: Literal["add_device"] = "add_device"
    device: dict[str, Any] = Field(max_length=len(_DEVICE_FIELDS))

    @field_validator("device")
    @classmethod
    def _check(cls, value: dict[str, Any]) -> dict[str, Any]:
        for key in SECRET_KEYS & set(value):
            if value[key] == SECRET_MARK:
                raise ValueError(f"device.{key}: give the secret itself (the mark keeps one)")
        return _fields(value, _DEVICE_FIELDS, "device")


class EditDevice(_Change):
    """Fields of the device ``id`` set: a dotted path (``poll.fast``) to a value, or to
    None to remove the key; secrets left out (or given as SECRET_MARK) are kept."""

    kind: Literal["edit_device"] = "edit_device"
    id: Id
    set: dict[str, Any] = Field(min_length=1, max_length=64)

    @field_validator("set")
    @classmethod
    def _check(cls, value: dict[str, Any]) -> dict[str, Any]:
        for path in value:
            if (
                not _PATH.match(path)
                or _CONTROL.search(path)
                or path.split(".")[0] not in _DEVICE_FIELDS
            ):
                raise ValueError(
                    f"device.{path[:MAX_ID]}: not a device field (have {sorted(_DEVICE_FIELDS)})"
                )
        _bounded(value, "device")
        return value


class RemoveDevice(_Change):
    """The device ``id`` removed from ``devices``."""

    kind: Literal["remove_device"] = "remove_device"
    id: Id


class AddBus(_Change):
    """A bus (serial: ``transport: rtu|ascii``, TCP: ``tcp|rtu-over-tcp``) appended."""

    kind: Literal["add_bus"] = "add_bus"
    bus: dict[str, Any] = Field(max_length=len(_BUS_FIELDS))

    @field_validator("bus")
    @classmethod
    def _check(cls, value: dict[str, Any]) -> dict[str, Any]:
        return _fields(value, _BUS_FIELDS, "bus")


Change = Annotated[AddDevice | EditDevice | RemoveDevice | AddBus, Field(discriminator="kind")]
_CHANGE: TypeAdapter[AddDevice | EditDevice | RemoveDevice | AddBus] = TypeAdapter(Change)


def parse_change(data: object) -> AddDevice | EditDevice | RemoveDevice | AddBus:
    """A change from JSON data (``{"kind": "edit_device", ...}``); ConfigEditError naming
    the field otherwise."""
    try:
        return _CHANGE.validate_python(data)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in first["loc"][1:])
        message = str(first["msg"]).removeprefix("Value error, ")
        field, sep, rest = message.partition(": ")
        if sep and " " not in field:  # our own messages name their field first
            _raise(rest, field)
        _raise(message[:300], where)


def _raise(message: str, field: str) -> NoReturn:
    raise ConfigEditError(message, field)


def describe(change: AddDevice | EditDevice | RemoveDevice | AddBus) -> str:
    """One line naming the change (no values: those are in the summary's rows)."""
    if isinstance(change, AddDevice):
        return f"add device {change.device.get('id')!s}"
    if isinstance(change, AddBus):
        return f"add bus {change.bus.get('id')!s}"
    verb = "edit" if isinstance(change, EditDevice) else "remove"
    return f"{verb} device {change.id}"


def make_change(
    root: MutableMapping[str, Any],
    change: AddDevice | EditDevice | RemoveDevice | AddBus,
    make: Make,
) -> None:
    """Make ``change`` to the document ``root``; new values go through ``make``.
    ConfigEditError if it names a device that is not there."""
    if isinstance(change, AddDevice | AddBus):
        section = "devices" if isinstance(change, AddDevice) else "buses"
        entry = change.device if isinstance(change, AddDevice) else change.bus
        items = root.get(section)
        if not isinstance(items, list):
            root[section] = make([], None)
            items = root[section]
        items.append(make(entry, items[-1] if items else None))
        return
    devices, index = _device_index(root.get("devices"), change.id)
    if isinstance(change, RemoveDevice):
        del devices[index]
        return
    device = devices[index]
    for path, value in change.set.items():
        _set(device, path.split("."), value, make)
    new_id = change.set.get("id")
    if isinstance(new_id, str) and new_id != change.id:
        _rename_references(root, change.id, new_id, make)


def _device_index(devices: Any, device_id: str) -> tuple[list[Any], int]:
    """The devices list and where the device ``device_id`` is in it."""
    listed: list[Any] = devices if isinstance(devices, list) else []
    for index, device in enumerate(listed):
        if isinstance(device, dict) and device.get("id") == device_id:
            return listed, index
    have = sorted(str(d.get("id")) for d in listed if isinstance(d, dict))
    shown = ", ".join(have[:20]) + (f" and {len(have) - 20} more" if len(have) > 20 else "")
    _raise(f"no device {device_id!r} in the file (have {shown or 'none'})", f"devices.{device_id}")


def _set(node: MutableMapping[Any, Any], path: list[str], value: Any, make: Make) -> None:
    key, rest = path[0], path[1:]
    if not rest:
        if value is None:
            node.pop(key, None)
        elif not (value == SECRET_MARK and key in SECRET_KEYS):
            node[key] = make(value, None)
        return
    child = node.get(key)
    if not isinstance(child, dict):
        if value is None:
            return
        node[key] = make({}, None)
        child = node[key]
    _set(child, rest, value, make)


def _rename_references(root: MutableMapping[str, Any], old: str, new: str, make: Make) -> None:
    """The gateway's units that name the device by its old id name the new one."""
    bridge = root.get("bridge")
    gateway = bridge.get("gateway") if isinstance(bridge, dict) else None
    units = gateway.get("units") if isinstance(gateway, dict) else None
    if not isinstance(units, dict):
        return
    for unit, target in list(units.items()):
        if target == old:
            units[unit] = make(new, None)
