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
