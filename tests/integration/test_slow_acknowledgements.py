"""A broker that acknowledges the bridge's publishes seconds late after a reconnect (NATS 2.9
on a cluster stores each QoS 1 publish in JetStream first, and a stream that lost its leader
with a node holds the PUBACK for seconds): the commands that arrive meanwhile are served on
time, not left waiting behind the state's acknowledgement until they expire (issue 28: the
commands lost after a node failure)."""

from __future__ import annotations

import pytest

from bridge.app import Bridge
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
