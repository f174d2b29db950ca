"""The bus a request of the page's "Add a device" names: a configured bus by its id, or a
bus not configured yet, opened for that request only.

A new bus is given as a config's bus is, without its id: ``{"transport": "rtu", "port":
"/dev/serial/by-id/...", "baudrate": 9600, "parity": "N", "stopbits": 1}`` or
``{"transport": "tcp", "host": "10.0.0.7", "tcp_port": 502}``. It is checked as the
config checks a bus, then opened for the request and closed after it (``TemporaryBuses``):

- a serial port must be one the host lists (bridge/modbus/ports.py): no other file is
  opened as a serial line;
- a port or gateway a configured bus already uses is refused (naming that bus: the page
  picks it instead), so a request never opens a second connection beside the bridge's own;
- never two requests on one port or gateway at once, at most ``MAX_TEMPORARY`` new buses
  open at a time.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections.abc import AsyncIterator
from dataclasses import dataclass
from http import HTTPStatus
from typing import Any

from pydantic import TypeAdapter, ValidationError

from bridge.config import Bus, LoadedConfig, SerialBus, TcpBus
from bridge.core.mapping import format_validation_errors
from bridge.errors import BusError
from bridge.modbus.commission import open_scheduler
from bridge.modbus.engine import Engine
from bridge.modbus.ports import listed, same_port, serial_ports
from bridge.modbus.scheduler import BusScheduler

NEW_BUS = "new"  # the id a bus not configured yet has for the request
MAX_TEMPORARY = 2  # new buses open at a time
MAX_NEW_TIMEOUT = 5.0  # seconds a new bus waits for a reply at most
MAX_TEXT = 255  # characters of a port or host name
FIELDS = frozenset(
    {"transport", "port", "baudrate", "parity", "stopbits", "bytesize", "host", "tcp_port"}
    | {"timeout"}
)
_BUS: TypeAdapter[SerialBus | TcpBus] = TypeAdapter(Bus)


class AskError(Exception):
    """A request of the page refused: ``status`` and one line saying why."""

    def __init__(self, status: HTTPStatus, message: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True, slots=True)
class ChosenBus:
    """The bus a request runs on: configured (``scheduler`` set) or new (opened for it)."""

    bus: SerialBus | TcpBus
    scheduler: BusScheduler | None = None

    @property
    def configured(self) -> bool:
        return self.scheduler is not None


def new_bus(given: dict[str, Any]) -> SerialBus | TcpBus:
    """A new bus's settings checked as the config checks a bus; AskError (400) if not."""
    unknown = sorted(str(k)[:40] for k in given if k not in FIELDS)
    if unknown:
        raise AskError(HTTPStatus.BAD_REQUEST, f"bus: unknown fields {unknown}")
    for name in ("port", "host", "transport", "parity"):
        value = given.get(name)
        if isinstance(value, str) and len(value) > MAX_TEXT:
            raise AskError(HTTPStatus.BAD_REQUEST, f"bus.{name}: at most {MAX_TEXT} characters")
    timeout = given.get("timeout", 1.0)
    if not isinstance(timeout, int | float) or isinstance(timeout, bool):
        raise AskError(HTTPStatus.BAD_REQUEST, "bus.timeout: seconds, a number")
    if not 0 < timeout <= MAX_NEW_TIMEOUT:
        raise AskError(HTTPStatus.BAD_REQUEST, f"bus.timeout: 0 to {MAX_NEW_TIMEOUT:g} seconds")
    try:
        return _BUS.validate_python({**given, "id": NEW_BUS}, strict=False)
    except ValidationError as exc:
        rows = [f"bus.{row}" for row in format_validation_errors(exc)]
        raise AskError(HTTPStatus.BAD_REQUEST, "; ".join(rows[:5])) from None


class TemporaryBuses:
    """The buses the page opens for one request each; see the module."""

    def __init__(self) -> None:
        self._open: set[tuple[str, ...]] = set()  # ports and gateways in use by a request

    async def choose(self, given: object, loaded: LoadedConfig, engine: Engine) -> ChosenBus:
        """The bus ``given`` names: a configured bus id, or a new bus's settings."""
        if isinstance(given, str):
            scheduler = engine.schedulers.get(given)
            if scheduler is None:
                known = sorted(engine.schedulers)[:20]
                raise AskError(HTTPStatus.NOT_FOUND, f"bus: no bus {given[:40]!r} (have {known})")
            return ChosenBus(scheduler.transport.bus, scheduler)
        if not isinstance(given, dict):
            raise AskError(HTTPStatus.BAD_REQUEST, "bus: a configured bus's id, or a new bus")
        bus = new_bus(given)
        for configured in loaded.config.buses:
            if _same_line(bus, configured):
                raise AskError(
                    HTTPStatus.CONFLICT,
                    f"bus: bus {configured.id!r} uses this "
                    f"{'port' if isinstance(bus, SerialBus) else 'gateway'}: pick that bus",
                )
        if isinstance(bus, SerialBus):
            ports = await asyncio.to_thread(serial_ports)
            if not listed(bus.port, ports):
                shown = ", ".join(p.path for p in ports[:5]) or "none"
                raise AskError(
                    HTTPStatus.NOT_FOUND, f"bus.port: no serial port {bus.port!r} here ({shown})"
                )
        return ChosenBus(bus)

    def in_use(self, bus: SerialBus | TcpBus) -> bool:
        """Whether a request has this port or gateway open now."""
        return _line_key(bus) in self._open

    @contextlib.asynccontextmanager
    async def opened(self, chosen: ChosenBus) -> AsyncIterator[BusScheduler]:
        """The chosen bus's scheduler: a configured bus's own, or the new bus opened for
        the block and closed after it (AskError when busy or when it cannot be opened)."""
        if chosen.scheduler is not None:
            yield chosen.scheduler
            return
        key = _line_key(chosen.bus)
        if key in self._open:
            raise AskError(HTTPStatus.TOO_MANY_REQUESTS, "busy: another request uses this bus")
        if len(self._open) >= MAX_TEMPORARY:
            raise AskError(HTTPStatus.TOO_MANY_REQUESTS, "busy: two new buses are open already")
        self._open.add(key)
        try:
            async with open_scheduler(chosen.bus) as scheduler:
                yield scheduler
        except BusError as exc:
            raise AskError(HTTPStatus.BAD_GATEWAY, f"bus: {exc}") from None
        finally:
            self._open.discard(key)


def _same_line(new: SerialBus | TcpBus, configured: SerialBus | TcpBus) -> bool:
    if isinstance(new, SerialBus):
        return isinstance(configured, SerialBus) and same_port(new.port, configured.port)
    return (
        isinstance(configured, TcpBus)
        and new.host.lower() == configured.host.lower()
        and new.tcp_port == configured.tcp_port
    )


def _line_key(bus: SerialBus | TcpBus) -> tuple[str, ...]:
    if isinstance(bus, SerialBus):
        return ("serial", os.path.realpath(bus.port))
    return ("tcp", bus.host.lower(), str(bus.tcp_port))
