"""The seed devices as they behave on a real line (issue 12), end to end: a real Mosquitto,
the simulator with the device's quirk switched on, and ``Bridge.run()``.

Each test runs only the devices it needs, with the device fields it needs (a password,
``allow_dangerous_writes``). Waits are bounded; nothing asserts wall-clock time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.modbus.simulator import Simulator
from tests.integration.harness import cancel, eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

H = Table.HOLDING


def device(name: str, unit: int = 1, **fields: Any) -> dict[str, Any]:
    return {
        "id": name,
        "bus": "tcp",
        "unit": unit,
        "mapping": name,
        "poll": {"fast": 0.5, "slow": 5},
    } | fields


@contextlib.asynccontextmanager
async def bridged(
    broker: Broker,
    sim: Simulator,
    devices: list[dict[str, Any]],
    bridge: dict[str, Any] | None = None,
) -> AsyncIterator[Bridge]:
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {"url": broker.url, "base_topic": "modbus", "command_expiry": 3},
            "bridge": {"health_interval": 0} | (bridge or {}),
            "buses": [
                {
                    "id": "tcp",
                    "transport": "tcp",
                    "host": "127.0.0.1",
                    "tcp_port": port,
                    "timeout": 0.5,
                }
            ],
            "devices": devices,
        }
        running = Bridge(load_config_data(data, Path("seed-behaviours.yaml")))
        task = asyncio.create_task(running.run())
        try:
            yield running
        finally:
            await cancel(task)


def errors(observer: Observer, device_id: str, since: int = 0) -> list[dict[str, Any]]:
    return [json.loads(m.payload) for m in observer.after(since, f"modbus/{device_id}/error")]


def writes_to(sim: Simulator, unit: int) -> list[Any]:
    return [w for u, w in sim.writes if u == unit]


async def online(observer: Observer, *device_ids: str) -> None:
    await eventually(
        lambda: all(
            observer.retained.get(f"modbus/{d}/availability") == b"online" for d in device_ids
        ),
        timeout=20,
    )


# --- item 4: a negative speed reference is guarded like reverse run ------------------------

P2_SET_VALUE = 0x1000
VACON_SPEED_REFERENCE = 2002  # ID 2003


@pytest.mark.asyncio
async def test_a_negative_speed_reference_is_refused_unless_dangerous_writes_are_allowed(
    mosquitto: Broker,
) -> None:
    """P2 1000H and Vacon 2003: -10 % is refused over MQTT and as a raw write (nothing on
    the wire), +25 % is written; a P2 that allows dangerous writes takes -10 %."""
    sim = simulator((1, "p2_vfd"), (2, "vacon_nx"), (3, "p2_vfd"))
    devices = [
        device("p2_vfd", 1),
        device("vacon_nx", 2),
        device("p2_reversible", 3, mapping="p2_vfd", allow_dangerous_writes=True),
    ]
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, devices, {"allow_raw_writes": True}),
    ):
        await online(observer, "p2_vfd", "vacon_nx", "p2_reversible")
        await observer.client.publish("modbus/p2_vfd/set_value/set", "-10")
        await observer.client.publish("modbus/vacon_nx/set", '{"speed_reference": -0.01}')
        await eventually(lambda: errors(observer, "p2_vfd") and errors(observer, "vacon_nx"))
        for device_id, key in (("p2_vfd", "set_value"), ("vacon_nx", "speed_reference")):
            [error] = errors(observer, device_id)
            assert error["key"] == key
            assert "a value below 0 is a guarded write" in error["error"], error
        raw = json.dumps({"device": "p2_vfd", "address": P2_SET_VALUE, "values": [0xEC78]})
        await observer.client.publish("modbus/bridge/request/device/write", raw)
        await eventually(lambda: observer.after(0, "modbus/bridge/response/device/write"))
        answer = json.loads(observer.after(0, "modbus/bridge/response/device/write")[0].payload)
        assert answer["status"] == "error" and "guarded" in answer["error"], answer
        await asyncio.sleep(0.3)
        assert sim.writes == []
        await observer.client.publish("modbus/p2_vfd/set_value/set", "25")
        await observer.client.publish("modbus/vacon_nx/speed_reference/set", "0")
        await observer.client.publish("modbus/p2_reversible/set_value/set", "-10")
        await eventually(lambda: len(sim.writes) == 3)
        assert {(u, w.address, w.values) for u, w in sim.writes} == {
            (1, P2_SET_VALUE, (2500,)),
            (2, VACON_SPEED_REFERENCE, (0,)),
            (3, P2_SET_VALUE, (0xFC18,)),  # -1000 = -10.00 %
        }
