"""Requests of the management API (``<base>/bridge/request/<cmd>``) and their responses. Pure.

Every request is a JSON object (an empty payload counts as ``{}``) with an optional
``transaction`` that the response echoes, Zigbee2MQTT style::

    modbus/bridge/request/device/read   {"bus": "rs485", "unit": 3, "address": 0, "count": 4,
                                         "transaction": "t1"}
    modbus/bridge/response/device/read  {"status": "ok", "data": {...}, "error": null,
                                         "transaction": "t1"}

``parse_request`` validates a payload for its command and raises RequestError with a
message naming the field; ``response`` builds the answer.
"""

from __future__ import annotations

import json
import re
from typing import Any, Literal, Self

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from bridge.core.duration import Duration
from bridge.core.mapping import format_validation_errors
from bridge.errors import BridgeError

Transaction = str | int | None
MAX_SCAN_TIMEOUT = 5.0
MAX_UNIT = 247  # unit ids a bus addresses; 0 is broadcast (nobody answers), 248-255 reserved
MAX_TCP_UNIT = 255  # a Modbus TCP gateway may answer as 255
_UNITS = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+))?\s*$")


class RequestError(BridgeError):
    """A management request that cannot be run; ``transaction`` is echoed in the answer."""

    def __init__(self, message: str, transaction: Transaction = None) -> None:
        super().__init__(message)
        self.transaction = transaction


