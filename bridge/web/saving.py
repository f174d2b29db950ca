"""The page's "Save": a device (and the new bus it is on) written to the config file and
applied to the running bridge.

    POST api/config/devices  {"device": {id, name, bus, unit, mapping, options},
                              "bus": {id, transport, port, ...}}   ("bus": a new bus only)

The request is checked as a trial's is (types strict, strings bounded, a shipped mapping;
a new bus as bridge/web/new_bus.py checks one: a port the host lists, no port or gateway
a configured bus uses); no field beyond these is taken, so a page change never turns on
dangerous writes. The config store (bridge/config/store.py) then checks the change as ``check``
does, writes it atomically with a backup and keeps the user's comments; a file changed
on disk since the page opened it (``open``, as the page starts) is never overwritten
(409, with the difference; the next save starts from the file as it is then). A new bus is
written first, then the device on it. ``apply_config`` then starts only what changed: the
other devices keep polling. The caller logs each save once: who, and the store's summary
(secrets hidden).
"""

from __future__ import annotations

import asyncio
from http import HTTPStatus
from typing import Annotated, Any, Protocol

from pydantic import Field, StringConstraints

from bridge.config import LoadedConfig
from bridge.config.edits import AddBus, AddDevice
from bridge.config.store import Applied, ConfigStore
from bridge.core.mapping import builtin_mapping_names
from bridge.errors import ConfigConflictError, ConfigEditError, ConfigError, ConfigReadOnlyError
from bridge.modbus.engine import Engine
from bridge.web.adding import Ask, Text, parse_ask
from bridge.web.new_bus import AskError, TemporaryBuses

Id = Annotated[str, StringConstraints(min_length=1, max_length=64)]


class NewDevice(Ask):
    """The device as the add flow gives it (nothing else: no dangerous writes, no secret)."""

    id: Id
    name: Text | None = None
    bus: Id
    unit: int = Field(ge=1, le=255)
    mapping: Text
    options: dict[Text, Text] = Field(default_factory=dict, max_length=20)


class SaveAsk(Ask):
    device: NewDevice
    bus: dict[str, Any] | None = Field(None, max_length=12)


class SavingBridge(Protocol):
    """What saving needs of the running bridge."""

    @property
    def loaded(self) -> LoadedConfig: ...
    @property
    def engine(self) -> Engine: ...
    async def apply_config(self, new: LoadedConfig) -> dict[str, Any]: ...


class SaveError(AskError):
    """A save refused; ``diff``: how the file changed on disk, for a conflict."""

    def __init__(self, status: HTTPStatus, message: str, diff: str = "") -> None:
        super().__init__(status, message)
        self.diff = diff


class Saving:
    """Saves to the running bridge's config file (read by ``open`` as the page starts)."""

    def __init__(self, bridge: SavingBridge, buses: TemporaryBuses) -> None:
        self.bridge = bridge
        self.buses = buses
        self._store: ConfigStore | None = None
        self._lock = asyncio.Lock()  # one save at a time: written, then applied

    async def open(self) -> ConfigStore:
        """Read the config file now (as the page starts): a change on disk after this is
        a conflict, never overwritten. A config that is no file refuses edits."""
        loaded = self.bridge.loaded
        if not loaded.path.is_file():
            reason = f"built without a file ({loaded.path.name} is not there)"
            self._store = ConfigStore.read_only(loaded, reason)
            return self._store
        try:
            self._store = await asyncio.to_thread(ConfigStore.open, loaded.path)
        except ConfigError as exc:  # unreadable now: refused at each save, with why
            reason = f"a file the page cannot read ({exc.issues[0]})"
            self._store = ConfigStore.read_only(loaded, reason)
        return self._store

    async def add_device(self, body: bytes) -> tuple[dict[str, Any], str]:
        """Write the device (and its new bus), then apply the file; data and a log line."""
        ask = parse_ask(SaveAsk, body)
        changes = await self._changes(ask)
        async with self._lock:
            store = await self._opened()
            applied = [await _apply(store, change) for change in changes]
            answer = await self.bridge.apply_config(applied[-1].loaded)
        summary = "; ".join(_one_line(a.summary) for a in applied)
        data = {"device": ask.device.id, "saved": summary, "applied": answer}
        if answer.get("status") != "ok":
            return data, f"saved, not applied ({answer.get('error')}): {summary}"
        return data, f"saved and applied ({answer.get('description')}): {summary}"

    async def _changes(self, ask: SaveAsk) -> list[AddBus | AddDevice]:
        if ask.device.mapping not in builtin_mapping_names():
            message = f"device.mapping: no shipped mapping {ask.device.mapping!r}"
            raise SaveError(HTTPStatus.NOT_FOUND, message)
        device = ask.device.model_dump(exclude_none=True)
        if not device.get("options"):
            device.pop("options", None)
        if ask.bus is None:
            if ask.device.bus not in self.bridge.engine.schedulers:
                raise SaveError(HTTPStatus.NOT_FOUND, f"device.bus: no bus {ask.device.bus!r}")
            return [AddDevice(device=device)]
        settings = {k: v for k, v in ask.bus.items() if k != "id"}
        bus_id = ask.bus.get("id")
        if bus_id != ask.device.bus:
            raise SaveError(HTTPStatus.BAD_REQUEST, "bus.id: the new bus's id is device.bus")
        chosen = await self.buses.choose(settings, self.bridge.loaded, self.bridge.engine)
        if self.buses.in_use(chosen.bus):  # the bridge would open it beside a scan's
            raise SaveError(HTTPStatus.TOO_MANY_REQUESTS, "busy: a request uses this bus now")
        try:
            return [AddBus(bus=dict(ask.bus)), AddDevice(device=device)]
        except ValueError as exc:  # pydantic's, naming the field
            raise SaveError(HTTPStatus.BAD_REQUEST, str(exc).splitlines()[-1]) from None

    async def _opened(self) -> ConfigStore:
        return self._store if self._store is not None else await self.open()


async def _apply(store: ConfigStore, change: AddBus | AddDevice) -> Applied:
    try:
        return await asyncio.to_thread(store.apply, change)
    except ConfigConflictError as exc:
        await asyncio.to_thread(store.refresh)  # the next save starts from the file on disk
        raise SaveError(HTTPStatus.CONFLICT, exc.message, exc.diff) from None
    except ConfigReadOnlyError as exc:
        raise SaveError(HTTPStatus.FORBIDDEN, exc.message) from None
    except ConfigEditError as exc:
        raise SaveError(HTTPStatus.BAD_REQUEST, "; ".join(exc.issues[:5])) from None


def _one_line(summary: str) -> str:
    """The store's summary (a line, then a row per value) as one log line."""
    first, *rows = summary.splitlines()
    return f"{first} ({', '.join(row.strip() for row in rows)})" if rows else first
