"""Each entity's own poll interval, end to end: a real Mosquitto, the simulator on loopback
TCP and ``Bridge.run()``. Polls are counted on the simulator (the reads it answered per
table), never timed."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing

# one table per interval, so that no read serves two of them
MAPPING = """\
manufacturer: Test
model: Intervals
description: entities at intervals of their own
source: {title: test}
entities:
  quick: {name: Quick, table: holding, address: 1, poll: 300ms}
  tuned: {name: Tuned, table: discrete, address: 1, poll: slow}
  slowly: {name: Slowly, table: input, address: 1, poll: slow}
"""


@contextlib.asynccontextmanager
async def bridge_on(broker: Broker, sim: Simulator, mapping: Path) -> AsyncIterator[Bridge]:
    async with serving_tcp(sim) as port:
        device = {
            "id": "meter",
            "bus": "tcp",
            "unit": 1,
            "mapping": str(mapping),
            # the device config gives one entity an interval of its own
            "poll": {"fast": 10, "slow": 60, "entities": {"tuned": "300ms"}},
        }
        data = {
            "mqtt": {"url": broker.url, "base_topic": "modbus"},
            "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}],
            "devices": [device],
        }
        bridge = Bridge(load_config_data(data, Path("intervals.yaml")))
        task = asyncio.create_task(bridge.run())
        try:
            yield bridge
        finally:
            await cancel(task)


@pytest.mark.asyncio
async def test_an_entity_with_its_own_short_interval_is_read_more_often(
    mosquitto: Broker, tmp_path: Path
) -> None:
    path = tmp_path / "intervals.yaml"
    path.write_text(MAPPING)
    sim = Simulator([SimulatedUnit(1, load_mapping(path))], tick=0, read_log=10_000)

    def reads(table: Table) -> int:
        return sum(1 for read, _ in sim.reads(1) if read.table is table)

    async with (
        observing(mosquitto, "homeassistant/device/meter/config") as observer,
        bridge_on(mosquitto, sim, path) as bridge,
    ):
        await eventually(lambda: reads(Table.HOLDING) >= 6 and reads(Table.DISCRETE) >= 6, 20)
        slow_reads = reads(Table.INPUT)
        await eventually(lambda: "homeassistant/device/meter/config" in observer.retained, 10)
        poller = bridge.engine.devices["meter"]
    assert slow_reads == 1  # the slow entity: once at start, the next in 60 s
    assert poller.state.intervals == {"quick": 0.3, "tuned": 0.3, "slowly": 60.0}
    components = json.loads(observer.retained["homeassistant/device/meter/config"])["cmps"]
    refresh = 2 * 300  # two state refreshes, then the entity's own interval
    assert components["quick"]["expire_after"] == int(refresh + 0.3)
    assert components["tuned"]["expire_after"] == int(refresh + 0.3)
    assert components["slowly"]["expire_after"] == refresh + 60
