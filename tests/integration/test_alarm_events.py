"""Alarm events through the whole bridge (issue 25): a real Mosquitto, the simulator tripped
on demand, and the messages counted on ``modbus/<device>/event``: each raise and clear
once, and nothing again on a restart, a broker restart, Home Assistant's ``online``, a
mapping reload or a device going offline and back."""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.cli.demo_control import fault_request
from bridge.config import load_config_data
from bridge.core.mapping import builtin_mapping_path
from bridge.modbus.simulator import Quirks, Simulator
from tests.integration.harness import cancel, eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

PUMP, DRIVE = 1, 2
POLL = 0.2


def alarm_sim() -> Simulator:
    return simulator((PUMP, "nastec_vasco"), (DRIVE, "p2_vfd"))


@contextlib.asynccontextmanager
async def bridged(broker: Broker, sim: Simulator, folder: Path) -> AsyncIterator[Bridge]:
    """The bridge on ``sim``; the pump's mapping is a copy in ``folder`` (to reload)."""
    pump = folder / "pump.yaml"
    if not pump.exists():
        shutil.copy(builtin_mapping_path("nastec_vasco"), pump)
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {"url": broker.url, "base_topic": "modbus"},
            "bridge": {"mapping_dirs": ["."]},
            "buses": [
                {
                    "id": "tcp",
                    "transport": "tcp",
                    "host": "127.0.0.1",
                    "tcp_port": port,
                    "timeout": 0.3,
                }
            ],
            "devices": [
                {
                    "id": device_id,
                    "bus": "tcp",
                    "unit": unit,
                    "mapping": mapping,
                    "poll": {"fast": POLL, "slow": POLL},
                }
                for device_id, unit, mapping in [
                    ("pump", PUMP, "pump.yaml"),
                    ("drive", DRIVE, "p2_vfd"),
                ]
            ],
        }
        bridge = Bridge(load_config_data(data, folder / "config.yaml"))
        task = asyncio.create_task(bridge.run())
        try:
            yield bridge
        finally:
            await cancel(task)


def events(observer: Observer, device: str) -> list[tuple[str, str]]:
    return [
        (json.loads(m.payload)["alarm"], json.loads(m.payload)["transition"])
        for m in observer.log
        if m.topic == f"modbus/{device}/event"
    ]


async def quiet(seconds: float = 1.5) -> None:
    """Long enough for several polls: an event that would come has come."""
    await asyncio.sleep(seconds)


async def online(observer: Observer, *devices: str) -> None:
    for device in devices:
        topic = f"modbus/{device}/availability"
        # generous: a device back from offline waits out its retry backoff, longer on a
        # loaded machine (returns as soon as it is online)
        await eventually(lambda t=topic: observer.retained.get(t) == b"online", timeout=30)


@pytest.mark.asyncio
async def test_a_raise_and_a_clear_each_fire_once(mosquitto: Broker, tmp_path: Path) -> None:
    sim = alarm_sim()
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim, tmp_path):
        await online(observer, "pump", "drive")
        await quiet()
        assert events(observer, "pump") == events(observer, "drive") == []
        sim.raise_fault(PUMP, "alarm_dry_running")
        await eventually(lambda: events(observer, "pump") == [("alarm_dry_running", "raised")])
        await quiet()
        assert events(observer, "pump") == [("alarm_dry_running", "raised")]
        (message,) = [m for m in observer.log if m.topic == "modbus/pump/event"]
        document = json.loads(message.payload)
        assert document["event_type"] == "alarm_dry_running_raised"
        assert (document["name"], document["entity"], document["code"]) == (
            "Dry running",
            "alarm_dry_running",
            True,
        )
        assert not message.retain
        sim.clear_faults(PUMP)
        await eventually(lambda: len(events(observer, "pump")) == 2)
        await quiet()
        assert events(observer, "pump") == [
            ("alarm_dry_running", "raised"),
            ("alarm_dry_running", "cleared"),
        ]


