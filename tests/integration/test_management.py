"""The management API end to end: requests over a real Mosquitto, the simulator behind.

Every request carries a transaction and must come back on bridge/response/<cmd> with it;
raw reads are checked against the simulator's own registers, writes against what it
received, mapping reloads against the discovery the bridge publishes afterwards.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import shutil
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.core.entity import Table
from bridge.core.mapping import builtin_mapping_path
from bridge.modbus.simulator import Simulator
from bridge.mqtt import MqttClient
from tests.conftest import BROKER_PASSWORD, BROKER_USER
from tests.integration.harness import cancel, eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer

_transactions = itertools.count(1)


@contextlib.asynccontextmanager
async def site(
    broker: Broker,
    folder: Path,
    *,
    raw_writes: bool = False,
    bridge: dict[str, Any] | None = None,
    **mqtt: Any,
) -> AsyncIterator[tuple[Bridge, Simulator]]:
    """The Nastec pump (mapping file in ``folder``) on unit 1, a soft starter on unit 3;
    ``bridge``: more settings of the config's bridge section."""
    shutil.copy(builtin_mapping_path("nastec_vasco"), folder / "pump.yaml")
    sim = simulator((1, "nastec_vasco"), (3, "soft_starter"), tick=0)
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {"url": broker.url} | mqtt,
            "bridge": {"allow_raw_writes": raw_writes, "scan_timeout": 0.1} | (bridge or {}),
            "buses": [
                {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
                | {"timeout": 0.3}
            ],
            "devices": [
                {"id": "pump", "bus": "tcp", "unit": 1, "mapping": "pump.yaml"},
                {"id": "starter", "bus": "tcp", "unit": 3, "mapping": "soft_starter"},
            ],
        }
        running = Bridge(load_config_data(data, folder / "config.yaml"))
        task = asyncio.create_task(running.run())
        try:
            yield running, sim
        finally:
            await cancel(task)


@contextlib.asynccontextmanager
async def client_of(broker: Broker, version: str = "5") -> AsyncIterator[Observer]:
    config = MqttConfig(url=broker.url, version=version)  # type: ignore[arg-type]
    async with MqttClient(config, will_topic="tester/state", client_id="tester") as client:
        observer = Observer(client)
        task = asyncio.create_task(observer.run())
        await client.subscribe("modbus/bridge/#", "homeassistant/device/+/config")
        try:
            yield observer
        finally:
            await cancel(task)


async def request(observer: Observer, command: str, body: dict[str, Any] | bytes) -> Any:
    """Publish a request with a fresh transaction; return the response that echoes it."""
    transaction = f"t{next(_transactions)}"
    payload = body if isinstance(body, bytes) else json.dumps(body | {"transaction": transaction})
    start = len(observer.log)
    await observer.client.publish(f"modbus/bridge/request/{command}", payload)
    topic = f"modbus/bridge/response/{command}"

    def answered() -> list[Any]:
        answers = [json.loads(m.payload) for m in observer.after(start, topic)]
        if isinstance(body, bytes):
            return answers
        return [a for a in answers if a["transaction"] == transaction]

    await eventually(answered, timeout=15)
    (answer,) = answered()
    assert set(answer) == {"status", "data", "error", "transaction"}
    return answer


async def online(bridge: Bridge, tester: Observer | None = None) -> None:
    """Every device answers, the bridge said online (its values and info go out before
    that) and it listens (its info, sent after subscribing)."""
    await eventually(lambda: all(p.health.online for p in bridge.engine.devices.values()), 10)
    await eventually(lambda: bridge.mqtt_state == "online", 10)
    if tester is not None:
        await eventually(lambda: "modbus/bridge/info" in tester.retained, 10)


@pytest.mark.asyncio
async def test_info_is_retained_with_the_config_without_secrets(
    mosquitto_auth: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto_auth, tmp_path, username=BROKER_USER, password=BROKER_PASSWORD) as (
        bridge,
        _,
    ):
        await eventually(lambda: bridge.mqtt_state == "online", 10)
        config = MqttConfig(url=mosquitto_auth.url, username=BROKER_USER, password=BROKER_PASSWORD)
        async with MqttClient(config, will_topic="tester/state", client_id="reader") as client:
            found = await client.retained("modbus/bridge/info")
    raw = found["modbus/bridge/info"]
    assert BROKER_PASSWORD.encode() not in raw
    info = json.loads(raw)
    assert info["version"]
    assert info["config"]["mqtt"]["password"] == "**********"
    assert info["config"]["bridge"]["allow_raw_writes"] is False
    assert set(info["mappings"]["in_use"]) == {"pump", "starter"}
    assert "nastec_vasco" in info["mappings"]["shipped"]
    assert info["config_schema"]["properties"]["buses"]
    assert info["mapping_schema"]["properties"]
    assert "device/read" in info["requests"]


