"""A raw write cannot escape a device's guard by naming another unit.

Many Modbus TCP devices answer any unit id. Here a P2 drive answers every unit of bus
``tcp1`` (the simulator's unit 0) and is configured as ``drive`` at unit 1: its reverse
run (2000H <- 2) and a negative speed reference (1000H <- 60536) stay guarded when a raw
write names unit 255 or an unconfigured unit, over MQTT (a real Mosquitto) and through
the web page's commissioning; the drive's registers never change, and the answer says
why and what to configure.
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
from bridge.core.request import Write
from bridge.management import Management
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Simulator
from tests.integration.harness import cancel, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_management import client_of, online, request
from tests.integration.web import http, listening
from tests.ports import free_port

ANY_UNIT = 0  # the simulated drive answers every unit id
COMMAND, SET_VALUE, PASSWORD = 0x2000, 0x1000, 0x1F00  # P2 wire addresses
REVERSE_RUN = {"address": COMMAND, "values": [2]}  # dangerous: reverse may be forbidden
REVERSE_SPEED = {"address": SET_VALUE, "values": [60536]}  # -50.00 %: below 0 is guarded
HARMLESS = {"address": SET_VALUE, "values": [2500]}  # +25.00 %
BY_NAME = ({"device": "drive"}, {"unit": 1})  # what was refused before too
ELSEWHERE = ({"bus": "tcp1", "unit": 255}, {"bus": "tcp1", "unit": 2})


@contextlib.asynccontextmanager
async def drive_site(
    broker: Broker,
    folder: Path,
    *,
    bridge: dict[str, Any] | None = None,
    bus: dict[str, Any] | None = None,
) -> AsyncIterator[tuple[Bridge, Simulator]]:
    """The P2 answering every unit id, configured at unit 1 of TCP bus tcp1."""
    sim = simulator((ANY_UNIT, "p2_vfd"), tick=0)
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {"url": broker.url},
            "bridge": {"allow_raw_writes": True, "scan_timeout": 0.1} | (bridge or {}),
            "buses": [
                {"id": "tcp1", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
                | {"timeout": 0.3}
                | (bus or {})
            ],
            "devices": [{"id": "drive", "bus": "tcp1", "unit": 1, "mapping": "p2_vfd"}],
        }
        running = Bridge(load_config_data(data, folder / "config.yaml"))
        task = asyncio.create_task(running.run())
        try:
            await online(running)
            yield running, sim
        finally:
            await cancel(task)


def held(sim: Simulator) -> tuple[int | None, int | None]:
    """What the drive's command word (None: never written) and speed reference hold."""
    image = sim.image(ANY_UNIT)
    return image.get((Table.HOLDING, COMMAND)), image.get((Table.HOLDING, SET_VALUE))


def refused_as_guarded(answer: dict[str, Any], address: int) -> None:
    assert answer["status"] == "error", answer
    error = answer["error"]
    assert f"drive: addresses {address} are guarded (dangerous)" in error, error
    assert "set allow_dangerous_writes: true for" in error, error


def refused_as_unconfigured(answer: dict[str, Any], unit: int) -> None:
    assert answer["status"] == "error", answer
    error = answer["error"]
    assert f"unit {unit}: no device is configured at it on TCP bus tcp1" in error, error
    assert "ignores the unit id may answer it (drive)" in error, error
    assert f"add raw_units: [{unit}] to bus tcp1" in error, error


