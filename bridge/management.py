"""The management API: ``<base>/bridge/request/<cmd>`` run against the live engine.

``Management.handle(command, payload)`` validates a request (bridge/core/management_request.py)
and answers with the JSON of ``<base>/bridge/response/<cmd>``; nothing reaches a bus
unless the request is valid. Raw reads, writes and scans go through the bus's own
scheduler, so they never collide with polling: reads and writes queue ahead of polls,
scan probes queue with them (a scan of a busy bus does not stop its devices' polling).
``info()`` is the retained ``<base>/bridge/info`` document.

Limits, checked before anything is queued: one scan per bus at a time and ``MAX_RAW``
raw reads or writes waiting per bus (more are answered "busy"); unit 0 (broadcast) is
never addressed, serial lines only 1..247. Registers a device's mapping guards stay
guarded for raw access too, whatever unit a request names (bridge/core/reach.py): the
guards of every configured device that may answer the unit apply (on a TCP bus a gateway,
or a device that ignores the unit id, answers 255 and units no device is configured at as
any device there). A raw write to a dangerous register needs that device's
``allow_dangerous_writes``, a raw read of a secret or write-only one
``bridge.allow_raw_writes``; on a TCP bus a raw write to a unit no device is configured at
needs the bus's ``raw_units`` to name it. A mapping switch (``mapping/reload`` with
``mapping``) needs ``bridge.mapping_switch`` and takes only shipped names or files under
``bridge.mapping_dirs``; a refused path is answered without a word about the file.
"""

from __future__ import annotations

import asyncio
import functools
from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any

from bridge import __version__
from bridge.config import (
    DeviceConfig,
    LoadedConfig,
    SerialBus,
    TcpBus,
    config_schema,
    load_device_mapping,
)
from bridge.core.guard import Guard
from bridge.core.instance import Instance
from bridge.core.management_request import (
    MAX_UNIT,
    REQUESTS,
    DeviceIdentify,
    DeviceRead,
    DeviceScan,
    DeviceWrite,
    HealthCheck,
    MappingReload,
    Request,
    RequestError,
    Target,
    Transaction,
    parse_request,
    response,
)
from bridge.core.mapping import (
    Mapping,
    builtin_mapping_names,
    mapping_schema,
    shipped_library,
)
from bridge.core.reach import Neighbour, Reach, check_raw_read, check_raw_write, reach_of
from bridge.errors import BridgeError, ModbusError
from bridge.modbus.commission import (
    explain,
    raw_read,
    raw_write,
    read_interpreted,
    scan,
    scheduler_submit,
)
from bridge.modbus.engine import Engine
from bridge.modbus.identify import identify, request_bound
from bridge.modbus.poller import DevicePoller
from bridge.modbus.scheduler import BusScheduler, Priority
from bridge.sunspec_devices import SunSpecDevices

Reloaded = Callable[[list[str]], Awaitable[None]]
MAX_RAW = 2  # raw reads and writes waiting per bus; more are answered "busy"
REFUSED_MAPPING = "mapping: not a shipped mapping name, nor a .yaml file under bridge.mapping_dirs"


