"""The Modbus side of the bridge: one scheduler per bus, one poller per device, one TaskGroup.

``Engine(loaded_config, on_update).run()`` polls every enabled device until cancelled;
``engine.write(device_id, key, value)`` and ``engine.read_now(device_id, keys)`` are what
the MQTT side calls for commands; ``engine.snapshot()`` copies every counter for health
reports and metrics. Buses are independent: a dead port or a dead unit on one bus never
touches another bus.

While it runs, a config applied live (bridge/reconfigure.py) changes it piece by piece:
``add_bus``, ``restart_bus``, ``remove_bus``, ``add_device``, ``remove_device`` and
``replace_mapping`` (a device's settings or mapping); the other buses and devices carry on
untouched.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Coroutine, Iterable
from typing import Any

from bridge.config import DeviceConfig, LoadedConfig, SerialBus, TcpBus
from bridge.core.codec import Value
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.health import Fault, HealthPolicy
from bridge.core.health_report import BusSnapshot, DeviceSnapshot, Snapshot, WriteSnapshot
from bridge.core.mapping import Mapping
from bridge.core.timing import LinkTiming, Mode
from bridge.errors import ValueRejectedError
from bridge.modbus.poller import DEFAULT_POLICY, DevicePoller, DeviceUpdate
from bridge.modbus.scheduler import BusScheduler
from bridge.modbus.transport import Transport


def link_timing(bus: SerialBus | TcpBus) -> LinkTiming:
    """The wire-time model of a bus: serial framing, the RTU line behind a TCP gateway
    (``serial_behind``), or TCP."""
    line = bus if isinstance(bus, SerialBus) else bus.serial_behind
    if line is None:
        return LinkTiming(mode="tcp")
    mode: Mode = "ascii" if bus.transport == "ascii" else "rtu"
    return LinkTiming.for_serial(
        line.baudrate, line.parity, line.stopbits, line.bytesize, mode=mode
    )


def bus_scheduler(bus: SerialBus | TcpBus, *, guard_late_replies: bool = True) -> BusScheduler:
    """The scheduler of one bus: its transport, the serial inter-frame silence (also behind a
    transparent serial server, which forwards bytes as they come; a Modbus TCP gateway
    keeps its own), and (unless turned off) a silent timeout after a timeout where replies
    carry no transaction id."""
    serial = isinstance(bus, SerialBus) or (
        bus.transport == "rtu-over-tcp" and bus.serial_behind is not None
    )
    gap = link_timing(bus).silence if serial else 0.0
    late_replies = guard_late_replies and bus.transport != "tcp"  # only TCP names requests
    return BusScheduler(
        Transport(bus), gap, late_replies=late_replies, connect_delay=bus.connect_delay
    )


class Engine:
    """All buses and devices of one config."""

    def __init__(
        self,
        loaded: LoadedConfig,
        on_update: Callable[[DeviceUpdate], None] | None = None,
        policy: HealthPolicy = DEFAULT_POLICY,
    ) -> None:
        config = loaded.config
        self.started = time.monotonic()  # every counter starts at zero here
        self.schedulers: dict[str, BusScheduler] = {}
        self.devices: dict[str, DevicePoller] = {}
        self._poll_share = config.bridge.gateway.poll_share
        for bus in config.buses:
            self.schedulers[bus.id] = self._scheduler(bus)
        self._buses = {bus.id: bus for bus in config.buses}
        self._on_update = on_update
        self._policy = policy
        self._group: asyncio.TaskGroup | None = None
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self._bus_tasks: dict[str, asyncio.Task[None]] = {}
        self.retired: dict[str, Guard] = {}  # the guards of devices no longer polled
        # work that runs while the engine runs (and stops with it): the SunSpec walks
        self.companions: list[Callable[[], Coroutine[Any, Any, None]]] = []
        for device in config.devices:
            if device.enabled:
                self.devices[device.id] = self._poller(device, loaded.mappings[device.id])

    def _scheduler(self, bus: SerialBus | TcpBus) -> BusScheduler:
        scheduler = bus_scheduler(bus)
        scheduler.fair.share = self._poll_share
        return scheduler

    def _poller(
        self, device: DeviceConfig, mapping: Mapping, guard: Guard = UNGUARDED
    ) -> DevicePoller:
        bus = self._buses[device.bus]
        shares = self.schedulers[bus.id].fair.shares
        if device.gateway_poll_share is None:
            shares.pop(device.unit, None)
        else:
            shares[device.unit] = device.gateway_poll_share
        return DevicePoller(
            device,
            mapping,
            self.schedulers[bus.id],
            timing=link_timing(bus),
            timeout=bus.timeout,
            retries=bus.retries,
            on_update=self._on_update,
            policy=self._policy,
            guard=guard,
        )

    async def run(self) -> None:
        """Run every scheduler and poller until cancelled."""
        try:
            async with asyncio.TaskGroup() as group:
                self._group = group
                for bus_id in self.schedulers:
                    self._start_bus(bus_id)
                for device_id in self.devices:
                    self._start(device_id)
                for companion in self.companions:
                    name = getattr(companion, "__name__", "companion")
                    group.create_task(companion(), name=name)
                # open until cancelled: a bus restarted stops every task for a moment, and
                # a group left with none ends (and takes no task again)
                await asyncio.get_running_loop().create_future()
        finally:
            self._group = None
            self._tasks.clear()
            self._bus_tasks.clear()

    def _start_bus(self, bus_id: str) -> None:
        if self._group is not None:
            scheduler = self.schedulers[bus_id]
            self._bus_tasks[bus_id] = self._group.create_task(scheduler.run(), name=f"bus:{bus_id}")

    def _start(self, device_id: str) -> None:
        """Poll a device in the engine's TaskGroup (when running; a SunSpec device not
        walked yet polls nothing)."""
        poller = self.devices[device_id]
        if self._group is not None and poller.points:
            self._tasks[device_id] = self._group.create_task(
                poller.run(), name=f"device:{device_id}"
            )

    async def _stop(self, device_id: str) -> None:
        """The device's polling stopped (its poll in flight cut short; a write runs in the
        task of its command, not here)."""
        await _cancelled(self._tasks.pop(device_id, None))

    # --- a config applied live ------------------------------------------------------------

    def add_bus(self, bus: SerialBus | TcpBus) -> None:
        """A new bus: its scheduler (and transport) started."""
        self._buses[bus.id] = bus
        self.schedulers[bus.id] = self._scheduler(bus)
        self._start_bus(bus.id)

    async def remove_bus(self, bus_id: str) -> None:
        """A bus no device uses any more: its scheduler stopped, its port closed."""
        await _cancelled(self._bus_tasks.pop(bus_id, None))
        self.schedulers.pop(bus_id).transport.close()
        del self._buses[bus_id]

    async def restart_bus(self, bus: SerialBus | TcpBus) -> None:
        """A bus's new settings: its devices' polling and its scheduler stopped (the port
        closed before it is opened again), a new scheduler started. Its devices' pollers
        are started again by ``replace_mapping``."""
        for device_id, poller in self.devices.items():
            if poller.device.bus == bus.id:
                await self._stop(device_id)
        await self.remove_bus(bus.id)
        self.add_bus(bus)

    def add_device(self, device: DeviceConfig, mapping: Mapping) -> DevicePoller:
        """Poll a new (or enabled) device from now on; a device polled before under this id
        keeps the guard it had (the guard only grows)."""
        guard = self.retired.pop(device.id, UNGUARDED)
        self.devices[device.id] = self._poller(device, mapping, guard)
        self._start(device.id)
        return self.devices[device.id]

    async def remove_device(self, device_id: str) -> DevicePoller:
        """Stop polling a device (removed or disabled); its poller is returned."""
        await self._stop(device_id)
        poller = self.devices.pop(device_id)
        self.retired[device_id] = poller.guard
        shares = poller.scheduler.fair.shares
        if poller.device.gateway_poll_share is not None:
            shares.pop(poller.device.unit, None)
        return poller

    async def replace_mapping(
        self, device_id: str, mapping: Mapping, device: DeviceConfig | None = None
    ) -> DevicePoller:
        """Poll ``device_id`` with ``mapping`` (and ``device``'s settings if given) from now
        on: its poller starts afresh (values, health and learnt refusals; the write spacing,
        the guard and the counters' published values carry over); the bus and the other
        devices carry on untouched."""
        old = self.device(device_id)
        await self._stop(device_id)
        if old.device.gateway_poll_share is not None:  # its unit may change: set again below
            old.scheduler.fair.shares.pop(old.device.unit, None)
        poller = self._poller(device or old.device, mapping, old.guard)  # the guard only grows
        poller.writer.inherit(old.writer)
        poller.state.carry_counters(old.state)
        if old.carried is not None:  # published before a restart, before it had a mapping
            poller.seed_counters(old.carried)
        self.devices[device_id] = poller
        self._start(device_id)
        return poller

    def device(self, device_id: str) -> DevicePoller:
        if device_id not in self.devices:
            raise ValueRejectedError(f"no device {device_id!r}")
        return self.devices[device_id]

    async def write(self, device_id: str, key: str, value: object) -> Value:
        return await self.device(device_id).write(key, value)

    async def read_now(self, device_id: str, keys: Iterable[str] | None = None) -> dict[str, Value]:
        return await self.device(device_id).read_now(keys)

    def snapshot(self) -> Snapshot:
        """Every bus's and device's counters now (an immutable copy)."""
        now = time.monotonic()
        return Snapshot(
            wall=time.time(),
            monotonic=now,
            uptime=now - self.started,
            buses=tuple(bus_snapshot(s) for s in self.schedulers.values()),
            devices=tuple(device_snapshot(p) for p in self.devices.values()),
        )


async def _cancelled(task: asyncio.Task[None] | None) -> None:
    if task is not None:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


_WITH_REASON = (Fault.LOCKED, Fault.UNMAPPED)  # offline for a reason beyond failed requests


def bus_snapshot(scheduler: BusScheduler) -> BusSnapshot:
    counters = scheduler.counters
    return BusSnapshot(
        bus_id=scheduler.bus_id,
        transport=scheduler.transport.bus.transport,
        connected=scheduler.transport.connected,
        requests=counters.transactions,
        busy_seconds=counters.busy_seconds,
        timeouts=counters.timeouts,
        frame_errors=counters.frame_errors,
        exceptions=counters.exceptions,
        reopenings=counters.reopenings,
        down_reason=None if scheduler.transport.connected else scheduler.down_reason,
    )


def device_snapshot(poller: DevicePoller) -> DeviceSnapshot:
    health, writes = poller.health, poller.writes
    return DeviceSnapshot(
        device_id=poller.device.id,
        bus=poller.device.bus,
        unit=poller.device.unit,
        online=health.online,
        requests=health.requests,
        errors=health.errors,
        timeouts=health.timeouts,
        busy=health.busy,
        exceptions=tuple(sorted(health.exceptions.items())),
        latency_p50=health.percentile(0.5),
        latency_p95=health.percentile(0.95),
        last_success=health.last_success,
        consecutive_failures=health.consecutive_failures,
        backoff=health.backoff,
        writes=WriteSnapshot(
            done=writes.done,
            skipped_unchanged=writes.skipped_unchanged,
            rejected=writes.rejected,
            failed=writes.failed,
            expired=writes.expired,
        ),
        unknown_codes=poller.unknown_codes,
        counter_readings_held=poller.counter_readings_held,
        counter_resets=poller.counter_resets,
        scaled_values_held=poller.scaled_values_held,
        error=health.lock_reason if health.fault in _WITH_REASON and not health.online else None,
    )
