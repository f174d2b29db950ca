"""The gateway: other Modbus masters read and write the bridge's buses through its Modbus
TCP server (bridge/modbus/gateway_server.py), between the bridge's own polls.

``Gateway.answer(client, request)`` decides every request (the pure rules are
bridge/core/gateway.py, and what a write's words mean bridge/core/gateway_writes.py):

- its unit must be in ``bridge.gateway.units`` (else 0x0A); a configured device that is
  offline answers 0x0B at once, without a frame (the poller brings it back);
- a read goes through the bus scheduler at ``Priority.PROXY`` (after commands and reads
  on request; against the bridge's due polls the fair share decides, bridge/core/
  fair_share.py, so masters never starve the polls of a slow device), split into the
  device's read limits and joined as ``device/read`` does; a read still waiting for the
  bus after ``max_wait`` (by default twice the bus timeout, plus the device's own time
  between requests) answers 0x06 (busy) rather
  than making its master wait on (0x0B when its unit rests after not answering);
  with ``max_age`` (the server's, or the device's ``gateway_max_age``) a read whose
  words the bridge read or wrote within that age is answered from its image without a
  frame. What a proxied read returns goes into the
  device's image too.
- a write needs ``allow_writes`` (else 0x01) and a configured device. The words are turned
  into the values of the entities they write (every word of each entity, else 0x03) and
  run as one MQTT command would (``Dispatcher.write_for``: after the device's waiting
  commands, the offline check and the command expiry; then the writer's checks: writable,
  type, range, enum, the dangerous-write guard, EEPROM spacing, a password lock), read
  back and published; words that mean no value the entity is set to by exactly those
  words (a NaN, a sentinel, an enum code without a label) answer 0x03. Words no writable
  entity covers are refused (0x01) unless the device sets ``gateway_raw_writes``; then
  they go raw under the rule of raw writes (bridge/core/reach.py ``check_raw_write``: the
  guard of every device that may answer the unit, ``allow_dangerous_writes``), never to
  the register that locks a device whose password the bridge holds, and never together
  with an entity's words (0x01). A refusal never reaches the bus.
- a read of a secret or write-only register (a password) of any device that may answer
  the unit answers 0x02 (illegal data address: what a device answers for an address it
  does not serve), from the bus and from the image alike, unless
  ``bridge.allow_raw_writes`` permits raw reads of them (the rule of raw reads,
  ``check_raw_read``).
- at most ``max_queued_per_bus`` gateway requests wait per bus; more answer 0x06.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections import Counter
from collections.abc import AsyncIterator, Callable
from typing import Any

from bridge.config import GatewayConfig, LoadedConfig, TcpBus
from bridge.core.address import to_wire
from bridge.core.entity import Table
from bridge.core.gateway import (
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    ClientBook,
    ClientCounters,
    Code,
    ProxyRequest,
    Route,
    cached_words,
    check_request,
    code_for,
)
from bridge.core.gateway_writes import GatewayRefusalError, items_of
from bridge.core.management_request import RequestError
from bridge.core.reach import check_raw_read, check_raw_write
from bridge.core.request import Read, Write
from bridge.dispatcher import Dispatcher
from bridge.errors import BridgeError, CommandExpiredError, ValueRejectedError
from bridge.management import reach_at
from bridge.modbus.commission import Submit, read_in_parts
from bridge.modbus.engine import Engine
from bridge.modbus.gateway_server import GatewayServer, Limits
from bridge.modbus.poller import DevicePoller
from bridge.modbus.scheduler import BusScheduler, Priority

log = logging.getLogger(__name__)
Cell = tuple[Table, int]
MASKED = "***"  # what the log shows for the value of a secret register


class Gateway:
    """Answers the requests of other masters for one bridge."""

    def __init__(self, loaded: LoadedConfig, engine: Engine, dispatcher: Dispatcher) -> None:
        self.loaded = loaded
        self.settings: GatewayConfig = loaded.config.bridge.gateway
        self.engine = engine
        self.dispatcher = dispatcher
        self.expiry = loaded.config.mqtt.command_expiry
        self.book = ClientBook()
        self.routes = routes_of(loaded)
        self.waiting: Counter[str] = Counter()  # gateway requests waiting or running, per bus
        self.transactions: Counter[str] = Counter()  # bus transactions they took, per bus
        self.server = GatewayServer(
            self.settings.host,
            self.settings.port,
            self.answer,
            Limits(
                self.settings.max_clients,
                self.settings.max_queued_per_client,
                self.settings.idle_timeout,
            ),
            self.book,
        )

    async def run(self) -> None:
        """Serve until cancelled (nothing when the gateway is off)."""
        if self.settings.enabled:
            await self.server.run()

    async def answer(self, client: ClientCounters, request: ProxyRequest) -> tuple[int, ...] | int:
        """The values (a write: those written) or the exception code; never raises."""
        try:
            code = check_request(request)
            if code is not None:
                raise GatewayRefusalError(
                    code, f"FC{request.function:02d} {request.address}+{request.count}"
                )
            route = self.routes.get(request.unit)
            if route is None:
                raise GatewayRefusalError(
                    Code.PATH_UNAVAILABLE, f"unit {request.unit} is not served"
                )
            if request.is_write:
                values = await self._write(route, request)
            else:
                read = request.read()
                self._check_read(route, read)
                values = await self._read(client, route, read)
        except GatewayRefusalError as refusal:
            client.refused += 1
            if request.is_write:
                self._refused(request, refusal)
            return int(refusal.code)
        except ValueRejectedError as rejected:  # the writer's checks: nothing was sent
            client.refused += 1
            self._refused(request, rejected)
            return code_for(rejected)
        except CommandExpiredError as expired:  # waited past the bus timeout, never sent
            client.busy += 1
            return code_for(expired)
        except BridgeError as error:
            client.failed += 1
            return code_for(error)
        client.served += 1
        return values

    # --- reads ---------------------------------------------------------------------------

    def _check_read(self, route: Route, read: Read) -> None:
        """0x02 for a read of a secret or write-only cell of any device that may answer the
        route's unit, from the bus or the image alike, unless ``bridge.allow_raw_writes``
        (the rule of raw reads: bridge/core/reach.py)."""
        reach = reach_at(self.loaded, self.engine, route.bus, route.unit)
        allowed = self.loaded.config.bridge.allow_raw_writes
        try:
            check_raw_read(reach, read, secrets_allowed=allowed)
        except RequestError as hidden:
            raise GatewayRefusalError(Code.ILLEGAL_ADDRESS, str(hidden)) from None

    async def _read(self, client: ClientCounters, route: Route, read: Read) -> tuple[int, ...]:
        poller = self._device(route)
        scheduler = self.engine.schedulers[route.bus]
        bus_timeout = scheduler.transport.bus.timeout
        pacing = poller.protocol.min_request_interval if poller is not None else 0.0
        # then 0x06, not a longer wait; the device's own pacing is no busy bus
        wait = self.settings.max_wait or 2 * bus_timeout + pacing

        def delayed() -> None:
            client.delayed += 1

        if poller is None:
            limit = MAX_READ_BITS if read.table.is_bits else MAX_READ_REGISTERS
            submit = _bus_submit(scheduler, wait, delayed)
            timeout = bus_timeout
        else:
            state = poller.state
            max_age = poller.device.gateway_max_age
            age = self.settings.max_age if max_age is None else max_age
            cached = cached_words(read, state.image, state.read_at, time.monotonic(), age)
            if cached is not None:
                client.cached += 1
                return cached
            limit = state.limits().max_count(read.table)
            submit = _device_submit(poller, wait, delayed)
            timeout = poller.link.timeout
        async with self._slot(route.bus):
            values, requests, _ = await read_in_parts(submit, route.unit, read, timeout, limit)
        self.transactions[route.bus] += requests
        if poller is not None:
            poller.link.keep(read, values, set())
        return values

    # --- writes --------------------------------------------------------------------------

    async def _write(self, route: Route, request: ProxyRequest) -> tuple[int, ...]:
        if not self.settings.allow_writes:
            raise GatewayRefusalError(
                Code.ILLEGAL_FUNCTION, "writes are off (bridge.gateway.allow_writes)"
            )
        poller = self._device(route)
        if poller is None:
            raise GatewayRefusalError(
                Code.ILLEGAL_FUNCTION, f"unit {request.unit}: writes go to configured devices only"
            )
        items = items_of(poller.points.values(), poller.state.image, request)
        deadline = time.monotonic() + self.expiry
        device_id = poller.device.id
        async with self._slot(route.bus):
            if items is None:
                write = self._raw(poller, request)
                await poller.link.submit(write, Priority.WRITE, deadline=deadline)
                poller.state.store(write)
                shown = MASKED if _hidden(poller, request) else write
                log.info("gateway: %s: raw %s written", device_id, shown)
            else:
                done = await self.dispatcher.write_for(device_id, items, deadline)
                secret = {k for k in done if poller.points[k].entity.secret}
                log.info(
                    "gateway: %s: %s written",
                    device_id,
                    {k: MASKED if k in secret else v for k, v in done.items()},
                )
        self.transactions[route.bus] += 1
        return request.values

    def _raw(self, poller: DevicePoller, request: ProxyRequest) -> Write:
        """A write of words no entity covers, where the device allows it, unguarded."""
        device = poller.device
        if not device.gateway_raw_writes:
            raise GatewayRefusalError(
                Code.ILLEGAL_FUNCTION,
                f"{device.id}: {request.table.value} {request.address}+{request.count} is "
                "not mapped as writable; set gateway_raw_writes: true for the device to permit it",
            )
        write = request.write(poller.protocol.coil_on_value)
        unlock = poller.protocol.unlock
        if unlock is not None and unlock.lock is not None and device.has_password:
            lock = to_wire(unlock.lock, poller.protocol.addressing)
            if write.table is Table.HOLDING and lock in range(
                write.address, write.address + request.count
            ):
                raise GatewayRefusalError(
                    Code.ILLEGAL_FUNCTION,
                    f"{device.id}: register {lock} locks the device, which the bridge unlocks "
                    "again with the password in its config",
                )
        bus = self.engine.schedulers[device.bus].transport.bus
        raw_units = bus.raw_units if isinstance(bus, TcpBus) else ()
        reach = reach_at(self.loaded, self.engine, device.bus, device.unit)
        try:  # the rule of raw writes: every device that may answer the unit, its guard
            check_raw_write(reach, write, raw_units)
        except RequestError as refused:
            raise GatewayRefusalError(Code.ILLEGAL_FUNCTION, str(refused)) from None
        return write

    # --- shared --------------------------------------------------------------------------

    def _refused(self, request: ProxyRequest, refusal: BridgeError) -> None:
        """Log a refused write; without its reason when it writes a secret register (the
        reason may quote the value: a password tried)."""
        route = self.routes.get(request.unit)
        poller = self._device(route) if route is not None else None
        reason = str(refusal)
        if poller is not None and _hidden(poller, request):
            reason = "a write of secret registers (the reason may quote the value: not logged)"
        log.info("gateway: unit %d: write refused: %s", request.unit, reason)

    def _device(self, route: Route) -> DevicePoller | None:
        return self.engine.devices.get(route.device) if route.device is not None else None

    @contextlib.asynccontextmanager
    async def _slot(self, bus: str) -> AsyncIterator[None]:
        if self.waiting[bus] >= self.settings.max_queued_per_bus:
            raise GatewayRefusalError(
                Code.BUSY, f"{self.waiting[bus]} gateway requests wait for bus {bus}"
            )
        self.waiting[bus] += 1
        try:
            yield
        finally:
            self.waiting[bus] -= 1

    def health(self) -> dict[str, Any]:
        """The gateway's part of ``<base>/bridge/health``."""
        return {
            "enabled": self.settings.enabled,
            "port": self.server.port,
            "clients": {peer: c.as_dict() for peer, c in self.book.clients.items()},
            "total": self.book.totals().as_dict(),
            "bus_transactions": dict(self.transactions),
        }


