"""A broker that acknowledges the bridge's publishes seconds late after a reconnect (NATS 2.9
on a cluster stores each QoS 1 publish in JetStream first, and a stream that lost its leader
with a node holds the PUBACK for seconds): the commands that arrive meanwhile are served on
time, not left waiting behind the state's acknowledgement until they expire (issue 28: the
commands lost after a node failure)."""

from __future__ import annotations

import asyncio
import time

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig
from bridge.mqtt import MqttClient, MqttDisconnectedError
from bridge.mqtt import connection as connection_module
from tests.integration.harness import eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.proxy import relayed
from tests.integration.test_one_bridge import PUMP, bridge_config_for, pump_writes, send, started

LATE = 6.0  # seconds the PUBACKs are held: twice the config's command_expiry (3 s)


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_commands_are_served_while_the_state_waits_for_its_acknowledgement(
    mosquitto: Broker,
) -> None:
    sim = simulator((1, PUMP))
    async with serving_tcp(sim) as port, relayed(mosquitto) as (relay, url):
        bridge = Bridge(bridge_config_for(url, port))
        async with started(bridge):
            await eventually(lambda: bridge.mqtt_state == "online", 10)
            relay.late_pubacks = LATE
            relay.cut()  # the node dies: the bridge reconnects through the relay
            relay.mend()
            await eventually(lambda: bridge.mqtt_state != "online", 10)
            await eventually(lambda: bridge.subscriptions.states["commands"] == "live", 10)
            assert bridge.mqtt_state != "online"  # its state still waits for the PUBACKs
            before = pump_writes(sim)
            await send(mosquitto, "modbus/nastec_vasco/set", '{"start_stop": true}')
            await eventually(lambda: pump_writes(sim) == before + 1, 2 * LATE)
            await eventually(lambda: bridge.mqtt_state == "online", 3 * LATE)  # two round trips


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_publish_behind_a_slowly_acknowledged_burst_waits_and_silence_ends_it(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The broker's answers come 1.5 s late and paho keeps 20 publishes in flight: a single
    publish handed over after a burst of 60 gets its own acknowledgement only after four
    such round trips (6 s), three times the 2 s timeout. The broker acknowledged something
    every 1.5 s meanwhile, so it is waited for (it ended the session: issue 27's slow-broker
    test). A broker that acknowledges nothing at all times out as before."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 2.0)
    async with relayed(mosquitto) as (relay, url):
        config = MqttConfig(url=url, version="5", qos=1)
        async with MqttClient(config, will_topic="slow/state", client_id="slow") as client:
            relay.delay = 1.5
            burst = asyncio.create_task(
                client.publish_many((f"slow/{n}", b"x", True) for n in range(60))
            )
            await asyncio.sleep(0.1)  # handed to paho first: the single one queues behind
            started = time.monotonic()
            await client.publish("slow/last", b"y", retain=True)
            waited = time.monotonic() - started
            await burst
            assert waited > 2 * connection_module.TIMEOUT  # longer than one timeout
            relay.hold = True  # from now on no answer at all
            with pytest.raises(MqttDisconnectedError, match="timed out"):
                await client.publish("slow/unanswered", b"z")
