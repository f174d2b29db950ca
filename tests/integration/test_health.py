"""Health reports and metrics end to end: a real Mosquitto, the simulator, `Bridge.run()`.

Three units on one simulated TCP gateway: ``pump`` answers, ``dead`` never answers
(timeouts), ``faulty`` answers every request with exception 04 (server device failure, which the
Vacon means as a failure too).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import socket
import time
import urllib.error
import urllib.request
from collections.abc import AsyncIterator
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.cli.console import EXIT_FAILED, main
from bridge.config import load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.errors import CommandExpiredError, DeviceTimeoutError, ValueRejectedError
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from tests.integration import harness
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing
from tests.ports import free_port

HEALTH = "modbus/bridge/health"
PUMP, DEAD, FAULTY = 1, 2, 3
FAILURE = 4  # exception 04: server device failure
Sample = tuple[str, tuple[tuple[str, str], ...]]


def three_units() -> Simulator:
    def unit(number: int, name: str, **quirks: Any) -> SimulatedUnit:
        return SimulatedUnit(
            number, load_mapping(builtin_mapping_path(name)), quirks=Quirks(**quirks)
        )

    return Simulator(
        [
            unit(PUMP, "nastec_vasco"),
            unit(DEAD, "p2_vfd", dead=True),
            unit(FAULTY, "vacon_nx", exception_code=FAILURE),
        ]
    )


def health_config(
    broker_url: str,
    port: int,
    *,
    health_interval: float = 0.2,
    mqtt: dict[str, Any] | None = None,
    **bridge: Any,
) -> Any:
    devices = [
        {"id": "pump", "bus": "tcp", "unit": PUMP, "mapping": "nastec_vasco"},
        {"id": "dead", "bus": "tcp", "unit": DEAD, "mapping": "p2_vfd"},
        {"id": "faulty", "bus": "tcp", "unit": FAULTY, "mapping": "vacon_nx"},
    ]
    data = {
        "mqtt": {"url": broker_url, "base_topic": "modbus", "command_expiry": 3} | (mqtt or {}),
        "bridge": {"health_interval": health_interval} | bridge,
        "buses": [
            {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port, "timeout": 0.3}
        ],
        "devices": [d | {"poll": {"fast": 0.3, "slow": 5}} for d in devices],
    }
    return load_config_data(data, Path("health.yaml"))


@contextlib.asynccontextmanager
async def running(broker: Broker, **bridge: Any) -> AsyncIterator[Bridge]:
    async with serving_tcp(three_units()) as port:
        running_bridge = Bridge(health_config(broker.url, port, **bridge))
        task = asyncio.create_task(running_bridge.run())
        try:
            yield running_bridge
        finally:
            await cancel(task)


def reports(observer: Observer) -> list[dict[str, Any]]:
    """The health reports seen (an empty payload clears the retained one: not a report)."""
    return [json.loads(m.payload) for m in observer.log if m.topic == HEALTH and m.payload]


def latest(observer: Observer) -> dict[str, Any]:
    found = reports(observer)
    return found[-1] if found else {}


def device(observer: Observer, device_id: str) -> dict[str, Any]:
    return latest(observer).get("devices", {}).get(device_id, {})


def scrape(port: int, path: str = "/metrics") -> dict[Sample, float]:
    """Every sample of a Prometheus text scrape, by name and sorted labels."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as answer:
        text = answer.read().decode()
    samples: dict[Sample, float] = {}
    for line in text.splitlines():
        if not line or line.startswith("#"):
            continue
        series, value = line.rsplit(" ", 1)
        name, _, labels = series.partition("{")
        pairs = tuple(sorted(re.findall(r'(\w+)="([^"]*)"', labels)))
        samples[(name, pairs)] = float(value)
    return samples