class Request(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    transaction: Transaction = None


class Target(Request):
    """One unit: a configured ``device``, or ``unit`` on ``bus`` (the only bus if omitted).
    Unit 0 is broadcast: nobody answers it, so it is never read or written."""

    device: str | None = None
    bus: str | None = None
    unit: int | None = Field(None, ge=0, le=MAX_TCP_UNIT)
    timeout: Duration | None = Field(None, le=MAX_SCAN_TIMEOUT)

    @field_validator("unit")
    @classmethod
    def _not_broadcast(cls, unit: int | None) -> int | None:
        if unit == 0:
            raise ValueError(f"0 is broadcast (nobody answers it): give a unit 1..{MAX_UNIT}")
        return unit

    @model_validator(mode="after")
    def _device_or_unit(self) -> Self:
        if self.device is None and self.unit is None:
            raise ValueError("give a configured device, or a unit (and its bus)")
        if self.device is not None and (self.unit is not None or self.bus is not None):
            raise ValueError("give either device, or bus and unit, not both")
        return self


class DeviceRead(Target):
    """Raw registers or bits, with every interpretation (a commissioning aid)."""

    table: Literal["holding", "input", "coil", "discrete"] = "holding"
    address: int = Field(ge=0, le=0xFFFF, description="wire address, 0-based")
    count: int = Field(1, ge=1, le=2000)


class DeviceWrite(Target):
    """Raw register or coil values, written as given (needs bridge.allow_raw_writes)."""

    table: Literal["holding", "coil"] = "holding"
    address: int = Field(ge=0, le=0xFFFF, description="wire address, 0-based")
    values: list[int] = Field(min_length=1, max_length=1968)


class DeviceScan(Request):
    """Which unit ids answer on a bus: ``units`` like ``"1-247"`` or ``[1, 2, 10]``."""

    bus: str | None = None
    units: str | list[int] = "1-247"
    timeout: Duration | None = Field(None, gt=0, le=MAX_SCAN_TIMEOUT)

    def unit_ids(self) -> list[int]:
        return parse_units(self.units)


class DeviceIdentify(Request):
    """What answers at ``unit`` (or each of ``units``) on a bus: read-only probes."""

    bus: str | None = None
    unit: int | None = Field(None, ge=1, le=MAX_UNIT)
    units: str | list[int] | None = Field(None, max_length=MAX_UNIT)
    timeout: Duration | None = Field(None, gt=0, le=MAX_SCAN_TIMEOUT)

    @model_validator(mode="after")
    def _unit_or_units(self) -> Self:
        if (self.unit is None) == (self.units is None):
            raise ValueError('give unit or units (like "1-247"), one of them')
        return self

    def unit_ids(self) -> list[int]:
        return [self.unit] if self.unit is not None else parse_units(self.units or [])


class MappingReload(Request):
    """Read the mapping files again (all devices, or those listed) and apply them; with
    ``mapping`` (a shipped name or a file under ``bridge.mapping_dirs``; needs
    ``bridge.mapping_switch``), one listed device switches to that mapping. A ``mapping:
    sunspec`` device keeps its built mapping, unless ``rewalk``: then the SunSpec devices
    (all, or those listed: only SunSpec devices) are walked and built again."""

    devices: list[str] | None = Field(None, max_length=1000)
    mapping: str | None = Field(None, min_length=1, max_length=1024)
    rewalk: bool = False

    @model_validator(mode="after")
    def _one_device_for_a_new_mapping(self) -> Self:
        if self.mapping is not None and (self.devices is None or len(self.devices) != 1):
            raise ValueError("mapping: name exactly one device in devices to switch it")
        if self.mapping is not None and self.rewalk:
            raise ValueError("rewalk: a SunSpec device's mapping is built, not switched")
        return self


class HealthCheck(Request):
    """Is the bridge working: MQTT, buses, devices online."""


REQUESTS: dict[str, type[Request]] = {
    "device/read": DeviceRead,
    "device/write": DeviceWrite,
    "device/scan": DeviceScan,
    "device/identify": DeviceIdentify,
    "mapping/reload": MappingReload,
    "health_check": HealthCheck,
}


def parse_request(command: str, payload: bytes) -> Request:
    """The validated request; RequestError (with the transaction if one was readable)."""
    try:
        data = json.loads(payload) if payload.strip() else {}
    except (ValueError, UnicodeDecodeError):
        raise RequestError("the payload is not JSON; send an object like {}") from None
    if not isinstance(data, dict):
        raise RequestError("the payload must be a JSON object")
    transaction = data.get("transaction")
    if not isinstance(transaction, str | int) or isinstance(transaction, bool):
        transaction = None
    model = REQUESTS.get(command)
    if model is None:
        known = ", ".join(sorted(REQUESTS))
        raise RequestError(f"unknown request {command!r} (known: {known})", transaction)
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise RequestError("; ".join(format_validation_errors(exc)), transaction) from None


def parse_units(spec: str | list[int]) -> list[int]:
    """``"1-10,20"`` or ``[1, 2]`` -> sorted unique unit ids in 1..247; RequestError if not.
    Every bound is checked before a range is expanded (``"1-100000000"`` costs nothing)."""
    bounds: list[tuple[int, int]] = []
    if isinstance(spec, list):
        bounds = [(unit, unit) for unit in spec]
    else:
        for part in spec.split(","):
            match = _UNITS.match(part)
            if match is None:
                shown = part.strip()[:20]
                raise RequestError(f"units: {shown!r} is not a unit or a range like 1-247")
            first, last = match.group(1), match.group(2) or match.group(1)
            if max(len(first), len(last)) > 3:  # int() of a long digit string is slow
                raise RequestError(f"units: unit ids are 1..{MAX_UNIT}")
            bounds.append((int(first), int(last)))
    if not bounds or any(not 1 <= a <= b <= MAX_UNIT for a, b in bounds):
        raise RequestError(f"units: unit ids are 1..{MAX_UNIT}, ranges low-high")
    return sorted({unit for first, last in bounds for unit in range(first, last + 1)})


def response(
    data: object = None, *, error: str | None = None, transaction: Transaction = None
) -> str:
    """The JSON answer: ``{status, data, error, transaction}``."""
    document: dict[str, Any] = {
        "status": "error" if error is not None else "ok",
        "data": {} if data is None else data,
        "error": error,
        "transaction": transaction,
    }
    return json.dumps(document, default=str)
