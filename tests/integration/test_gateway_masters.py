"""Masters beside the bridge: while the whole bridge (real Mosquitto, the simulator on a
pty pair) polls two devices on one serial line and executes MQTT commands, a pymodbus
client and libmodbus' ``mbpoll`` read and write through the gateway at the same time.

Every answer must equal the simulator's registers, the line must carry no CRC or framing
error and no timeout (no collision), guarded writes must be refused before the wire, the
devices must stay online and keep being polled, and the health report and the web page
must show the clients. (Home Assistant's own ``modbus`` integration is the third master:
tests/ha/test_gateway.py.)
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import shutil
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.core.request import Write
from bridge.modbus.simulator import Simulator
from tests.integration.harness import cancel, eventually, serving_serial, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing
from tests.integration.web import http, listening
from tests.ports import free_port

H = Table.HOLDING
PUMP, STARTER = 1, 3
MBPOLL = shutil.which("mbpoll")


@dataclass
class Site:
    bridge: Bridge
    sim: Simulator
    gateway_port: int
    web_port: int


@contextlib.asynccontextmanager
async def site(
    broker: Broker, folder: Path, gateway_port: int | None = None, *, web: bool = True
) -> AsyncIterator[Site]:
    """The bridge polling two devices on one RTU line, with its gateway (writes allowed) on
    ``gateway_port`` (a free one by default) and, with ``web``, its web page."""
    sim = simulator((PUMP, "nastec_vasco"), (STARTER, "soft_starter"))
    web_port = free_port() if web else 0
    gateway_port = gateway_port or free_port()
    async with serving_serial(sim, baudrate=38400) as path:
        data = {
            "mqtt": {"url": broker.url, "command_expiry": 3},
            "bridge": {
                "health_interval": 0.3,
                "gateway": {
                    "enabled": True,
                    "port": gateway_port,
                    "units": {1: "pump", 3: "starter"},
                    "allow_writes": True,
                },
            },
            "buses": [
                {"id": "line", "transport": "rtu", "port": path, "baudrate": 38400}
                | {"timeout": 0.5, "retries": 0}
            ],
            "devices": [
                {"id": "pump", "bus": "line", "unit": PUMP, "mapping": "nastec_vasco"},
                {"id": "starter", "bus": "line", "unit": STARTER, "mapping": "soft_starter"},
            ],
        }
        if web:
            data["bridge"]["web"] = {"enabled": True, "port": web_port}
        for device in data["devices"]:
            device["poll"] = {"fast": 1.0, "slow": 5}
        running = Bridge(load_config_data(data, folder / "config.yaml"))
        task = asyncio.create_task(running.run())
        try:
            if web:
                await listening(web_port)
            await asyncio.wait_for(running.gateway.server.ready.wait(), 10)
            await eventually(
                lambda: all(p.health.online for p in running.engine.devices.values()), 15
            )
            yield Site(running, sim, gateway_port, web_port)
        finally:
            await cancel(task)


def words(sim: Simulator, unit: int, address: int, count: int) -> list[int]:
    image = sim.image(unit)
    return [image.get((H, a), 0) for a in range(address, address + count)]


async def mbpoll(
    port: int, unit: int, address: int, *options: str, values: tuple[int, ...] = ()
) -> tuple[int, str]:
    """mbpoll once (0-based ``address``): a read, or a write of ``values``; its exit status
    and output."""
    process = await asyncio.create_subprocess_exec(
        str(MBPOLL),
        *("-m", "tcp", "-p", str(port), "-a", str(unit), "-0", "-r", str(address)),
        *("-t", "4", "-1", "-o", "3"),
        *options,
        "127.0.0.1",
        *(str(v) for v in values),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    output, _ = await asyncio.wait_for(process.communicate(), 30)
    return process.returncode or 0, output.decode(errors="replace")


def mbpoll_values(output: str) -> list[int]:
    return [int(v) for v in re.findall(r"^\[\d+\]:\s+(-?\d+)", output, re.MULTILINE)]


Seen = list[tuple[list[int], tuple[list[int], list[int]]]]


async def pymodbus_master(site: Site, rounds: int) -> Seen:
    """Reads of both devices: each answer with the simulator's registers just before and
    just after it (an MQTT command may change one while the read is on the line)."""
    seen: Seen = []
    client = AsyncModbusTcpClient("127.0.0.1", port=site.gateway_port, timeout=5, retries=0)
    await client.connect()
    try:
        for _ in range(rounds):
            before = words(site.sim, PUMP, 50, 8)
            pump = await client.read_holding_registers(50, count=8, device_id=PUMP)
            seen.append((pump.registers, (before, words(site.sim, PUMP, 50, 8))))
            before = words(site.sim, STARTER, 4097, 12)
            starter = await client.read_holding_registers(4097, count=12, device_id=STARTER)
            seen.append((starter.registers, (before, words(site.sim, STARTER, 4097, 12))))
    finally:
        client.close()
    return seen


async def mbpoll_master(site: Site, rounds: int) -> Seen:
    seen: Seen = []
    for _ in range(rounds):
        before = words(site.sim, STARTER, 4104, 6)
        status, output = await mbpoll(site.gateway_port, STARTER, 4104, "-c", "6")
        assert status == 0, output
        seen.append((mbpoll_values(output), (before, words(site.sim, STARTER, 4104, 6))))
    return seen


@pytest.mark.asyncio
@pytest.mark.skipif(MBPOLL is None, reason="mbpoll (libmodbus) is not installed")
async def test_two_masters_and_mqtt_commands_share_the_line(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with (
        site(mosquitto, tmp_path) as s,
        observing(mosquitto, "modbus/bridge/health", "modbus/starter") as observer,
    ):
        engine = s.bridge.engine
        polls_before = {d: p.health.requests for d, p in engine.devices.items()}
        command = observer.client.publish("modbus/starter/set", json.dumps({"soft_stop_time": 12}))
        pymodbus_reads, mbpoll_reads, _ = await asyncio.gather(
            pymodbus_master(s, 10), mbpoll_master(s, 5), command
        )
        for answer, registers in pymodbus_reads + mbpoll_reads:
            assert answer in registers  # the device's registers at one moment of the read
        await eventually(lambda: s.sim.value(STARTER, "soft_stop_time") == 12)

        # a write through mbpoll (libmodbus FC06), checked and read back like a command
        status, output = await mbpoll(s.gateway_port, STARTER, 4101, values=(25,))
        assert status == 0, output
        assert s.sim.value(STARTER, "soft_start_time") == 25
        await eventually(
            lambda: (
                json.loads(observer.retained.get("modbus/starter", b"{}")).get("soft_start_time")
                == 25
            )
        )
        # guarded: rated_voltage needs allow_dangerous_writes; refused before the wire
        written = list(s.sim.writes)
        status, output = await mbpoll(s.gateway_port, STARTER, 4103, values=(400,))
        assert status != 0 and "Illegal function" in output, output
        client = AsyncModbusTcpClient("127.0.0.1", port=s.gateway_port, timeout=5, retries=0)
        await client.connect()
        reply = await client.write_register(4103, 400, device_id=STARTER)
        client.close()
        assert reply.isError() and reply.exception_code == 0x01
        assert s.sim.writes == written
        assert (STARTER, Write(6, H, 4103, (400,))) not in s.sim.writes

        counters = engine.schedulers["line"].counters
        assert (counters.frame_errors, counters.timeouts) == (0, 0)
        for device_id, poller in engine.devices.items():
            assert poller.health.online, device_id
            assert poller.health.requests > polls_before[device_id], device_id

        def gateway_reported() -> bool:
            total = observer.json("modbus/bridge/health").get("gateway", {}).get("total", {})
            return total.get("served", 0) >= 10 * 2 + 5 + 1 and total.get("refused") == 2

        await eventually(gateway_reported)
        report: dict[str, Any] = observer.json("modbus/bridge/health")["gateway"]
        assert report["total"]["failed"] == 0
        assert report["clients"]["127.0.0.1"]["connections"] >= 6
        overview = (await http(s.web_port, "GET", "/api/overview")).json()
        assert overview["gateway"]["clients"]["127.0.0.1"]["served"] >= 26