@pytest.mark.asyncio
async def test_health_is_published_periodically_and_counts_what_happens(mosquitto: Broker) -> None:
    async with observing(mosquitto, "modbus/bridge/#") as observer, running(mosquitto):
        await eventually(lambda: len(reports(observer)) >= 3, timeout=10)
        assert all(not m.retain for m in observer.log if m.topic == HEALTH)
        first, second = reports(observer)[:2]
        assert datetime.fromisoformat(first["timestamp"]) <= datetime.fromisoformat(
            second["timestamp"]
        )
        assert first["uptime_s"] <= second["uptime_s"]
        assert set(second["buses"]) == {"tcp"}
        assert set(second["devices"]) == {"pump", "dead", "faulty"}

        # the dead unit: timeouts, then offline with a backoff and never a success
        await eventually(lambda: device(observer, "dead").get("state") == "offline", timeout=10)
        dead = device(observer, "dead")
        assert dead["timeouts"] >= 3
        assert dead["errors"] >= dead["timeouts"]
        assert dead["consecutive_failures"] >= 3
        assert dead["backoff_s"] > 0
        assert dead["last_success"] is None
        assert dead["latency_p95_ms"] is None

        # the faulty unit: its exception code counted under its string key
        await eventually(lambda: device(observer, "faulty").get("exceptions", {}).get("4", 0) >= 3)
        faulty = device(observer, "faulty")
        assert set(faulty["exceptions"]) == {"4"}
        assert faulty["state"] == "offline"  # 04 means failure: it counts towards offline
        assert faulty["timeouts"] == 0

        # the healthy unit: online, latencies and a last success in UTC
        await eventually(lambda: device(observer, "pump").get("latency_p95_ms") is not None)
        document = latest(observer)
        pump = document["devices"]["pump"]
        assert (pump["state"], pump["bus"], pump["unit"]) == ("online", "tcp", PUMP)
        assert pump["requests"] > 0
        assert pump["errors"] == 0
        assert 0 < pump["latency_p50_ms"] <= pump["latency_p95_ms"]
        assert datetime.fromisoformat(pump["last_success"]).utcoffset().total_seconds() == 0

        # the bus sees every frame of every device
        bus = document["buses"]["tcp"]
        devices = document["devices"].values()
        assert (bus["transport"], bus["connected"]) == ("tcp", True)
        assert bus["requests"] >= sum(d["requests"] for d in devices)
        assert bus["timeouts"] >= document["devices"]["dead"]["timeouts"]
        assert bus["exceptions"] >= document["devices"]["faulty"]["exceptions"]["4"]
        assert bus["frame_errors"] == 0
        assert 0 <= bus["utilisation"] <= 1
        await eventually(lambda: latest(observer)["buses"]["tcp"]["requests_per_s"] > 0)


@pytest.mark.asyncio
async def test_write_counters(mosquitto: Broker) -> None:
    """delta_start is an EEPROM setting: the value it holds is skipped, a new one written,
    the same again skipped, another within the EEPROM interval refused; out of range too."""
    async with observing(mosquitto, "modbus/#") as observer, running(mosquitto):
        await eventually(
            lambda: (
                "modbus/pump" in observer.retained and "delta_start" in observer.json("modbus/pump")
            ),
            timeout=10,
        )
        held = observer.json("modbus/pump")["delta_start"]
        client = observer.client

        await client.publish("modbus/pump/delta_start/set", str(held))
        await eventually(lambda: device(observer, "pump").get("writes_skipped_unchanged") == 1)
        assert device(observer, "pump")["writes_done"] == 0

        new = round(held + 1.5, 1)
        await client.publish("modbus/pump/delta_start/set", str(new))
        await eventually(lambda: device(observer, "pump").get("writes_done") == 1)
        await eventually(lambda: observer.json("modbus/pump")["delta_start"] == new)

        await client.publish("modbus/pump/delta_start/set", str(new))  # the same: skipped
        await client.publish("modbus/pump/delta_start/set", str(held))  # EEPROM rate limit
        await client.publish("modbus/pump/delta_start/set", "5000")  # out of range
        await eventually(lambda: device(observer, "pump").get("writes_rejected") == 2)
        pump = device(observer, "pump")
        assert (pump["writes_done"], pump["writes_skipped_unchanged"]) == (1, 2)
        assert (pump["writes_failed"], pump["writes_expired"]) == (0, 0)


@pytest.mark.asyncio
async def test_every_write_ends_in_one_counter() -> None:
    """Failed (no answer) and expired (not sent by its deadline) writes, on the engine."""
    async with serving_tcp(three_units()) as port:
        engine = Engine(health_config("mqtt://127.0.0.1:1", port))
        async with harness.running(engine, pollers=False):
            with pytest.raises(DeviceTimeoutError):
                await engine.devices["dead"].write("set_value", 10)
            pump = engine.devices["pump"]
            await pump.read_now(["delta_start"])
            new = float(pump.values["delta_start"] or 0) + 1
            with pytest.raises(CommandExpiredError):
                await pump.write("delta_start", new, deadline=time.monotonic() - 1)
            with pytest.raises(ValueRejectedError):
                await pump.write("no_such_entity", 1)
        writes = {d.device_id: d.writes for d in engine.snapshot().devices}
    assert (writes["dead"].failed, writes["dead"].done) == (1, 0)
    assert (writes["pump"].expired, writes["pump"].rejected, writes["pump"].done) == (1, 1, 0)


