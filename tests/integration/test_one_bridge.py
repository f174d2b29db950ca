"""One bridge per base topic and per port.

Two bridges started with the same config (an old container left running after moving to
the add-on) both executed every ``/set`` (two writes, two answers, each with its own
breaker-toggle spacing), and each one's Last Will marked the other offline. Now the second
stands by: no commands, no state, no will, no polling, an ERROR naming the other, and it
takes over once the first is gone. A serial port is opened exclusively.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig, SerialBus, load_config_data
from bridge.core.instance import Instance
from bridge.errors import BridgeError
from bridge.modbus.transport import Transport
from bridge.mqtt import MqttClient
from bridge.mqtt import connection as connection_module
from bridge.mqtt import reconnect as reconnect_module
from tests.integration.harness import cancel, eventually, serving_serial, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.proxy import relayed
from tests.integration.test_bridge import observing

PUMP = "nastec_vasco"


@contextlib.asynccontextmanager
async def started(bridge: Bridge) -> AsyncIterator[asyncio.Task[None]]:
    task = asyncio.create_task(bridge.run())
    try:
        yield task
    finally:
        await cancel(task)


async def send(broker: Broker, topic: str, payload: str, *, retain: bool = False) -> None:
    config = MqttConfig(url=broker.url)
    async with MqttClient(config, will_topic="sender/state", client_id="sender") as client:
        await client.publish(topic, payload, retain=retain)


def pump_writes(sim: Any) -> int:
    return sum(1 for unit, _ in sim.writes if unit == 1)


@pytest.fixture(autouse=True)
def quick_standby(monkeypatch: pytest.MonkeyPatch) -> None:
    """Look again every half second (the tests wait for a takeover)."""
    monkeypatch.setattr(reconnect_module, "STANDBY_RETRY", 0.5)


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_a_second_bridge_stands_by_and_a_command_runs_once(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    sim = simulator((1, PUMP))
    watched = (
        "modbus/bridge/state",
        "modbus/nastec_vasco/availability",
        "modbus/nastec_vasco/error",
    )
    async with serving_tcp(sim) as port, observing(mosquitto, *watched) as observer:
        first = Bridge(bridge_config_for(mosquitto, port))
        async with started(first):
            await eventually(lambda: observer.retained.get(watched[1]) == b"online", 15)
            second = Bridge(bridge_config_for(mosquitto, port))
            with caplog.at_level(logging.ERROR, logger="bridge.mqtt.reconnect"):
                async with started(second):
                    await eventually(lambda: second.mqtt_state == "standby", 10)
                    said = [
                        r.getMessage() for r in caplog.records if "another bridge" in r.getMessage()
                    ]
                    assert len(said) == 1, said
                    assert first.instance.host in said[0] and first.instance.id in said[0]
                    assert "docker stop" in said[0] and "mqtt.base_topic" in said[0]
                    polled = second.engine.snapshot()
                    before = pump_writes(sim)
                    await send(mosquitto, "modbus/nastec_vasco/set", '{"start_stop": true}')
                    await eventually(lambda: pump_writes(sim) > before, 10)
                    await asyncio.sleep(1.5)  # a second bridge would have written by now
                    assert pump_writes(sim) == before + 1
                    assert second.engine.snapshot().buses[0].requests == polled.buses[0].requests
                    await asyncio.sleep(1.2)  # it looked again twice: still standing by
                    assert second.mqtt_state == "standby"
                    assert (
                        len([r for r in caplog.records if "another bridge" in r.getMessage()]) == 1
                    )
                # the second one stopped: the first one's state and availability stand
                await asyncio.sleep(0.5)
                assert observer.retained["modbus/bridge/state"] == b"online"
                assert observer.retained[watched[1]] == b"online"
            offline_seen = len([m for m in observer.log if m.payload == b"offline"])
            assert offline_seen == 0


def bridge_config_for(broker: Broker | str, port: int, **bridge: Any) -> Any:
    """One pump on one TCP bus, as two copies of one config file would have it (on the
    broker, or on a URL: a relay in front of it)."""
    url = broker if isinstance(broker, str) else broker.url
    data = {
        "mqtt": {"url": url, "base_topic": "modbus", "command_expiry": 3},
        "bridge": bridge,
        "buses": [
            {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port, "timeout": 0.5}
        ],
        "devices": [{"id": PUMP, "bus": "tcp", "unit": 1, "mapping": PUMP, "poll": {"fast": 0.5}}],
    }
    return load_config_data(data, Path("site.yaml"))


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_the_bridge_standing_by_takes_over_when_the_first_stops(mosquitto: Broker) -> None:
    sim = simulator((1, PUMP))
    async with serving_tcp(sim) as port, observing(mosquitto, "modbus/bridge/info") as observer:
        first = Bridge(bridge_config_for(mosquitto, port))
        second = Bridge(bridge_config_for(mosquitto, port))
        first_task = asyncio.create_task(first.run())
        try:
            await eventually(lambda: first.mqtt_state == "online", 10)
            await eventually(lambda: "modbus/bridge/info" in observer.retained, 10)
            async with started(second):
                await eventually(lambda: second.mqtt_state == "standby", 10)
                await cancel(first_task)
                await eventually(lambda: second.mqtt_state == "online", 10)
                await eventually(
                    lambda: (
                        observer.json("modbus/bridge/info")["instance"]["id"] == second.instance.id
                    ),
                    10,
                )
                before = pump_writes(sim)
                await send(mosquitto, "modbus/nastec_vasco/set", '{"start_stop": true}')
                await eventually(lambda: pump_writes(sim) == before + 1, 10)
                await eventually(lambda: bool(second.engine.devices[PUMP].values), 10)
        finally:
            await cancel(first_task)


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_stale_online_that_nobody_answers_is_taken_over(mosquitto: Broker) -> None:
    """A broker that kept ``online`` through a power cut: the bridge it names is gone."""
    gone = Instance("0123456789ab", "old-host", 7, 1.0)
    info = json.dumps({"instance": gone.document()})
    await send(mosquitto, "modbus/bridge/state", "online", retain=True)
    await send(mosquitto, "modbus/bridge/info", info, retain=True)
    sim = simulator((1, PUMP))
    async with serving_tcp(sim) as port:
        bridge = Bridge(bridge_config_for(mosquitto, port))
        async with started(bridge):
            await eventually(lambda: bridge.mqtt_state == "online", 10)
            await eventually(lambda: bool(bridge.engine.devices[PUMP].values), 10)


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_of_two_bridges_started_together_the_later_one_stands_by(mosquitto: Broker) -> None:
    """Both passed the check at connect; each sees the other's bridge/info arrive live."""
    sim = simulator((1, PUMP))
    async with serving_tcp(sim) as port, observing(mosquitto, "modbus/bridge/info") as observer:
        bridge = Bridge(bridge_config_for(mosquitto, port))
        async with started(bridge):
            await eventually(lambda: bridge.mqtt_state == "online", 10)
            await eventually(lambda: "modbus/bridge/info" in observer.retained, 10)
            mine = bridge.instance
            later = Instance("ffffffffffff", "late-host", 8, mine.started + 5)
            await send(
                mosquitto,
                "modbus/bridge/info",
                json.dumps({"instance": later.document()}),
                retain=True,
            )
            # this one started first: it stays and says so in the record
            await eventually(
                lambda: observer.json("modbus/bridge/info")["instance"]["id"] == mine.id, 10
            )
            assert bridge.mqtt_state == "online"
            earlier = Instance("000000000000", "early-host", 9, mine.started - 5)
            await send(
                mosquitto,
                "modbus/bridge/info",
                json.dumps({"instance": earlier.document()}),
                retain=True,
            )
            await eventually(lambda: bridge.mqtt_state == "standby", 10)


