"""The page's routes: static files, the JSON API, the event stream, commissioning.

    GET  /  (also app.js, style.css)     the page: static files shipped in the wheel
    GET  api/overview                    devices, buses, MQTT link (bridge.web.views)
    GET  api/devices/<id>                one device and every published value
    GET  api/errors                      the last refused commands (``<device>/error``)
    GET  api/config                      the loaded config without secrets (as bridge/info)
    GET  api/events[?device=<id>]        Server-Sent Events: ``overview`` (at once, then at
                                         least every second), ``device`` (at once, with
                                         ?device), ``values`` (what changed on it),
                                         ``errors`` (at once, oldest first),
                                         ``refused`` (each refusal as it happens)
    POST api/login                       {"token": ...} -> the session cookie
    POST api/request/device/scan|identify|read|write   the management request of the same
                                         name, run by bridge/management.py with its limits
                                         and guards; answered like bridge/response/<cmd>
    GET  api/ports                       the host's serial ports, by-id names first
    GET  api/library[?q=...]             the shipped mappings, searched (bridge/web/library.py)
    POST api/add/scan|identify, api/trial   "Add a device" on a configured or a new bus
                                         (bridge/web/adding.py); each logged once: who, what
    POST api/config/devices              Save: the device (and its new bus) written to the
                                         config file and applied (bridge/web/saving.py)
    POST api/entity/preview|add          a raw register as a new entity of a device's
                                         mapping (bridge/web/entity.py)
    GET|POST api/config/devices/<id>...  edit or remove a configured device
                                         (bridge/web/device_edits.py)

Every ``api/`` route but ``login`` needs access (bridge/web/access.py); every POST must
come from the page itself. At most ``MAX_REQUESTS`` commissioning requests run at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from http import HTTPStatus
from importlib import resources
from typing import Any

from bridge import __version__
from bridge.modbus.ports import serial_ports
from bridge.web.access import Access, Refusal, change_refusal
from bridge.web.adding import Adding
from bridge.web.config_file import ConfigFile
from bridge.web.device_edits import DeviceEdits
from bridge.web.entity import ROUTES as ENTITY_ROUTES
from bridge.web.entity import EntityRoutes
from bridge.web.http import EventSink, EventStream, Request, Response
from bridge.web.library import QueryError, search, shipped_rows
from bridge.web.new_bus import AskError
from bridge.web.parts import BridgeState
from bridge.web.saving import SaveError, Saving
from bridge.web.views import BusWindow, changed_values, device_document, overview

MAX_REQUESTS = 4  # commissioning requests from the page running at once
OVERVIEW_EVERY = 1.0  # seconds between two overview events at most
OVERVIEW_GAP = 0.5  # ... and at least, when devices keep changing
SEND_GAP = 0.2  # an event stream sends at most this often (bursts are merged)
FRESH = 0.25  # seconds an overview (or a fetched device page) is served again as built
COMMISSIONING = frozenset({"device/scan", "device/identify", "device/read", "device/write"})
STATIC = {
    "/app.js": "text/javascript; charset=utf-8",
    "/add.js": "text/javascript; charset=utf-8",
    "/edit.js": "text/javascript; charset=utf-8",
    "/style.css": "text/css; charset=utf-8",
    "/entity.js": "text/javascript; charset=utf-8",
}
ADDING = {
    "/api/add/scan": "scan",
    "/api/add/identify": "identify",
    "/api/trial": "trial",
    "/api/config/devices": "save",
}
CATALOGUES = frozenset({"/api/ports", "/api/library"})
_INGRESS_PATH = re.compile(r"^(/[A-Za-z0-9_.~-]+)+$")
_JSON = "application/json"
log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class StaticFiles:
    """The page as shipped in the wheel: ``index.html`` and the files of ``STATIC``."""

    index: str
    files: dict[str, bytes]


def load_static() -> StaticFiles:
    folder = resources.files(__package__) / "static"
    index = (folder / "index.html").read_text(encoding="utf-8")
    return StaticFiles(index, {path: (folder / path[1:]).read_bytes() for path in STATIC})


class WebApp:
    """Answers the page's requests from the running bridge."""

    def __init__(self, bridge: BridgeState, access: Access, static: StaticFiles) -> None:
        self.bridge = bridge
        self.access = access
        self.static = static
        self.window = BusWindow()
        self.running = 0  # commissioning requests running
        self.adding = Adding(bridge)
        self.config_file = ConfigFile(bridge)  # the one writer of the config file
        self.edits = DeviceEdits(bridge, access, self.config_file)
        self.saving = Saving(bridge, self.adding.buses, self.config_file)
        self._built: dict[str, tuple[float, bytes]] = {}  # documents FRESH enough to reuse
        self.entities = EntityRoutes(bridge)

    async def handle(self, request: Request) -> Response | EventStream:
        path, method = request.path, request.method
        if not path.startswith("/api/"):
            if method not in ("GET", "HEAD"):
                return _error(HTTPStatus.METHOD_NOT_ALLOWED, "GET only")
            return self._static(request)
        if path == "/api/login":
            return self._login(request)
        if self.edits.serves(request):  # checks access itself: a refused change is logged
            return await self.edits.handle(request)
        refusal = self.access.refusal(request)
        if refusal is not None:
            return _error(refusal.status, refusal.message)
        if path.startswith("/api/request/"):
            return await self._request(request, path.removeprefix("/api/request/"))
        if path in ADDING:
            return await self._add(request, ADDING[path])
        if path in CATALOGUES and method == "GET":
            return await self._catalogue(request)
        if path in ENTITY_ROUTES:
            return await self._change(request, self.entities.handle)
        if method not in ("GET", "HEAD"):
            return _error(HTTPStatus.METHOD_NOT_ALLOWED, "GET only")
        return self._read(request)

    # --- the page ---------------------------------------------------------------------

    def _static(self, request: Request) -> Response:
        if request.path in ("/", "/index.html"):
            base = self._ingress_path(request) or "."
            html = self.static.index.replace('<base href="./">', f'<base href="{base}/">')
            return Response(200, html.encode("utf-8"), "text/html; charset=utf-8")
        if request.path in STATIC:
            return Response(200, self.static.files[request.path], STATIC[request.path])
        return _error(HTTPStatus.NOT_FOUND, "no such page")

    def _ingress_path(self, request: Request) -> str | None:
        """The page's path behind Home Assistant's ingress (``X-Ingress-Path``), taken only
        from the ingress proxy and only when it is a plain path."""
        base = request.headers.get("x-ingress-path", "")
        if not self.access.from_proxy(request) or not _INGRESS_PATH.match(base):
            return None
        return None if ".." in base else base

    def _login(self, request: Request) -> Response:
        if request.method != "POST":
            return _error(HTTPStatus.METHOD_NOT_ALLOWED, "POST only")
        refusal = change_refusal(request, proxied=self.access.from_proxy(request))
        if refusal is not None:
            return _error(refusal.status, refusal.message)
        given = _json_object(request.body).get("token")
        if not isinstance(given, str) or not self.access.login(given):
            return _error(HTTPStatus.UNAUTHORIZED, "wrong token")
        cookie = self.access.cookie_header(self._ingress_path(request) or "/")
        return Response(200, b'{"status": "ok"}', _JSON, (cookie,))

    # --- reading ----------------------------------------------------------------------

    def _read(self, request: Request) -> Response | EventStream:
        path = request.path
        if path == "/api/overview":
            return Response(200, self._fresh("overview", self.overview), _JSON)
        if path == "/api/errors":
            return _json(list(self.bridge.feed.recent))
        if path == "/api/config":
            info = self.bridge.management.info()
            return _json({k: v for k, v in info.items() if not k.endswith("_schema")})
        if path.startswith("/api/devices/"):
            device_id = path.removeprefix("/api/devices/")
            if device_id not in self.bridge.engine.devices:
                return _no_device()
            document = self._fresh(f"device:{device_id}", lambda: self.device(device_id))
            return Response(200, document, _JSON)
        if path == "/api/events":
            if request.method != "GET":
                return _error(HTTPStatus.METHOD_NOT_ALLOWED, "GET only")
            shown = request.query.get("device")
            if shown is not None and shown not in self.bridge.engine.devices:
                return _no_device()
            return EventStream(lambda sink: self._events(sink, shown))
        return _error(HTTPStatus.NOT_FOUND, "no such API")

    def _fresh(self, name: str, build: Callable[[], object]) -> bytes:
        """The JSON of ``build()``, built at most once per ``FRESH`` seconds: a hundred
        browsers cost one build, whatever they ask."""
        now = time.monotonic()
        built = self._built.get(name)
        if built is None or now - built[0] > FRESH:
            built = (now, json.dumps(build(), default=str).encode("utf-8"))
            self._built[name] = built
        return built[1]

    def overview(self) -> dict[str, Any]:
        bridge = self.bridge
        report = self.window.report(bridge.engine.snapshot())
        return overview(
            bridge.engine.devices.values(),
            report,
            version=__version__,
            mqtt=bridge.mqtt_state,
            subscriptions=bridge.mqtt_subscriptions,
            raw_writes=bridge.loaded.config.bridge.allow_raw_writes,
            refused=bridge.feed.refused,
            gateway=bridge.gateway.health() if bridge.gateway is not None else None,
        )

    def device(self, device_id: str) -> dict[str, Any] | None:
        poller = self.bridge.engine.devices.get(device_id)
        if poller is None:
            return None
        snapshot = self.bridge.engine.snapshot()
        health = self.window.report(snapshot)["devices"].get(device_id, {})
        return device_document(poller, health, self.bridge.topics.device(device_id))

    async def _events(self, sink: EventSink, device_id: str | None) -> None:
        """Everything at once, then what changes; an overview at least every second."""
        with self.bridge.feed.watch(device_id) as watcher:
            await sink.send("overview", self._fresh("overview", self.overview).decode())
            if device_id is not None:  # built now: no change after this one is missed
                await sink.send("device", json.dumps(self.device(device_id)))
            await sink.send("errors", json.dumps(list(self.bridge.feed.recent)))
            sent = time.monotonic()
            while True:
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(OVERVIEW_EVERY):
                        await watcher.wake.wait()
                keys, refusals, changed = watcher.take()
                poller = self.bridge.engine.devices.get(device_id or "")
                if keys and poller is not None:
                    await sink.send("values", json.dumps(changed_values(poller, keys)))
                for refusal in refusals:
                    await sink.send("refused", json.dumps(refusal))
                elapsed = time.monotonic() - sent
                if elapsed >= OVERVIEW_EVERY or (changed and elapsed >= OVERVIEW_GAP):
                    await sink.send("overview", self._fresh("overview", self.overview).decode())
                    sent = time.monotonic()
                await asyncio.sleep(SEND_GAP)

    async def _change(
        self, request: Request, run: Callable[[Request], Awaitable[Response]]
    ) -> Response:
        """A change from the page: a POST of JSON from the page itself, ``MAX_REQUESTS``
        at most running with the commissioning requests."""
        if request.method != "POST":
            return _error(HTTPStatus.METHOD_NOT_ALLOWED, "POST only")
        refusal = change_refusal(request, proxied=self.access.from_proxy(request))
        if refusal is not None:
            log.warning("change refused from %s: %s", request.peer, refusal.message)
            return _error(refusal.status, refusal.message)
        if self.running >= MAX_REQUESTS:
            return _error(HTTPStatus.TOO_MANY_REQUESTS, f"busy: {self.running} requests run")
        self.running += 1
        try:
            return await run(request)
        finally:
            self.running -= 1

    # --- commissioning ----------------------------------------------------------------

    async def _request(self, request: Request, command: str) -> Response:
        if request.method != "POST":
            return _error(HTTPStatus.METHOD_NOT_ALLOWED, "POST only")
        if command not in COMMISSIONING:
            return _error(HTTPStatus.NOT_FOUND, f"the page runs {', '.join(sorted(COMMISSIONING))}")
        refusal: Refusal | None = change_refusal(request, proxied=self.access.from_proxy(request))
        if refusal is not None:
            return _error(refusal.status, refusal.message)
        if self.running >= MAX_REQUESTS:
            return _error(HTTPStatus.TOO_MANY_REQUESTS, f"busy: {self.running} requests run")
        if command == "device/write":  # who wrote what, for the site's records
            log.info("raw write from the web page (%s): %s", request.peer, request.body[:300])
        self.running += 1
        try:
            answer = await self.bridge.management.handle(command, request.body)
        finally:
            self.running -= 1
        return Response(200, answer.encode("utf-8"), _JSON)

    # --- adding a device ------------------------------------------------------------------

    async def _catalogue(self, request: Request) -> Response:
        """The host's serial ports, or the library searched for ``q``."""
        if request.path == "/api/ports":
            ports = await asyncio.to_thread(serial_ports)
            return _json({"ports": [port.as_dict() for port in ports]})
        rows = await asyncio.to_thread(shipped_rows)  # loaded once, off the event loop
        try:
            return _json(search(rows, request.query.get("q", "")))
        except QueryError as exc:
            who = self.access.who(request)
            log.warning("web page: library search refused (%s): 400 %s", who, exc)
            return _error(HTTPStatus.BAD_REQUEST, str(exc))

    async def _add(self, request: Request, step: str) -> Response:
        """One step of "Add a device"; answered and logged once (who, what, or why not)."""
        who = self.access.who(request)
        try:
            data, said = await self._add_step(request, step)
        except AskError as exc:
            log.warning("web page: %s refused (%s): %d %s", step, who, exc.status, exc)
            more = {"diff": exc.diff} if isinstance(exc, SaveError) and exc.diff else {}
            return _error(exc.status, str(exc), **more)
        log.info("web page: %s (%s)", said, who)
        return _json({"status": "ok", "data": data})

    async def _add_step(self, request: Request, step: str) -> tuple[dict[str, Any], str]:
        if request.method != "POST":
            raise AskError(HTTPStatus.METHOD_NOT_ALLOWED, "POST only")
        refusal = change_refusal(request, proxied=self.access.from_proxy(request))
        if refusal is not None:
            raise AskError(refusal.status, refusal.message)
        if self.running >= MAX_REQUESTS:
            raise AskError(HTTPStatus.TOO_MANY_REQUESTS, f"busy: {self.running} requests run")
        self.running += 1
        try:
            work = {
                "scan": self.adding.scan,
                "identify": self.adding.identify,
                "trial": self.adding.trial,
                "save": self.saving.add_device,
            }
            return await work[step](request.body)
        finally:
            self.running -= 1


def _json(document: object) -> Response:
    return Response(200, json.dumps(document, default=str).encode("utf-8"), _JSON)


def _error(status: HTTPStatus, message: str, **more: str) -> Response:
    body = json.dumps({"status": "error", "error": message, **more}).encode("utf-8")
    return Response(status, body, _JSON)


def _no_device() -> Response:
    return _error(HTTPStatus.NOT_FOUND, "no such device")


def _json_object(body: bytes) -> dict[str, Any]:
    try:
        document = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        return {}
    return document if isinstance(document, dict) else {}
