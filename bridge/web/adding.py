"""The page's "Add a device": scan a bus, identify what answers, try a mapping, each on a
configured bus or on a bus not configured yet (bridge/web/new_bus.py).

    POST api/add/scan      {bus, units, timeout}   which units answer (the management scan
                                                   on a configured bus)
    POST api/add/identify  {bus, units, timeout}   what each unit is, with its confidence
    POST api/trial         {bus, unit, mapping, options, id, name}
                                                   one trial poll (bridge/modbus/trial.py):
                                                   the decoded values and refused registers

``bus`` is a configured bus's id or a new bus's settings. Each request is checked whole
before anything is sent (types strict, strings and lists bounded, a unit the line can
address, an id no device has, a shipped mapping); a refusal is an ``AskError`` with its
HTTP status. Everything on a bus is read-only and queued as a poll: the bus's own polls,
commands and other masters go first. Nothing is saved or published.
"""

from __future__ import annotations

import asyncio
import json
from http import HTTPStatus
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, ValidationError

from bridge.config import DeviceConfig, SerialBus, load_device_mapping
from bridge.core.management_request import MAX_SCAN_TIMEOUT, MAX_UNIT, RequestError, parse_units
from bridge.core.mapping import (
    Mapping,
    builtin_mapping_names,
    format_validation_errors,
    shipped_library,
)
from bridge.core.state import published
from bridge.core.wording import unit_sources
from bridge.modbus.commission import Found, scan, scheduler_submit
from bridge.modbus.identify import identify
from bridge.modbus.poller import DevicePoller
from bridge.modbus.scheduler import Priority
from bridge.modbus.trial import TRIAL_LIMIT, trial_poll
from bridge.web.new_bus import NEW_BUS, AskError, ChosenBus, TemporaryBuses
from bridge.web.parts import BridgeParts
from bridge.web.views import value_row

TRIAL_ID = "trial"  # the trial device's id in the log: "trial-<id given>" or "trial"
Text = Annotated[str, StringConstraints(min_length=1, max_length=100)]
BusChoice = Annotated[str, StringConstraints(min_length=1, max_length=64)] | dict[str, Any]
Units = (
    Annotated[str, StringConstraints(max_length=200)]
    | Annotated[list[int], Field(min_length=1, max_length=MAX_UNIT)]
)