class Management:
    """Runs management requests for one bridge."""

    def __init__(
        self,
        loaded: LoadedConfig,
        engine: Engine,
        *,
        on_reload: Reloaded,
        mqtt_state: Callable[[], str],
        instance: Instance | None = None,
    ) -> None:
        self.loaded = loaded
        self.engine = engine
        self.settings = loaded.config.bridge
        self._on_reload = on_reload
        self._mqtt_state = mqtt_state
        self.instance = instance  # this run, named in info and health checks
        self.reloading = asyncio.Lock()  # one reload at a time (and one config applied live)
        # the mapping: sunspec devices' walks, run beside the engine's polls
        self.sunspec = SunSpecDevices(loaded, engine, swap=self.swap_mapping)
        engine.companions.append(self.sunspec.run)
        self._scanning: set[str] = set()  # buses with a scan running
        self._raw: Counter[str] = Counter()  # raw requests waiting or running, per bus

    async def handle(self, command: str, payload: bytes) -> str:
        """The response JSON for one request (never raises for a bad request)."""
        transaction: Transaction = None
        try:
            request = parse_request(command, payload)
            transaction = request.transaction
            data = await self._run(request)
        except RequestError as exc:
            return response(error=str(exc), transaction=exc.transaction or transaction)
        except ModbusError as exc:
            unit = getattr(request, "unit", None)
            message = explain(unit, exc) if isinstance(unit, int) else str(exc)
            return response(error=message, transaction=transaction)
        except BridgeError as exc:
            return response(error=str(exc), transaction=transaction)
        return response(data, transaction=transaction)

    async def _run(self, request: Request) -> Any:
        if isinstance(request, DeviceRead):
            return await self._read(request)
        if isinstance(request, DeviceWrite):
            return await self._write(request)
        if isinstance(request, DeviceScan):
            return await self._scan(request)
        if isinstance(request, DeviceIdentify):
            return await self._identify(request)
        if isinstance(request, MappingReload):
            return await self._reload(request)
        if isinstance(request, HealthCheck):
            return self.health_check()
        raise RequestError(f"no handler for {type(request).__name__}")  # pragma: no cover

    # --- raw access ---------------------------------------------------------------------

    def _target(self, request: Target) -> tuple[BusScheduler, int, float]:
        """The scheduler, unit and timeout a request addresses."""
        if request.device is not None:
            poller = self.engine.devices.get(request.device)
            if poller is None:
                raise RequestError(f"device: no device {request.device!r}")
            scheduler, unit = poller.scheduler, poller.device.unit
        else:
            scheduler, unit = self._bus(request.bus), request.unit or 0  # validated: given
        bus = scheduler.transport.bus
        if isinstance(bus, SerialBus) and unit > MAX_UNIT:
            raise RequestError(f"unit: serial lines address units 1..{MAX_UNIT}")
        return scheduler, unit, request.timeout or bus.timeout

    def _device_at(self, scheduler: BusScheduler, unit: int) -> DevicePoller | None:
        """The configured device answering as ``unit`` on that bus, if any."""
        for poller in self.engine.devices.values():
            if poller.scheduler is scheduler and poller.device.unit == unit:
                return poller
        return None

    @asynccontextmanager
    async def _raw_slot(self, scheduler: BusScheduler) -> AsyncIterator[None]:
        """One of the ``MAX_RAW`` places for raw requests on a bus, or "busy"."""
        bus_id = scheduler.bus_id
        if self._raw[bus_id] >= MAX_RAW:
            raise RequestError(f"busy: {self._raw[bus_id]} raw requests wait for bus {bus_id}")
        self._raw[bus_id] += 1
        try:
            yield
        finally:
            self._raw[bus_id] -= 1

    @asynccontextmanager
    async def _scan_slot(self, scheduler: BusScheduler) -> AsyncIterator[None]:
        """The bus's one place for a scan or an identify, or "busy"."""
        if scheduler.bus_id in self._scanning:
            raise RequestError(f"busy: a scan of bus {scheduler.bus_id} is running")
        self._scanning.add(scheduler.bus_id)
        try:
            yield
        finally:
            self._scanning.discard(scheduler.bus_id)

    def _bus(self, bus_id: str | None) -> BusScheduler:
        schedulers = self.engine.schedulers
        if bus_id is None:
            if len(schedulers) != 1:
                raise RequestError(f"bus: name one of {sorted(schedulers)}")
            return next(iter(schedulers.values()))
        if bus_id not in schedulers:
            raise RequestError(f"bus: no bus {bus_id!r} (have {sorted(schedulers)})")
        return schedulers[bus_id]

    def _reach(self, scheduler: BusScheduler, unit: int) -> Reach:
        return reach_at(self.loaded, self.engine, scheduler.bus_id, unit)

    async def _read(self, request: DeviceRead) -> dict[str, Any]:
        scheduler, unit, timeout = self._target(request)
        read = raw_read(request.table, request.address, request.count)
        reach = self._reach(scheduler, unit)
        check_raw_read(reach, read, secrets_allowed=self.settings.allow_raw_writes)
        device = self._device_at(scheduler, unit)
        limit = device.limits().max_count(read.table) if device is not None else None
        async with self._raw_slot(scheduler):
            reading = await read_interpreted(
                scheduler_submit(scheduler), unit, read, timeout, limit=limit
            )
        return {"bus": scheduler.bus_id, **reading}

    async def _write(self, request: DeviceWrite) -> dict[str, Any]:
        if not self.settings.allow_raw_writes:
            raise RequestError(
                "raw writes are off: set bridge.allow_raw_writes: true in the config"
            )
        scheduler, unit, timeout = self._target(request)
        write = raw_write(request.table, request.address, request.values)
        bus = scheduler.transport.bus
        raw_units = bus.raw_units if isinstance(bus, TcpBus) else ()
        check_raw_write(self._reach(scheduler, unit), write, raw_units)
        async with self._raw_slot(scheduler):
            await scheduler_submit(scheduler, Priority.WRITE)(unit, write, timeout)
        return {
            "bus": scheduler.bus_id,
            "unit": unit,
            "table": request.table,
            "address": request.address,
            "function": write.function,
            "values": list(request.values),
        }

    async def _scan(self, request: DeviceScan) -> dict[str, Any]:
        scheduler = self._bus(request.bus)
        units = request.unit_ids()
        timeout = request.timeout or self.settings.scan_timeout
        known = {
            p.device.unit: device_id
            for device_id, p in self.engine.devices.items()
            if p.scheduler is scheduler
        }
        async with self._scan_slot(scheduler):
            found = await scan(scheduler_submit(scheduler, Priority.POLL), units, timeout)
        return {
            "bus": scheduler.bus_id,
            "probed": len(units),
            "found": [
                {
                    "unit": f.unit,
                    "answer": f.answer.value,
                    "exception_code": f.exception_code,
                    "detail": f.detail,
                    "latency_ms": round(f.latency * 1000, 1),
                    "device": known.get(f.unit),
                }
                for f in found
            ],
        }

    async def _identify(self, request: DeviceIdentify) -> dict[str, Any]:
        """``identify`` (bridge/modbus/identify.py) through the bus's scheduler, with the
        polls, one scan or identify per bus at a time: ``timeout`` for each unit's first
        answer, the bus's for the reads after. Only scores are answered, not values read."""
        scheduler = self._bus(request.bus)
        units = request.unit_ids()
        timeout = request.timeout or self.settings.scan_timeout
        library = await asyncio.to_thread(shipped_library)
        wait = scheduler.transport.bus.timeout
        async with self._scan_slot(scheduler):
            submit = scheduler_submit(scheduler, Priority.POLL)
            found = await identify(
                submit, units, library, timeout, scheduler.bus_id, read_timeout=wait
            )
        return {
            "bus": scheduler.bus_id,
            "probed": len(units),
            "max_requests_per_unit": request_bound(library),
            "found": [identity.as_dict() for identity in found],
        }

    # --- mappings -------------------------------------------------------------------------

    async def _reload(self, request: MappingReload) -> dict[str, Any]:
        devices = self.engine.devices
        wanted = request.devices if request.devices is not None else list(devices)
        unknown = [d for d in wanted if d not in devices]
        if unknown:
            raise RequestError(f"devices: no such devices {unknown}")
        if request.rewalk:
            return await self.sunspec.rewalk_many(wanted if request.devices is not None else None)
        settings = {d: devices[d].device for d in wanted}
        if request.mapping is not None:  # one device switches to another mapping
            (device_id,) = wanted
            settings[device_id] = settings[device_id].model_copy(
                update={"mapping": self._switch_to(request.mapping)}
            )
        async with self.reloading:
            # all or nothing: errors change nothing; files are read off the event loop
            fresh = await asyncio.to_thread(self._load_mappings, settings)
            # like with like: the file as loaded now against the file as loaded before (a
            # poller's mapping carries the device's protocol overrides); an unchanged device
            # keeps its poller, values, learnt refusals and health counters
            changed = [
                d
                for d in wanted
                if fresh[d] != self.loaded.mappings.get(d) or settings[d] != devices[d].device
            ]
            for device_id in changed:
                await self._replace(device_id, fresh[device_id], settings[device_id])
            if changed:
                await self._on_reload(changed)
        return {"reloaded": wanted, "changed": changed}

    async def swap_mapping(self, device_id: str, mapping: Mapping) -> None:
        """Poll a device with another mapping from now on, as a reload does (its poller
        afresh, discovery and state again): a SunSpec device's built mapping."""
        async with self.reloading:
            await self._replace(device_id, mapping, self.engine.device(device_id).device)
            await self._on_reload([device_id])

    async def _replace(self, device_id: str, mapping: Mapping, device: DeviceConfig) -> None:
        await self.engine.replace_mapping(device_id, mapping, device)
        self.loaded.mappings[device_id] = mapping

    def _switch_to(self, mapping: str) -> str:
        """The mapping a switch may load: a shipped name, or the resolved path of a .yaml
        file under ``bridge.mapping_dirs`` (symbolic links followed); else one answer that
        says nothing about the file."""
        if not self.settings.mapping_switch:
            raise RequestError(
                "mapping switches are off: set bridge.mapping_switch: true in the config"
            )
        if mapping in builtin_mapping_names():
            return mapping
        base = self.loaded.path.parent
        try:
            path = (base / mapping).resolve()
            folders = [(base / folder).resolve() for folder in self.settings.mapping_dirs]
        except (OSError, ValueError):  # a NUL byte, a symlink loop
            raise RequestError(REFUSED_MAPPING) from None
        if path.suffix in (".yaml", ".yml") and any(path.is_relative_to(f) for f in folders):
            return str(path)
        raise RequestError(REFUSED_MAPPING)

    def _load_mappings(self, settings: dict[str, DeviceConfig]) -> dict[str, Mapping]:
        """The mapping of each device read again, checked as ``check`` checks a config."""
        loaded: dict[str, Mapping] = {}
        errors: list[str] = []
        for device_id, device in settings.items():
            if device.is_sunspec:  # built from its chain: kept (a rewalk builds it again)
                loaded[device_id] = self.loaded.mappings[device_id]
                continue
            bus = self.engine.schedulers[device.bus].transport.bus
            base = self.loaded.path.parent
            mapping, problems = load_device_mapping(
                device, bus, base, state_dir=base / self.settings.state_dir
            )
            errors += problems
            if mapping is not None:
                loaded[device_id] = mapping
        if errors:
            raise RequestError("nothing reloaded: " + "; ".join(errors))
        return loaded

    # --- state of the bridge --------------------------------------------------------------

    def health_check(self) -> dict[str, Any]:
        """Healthy while MQTT is up and no bus is down; offline devices are listed."""
        snapshot = self.engine.snapshot()
        down = [b.bus_id for b in snapshot.buses if not b.connected and b.requests]
        online = [d for d, p in self.engine.devices.items() if p.health.online]
        offline = [d for d, p in self.engine.devices.items() if p.health.online is False]
        return {
            "healthy": self._mqtt_state() == "online" and not down,
            "mqtt": self._mqtt_state(),
            "buses_down": down,
            "devices_online": online,
            "devices_offline": offline,
            "uptime_s": round(snapshot.uptime, 1),
            **self._instance(),
        }

    def info(self) -> dict[str, Any]:
        """``<base>/bridge/info``: version, the config without secrets, schemas, mappings."""
        config = self.loaded.config
        in_use = {
            device_id: {
                "mapping": p.device.mapping,
                "manufacturer": p.mapping.manufacturer,
                "model": p.mapping.model,
                "entities": len(p.points),
            }
            for device_id, p in self.engine.devices.items()
        }
        return {
            "version": __version__,
            "config_file": str(self.loaded.path),
            "config": config.model_dump(mode="json"),
            "mappings": {"shipped": builtin_mapping_names(), "in_use": in_use},
            "requests": sorted(REQUESTS),
            "raw_writes": self.settings.allow_raw_writes,
            **self._instance(),
            **_schemas(),
        }

    def _instance(self) -> dict[str, Any]:
        return {"instance": self.instance.document()} if self.instance is not None else {}