@pytest.mark.asyncio
async def test_metrics_endpoint_serves_the_same_counters(mosquitto: Broker) -> None:
    port = free_port()
    metrics = {"enabled": True, "host": "127.0.0.1", "port": port}
    async with (
        observing(mosquitto, "modbus/bridge/#") as observer,
        running(mosquitto, metrics=metrics) as bridge,
    ):
        await eventually(
            lambda: (
                device(observer, "dead").get("state") == "offline"
                and device(observer, "faulty").get("exceptions", {}).get("4", 0) > 0
                and device(observer, "pump").get("requests", 0) > 0
            ),
            timeout=10,
        )
        before = latest(observer)
        samples = await asyncio.to_thread(scrape, port)
        after = bridge.engine.snapshot()

        def sample(name: str, **labels: str) -> float:
            return samples[(name, tuple(sorted(labels.items())))]

        # counters only grow: the report before the scrape <= the scrape <= a snapshot after
        bus_before, bus_after = before["buses"]["tcp"], after.buses[0]
        for name, field in (("requests", "requests"), ("timeouts", "timeouts")):
            scraped = sample(f"modbus_bus_{name}_total", bus="tcp")
            assert bus_before[field] <= scraped <= getattr(bus_after, field), name
        devices_after = {d.device_id: d for d in after.devices}
        for device_id in ("pump", "dead", "faulty"):
            scraped = sample("modbus_device_requests_total", device=device_id)
            assert before["devices"][device_id]["requests"] <= scraped
            assert scraped <= devices_after[device_id].requests
        faults = sample("modbus_device_exceptions_total", device="faulty", code="4")
        assert before["devices"]["faulty"]["exceptions"]["4"] <= faults
        assert sample("modbus_device_timeouts_total", device="dead") >= 3
        assert sample("modbus_device_unknown_codes_total", device="pump") == 0
        assert sample("modbus_device_online", device="pump") == 1.0
        assert sample("modbus_device_online", device="dead") == 0.0
        assert sample("modbus_device_consecutive_failures", device="dead") >= 3
        assert sample("modbus_device_backoff_seconds", device="dead") > 0
        assert sample("modbus_bus_connected", bus="tcp") == 1.0
        assert sample("modbus_bus_busy_seconds_total", bus="tcp") > 0
        assert sample("modbus_device_latency_seconds", device="pump", quantile="0.95") > 0
        assert sample("modbus_device_last_success_timestamp_seconds", device="pump") > 0
        assert ("modbus_device_last_success_timestamp_seconds", (("device", "dead"),)) not in (
            samples
        )
        for result in ("done", "skipped_unchanged", "rejected", "failed", "expired"):
            assert sample("modbus_device_writes_total", device="pump", result=result) == 0

        with pytest.raises(urllib.error.HTTPError, match="404"):
            await asyncio.to_thread(scrape, port, "/elsewhere")

    with pytest.raises(urllib.error.URLError):  # stopped with the bridge
        await asyncio.to_thread(scrape, port)


@pytest.mark.asyncio
async def test_health_interval_zero_publishes_no_health_and_no_health_sensors(
    mosquitto: Broker,
) -> None:
    async with (
        observing(mosquitto, "modbus/bridge/#", "homeassistant/device/modbus/config") as observer,
        serving_tcp(three_units()) as port,
    ):
        config = health_config(mosquitto.url, port, health_interval=0, mqtt={"state_refresh": 0.3})
        task = asyncio.create_task(Bridge(config).run())
        try:
            # a second bridge/devices comes from the refresher, which starts with the
            # health task: by then a first report would have been published
            await eventually(
                lambda: sum(m.topic == "modbus/bridge/devices" for m in observer.log) >= 2,
                timeout=10,
            )
            discovery = observer.json("homeassistant/device/modbus/config")
        finally:
            await cancel(task)
    assert reports(observer) == []
    cleared = [m for m in observer.log if m.topic == HEALTH]
    assert all(m.payload == b"" for m in cleared)  # an old retained report is cleared
    assert list(discovery["cmps"]) == ["connection_state"]


