"""The page's "Save": a device (and the new bus it is on) written to the config file and
applied to the running bridge.

    POST api/config/devices  {"device": {id, name, bus, unit, mapping, options},
                              "bus": {id, transport, port, ...}}   ("bus": a new bus only)

The request is checked as a trial's is (types strict, strings bounded, a shipped mapping;
a new bus as bridge/web/new_bus.py checks one: a port the host lists, no port or gateway
a configured bus uses); no field beyond these is taken, so a page change never turns on
dangerous writes. The page's one writer of the config file (bridge/web/config_file.py,
shared with the edits) then has the config store check the change as ``check`` does,
write it atomically with a backup and keep the user's comments; a file changed on disk
since the page read it is never overwritten (409, with the difference). A new bus is
written first, then the device on it. ``apply_config`` then starts only what changed: the
other devices keep polling. The caller logs each save once: who, and the store's summary
(secrets hidden).
"""

from __future__ import annotations

from http import HTTPStatus
from typing import Annotated, Any, Protocol

from pydantic import Field, StringConstraints

from bridge.config import LoadedConfig
from bridge.config.edits import AddBus, AddDevice
from bridge.core.mapping import builtin_mapping_names
from bridge.modbus.engine import Engine
from bridge.web.adding import Ask, Text, parse_ask
from bridge.web.config_file import ConfigChangeError, ConfigFile
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
    """Saves to the running bridge's config file, through the page's one writer."""

    def __init__(self, bridge: SavingBridge, buses: TemporaryBuses, file: ConfigFile) -> None:
        self.bridge = bridge
        self.buses = buses
        self.file = file

    async def add_device(self, body: bytes) -> tuple[dict[str, Any], str]:
        """Write the device (and its new bus), then apply the file; data and a log line."""
        ask = parse_ask(SaveAsk, body)
        changes = await self._changes(ask)
        try:
            changed = await self.file.change(*changes)
        except ConfigChangeError as exc:
            raise SaveError(exc.status, str(exc), exc.diff) from None
        summary = "; ".join(_one_line(s) for s in changed.summaries)
        answer = changed.applied
        data = {"device": ask.device.id, "saved": summary, "applied": answer}
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


def _one_line(summary: str) -> str:
    """The store's summary (a line, then a row per value) as one log line."""
    first, *rows = summary.splitlines()
    return f"{first} ({', '.join(row.strip() for row in rows)})" if rows else first