@functools.cache
def _schemas() -> dict[str, Any]:
    """The config and mapping JSON schemas (built once: about 12 ms each)."""
    return {"config_schema": config_schema(), "mapping_schema": mapping_schema()}


def reach_at(loaded: LoadedConfig, engine: Engine, bus_id: str, unit: int) -> Reach:
    """The configured devices (disabled ones too: they are wired) that may answer ``unit``
    on bus ``bus_id``, each with its guard (bridge/core/reach.py); raw requests and the
    Modbus TCP gateway (bridge/gateway.py) check their reads and writes against it."""
    bus = engine.schedulers[bus_id].transport.bus
    neighbours = []
    for configured in loaded.config.devices:
        if configured.bus != bus.id:
            continue
        poller = engine.devices.get(configured.id)
        if poller is not None:  # its guard holds what earlier mappings guarded too
            device, guard = poller.device, poller.guard
        else:  # and what it guarded while it was polled in this run, if it was
            device = configured
            guard = _guard_of(device, loaded.mappings[device.id])
            guard |= engine.retired.get(device.id, guard)
        neighbours.append(Neighbour(device.id, device.unit, guard, device.allow_dangerous_writes))
    return reach_of(bus.id, unit, neighbours, tcp=isinstance(bus, TcpBus))


def _guard_of(device: DeviceConfig, mapping: Mapping) -> Guard:
    """The guard of a device the engine does not poll (disabled), from its mapping."""
    options = tuple(sorted((mapping.default_options() | device.options).items()))
    return mapping.memo(
        ("guard", options), lambda: Guard.of(mapping.points(device.options).values())
    )