class Ask(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class UnitsAsk(Ask):
    """A scan's or an identify's: which units of which bus."""

    bus: BusChoice
    units: Units = "1-247"
    timeout: float | None = Field(None, gt=0, le=MAX_SCAN_TIMEOUT)


class TrialAsk(Ask):
    """A trial poll's: the device as it would be configured."""

    bus: BusChoice
    unit: int = Field(ge=1, le=255)
    mapping: Text
    options: dict[Text, Text] = Field(default_factory=dict, max_length=20)
    id: Annotated[str, StringConstraints(min_length=1, max_length=64)] | None = None
    name: Text | None = None


_Ask = TypeVar("_Ask", bound=Ask)


def parse_ask(model: type[_Ask], body: bytes) -> _Ask:
    """The request, checked whole; AskError (400) naming the fields that are wrong."""
    try:
        data = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        raise AskError(HTTPStatus.BAD_REQUEST, "the body is not JSON") from None
    if not isinstance(data, dict):
        raise AskError(HTTPStatus.BAD_REQUEST, "send a JSON object")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        rows = list(format_validation_errors(exc))
        raise AskError(HTTPStatus.BAD_REQUEST, "; ".join(rows[:5])) from None


class Adding:
    """Runs the add flow's requests for one bridge."""

    def __init__(self, bridge: BridgeParts) -> None:
        self.bridge = bridge
        self.buses = TemporaryBuses()
        self._trials: set[str] = set()  # configured buses with a trial running

    async def _choose(self, given: object) -> ChosenBus:
        return await self.buses.choose(given, self.bridge.loaded, self.bridge.engine)

    async def scan(self, body: bytes) -> tuple[dict[str, Any], str]:
        """Which units answer; the answer's data and one line for the log."""
        ask = parse_ask(UnitsAsk, body)
        units = _units(ask.units)
        chosen = await self._choose(ask.bus)
        if chosen.configured:
            data = await self._management("device/scan", chosen, units, ask.timeout)
        else:
            timeout = ask.timeout or self.bridge.loaded.config.bridge.scan_timeout
            async with self.buses.opened(chosen) as scheduler:
                found = await scan(scheduler_submit(scheduler, Priority.POLL), units, timeout)
            data = {"bus": NEW_BUS, "probed": len(units), "found": [_found(f) for f in found]}
        answered = len(data["found"])
        return data, f"scanned {_units_said(units)} on bus {data['bus']}: {answered} answered"

    async def identify(self, body: bytes) -> tuple[dict[str, Any], str]:
        """What each unit is (read-only probes); the answer's data and one log line."""
        ask = parse_ask(UnitsAsk, body)
        units = _units(ask.units)
        chosen = await self._choose(ask.bus)
        if chosen.configured:
            data = await self._management("device/identify", chosen, units, ask.timeout)
        else:
            timeout = ask.timeout or self.bridge.loaded.config.bridge.scan_timeout
            library = await asyncio.to_thread(shipped_library)
            async with self.buses.opened(chosen) as scheduler:
                submit = scheduler_submit(scheduler, Priority.POLL)
                wait = chosen.bus.timeout
                found = await identify(submit, units, library, timeout, NEW_BUS, read_timeout=wait)
            data = {"bus": NEW_BUS, "probed": len(units), "found": [i.as_dict() for i in found]}
        said = ", ".join(f"{f['unit']}: {f['summary']}" for f in data["found"][:5])
        where = f"{_units_said(units)} on bus {data['bus']}"
        return data, f"identified {where}: {said or 'none answered'}"

    async def _management(
        self, command: str, chosen: ChosenBus, units: list[int], timeout: float | None
    ) -> dict[str, Any]:
        """A configured bus's scan or identify, run by the management code (its limits)."""
        ask: dict[str, Any] = {"bus": chosen.bus.id, "units": units}
        if timeout is not None:
            ask["timeout"] = timeout
        answer = json.loads(await self.bridge.management.handle(command, json.dumps(ask).encode()))
        if answer["status"] != "ok":
            error = str(answer["error"])
            busy = error.startswith("busy")
            raise AskError(HTTPStatus.TOO_MANY_REQUESTS if busy else HTTPStatus.BAD_GATEWAY, error)
        data: dict[str, Any] = answer["data"]
        return data

    async def trial(self, body: bytes) -> tuple[dict[str, Any], str]:
        """One trial poll of a proposed device; the answer's data and one log line."""
        ask = parse_ask(TrialAsk, body)
        loaded = self.bridge.loaded
        if ask.id is not None and ask.id in {d.id for d in loaded.config.devices}:
            raise AskError(HTTPStatus.CONFLICT, f"id: a device {ask.id!r} exists already")
        if ask.mapping not in builtin_mapping_names():
            raise AskError(
                HTTPStatus.NOT_FOUND,
                f"mapping: no shipped mapping {ask.mapping!r} (search the library)",
            )
        chosen = await self._choose(ask.bus)
        if isinstance(chosen.bus, SerialBus) and ask.unit > MAX_UNIT:
            raise AskError(
                HTTPStatus.BAD_REQUEST, f"unit: serial lines address units 1..{MAX_UNIT}"
            )
        device = _device(ask, chosen.bus.id)
        mapping, problems = await asyncio.to_thread(
            load_device_mapping, device, chosen.bus, loaded.path.parent
        )
        if mapping is None or problems:
            shown = [p.removeprefix(f"devices.{device.id}.") for p in problems[:5]]
            raise AskError(HTTPStatus.BAD_REQUEST, "; ".join(shown))
        poller = await self._trial_on(chosen, device, mapping)
        data = trial_document(poller, chosen.bus.id)
        where = f"unit {ask.unit} on bus {chosen.bus.id}"
        read, refused = data["read"], len(data["refused"])
        return data, f"trial of {ask.mapping} at {where}: {read} values read, {refused} refused"

    async def _trial_on(
        self, chosen: ChosenBus, device: DeviceConfig, mapping: Mapping
    ) -> DevicePoller:
        """One trial at a time per configured bus (a new bus is one request's anyway)."""
        slot = chosen.bus.id if chosen.configured else None
        if slot is not None and slot in self._trials:
            raise AskError(HTTPStatus.TOO_MANY_REQUESTS, f"busy: a trial runs on bus {slot}")
        if slot is not None:
            self._trials.add(slot)
        try:
            async with self.buses.opened(chosen) as scheduler:
                return await trial_poll(device, mapping, scheduler, chosen.bus)
        except TimeoutError:
            raise AskError(
                HTTPStatus.GATEWAY_TIMEOUT, f"the trial poll took over {TRIAL_LIMIT:g} s"
            ) from None
        finally:
            if slot is not None:
                self._trials.discard(slot)


def trial_document(poller: DevicePoller, bus_id: str) -> dict[str, Any]:
    """What a trial poll read: every published value (decoded, in Home Assistant's words,
    with its unit and name, as the device page shows it: bridge/web/views.py),
    the registers the device refused, and its requests' outcomes."""
    health, device, mapping = poller.health, poller.device, poller.mapping
    units = unit_sources(poller.points)
    values = [value_row(poller, key, units) for key in published(poller.points)]
    silent = health.requests > 0 and health.timeouts == health.requests
    return {
        "bus": bus_id,
        "unit": device.unit,
        "mapping": device.mapping,
        "model": f"{mapping.manufacturer} {mapping.model}",
        "requests": health.requests,
        "errors": health.errors,
        "timeouts": health.timeouts,
        "exceptions": {str(code): count for code, count in sorted(health.exceptions.items())},
        "read": sum(v["value"] is not None for v in values),
        "values": values,
        "refused": [{"table": t.value, "address": a} for t, a in sorted(poller.refused)],
        "note": f"unit {device.unit} did not answer" if silent else None,
    }


def _units(spec: str | list[int]) -> list[int]:
    try:
        return parse_units(spec)
    except RequestError as exc:
        raise AskError(HTTPStatus.BAD_REQUEST, str(exc)) from None


def _units_said(units: list[int]) -> str:
    return f"unit {units[0]}" if len(units) == 1 else f"{len(units)} units"


def _device(ask: TrialAsk, bus_id: str) -> DeviceConfig:
    fields = {"id": ask.id or TRIAL_ID, "name": ask.name, "bus": bus_id, "unit": ask.unit}
    try:
        return DeviceConfig.model_validate(
            fields | {"mapping": ask.mapping, "options": ask.options}
        )
    except ValidationError as exc:
        rows = list(format_validation_errors(exc))
        raise AskError(HTTPStatus.BAD_REQUEST, "; ".join(rows[:5])) from None


def _found(found: Found) -> dict[str, Any]:
    """A unit that answered a new bus's scan, as the management scan says it."""
    return {
        "unit": found.unit,
        "answer": found.answer.value,
        "exception_code": found.exception_code,
        "detail": found.detail,
        "latency_ms": round(found.latency * 1000, 1),
        "device": None,
    }