@pytest.mark.asyncio
async def test_a_raw_write_to_another_unit_of_a_tcp_device_is_refused(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with (
        drive_site(mosquitto, tmp_path) as (bridge, sim),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        before = held(sim)
        for write in (REVERSE_RUN, REVERSE_SPEED):
            for target in BY_NAME:
                answer = await request(tester, "device/write", target | write)
                refused_as_guarded(answer, write["address"])
            for target in ELSEWHERE:
                answer = await request(tester, "device/write", target | write)
                refused_as_unconfigured(answer, target["unit"])
                refused_as_guarded(answer, write["address"])  # both reasons, at once
                assert "unit 255 on bus tcp1 may reach drive" in answer["error"] or (
                    "unit 2 on bus tcp1 may reach drive" in answer["error"]
                )
        for target in ELSEWHERE:  # harmless, but what answers there is not known
            answer = await request(tester, "device/write", target | HARMLESS)
            refused_as_unconfigured(answer, target["unit"])
            assert "guarded" not in answer["error"], answer
        await asyncio.sleep(0.3)  # a write let through would have arrived by now
        assert sim.writes == []
        assert held(sim) == before


@pytest.mark.asyncio
async def test_raw_units_open_an_unconfigured_unit_but_keep_every_guard(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with (
        drive_site(mosquitto, tmp_path, bus={"raw_units": [2, 255]}) as (bridge, sim),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        before = held(sim)
        for target in ELSEWHERE:
            for write in (REVERSE_RUN, REVERSE_SPEED):
                answer = await request(tester, "device/write", target | write)
                refused_as_guarded(answer, write["address"])
                assert f"unit {target['unit']} on bus tcp1 may reach drive" in answer["error"]
                assert "raw_units" not in answer["error"], answer
        await asyncio.sleep(0.3)
        assert sim.writes == []
        assert held(sim) == before
        done = await request(tester, "device/write", ELSEWHERE[0] | HARMLESS)
        assert done["status"] == "ok", done  # the drive does answer unit 255
        assert sim.writes == [(ANY_UNIT, Write(6, Table.HOLDING, SET_VALUE, (2500,)))]


@pytest.mark.asyncio
async def test_a_raw_read_of_another_unit_keeps_the_secret_guard(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with (
        drive_site(mosquitto, tmp_path, bridge={"allow_raw_writes": False}) as (bridge, _),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        for target in (*BY_NAME, *ELSEWHERE):
            answer = await request(tester, "device/read", target | {"address": PASSWORD})
            assert answer["status"] == "error", (target, answer)
            assert f"drive: addresses {PASSWORD} hold secret or write-only" in answer["error"]
            assert "bridge.allow_raw_writes: true" in answer["error"]
        for target in ELSEWHERE:  # reads of unconfigured units stay allowed
            answer = await request(tester, "device/read", target | {"address": 0x3000})
            assert answer["status"] == "ok", answer
            assert answer["data"]["registers"] == [1]  # running forward


@pytest.mark.asyncio
async def test_the_web_page_refuses_the_same_raw_writes(mosquitto: Broker, tmp_path: Path) -> None:
    port = free_port()
    web = {"web": {"enabled": True, "host": "127.0.0.1", "port": port}}
    async with drive_site(mosquitto, tmp_path, bridge=web) as (_, sim):
        await listening(port)
        before = held(sim)
        for write in (REVERSE_RUN, REVERSE_SPEED):
            for target in ELSEWHERE:
                sent = await http(port, "POST", "/api/request/device/write", target | write)
                assert sent.status == 200, sent.body
                refused_as_unconfigured(sent.json(), target["unit"])
                refused_as_guarded(sent.json(), write["address"])
        sent = await http(port, "POST", "/api/request/device/write", ELSEWHERE[0] | HARMLESS)
        refused_as_unconfigured(sent.json(), 255)
        await asyncio.sleep(0.3)
        assert sim.writes == []
        assert held(sim) == before


@pytest.mark.asyncio
async def test_a_disabled_device_keeps_its_guard(tmp_path: Path) -> None:
    """A device the config disables is still wired: raw writes that may reach it keep its
    guard (refused before anything reaches the bus, so no bus is needed)."""
    data = {
        "bridge": {"allow_raw_writes": True},
        "buses": [{"id": "tcp1", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 1}],
        "devices": [
            {"id": "drive", "bus": "tcp1", "unit": 1, "mapping": "p2_vfd"},
            {"id": "spare", "bus": "tcp1", "unit": 2, "mapping": "p2_vfd", "enabled": False},
        ],
    }
    loaded = load_config_data(data, tmp_path / "config.yaml")
    engine = Engine(loaded)  # not running

    async def reloaded(_: list[str]) -> None:
        raise AssertionError("nothing to reload")

    management = Management(loaded, engine, on_reload=reloaded, mqtt_state=lambda: "online")
    body = json.dumps({"unit": 2} | REVERSE_RUN).encode()
    answer = json.loads(await management.handle("device/write", body))
    assert answer["error"] == (
        "spare: addresses 8192 are guarded (dangerous); "
        "set allow_dangerous_writes: true for device spare to permit it"
    )
    assert engine.schedulers["tcp1"].counters.transactions == 0
