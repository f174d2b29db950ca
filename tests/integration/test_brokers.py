"""The bridge against the brokers users run: Mosquitto, NATS (MQTT + JetStream), RabbitMQ
(MQTT plugin) and amqtt, each a private instance on free loopback ports (a test skips when
its broker is not installed). docs/brokers.md is the table these tests back.

One scenario per broker, the bridge running as its own process (``modbus-mqtt-bridge run``)
with its default ``mqtt.version: 5``, so that each broker's answer to an MQTT 5 CONNECT is
part of the test:

1. a retained ``/set`` waits on the broker before the bridge starts: it is never executed;
2. discovery and state are retained: a client that subscribes to the exact topics later
   gets them (RabbitMQ gives retained messages to exact-topic subscriptions only);
3. a live command is written and its new value published;
4. the bridge dies (SIGKILL): the broker publishes its Last Will ``offline``;
5. the bridge starts again with a device less: that device's retained discovery config is
   emptied (found through ``<base>/bridge/discovery`` where wildcards see no retained);
6. the broker restarts: the bridge reconnects, publishes ``online`` and executes commands;
7. a clean stop publishes ``offline`` (retained).

Observers use MQTT 3.1.1 (what they speak does not matter here, and amqtt would make every
one of them wait for an MQTT 5 answer that never comes).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.config import MqttConfig
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Simulator
from bridge.mqtt import MqttClient, MqttDisconnectedError
from bridge.mqtt import connection as connection_module
from tests.integration.brokers import AmqttBroker, NatsBroker, RabbitBroker, ServerBroker
from tests.integration.harness import cancel, eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker, has_mosquitto

AnyBroker = Broker | ServerBroker
BROKERS = ("mosquitto", "nats", "rabbitmq", "amqtt")
PUMP, STARTER = 1, 3
FREQUENCY = load_mapping(builtin_mapping_path("nastec_vasco")).points()["operating_frequency"]


def _session_broker(
    kind: type[ServerBroker], factory: pytest.TempPathFactory, name: str
) -> Iterator[ServerBroker]:
    if not kind.available():  # type: ignore[attr-defined]
        pytest.skip(f"{name} is not installed")
    broker = kind(factory.mktemp(name))
    broker.start()
    try:
        yield broker
    finally:
        if broker.exited():  # shown under the failing test's teardown
            print(f"{name} had exited; its log:\n{broker.log}", file=sys.stderr)
        broker.stop()


@pytest.fixture(scope="module")
def nats(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerBroker]:
    yield from _session_broker(NatsBroker, tmp_path_factory, "nats")


@pytest.fixture(scope="module")
def rabbitmq(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerBroker]:
    yield from _session_broker(RabbitBroker, tmp_path_factory, "rabbitmq")


@pytest.fixture(scope="module")
def amqtt(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerBroker]:
    yield from _session_broker(AmqttBroker, tmp_path_factory, "amqtt")


@pytest.fixture(scope="module")
def mosquitto_module(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Broker]:
    if not has_mosquitto():
        pytest.skip("no /usr/sbin/mosquitto")
    broker = Broker(tmp_path_factory.mktemp("mosquitto"))
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


@pytest.fixture(params=BROKERS)
def broker(request: pytest.FixtureRequest) -> AnyBroker:
    name = "mosquitto_module" if request.param == "mosquitto" else request.param
    found: AnyBroker = request.getfixturevalue(name)
    return found


# --- observers ------------------------------------------------------------------------------


def observer_config(broker: AnyBroker) -> MqttConfig:
    return MqttConfig(url=broker.url, version="3.1.1", keepalive=10)


class Watcher:
    """Records every live message under some filters (a client of its own)."""

    def __init__(self, client: MqttClient) -> None:
        self.client = client
        self.messages: list[tuple[str, bytes]] = []

    async def run(self) -> None:
        with contextlib.suppress(MqttDisconnectedError):  # the broker restarts
            async for message in self.client.messages():
                self.messages.append((message.topic, message.payload))

    def got(self, topic: str, payload: bytes | None = None) -> bool:
        return any(t == topic and (payload is None or p == payload) for t, p in self.messages)

    def last(self, topic: str) -> bytes | None:
        found = [p for t, p in self.messages if t == topic]
        return found[-1] if found else None


@contextlib.asynccontextmanager
async def watching(broker: AnyBroker, *filters: str) -> AsyncIterator[Watcher]:
    config = observer_config(broker)
    name = f"watcher{os.getpid()}"
    async with MqttClient(config, will_topic=f"watchers/{name}", client_id=name) as client:
        watcher = Watcher(client)
        task = asyncio.create_task(watcher.run())
        await client.subscribe(*filters)
        try:
            yield watcher
        finally:
            await cancel(task)


async def retained(broker: AnyBroker, *topics: str) -> dict[str, bytes]:
    """The retained messages of exact topics, as a client that subscribes now gets them."""
    config = observer_config(broker)
    name = f"reader{os.getpid()}"
    found: dict[str, bytes] = {}
    async with MqttClient(config, will_topic=f"readers/{name}", client_id=name) as client:
        for topic in topics:
            found |= await client.retained(topic, settle=0.3)
    return {topic: payload for topic, payload in found.items() if payload}


async def publish(broker: AnyBroker, topic: str, payload: bytes, *, retain: bool = False) -> None:
    config = observer_config(broker)
    name = f"publisher{os.getpid()}"
    async with MqttClient(config, will_topic=f"publishers/{name}", client_id=name) as client:
        await client.publish(topic, payload, retain=retain)


# --- the bridge as a process ----------------------------------------------------------------


class BridgeProcess:
    """``modbus-mqtt-bridge run -c FILE`` in a child process."""

    def __init__(self, config: Path, log: Path) -> None:
        self.config, self.log_path = config, log
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "bridge.cli", "run", "-c", str(self.config)],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=dict(os.environ) | {"PYTHONPATH": str(Path(__file__).resolve().parents[2])},
            )

    def end(self, signum: int) -> int:
        assert self.process is not None
        self.process.send_signal(signum)
        code = self.process.wait(15)
        self.process = None
        return code

    @property
    def log(self) -> str:
        return self.log_path.read_text(errors="replace")[-3000:]


def write_config(
    path: Path,
    broker: AnyBroker,
    modbus_port: int,
    base: str,
    prefix: str,
    *,
    starter: bool,
    version: str = "5",
) -> None:
    devices = [{"id": "pump", "bus": "sim", "unit": PUMP, "mapping": "nastec_vasco"}]
    if starter:
        devices.append({"id": "starter", "bus": "sim", "unit": STARTER, "mapping": "soft_starter"})
    config = {
        "mqtt": {
            "url": broker.url,
            "base_topic": base,
            "discovery_prefix": prefix,
            "version": version,
        },
        "buses": [
            {"id": "sim", "transport": "tcp", "host": "127.0.0.1", "tcp_port": modbus_port,
             "timeout": "0.5s"}
        ],
        "devices": [d | {"poll": {"fast": "0.5s", "slow": "5s"}} for d in devices],
    }  # fmt: skip
    path.write_text(yaml.safe_dump(config), encoding="utf-8")


def frequency_writes(sim: Simulator) -> list[int]:
    return [
        write.values[0]
        for unit, write in sim.writes
        if unit == PUMP and write.address == FREQUENCY.address
    ]


def state(watcher: Watcher, base: str, device: str) -> dict[str, Any]:
    payload = watcher.last(f"{base}/{device}")
    return json.loads(payload) if payload else {}


@pytest.mark.asyncio
@pytest.mark.timeout(180)
async def test_the_bridge_on_each_broker(broker: AnyBroker, tmp_path: Path) -> None:
    name = broker.__class__.__name__.lower()
    base, prefix = f"site-{name}", f"ha-{name}"
    pump_config, starter_config = f"{prefix}/device/pump/config", f"{prefix}/device/starter/config"
    bridge_state = f"{base}/bridge/state"
    sim = simulator((PUMP, "nastec_vasco"), (STARTER, "soft_starter"))
    config, log = tmp_path / "config.yaml", tmp_path / "bridge.log"
    async with serving_tcp(sim) as modbus_port:
        # 1. a retained command waits on the broker before the bridge starts
        await publish(broker, f"{base}/pump/operating_frequency/set", b"33", retain=True)
        write_config(config, broker, modbus_port, base, prefix, starter=True)
        bridge = BridgeProcess(config, log)
        try:
            async with watching(broker, f"{base}/#", f"{prefix}/#") as watcher:
                bridge.start()
                await eventually(
                    lambda: (
                        watcher.got(f"{base}/pump/availability", b"online")
                        and watcher.got(f"{base}/starter/availability", b"online")
                    ),
                    timeout=40,
                )
                # 2. discovery and state are retained
                wanted = {pump_config, starter_config, f"{base}/pump", bridge_state,
                          f"{base}/pump/availability"}  # fmt: skip
                stored: dict[str, bytes] = {}
                for _ in range(50):  # discovery follows the first values
                    stored = await retained(broker, *wanted)
                    if set(stored) == wanted:
                        break
                    await asyncio.sleep(0.2)
                assert set(stored) == wanted, bridge.log
                assert json.loads(stored[pump_config])["device"]["identifiers"] == [f"{base}_pump"]
                assert "operating_frequency" in json.loads(stored[f"{base}/pump"])
                assert stored[bridge_state] == b"online"
                # 3. a live command is written and published
                await publish(broker, f"{base}/pump/operating_frequency/set", b"42")
                await eventually(
                    lambda: state(watcher, base, "pump").get("operating_frequency") == 42,
                    timeout=15,
                )
                # 1. the retained one was never written: only the live 42 reached the pump
                assert frequency_writes(sim) == [42], bridge.log
                await publish(broker, f"{base}/pump/operating_frequency/set", b"", retain=True)
                # 4. the bridge dies: the broker publishes its Last Will
                bridge.end(signal.SIGKILL)
                await eventually(lambda: watcher.last(bridge_state) == b"offline", timeout=30)
            assert (await retained(broker, bridge_state))[bridge_state] == b"offline"

            # 5. a device less: its retained discovery config is emptied (asking for the
            # version the broker answered: amqtt would keep it 10 s on an MQTT 5 CONNECT)
            version = "3.1.1" if "3.1.1" in bridge.log else "5"
            write_config(config, broker, modbus_port, base, prefix, starter=False, version=version)
            async with watching(broker, f"{base}/#", f"{prefix}/#") as watcher:
                bridge.start()
                await eventually(lambda: watcher.got(starter_config, b""), timeout=40)
                await eventually(lambda: watcher.last(bridge_state) == b"online", timeout=20)
            stored = await retained(broker, pump_config, starter_config, f"{base}/bridge/discovery")
            assert set(stored) == {pump_config, f"{base}/bridge/discovery"}
            recorded = json.loads(stored[f"{base}/bridge/discovery"])
            assert pump_config in recorded and starter_config not in recorded

            # 6. the broker restarts: the bridge reconnects and takes commands again
            await asyncio.to_thread(broker.restart)
            async with watching(broker, f"{base}/#") as watcher:
                # sent until the bridge is back (a command before its resubscription is
                # lost: commands are never retained)
                async with asyncio.timeout(60):
                    while frequency_writes(sim)[-1:] != [43]:
                        await publish(broker, f"{base}/pump/operating_frequency/set", b"43")
                        with contextlib.suppress(TimeoutError):
                            await eventually(lambda: frequency_writes(sim)[-1:] == [43], 1)
                await eventually(
                    lambda: state(watcher, base, "pump").get("operating_frequency") == 43,
                    timeout=15,
                )
            assert (await retained(broker, bridge_state))[bridge_state] == b"online"

            # 7. a clean stop says offline
            assert bridge.end(signal.SIGTERM) == 0, bridge.log
            assert (await retained(broker, bridge_state))[bridge_state] == b"offline"
        finally:
            if bridge.process is not None:
                bridge.end(signal.SIGKILL)
    assert "Traceback" not in bridge.log, bridge.log


@pytest.mark.asyncio
async def test_qos_2(broker: AnyBroker, monkeypatch: pytest.MonkeyPatch) -> None:
    """``mqtt.qos: 2`` works where the broker does QoS 2 (RabbitMQ grants QoS 1 for it);
    NATS before 2.10 never acknowledges a QoS 2 publish, and the error says to set
    ``mqtt.qos: 1``."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 2.0)  # NATS: the wait for an answer
    config = MqttConfig(url=broker.url, qos=2, version="3.1.1")
    if isinstance(broker, NatsBroker) and NatsBroker.version() < (2, 10):
        with pytest.raises(MqttDisconnectedError, match=r"set mqtt\.qos: 1"):
            await MqttClient(config, will_topic="qos2/state", client_id="qos2").__aenter__()
        return
    async with MqttClient(config, will_topic="qos2/state", client_id="qos2") as client:
        await client.subscribe("qos2/x", qos=2)
        await client.publish("qos2/x", b"exactly once")
        async with asyncio.timeout(10):
            async for message in client.messages():  # amqtt adds others' retained ones
                if message.topic == "qos2/x":
                    break
    assert message.payload == b"exactly once"