@pytest.mark.asyncio
async def test_health_sensors_in_discovery(mosquitto: Broker) -> None:
    """Per bus on the bridge device; per device on the device itself."""
    devices = ("pump", "dead", "faulty")
    topics = ["homeassistant/device/modbus/config"]
    topics += [f"homeassistant/device/{device_id}/config" for device_id in devices]
    async with observing(mosquitto, *topics) as observer, running(mosquitto):
        await eventually(lambda: all(t in observer.retained for t in topics), timeout=10)
        bridge = observer.json(topics[0])["cmps"]
        on_devices = {d: observer.json(t)["cmps"] for d, t in zip(devices, topics[1:], strict=True)}
    assert list(bridge) == ["connection_state"] + [
        f"bus_tcp_{suffix}"
        for suffix in ("request_rate", "utilisation", "timeouts", "frame_errors")
    ]
    for device_id, cmps in on_devices.items():
        health = [key for key in cmps if key.startswith(f"device_{device_id}_")]
        assert len(health) == 4, device_id
        assert cmps[f"device_{device_id}_state"]["state_topic"] == HEALTH


@pytest.mark.asyncio
async def test_metrics_port_in_use_is_a_clear_error(mosquitto: Broker) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        metrics = {"enabled": True, "host": "127.0.0.1", "port": port}
        config = health_config(mosquitto.url, 1, metrics=metrics)
        with pytest.raises(OSError, match=f"metrics endpoint: cannot listen on 127.0.0.1:{port}"):
            async with asyncio.timeout(10):
                await Bridge(config).run()


def test_metrics_port_in_use_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        config = tmp_path / "config.yaml"
        config.write_text(
            json.dumps(
                {
                    "mqtt": {"url": "mqtt://127.0.0.1:1"},
                    "bridge": {"metrics": {"enabled": True, "port": port}},
                    "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1"}],
                }
            )
        )
        assert main(["run", "-c", str(config)]) == EXIT_FAILED
    error = capsys.readouterr().err
    assert f"metrics endpoint: cannot listen on 127.0.0.1:{port}: address already in use" in error
    assert "Traceback" not in error


def health_check(port: int, path: str = "/health") -> tuple[int, dict[str, Any]]:
    """What a GET of ``path`` sees: the status code and the document."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as refused:
        return refused.code, json.loads(refused.read())


@pytest.mark.asyncio
async def test_health_says_a_bus_is_down_and_why_until_the_adapter_appears(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """A serial bus whose adapter is missing makes /health/buses answer 503 with the reason
    (and bridge/health carry it), while the TCP bus polls and /health (the container's
    check) answers 200 naming the bus; once the adapter appears (a pty linked at the
    configured path) the bus opens and /health/buses answers 200."""
    adapter = tmp_path / "ttyUSB0"
    metrics_port = free_port()
    async with (
        observing(mosquitto, HEALTH) as observer,
        serving_tcp(three_units()) as port,
        harness.serving_serial(harness.simulator((1, "vacon_nx"))) as bridge_end,
    ):
        loaded = health_config(mosquitto.url, port, metrics={"enabled": True, "port": metrics_port})
        serial = {"id": "rs485", "transport": "rtu", "port": str(adapter), "timeout": 0.3}
        drive = {"id": "drive", "bus": "rs485", "unit": 1, "mapping": "vacon_nx",
                 "poll": {"fast": 0.3, "slow": 5}}  # fmt: skip
        data = loaded.config.model_dump(mode="json", exclude_none=True)
        data["buses"].append(serial)
        data["devices"].append(drive)
        task = asyncio.create_task(Bridge(load_config_data(data, Path("health.yaml"))).run())
        try:
            await eventually(
                lambda: latest(observer).get("buses", {}).get("rs485", {}).get("error"),
                timeout=10,
            )
            alive = await asyncio.to_thread(health_check, metrics_port)
            assert alive == (200, {"status": "ok", "buses_down": ["rs485"]})
            status, document = await asyncio.to_thread(health_check, metrics_port, "/health/buses")
            assert status == 503
            assert document["status"] == "down"
            assert list(document["buses"]) == ["rs485"]  # the TCP bus is up
            reason = document["buses"]["rs485"]
            assert f"cannot open {adapter}" in reason
            assert "No such file or directory" in reason and "plugged in" in reason
            assert latest(observer)["buses"]["rs485"]["connected"] is False
            assert latest(observer)["buses"]["tcp"]["error"] is None

            adapter.symlink_to(bridge_end)  # the adapter is plugged in
            await eventually(
                lambda: latest(observer).get("buses", {}).get("rs485", {}).get("connected"),
                timeout=20,
            )
            for path in ("/health", "/health/buses"):
                status, document = await asyncio.to_thread(health_check, metrics_port, path)
                assert (status, document) == (200, {"status": "ok"}), path
            assert latest(observer)["buses"]["rs485"]["error"] is None
        finally:
            await cancel(task)
