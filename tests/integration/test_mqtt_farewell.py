"""The farewell at a stop (bridge.mqtt.session) against a broker that acknowledges late or not
at all: a real mosquitto behind a relay (tests/integration/proxy.py) that holds back what the broker answers (PUBACKs)
while passing on everything the client sends. Whatever the broker does, the will topic
must not be left ``online``. Where a test shortens ``FAREWELL_TIMEOUT``, it is to keep the
test short, not to replace anything."""

from __future__ import annotations

import pytest

from bridge.mqtt import MqttClient
from bridge.mqtt import session as session_module
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.proxy import relayed
from tests.integration.test_bridge import Observer, observing
from tests.integration.test_mqtt_client import STATE, cfg


def devices_offline(count: int) -> list[tuple[str, str]]:
    return [(f"t/device{i}/availability", "offline") for i in range(count)]


def state(observer: Observer) -> bytes | None:
    return observer.retained.get(STATE)


@pytest.mark.asyncio
async def test_a_broker_that_stops_acknowledging_is_left_offline(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch
) -> None:
    """More farewell messages than paho keeps in flight (20): the goodbye waits behind them
    and never goes out. No clean DISCONNECT then, so the broker publishes the will."""
    monkeypatch.setattr(session_module, "FAREWELL_TIMEOUT", 0.5)
    async with observing(mosquitto, "t/#") as observer, relayed(mosquitto) as (relay, url):
        client = MqttClient(cfg(url), will_topic=STATE)
        await client.__aenter__()
        await eventually(lambda: state(observer) == b"online")
        client.farewell = lambda: devices_offline(30)
        relay.hold = True
        await client.__aexit__(None, None, None)
        await eventually(lambda: state(observer) == b"offline")


@pytest.mark.asyncio
async def test_farewell_messages_are_acknowledged_together(mosquitto: Broker) -> None:
    """Each acknowledgement a second late: one after the other, ten would take twice the
    FAREWELL_TIMEOUT; together they take one second."""
    farewell = devices_offline(10)
    async with observing(mosquitto, "t/#") as observer, relayed(mosquitto) as (relay, url):
        client = MqttClient(cfg(url), will_topic=STATE)
        await client.__aenter__()
        await eventually(lambda: state(observer) == b"online")
        client.farewell = lambda: farewell
        relay.delay = 1.0
        await client.__aexit__(None, None, None)
        await eventually(lambda: state(observer) == b"offline")
        assert all(observer.retained.get(topic) == b"offline" for topic, _ in farewell)
