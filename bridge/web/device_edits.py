"""The page's edits of configured devices: rename, another unit, poll intervals, enable
and disable, ``allow_dangerous_writes``, remove (issue 39, item 3).

    GET  api/config/devices                  every configured device, enabled or not, with
                                             what the page may change of it
    GET  api/config/devices/<id>             one of them, with ``dangerous`` (below) and
                                             ``writable`` (false: the config is no file
                                             the page may write)
    GET  api/config/devices/<id>/dangerous   what ``allow_dangerous_writes`` permits: the
                                             entities by the names Home Assistant shows
    POST api/config/devices/<id>             change fields (bridge/web/edit_request.py)
    POST api/config/devices/<id>/remove      remove it: its discovery configs and retained
                                             state emptied

A change is written and applied by bridge/web/config_file.py (validated as ``check`` does,
written atomically with comments kept, only the device restarted): answered ``{status:
ok, device, summary, changes}``. Turning ``allow_dangerous_writes`` on takes two POSTs:
the first is answered 409 ``{status: confirm, confirm: {token, expires_s, entities,
raw_writes}}``; the same change sent again with ``confirmation: <token>`` within
``CONFIRM_FOR`` seconds applies it (a token confirms one change of one device, once).

Every request passes the page's access rules (bridge/web/access.py); a POST must also
come from the page itself (``change_refusal``). Each POST is logged once: who (the
address, or the Home Assistant user behind ingress) and the change's summary (no secret),
or why it was refused.
"""

from __future__ import annotations

import json
import logging
from http import HTTPStatus
from typing import Any

from bridge.config import DeviceConfig, SerialBus
from bridge.config.edits import MAX_ID, parse_change
from bridge.config.model import MAX_SERIAL_UNIT
from bridge.errors import ConfigEditError
from bridge.web.access import Access, change_refusal
from bridge.web.config_file import Changed, ConfigChangeError, ConfigFile
from bridge.web.edit_request import CONFIRM_FOR, Confirmations, dangerous_entities, parse_edit
from bridge.web.http import Request, Response
from bridge.web.parts import BridgeState

PREFIX = "/api/config/devices"
_JSON = "application/json"
log = logging.getLogger(__name__)


class ConfirmationError(ConfigChangeError):
    """Turning ``allow_dangerous_writes`` on waits for its confirmation (``document``)."""

    def __init__(self, message: str, document: dict[str, Any]) -> None:
        super().__init__(HTTPStatus.CONFLICT, message)
        self.document = document