@pytest.mark.asyncio
async def test_a_serial_port_is_opened_by_one_process_only() -> None:
    """pyserial's exclusive lock: a second open of the same adapter fails and says why."""
    async with serving_serial(simulator((1, PUMP))) as path:
        bus = SerialBus(id="rs485", transport="rtu", port=path, timeout=0.5)
        first, second = Transport(bus), Transport(bus)
        try:
            await first.open()
            with pytest.raises(BridgeError) as refused:
                await second.open()
            assert "another program holds the port" in str(refused.value)
        finally:
            first.close()
            second.close()


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_an_unanswered_subscription_is_asked_again_and_state_goes_out_meanwhile(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A cluster that does not answer a SUBSCRIBE in time (its consumer not created yet):
    the session goes on, state and availability go out, the commands are asked for again
    and work once held; bridge/health says which subscriptions hold."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 1.0)  # the SUBACK wait: 10 s in life
    sim = simulator((1, PUMP))
    watched = ("modbus/nastec_vasco/availability", "modbus/bridge/health")
    async with (
        serving_tcp(sim) as port,
        relayed(mosquitto) as (relay, url),
        observing(mosquitto, *watched) as observer,
    ):
        relay.unanswered = b"modbus/+/set"
        bridge = Bridge(bridge_config_for(url, port, health_interval=0.5))
        with caplog.at_level(logging.INFO, logger="bridge"):
            async with started(bridge):
                await eventually(lambda: observer.retained.get(watched[0]) == b"online", 10)
                assert bridge.subscriptions.states["commands"] == "pending"
                await eventually(lambda: bridge.subscriptions.states["commands"] == "live", 10)
                await eventually(lambda: watched[1] in observer.retained, 10)
                health = observer.json(watched[1])
                assert set(health["mqtt"]["subscriptions"]) == {
                    "commands",
                    "home_assistant",
                    "bridge_info",
                }
                before = pump_writes(sim)
                await send(mosquitto, "modbus/nastec_vasco/set", '{"start_stop": true}')
                await eventually(lambda: pump_writes(sim) == before + 1, 10)
    said = [r for r in caplog.records if "did not acknowledge the subscription" in r.getMessage()]
    assert [r.levelno for r in said] == [logging.WARNING]
    assert "commands and requests do not reach the bridge" in said[0].getMessage()
    assert any("subscribed to modbus/+/set" in r.getMessage() for r in caplog.records)
    sessions = [r for r in caplog.records if r.getMessage().startswith("MQTT connected to")]
    assert len(sessions) == 1  # one session throughout: the unanswered SUBACK did not end it
