"""Retained messages any client may publish where the bridge looks at start (discovery
configs under the discovery prefix, the record on ``<base>/bridge/discovery``) never end
the bridge: what it cannot read as its own is left alone, what it can is still cleared."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.discovery_publisher import MAX_RECORDED, recorded_topics
from tests.integration.harness import cancel, eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing

OURS = {"device": {"identifiers": ["modbus_old_pump"]}, "cmps": {}}  # a config we left
OLD = "homeassistant/device/old_pump/config"


@contextlib.asynccontextmanager
async def bare_bridge(broker: Broker) -> AsyncIterator[asyncio.Task[None]]:
    """A bridge without devices: it still sweeps stale discovery at every connect."""
    data = {
        "mqtt": {"url": broker.url, "base_topic": "modbus"},
        "bridge": {"health_interval": 0},
        "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 1}],
        "devices": [],
    }
    task = asyncio.create_task(Bridge(load_config_data(data, Path("bare.yaml"))).run())
    try:
        yield task
    finally:
        await cancel(task)


async def swept(broker: Broker, retained: dict[str, str]) -> dict[str, bytes]:
    """Publish ``retained`` (topic -> payload), start a bridge, wait until it emptied OLD
    (or ended); the retained messages under homeassistant/# then."""
    async with observing(broker, "homeassistant/#") as observer:
        for topic, payload in retained.items():
            await observer.client.publish(topic, payload, retain=True)
        async with bare_bridge(broker) as task:
            await eventually(lambda: observer.retained.get(OLD) == b"" or task.done(), timeout=10)
            assert not task.done(), task.exception()
        return observer.retained


FOREIGN_DEVICES = {
    "device_text": {"device": "modbus_x"},
    "device_list": {"device": ["modbus_x"]},
    "identifiers_number": {"device": {"identifiers": 5}},
    "identifiers_true": {"dev": {"ids": True}},
    "identifiers_object": {"device": {"identifiers": {"modbus_x": 1}}},
    "identifiers_nested": {"device": {"identifiers": [["modbus_x"], {"modbus_x": 1}]}},
}


@pytest.mark.asyncio
async def test_a_config_whose_device_is_not_an_object_is_left_alone(mosquitto: Broker) -> None:
    foreign = {
        f"homeassistant/device/{name}/config": json.dumps(document)
        for name, document in FOREIGN_DEVICES.items()
    }
    foreign["homeassistant/device/deep/config"] = "[" * 100_000  # json.loads: RecursionError
    retained = await swept(mosquitto, foreign | {OLD: json.dumps(OURS)})
    assert retained[OLD] == b""
    assert {t: retained[t].decode() for t in foreign} == foreign


NOT_PUBLISHABLE = [
    "homeassistant/+/config",  # paho refuses wildcards in a publish topic
    "homeassistant/device/#/config",
    "homeassistant/device/nul\x00/config",  # mosquitto drops a client that sends NUL
    "homeassistant/device/\ud800/config",  # a lone surrogate: not UTF-8
    "homeassistant/device/" + "x" * 70_000 + "/config",  # beyond 65535 bytes
    5,
    None,
    ["homeassistant/device/list/config"],
]


@pytest.mark.asyncio
async def test_a_record_of_topics_that_cannot_be_published_is_skipped(mosquitto: Broker) -> None:
    record = json.dumps([*NOT_PUBLISHABLE, OLD])
    retained = await swept(mosquitto, {"modbus/bridge/discovery": record, OLD: json.dumps(OURS)})
    assert retained[OLD] == b""


ZIGBEE = "homeassistant/light/0x1/light/config"
ZIGBEE_DEVICES = "homeassistant/sensor/0x2/config"  # a config without a node id


@pytest.mark.asyncio
async def test_a_record_naming_another_integration_s_configs_does_not_empty_them(
    mosquitto: Broker,
) -> None:
    """A client rewrites the record to list Zigbee configs: the broker shows them holding
    another integration's device, so they stay; our own stale config is still emptied."""
    foreign = json.dumps({"device": {"identifiers": ["zigbee2mqtt_0x1"]}})
    record = json.dumps([ZIGBEE, ZIGBEE_DEVICES, OLD])
    retained = await swept(
        mosquitto,
        {
            "modbus/bridge/discovery": record,
            ZIGBEE: foreign,
            ZIGBEE_DEVICES: foreign,
            OLD: json.dumps(OURS),
        },
    )
    assert retained[OLD] == b""
    assert retained[ZIGBEE] == foreign.encode() == retained[ZIGBEE_DEVICES]


def test_a_record_gives_its_first_topics_only() -> None:
    topics = [f"homeassistant/device/d{i}/config" for i in range(MAX_RECORDED + 10)]
    found = recorded_topics(json.dumps(topics).encode(), "homeassistant")
    assert found == set(topics[:MAX_RECORDED])
    outside = ["homeassistantx/device/a/config", "homeassistant/device/a/state", "[" * 100_000]
    assert recorded_topics(json.dumps(outside).encode(), "homeassistant") == set()
    assert recorded_topics(b"[" * 100_000, "homeassistant") == set()
