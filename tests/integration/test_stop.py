"""What a clean stop leaves on the broker: every device offline before the bridge (run), or
nothing at all (the demo's ``remove_on_stop``)."""

from __future__ import annotations

import asyncio

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig
from bridge.mqtt import MqttClient
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import SEEDS, all_units, bridge_config, observing


async def retained_now(broker: Broker, *filters: str) -> dict[str, bytes]:
    """Every retained message under ``filters``, read by a fresh client."""
    config = MqttConfig(url=broker.url)
    async with MqttClient(config, will_topic="reader/state", client_id="reader") as client:
        found: dict[str, bytes] = {}
        for topic_filter in filters:
            found |= await client.retained(topic_filter)
        return found


async def run_then_stop(broker: Broker, *, remove_on_stop: bool) -> list[tuple[str, bytes]]:
    """Run the bridge until every device is online, stop it as Ctrl-C does; the messages
    seen meanwhile on availability and bridge state topics, in order."""
    sim = all_units()
    watched = ("modbus/+/availability", "modbus/bridge/state")
    async with serving_tcp(sim) as port, observing(broker, *watched) as observer:
        bridge = Bridge(bridge_config(broker, port), remove_on_stop=remove_on_stop)
        task = asyncio.create_task(bridge.run())
        try:
            await eventually(
                lambda: all(
                    observer.retained.get(f"modbus/{d}/availability") == b"online" for d in SEEDS
                ),
                timeout=20,
            )
        finally:
            await cancel(task)
        await eventually(lambda: observer.retained.get("modbus/bridge/state") != b"online")
        return [(m.topic, m.payload) for m in observer.log]


@pytest.mark.asyncio
async def test_a_clean_stop_takes_every_device_offline_before_the_bridge(
    mosquitto: Broker,
) -> None:
    seen = await run_then_stop(mosquitto, remove_on_stop=False)
    last = seen[-(len(SEEDS) + 1) :]
    assert last == [(f"modbus/{d}/availability", b"offline") for d in SEEDS] + [
        ("modbus/bridge/state", b"offline")
    ]
    kept = await retained_now(mosquitto, "modbus/+/availability", "modbus/bridge/state")
    assert set(kept.values()) == {b"offline"}
    assert len(kept) == len(SEEDS) + 1


@pytest.mark.asyncio
async def test_remove_on_stop_leaves_nothing_retained(mosquitto: Broker) -> None:
    """The demo's clean stop: discovery configs, state, values, availability, bridge
    documents: every retained message it published is emptied."""
    seen = await run_then_stop(mosquitto, remove_on_stop=True)
    assert seen[-1] == ("modbus/bridge/state", b"")
    assert await retained_now(mosquitto, "modbus/#", "homeassistant/#") == {}