class DeviceEdits:
    """Answers ``api/config/devices...`` (see the module)."""

    def __init__(self, bridge: BridgeState, access: Access, file: ConfigFile) -> None:
        self.bridge = bridge
        self.access = access
        self.file = file
        self.confirmations = Confirmations()

    @staticmethod
    def serves(request: Request) -> bool:
        """Whether ``request`` is one of this module's (a POST to ``api/config/devices``
        itself adds a device: not here)."""
        path = request.path
        return path.startswith(PREFIX + "/") or (path == PREFIX and request.method != "POST")

    async def handle(self, request: Request) -> Response:
        changing = request.method not in ("GET", "HEAD")  # refused if not a POST
        who = self.access.who(request)
        what = _what(request)
        try:
            refusal = self.access.refusal(request)
            if refusal is None and changing:
                refusal = change_refusal(request, proxied=self.access.from_proxy(request))
            if refusal is not None:
                raise ConfigChangeError(refusal.status, refusal.message)
            if not changing:
                return await self._read(request)
            if request.method != "POST":
                raise ConfigChangeError(HTTPStatus.METHOD_NOT_ALLOWED, "GET or POST only")
            changed, device = await self._change(request)
        except ConfirmationError as exc:
            names = ", ".join(e["name"] for e in exc.document["entities"]) or "no entity"
            log.info("web page: %s waits for its confirmation (%s): %s", what, who, names)
            return _answer(exc.status, {"status": "confirm", "error": str(exc), **exc.document})
        except ConfigChangeError as exc:
            if changing:
                log.warning("web page: %s refused (%s): %d %s", what, who, exc.status, exc)
            body = {"status": "error", "error": str(exc)} | ({"diff": exc.diff} if exc.diff else {})
            return _answer(exc.status, body)
        log.info("web page: %s (%s)", changed.line, who)
        applied = changed.applied
        return _answer(
            HTTPStatus.OK,
            {"status": "ok", "device": device, "summary": changed.summary}
            | {"changes": applied.get("changes", {}), "description": applied.get("description")},
        )

    # --- reading ----------------------------------------------------------------------

    async def _read(self, request: Request) -> Response:
        if request.path == PREFIX:
            store = await self.file.store()
            rows = [self._row(d) for d in self.bridge.loaded.config.devices]
            return _answer(HTTPStatus.OK, {"writable": store.writable, "devices": rows})
        device_id, action = _target(request.path)
        device = self._device(device_id)
        if action == "dangerous":
            return _answer(HTTPStatus.OK, self._dangerous(device))
        if action:
            raise ConfigChangeError(HTTPStatus.NOT_FOUND, "no such API")
        writable = (await self.file.store()).writable
        document = self._row(device) | {"dangerous": self._dangerous(device)}
        return _answer(HTTPStatus.OK, document | {"writable": writable})

    def _row(self, device: DeviceConfig) -> dict[str, Any]:
        serial = isinstance(self._bus(device.bus), SerialBus)
        return {
            "id": device.id,
            "name": device.name,
            "display_name": device.display_name,
            "bus": device.bus,
            "unit": device.unit,
            "max_unit": MAX_SERIAL_UNIT if serial else 255,
            "mapping": device.mapping,
            "enabled": device.enabled,
            "polled": device.id in self.bridge.engine.devices,
            "poll": {"fast": device.poll.fast, "slow": device.poll.slow},
            "allow_dangerous_writes": device.allow_dangerous_writes,
        }

    def _dangerous(self, device: DeviceConfig) -> dict[str, Any]:
        poller = self.bridge.engine.devices.get(device.id)
        loaded = self.bridge.loaded.mappings.get(device.id)
        mapping = poller.mapping if poller is not None else loaded
        return {
            "device": device.id,
            "allowed": device.allow_dangerous_writes,
            "entities": dangerous_entities(mapping, device.display_name),
            "raw_writes": self.bridge.loaded.config.bridge.allow_raw_writes,
        }

    # --- changing ---------------------------------------------------------------------

    async def _change(self, request: Request) -> tuple[Changed, str | None]:
        device_id, action = _target(request.path)
        device = self._device(device_id)
        if action == "remove":
            change = _change({"kind": "remove_device", "id": device_id})
            return await self.file.change(change), None
        if action:
            raise ConfigChangeError(HTTPStatus.NOT_FOUND, "no such API")
        edit = parse_edit(request.body)
        self._check_collisions(device, edit.fields)
        if edit.fields.get("allow_dangerous_writes") and not device.allow_dangerous_writes:
            self._check_confirmed(device, edit.fields, edit.confirmation)
        change = _change({"kind": "edit_device", "id": device_id, "set": edit.fields})
        return await self.file.change(change), edit.fields.get("id", device_id)

    def _check_confirmed(
        self, device: DeviceConfig, fields: dict[str, Any], token: str | None
    ) -> None:
        if self.confirmations.take(token, device.id, fields):
            return
        document = self._dangerous(device)
        document |= {"token": self.confirmations.issue(device.id, fields)}
        document |= {"expires_s": CONFIRM_FOR}
        again = "the confirmation expired or was for another change; " if token else ""
        message = (
            f"{again}confirm: dangerous writes on {device.display_name} let Home Assistant "
            "and MQTT write the entities listed"
        )
        raise ConfirmationError(message, document)

    def _check_collisions(self, device: DeviceConfig, fields: dict[str, Any]) -> None:
        """409 for an id another device has, or a unit another enabled device answers."""
        others = [d for d in self.bridge.loaded.config.devices if d.id != device.id]
        new_id = fields.get("id", device.id)
        if any(d.id == new_id for d in others):
            raise ConfigChangeError(HTTPStatus.CONFLICT, f"a device {new_id!r} exists already")
        unit = fields.get("unit", device.unit)
        if not fields.get("enabled", device.enabled):
            return
        for other in others:
            if other.enabled and other.bus == device.bus and other.unit == unit:
                raise ConfigChangeError(
                    HTTPStatus.CONFLICT, f"unit {unit} on bus {device.bus} is {other.id!r} already"
                )

    def _device(self, device_id: str) -> DeviceConfig:
        for device in self.bridge.loaded.config.devices:
            if device.id == device_id:
                return device
        raise ConfigChangeError(HTTPStatus.NOT_FOUND, "no such device")

    def _bus(self, bus_id: str) -> object:
        return next((b for b in self.bridge.loaded.config.buses if b.id == bus_id), None)


def _target(path: str) -> tuple[str, str]:
    """``<id>`` and what after it (``remove``, ``dangerous`` or nothing) of a path."""
    rest = path.removeprefix(PREFIX + "/")
    device_id, _, action = rest.partition("/")
    if not device_id or len(device_id) > MAX_ID:
        raise ConfigChangeError(HTTPStatus.NOT_FOUND, "no such device")
    return device_id, action


def _what(request: Request) -> str:
    """The request in the log: ``edit of device pump`` (bounded, printable)."""
    rest = request.path.removeprefix(PREFIX).strip("/")
    device_id, _, action = rest.partition("/")
    shown = "".join(c for c in device_id[:MAX_ID] if c.isprintable())
    verb = "removal" if action == "remove" else "edit"
    return f"{verb} of device {shown}" if shown else "device list"


def _change(data: dict[str, Any]) -> Any:
    try:
        return parse_change(data)
    except ConfigEditError as exc:
        where = f"{exc.field}: " if exc.field else ""
        raise ConfigChangeError(HTTPStatus.BAD_REQUEST, where + exc.message) from None


def _answer(status: HTTPStatus, document: dict[str, Any]) -> Response:
    return Response(status, json.dumps(document, default=str).encode("utf-8"), _JSON)