def _hidden(poller: DevicePoller, request: ProxyRequest) -> bool:
    """The request writes a secret or write-only register of the device (a password)."""
    return bool(poller.guard.hidden_in(request.table, request.address, request.count))


def routes_of(loaded: LoadedConfig) -> dict[int, Route]:
    """Every gateway unit with its bus, unit and configured device (if any)."""
    config = loaded.config
    devices = {d.id: d for d in config.devices}
    routes: dict[int, Route] = {}
    for unit, target in config.bridge.gateway.units.items():
        if isinstance(target, str):
            device = devices[target]
            routes[unit] = Route(device.bus, device.unit, device.id)
            continue
        there = next(
            (
                d.id
                for d in config.devices
                if d.enabled and (d.bus, d.unit) == (target.bus, target.unit)
            ),
            None,
        )
        routes[unit] = Route(target.bus, target.unit, there)
    return routes


def _bus_submit(scheduler: BusScheduler, wait: float, delayed: Callable[[], None]) -> Submit:
    """Reads of a unit no configured device answers, straight through the bus scheduler;
    each part sent within ``wait`` seconds, or ended unsent (0x06)."""

    async def submit(unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        return await scheduler.submit(
            unit,
            request,
            timeout=timeout,
            priority=Priority.PROXY,
            deadline=time.monotonic() + wait,
            yielded=delayed,
        )

    return submit


def _device_submit(poller: DevicePoller, wait: float, delayed: Callable[[], None]) -> Submit:
    """Reads through the device's link (its unlock, its health), after commands; each
    part sent within ``wait`` seconds, or ended unsent (0x06)."""

    async def submit(unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        del unit, timeout  # the device's own
        if poller.health.online is False:
            raise GatewayRefusalError(Code.TARGET_NO_RESPONSE, f"{poller.device.id} is offline")
        if not isinstance(request, Read):
            raise TypeError("a gateway read")
        return await poller.link.proxy(request, time.monotonic() + wait, delayed)

    return submit
