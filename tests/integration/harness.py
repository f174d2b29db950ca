"""Run the real engine against the real simulator on loopback TCP or a pty pair."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from bridge.config import LoadedConfig, load_config_data
from bridge.core.health import HealthPolicy
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.engine import Engine
from bridge.modbus.null_modem import null_modem
from bridge.modbus.poller import DeviceUpdate
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator

FAST_POLICY = HealthPolicy(offline_after=2, backoff_initial=0.2, backoff_max=0.4)


def simulator(*units: tuple[int, str], tick: float = 0.0, **quirks: Any) -> Simulator:
    specs = [
        SimulatedUnit(unit, load_mapping(builtin_mapping_path(name)), quirks=Quirks(**quirks))
        for unit, name in units
    ]
    return Simulator(specs, tick=tick)


@contextlib.asynccontextmanager
async def serving_tcp(sim: Simulator, framer: str = "socket") -> AsyncIterator[int]:
    """Serve ``sim`` on a free loopback port; yield the port."""
    task = asyncio.create_task(sim.serve_tcp("127.0.0.1", 0, framer))  # type: ignore[arg-type]
    try:
        await asyncio.wait_for(sim.ready.wait(), 5)
        yield sim.port
    finally:
        await cancel(task)


@contextlib.asynccontextmanager
async def serving_serial(sim: Simulator, framer: str = "rtu", **line: Any) -> AsyncIterator[str]:
    """Serve ``sim`` on one end of a virtual cable; yield the path of the other end."""
    with null_modem() as (device_end, bridge_end):
        task = asyncio.create_task(sim.serve_serial(device_end, framer=framer, **line))  # type: ignore[arg-type]
        try:
            await asyncio.wait_for(sim.ready.wait(), 5)
            yield bridge_end
        finally:
            await cancel(task)


def config(buses: list[dict[str, Any]], devices: list[dict[str, Any]]) -> LoadedConfig:
    return load_config_data({"buses": buses, "devices": devices}, Path("test-config.yaml"))


def tcp_bus(port: int, **fields: Any) -> dict[str, Any]:
    return {
        "id": "tcp",
        "transport": "tcp",
        "host": "127.0.0.1",
        "tcp_port": port,
        "timeout": 0.5,
        "retries": 0,
    } | fields


class Recorder:
    """Collects every DeviceUpdate the engine reports."""

    def __init__(self) -> None:
        self.updates: list[DeviceUpdate] = []

    def __call__(self, update: DeviceUpdate) -> None:
        self.updates.append(update)

    def of(self, device_id: str) -> list[DeviceUpdate]:
        return [u for u in self.updates if u.device_id == device_id]


@contextlib.asynccontextmanager
async def running(engine: Engine, *, pollers: bool = True) -> AsyncIterator[Engine]:
    """Run the engine's schedulers (and pollers) for the duration of the block."""
    tasks = [asyncio.create_task(s.run()) for s in engine.schedulers.values()]
    if pollers:
        tasks += [asyncio.create_task(p.run()) for p in engine.devices.values()]
    try:
        yield engine
    finally:
        for task in tasks:
            await cancel(task)


async def cancel(task: asyncio.Task[Any], within: float = 10.0) -> None:
    """Cancel a task and wait for it to end, failing clearly if it does not stop."""
    task.cancel()
    done, _ = await asyncio.wait({task}, timeout=within)
    if not done:
        stacks = "".join(
            f"  {other.get_name()}: {[f'{f.f_code.co_filename}:{f.f_lineno}' for f in other.get_stack(limit=3)]}\n"
            for other in asyncio.all_tasks()
            if not other.done()
        )
        raise AssertionError(f"task {task.get_name()} did not stop within {within} s:\n{stacks}")
    with contextlib.suppress(asyncio.CancelledError):
        await task


async def eventually(condition: Any, timeout: float = 5.0) -> None:
    """Wait until ``condition()`` is true (bounded); fail with the condition's source."""
    async with asyncio.timeout(timeout):
        while not condition():
            await asyncio.sleep(0.02)