@pytest.mark.asyncio
async def test_a_fault_code_that_changes_is_one_clear_and_one_raise(
    mosquitto: Broker, tmp_path: Path
) -> None:
    sim = alarm_sim()
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim, tmp_path):
        await online(observer, "drive")
        sim.raise_fault(DRIVE, "fault_code", "module_overheat")
        await eventually(lambda: events(observer, "drive") == [("module_overheat", "raised")])
        sim.raise_fault(DRIVE, "fault_code", "motor_overload")
        await eventually(lambda: len(events(observer, "drive")) == 3)
        await quiet()
        assert events(observer, "drive") == [
            ("module_overheat", "raised"),
            ("module_overheat", "cleared"),
            ("motor_overload", "raised"),
        ]
        last = json.loads([m for m in observer.log if m.topic == "modbus/drive/event"][-1].payload)
        assert last["code"] is not None and last["entity"] == "fault_code"


@pytest.mark.asyncio
async def test_nothing_fires_again_on_offline_reload_ha_restart_or_restart(
    mosquitto: Broker, tmp_path: Path
) -> None:
    sim = alarm_sim()
    raised = [("alarm_dry_running", "raised")]
    async with observing(mosquitto, "modbus/#") as observer:
        async with bridged(mosquitto, sim, tmp_path) as bridge:
            await online(observer, "pump")
            sim.raise_fault(PUMP, "alarm_dry_running")
            await eventually(lambda: events(observer, "pump") == raised)

            sim.set_quirks(PUMP, Quirks(dead=True))  # offline is not "cleared"
            await eventually(lambda: observer.retained["modbus/pump/availability"] == b"offline")
            sim.set_quirks(PUMP, Quirks())  # back, the alarm still on: not a new raise
            await online(observer, "pump")
            await quiet()
            assert events(observer, "pump") == raised

            await observer.client.publish("homeassistant/status", "online")
            await quiet(2.5)  # Home Assistant's online: discovery and state again
            assert events(observer, "pump") == raised

            pump = tmp_path / "pump.yaml"
            pump.write_text(pump.read_text().replace("name: Dry running", "name: Dry run", 1))
            answered = len(observer.log)
            await observer.client.publish(
                "modbus/bridge/request/mapping/reload", json.dumps({"devices": ["pump"]})
            )
            await eventually(
                lambda: any(
                    m.topic == "modbus/bridge/response/mapping/reload"
                    for m in observer.log[answered:]
                )
            )
            await online(observer, "pump")
            await quiet()
            assert bridge.engine.devices["pump"].values.get("alarm_dry_running") is True
            assert events(observer, "pump") == raised
        assert events(observer, "pump") == raised

        # the bridge stopped; the alarm stays on, and another appears meanwhile
        sim.raise_fault(DRIVE, "fault_code", "module_overheat")
        async with bridged(mosquitto, sim, tmp_path):
            await online(observer, "pump", "drive")
            await eventually(lambda: events(observer, "drive") == [("module_overheat", "raised")])
            await quiet()
        assert events(observer, "pump") == raised
        assert events(observer, "drive") == [("module_overheat", "raised")]


@pytest.mark.asyncio
async def test_nothing_fires_again_on_a_broker_restart(mosquitto: Broker, tmp_path: Path) -> None:
    sim = alarm_sim()
    async with bridged(mosquitto, sim, tmp_path) as bridge:
        async with observing(mosquitto, "modbus/#") as observer:
            await online(observer, "pump")
            sim.raise_fault(PUMP, "alarm_dry_running")
            await eventually(lambda: events(observer, "pump") == [("alarm_dry_running", "raised")])
        mosquitto.stop()  # the observer is gone with it; a new one waits for the bridge
        await eventually(lambda: bridge.mqtt_state != "online", timeout=10)
        await asyncio.sleep(1.5)  # the bridge's next attempt is a backoff away
        mosquitto.restart()
        async with observing(mosquitto, "modbus/#") as observer:
            assert bridge.mqtt_state != "online"  # subscribed before the bridge is back
            await eventually(lambda: bridge.mqtt_state == "online", timeout=15)
            await online(observer, "pump")
            await quiet()
            assert events(observer, "pump") == []


@pytest.mark.asyncio
async def test_the_demo_fault_request_fires_the_event(mosquitto: Broker, tmp_path: Path) -> None:
    """What the demo's ``demo/fault`` does (bridge/cli/demo_control.py), end to end."""
    sim = alarm_sim()
    handle = fault_request({"pump": (sim, PUMP)})
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim, tmp_path):
        await online(observer, "pump")
        answer: Any = json.loads(await handle(b'{"device": "pump", "fault": "alarm_dry_running"}'))
        assert answer["status"] == "ok"
        await eventually(lambda: events(observer, "pump") == [("alarm_dry_running", "raised")])