@pytest.mark.asyncio
async def test_raw_read_returns_the_device_registers_and_every_interpretation(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as (bridge, sim), client_of(mosquitto) as tester:
        await online(bridge, tester)
        by_device = await request(tester, "device/read", {"device": "pump", "address": 0x33})
        assert by_device["status"] == "ok", by_device
        image = sim.image(1)
        assert by_device["data"]["registers"] == [image[(Table.HOLDING, 0x33)]]

        # the README's first example: two registers of the Nastec, which reads one at a time
        pair = await request(tester, "device/read", {"device": "pump", "address": 151, "count": 2})
        assert pair["status"] == "ok", pair
        assert pair["data"]["registers"] == [image[(Table.HOLDING, a)] for a in (151, 152)]
        assert pair["data"]["requests"] == 2
        assert pair["data"]["note"] == "2 requests: the device reads at most 1 register at once"

        answer = await request(
            tester, "device/read", {"bus": "tcp", "unit": 3, "address": 0x1001, "count": 4}
        )
        assert answer["status"] == "ok", answer
        data = answer["data"]
        expected = [sim.image(3)[(Table.HOLDING, a)] for a in range(0x1001, 0x1005)]
        assert data["registers"] == expected
        assert data["unit"] == 3 and data["bus"] == "tcp"
        assert len(data["pairs"]) == 3
        first = data["pairs"][0]
        assert set(first) >= {"ABCD", "CDAB", "BADC", "DCBA"}
        assert first["ABCD"]["u32"] == expected[0] << 16 | expected[1]
        assert first["CDAB"]["u32"] == expected[1] << 16 | expected[0]


@pytest.mark.asyncio
async def test_bad_requests_get_clear_errors_and_reach_no_bus(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as (bridge, sim), client_of(mosquitto) as tester:
        await online(bridge, tester)
        sent = bridge.engine.schedulers["tcp"].counters.transactions
        cases: list[tuple[str, dict[str, Any], str]] = [
            ("device/read", {"unit": 1}, "address"),
            ("device/read", {"unit": 1, "address": 70000}, "address"),
            ("device/read", {"unit": 1, "address": 0, "count": 126}, "count"),
            ("device/read", {"device": "nope", "address": 0}, "no device 'nope'"),
            ("device/read", {"bus": "rs485", "unit": 1, "address": 0}, "no bus 'rs485'"),
            ("device/read", {"device": "pump", "unit": 1, "address": 0}, "not both"),
            ("device/read", {"unit": 1, "address": 0, "tabel": "input"}, "tabel"),
            ("device/scan", {"units": "0-300"}, "1..247"),
            ("device/scan", {"units": "a-b"}, "'a-b'"),
            ("device/write", {"unit": 1, "address": 0x33, "values": [1]}, "allow_raw_writes"),
            ("mapping/reload", {"devices": ["ghost"]}, "ghost"),
            ("no/such", {}, "unknown request 'no/such'"),
        ]
        for command, body, words in cases:
            answer = await request(tester, command, body)
            assert answer["status"] == "error", (command, body, answer)
            assert words in answer["error"], (command, body, answer["error"])
            assert answer["transaction"] is not None
        garbled = await request(tester, "device/read", b"{not json")
        assert garbled["status"] == "error" and "not JSON" in garbled["error"]
        assert garbled["transaction"] is None
        # polls go on meanwhile; no request above may have added a raw transaction
        assert not list(sim.writes)
        assert bridge.engine.schedulers["tcp"].counters.transactions >= sent


@pytest.mark.asyncio
async def test_raw_write_when_allowed_reaches_the_device(mosquitto: Broker, tmp_path: Path) -> None:
    async with (
        site(mosquitto, tmp_path, raw_writes=True) as (bridge, sim),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        answer = await request(
            tester, "device/write", {"device": "pump", "address": 0x34, "values": [123]}
        )
        assert answer["status"] == "ok", answer
        assert answer["data"]["function"] == 6
        assert sim.image(1)[(Table.HOLDING, 0x34)] == 123
        several = await request(
            tester, "device/write", {"device": "starter", "address": 0x102A, "values": [0, 0]}
        )
        assert several["status"] == "ok", several
        assert several["data"]["function"] == 16
        assert (3, several["data"]["function"]) in [(u, w.function) for u, w in sim.writes]
        assert [sim.image(3)[(Table.HOLDING, a)] for a in (0x102A, 0x102B)] == [0, 0]
        not_supported = await request(
            tester, "device/write", {"unit": 1, "address": 0x3A, "values": [45, 2]}
        )  # the Nastec has no FC16: its own answer comes back, named
        assert not_supported["error"] == "unit 1 refused: exception 1 (illegal function)"
        refused = await request(
            tester, "device/write", {"unit": 1, "address": 0x34, "values": [70000]}
        )
        assert refused["status"] == "error" and "70000" in refused["error"]
        assert sim.image(1)[(Table.HOLDING, 0x34)] == 123


@pytest.mark.asyncio
async def test_scan_finds_the_units_that_answer(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as (bridge, _), client_of(mosquitto) as tester:
        await online(bridge, tester)
        answer = await request(tester, "device/scan", {"units": "1-6", "timeout": 0.1})
        assert answer["status"] == "ok", answer
        found = {f["unit"]: f["device"] for f in answer["data"]["found"]}
        assert found == {1: "pump", 3: "starter"}
        assert answer["data"]["probed"] == 6


@pytest.mark.asyncio
async def test_mapping_reload_applies_a_changed_file_and_refuses_a_broken_one(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as (bridge, _), client_of(mosquitto) as tester:
        await online(bridge, tester)
        topic = "homeassistant/device/pump/config"
        await eventually(lambda: topic in tester.retained, 10)
        assert "bluetooth_connection" in tester.json(topic)["cmps"]
        unchanged = await request(tester, "mapping/reload", {})
        assert unchanged["data"] == {"reloaded": ["pump", "starter"], "changed": []}

        path = tmp_path / "pump.yaml"
        original = path.read_text()
        broken = original.replace("  start_stop:\n", "  start_stop:\n    adress: 1\n", 1)
        path.write_text(broken)
        poller = bridge.engine.devices["pump"]
        refused = await request(tester, "mapping/reload", {"devices": ["pump"]})
        assert refused["status"] == "error"
        assert "nothing reloaded" in refused["error"] and "start_stop" in refused["error"]
        assert "devices.pump.mapping: " in refused["error"]  # the rows `check` prints
        assert bridge.engine.devices["pump"] is poller

        lines = original.splitlines(keepends=True)
        start = lines.index("  bluetooth_connection:\n")
        end = next(
            i
            for i in range(start + 1, len(lines))
            if lines[i].startswith("  ") and not lines[i].startswith("    ")
        )
        path.write_text("".join(lines[:start] + lines[end:]))
        before = len(tester.log)
        applied = await request(tester, "mapping/reload", {"devices": ["pump"]})
        assert applied["data"] == {"reloaded": ["pump"], "changed": ["pump"]}
        await eventually(lambda: tester.after(before, topic), 10)
        assert "bluetooth_connection" not in tester.json(topic)["cmps"]
        await online(bridge)


@pytest.mark.asyncio
async def test_mapping_reload_switches_a_device_to_a_new_mapping(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """Commissioning: a device gets the mapping just written for it, without a restart."""
    written = builtin_mapping_path("soft_starter").read_text()
    (tmp_path / "starter.yaml").write_text(
        written.replace("name: Fault reset\n", "name: Reset the fault\n", 1)
    )
    switches = {"mapping_switch": True, "mapping_dirs": ["."]}
    async with (
        site(mosquitto, tmp_path, bridge=switches) as (bridge, _),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        topic = "homeassistant/device/starter/config"
        await eventually(lambda: topic in tester.retained, 10)
        assert tester.json(topic)["cmps"]["fault_reset"]["name"] == "Fault reset"

        for body, words in [
            ({"mapping": "starter.yaml"}, "exactly one device"),
            ({"devices": ["pump", "starter"], "mapping": "starter.yaml"}, "exactly one device"),
            ({"devices": ["starter"], "mapping": "missing.yaml"}, "missing.yaml"),
        ]:
            refused = await request(tester, "mapping/reload", body)
            assert refused["status"] == "error" and words in refused["error"], refused

        before = len(tester.log)
        switched = await request(
            tester, "mapping/reload", {"devices": ["starter"], "mapping": "starter.yaml"}
        )
        assert switched["data"] == {"reloaded": ["starter"], "changed": ["starter"]}
        await eventually(lambda: tester.after(before, topic), 10)
        assert tester.json(topic)["cmps"]["fault_reset"]["name"] == "Reset the fault"
        in_use = str((tmp_path / "starter.yaml").resolve())  # the file checked, not a name
        assert bridge.engine.devices["starter"].device.mapping == in_use
        await eventually(lambda: tester.after(before, "modbus/bridge/devices"), 10)
        listing = {d["id"]: d for d in tester.json("modbus/bridge/devices")}
        assert listing["starter"]["mapping"] == in_use
        await online(bridge)


@pytest.mark.asyncio
async def test_health_check_answers(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as (bridge, _), client_of(mosquitto) as tester:
        await online(bridge, tester)
        answer = await request(tester, "health_check", {})
        assert answer["status"] == "ok"
        assert answer["data"]["healthy"] is True
        assert sorted(answer["data"]["devices_online"]) == ["pump", "starter"]
