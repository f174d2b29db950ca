"""A running bridge whose config the tests change (bridge/reconfigure.py): a real Mosquitto,
the simulator on loopback TCP, the config as data, and the measure of the devices a
change must leave alone (``Untouched``)."""

from __future__ import annotations

import asyncio
import contextlib
import copy
import itertools
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.app import Bridge
from bridge.config import LoadedConfig, MqttConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.poller import DevicePoller
from bridge.modbus.simulator import SimulatedUnit, Simulator, SunSpecUnit
from bridge.mqtt import MqttClient
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer

FAST = 0.5  # seconds: the fast interval of every device here
UNITS = {1: "nastec_vasco", 2: "vacon_nx", 3: "soft_starter", 4: "nastec_vasco"}


def unit_simulator(*extra: SunSpecUnit) -> Simulator:
    """The four units of ``UNITS`` (and ``extra``), every read logged with its time."""
    specs: list[SimulatedUnit | SunSpecUnit] = [
        SimulatedUnit(u, load_mapping(builtin_mapping_path(n))) for u, n in UNITS.items()
    ]
    return Simulator([*specs, *extra], tick=0, read_log=5000)


def device(device_id: str, unit: int, bus: str = "tcp", **fields: Any) -> dict[str, Any]:
    return {
        "id": device_id,
        "bus": bus,
        "unit": unit,
        "mapping": UNITS[unit],
        "poll": {"fast": FAST, "slow": 5},
    } | fields


def tcp_bus(bus_id: str, port: int, **fields: Any) -> dict[str, Any]:
    return {
        "id": bus_id,
        "transport": "tcp",
        "host": "127.0.0.1",
        "tcp_port": port,
        "timeout": 0.5,
    } | fields


@dataclass
class Site:
    """The bridge, its simulator, its config data (``data``: change a copy, then
    ``apply``), and an observer of everything it publishes."""

    broker: Broker
    bridge: Bridge
    sim: Simulator
    data: dict[str, Any]
    path: Path
    observer: Observer
    ports: dict[str, int] = field(default_factory=dict)

    def changed(self) -> dict[str, Any]:
        return copy.deepcopy(self.data)

    async def load(self, data: dict[str, Any]) -> LoadedConfig:
        """``data`` validated off the event loop (mappings are read: the polls go on)."""
        return await asyncio.to_thread(load_config_data, data, self.path)

    async def apply(self, data: dict[str, Any]) -> dict[str, Any]:
        answer = await self.bridge.apply_config(await self.load(data))
        if answer["status"] == "ok":
            self.data = data
        return answer

    def devices(self, data: dict[str, Any]) -> dict[str, dict[str, Any]]:
        return {d["id"]: d for d in data["devices"]}

    async def retained_now(self, *filters: str) -> dict[str, bytes]:
        """What a client subscribing now is sent retained under ``filters``."""
        async with observing(self.broker, "fresh", *filters) as fresh:
            await asyncio.sleep(0.5)  # the broker sends retained messages at once
            return {t: p for t, p in fresh.retained.items() if p}


@contextlib.asynccontextmanager
async def observing(broker: Broker, client_id: str, *filters: str) -> AsyncIterator[Observer]:
    """A client recording everything under ``filters``."""
    config = MqttConfig(url=broker.url)
    async with MqttClient(config, will_topic=f"{client_id}/state", client_id=client_id) as client:
        observer = Observer(client)
        task = asyncio.create_task(observer.run())
        await client.subscribe(*filters)
        try:
            yield observer
        finally:
            await cancel(task)


@contextlib.asynccontextmanager
async def site(
    broker: Broker,
    folder: Path,
    devices: list[dict[str, Any]],
    extra: tuple[SunSpecUnit, ...] = (),
    bridge_section: dict[str, Any] | None = None,
    **mqtt: Any,
) -> AsyncIterator[Site]:
    """The bridge on ``devices`` (bus ``tcp``: the simulator, with the ``extra`` units;
    ``bridge_section`` and ``mqtt``: more settings of those sections), every one published
    once."""
    sim = unit_simulator(*extra)
    async with contextlib.AsyncExitStack() as stack:
        port = await stack.enter_async_context(serving_tcp(sim))
        data = {
            "mqtt": {"url": broker.url, "command_expiry": 3} | mqtt,
            "bridge": {"allow_raw_writes": True} | (bridge_section or {}),
            "buses": [tcp_bus("tcp", port)],
            "devices": devices,
        }
        path = folder / "config.yaml"
        observer = await stack.enter_async_context(
            observing(broker, "observer", "modbus/#", "homeassistant/device/+/config")
        )
        bridge = Bridge(await asyncio.to_thread(load_config_data, data, path))
        task = asyncio.create_task(bridge.run())
        stack.push_async_callback(cancel, task)
        here = Site(broker, bridge, sim, data, path, observer, {"tcp": port})
        await eventually(lambda: published(here, [d["id"] for d in devices]), timeout=15)
        yield here


def published(site: Site, device_ids: list[str]) -> bool:
    retained = site.observer.retained
    return all(
        retained.get(f"homeassistant/device/{d}/config") and retained.get(f"modbus/{d}")
        for d in device_ids
    )


@dataclass
class Untouched:
    """The devices a change must leave alone, as they were before it: their poller (so
    their values, health and counters), their counters, and from when their polls are
    measured."""

    site: Site
    pollers: dict[str, DevicePoller]
    requests: dict[str, int]
    faults: dict[str, tuple[int, int]]
    since: float

    @classmethod
    def of(cls, site: Site, *device_ids: str) -> Untouched:
        pollers = {d: site.bridge.engine.devices[d] for d in device_ids}
        return cls(
            site,
            pollers,
            {d: p.health.requests for d, p in pollers.items()},
            {d: (p.health.errors, p.health.timeouts) for d, p in pollers.items()},
            time.monotonic(),
        )

    async def check(self, polls: int = 3) -> dict[str, float]:
        """Each went on with the same poller, its requests counted on from before (never
        reset), no error; ``polls`` more polls answered after the change, and between the
        measure's start and the last of them no gap of more than two fast intervals (no
        poll missed). Answers the longest gap of each, for the record."""
        engine = self.site.bridge.engine
        after = time.monotonic()
        for device_id, poller in self.pollers.items():
            assert engine.devices[device_id] is poller, f"{device_id} was restarted"
        await eventually(lambda: all(self._answered_since(d, after) >= polls for d in self.pollers))
        gaps = {}
        for device_id, poller in self.pollers.items():
            assert poller.health.requests > self.requests[device_id]
            assert (poller.health.errors, poller.health.timeouts) == self.faults[device_id]
            assert poller.first_poll_done and poller.values
            gaps[device_id] = self._longest_gap(device_id)
            assert gaps[device_id] <= 2 * FAST, (device_id, gaps[device_id])
        return gaps

    def _unit(self, device_id: str) -> int:
        return self.pollers[device_id].device.unit

    def _passes(self, device_id: str) -> list[float]:
        """When each poll of the device began: its reads, a new pass after a pause of more
        than half an interval."""
        times = [t for _, t in self.site.sim.reads(self._unit(device_id)) if t >= self.since]
        return [t for i, t in enumerate(times) if i == 0 or t - times[i - 1] > FAST / 2]

    def _answered_since(self, device_id: str, moment: float) -> int:
        return sum(1 for t in self._passes(device_id) if t > moment)

    def _longest_gap(self, device_id: str) -> float:
        passes = self._passes(device_id)
        return max((b - a for a, b in itertools.pairwise(passes)), default=0.0)
