"""Discovery at start is published once, with the units and limits read from the device:
Home Assistant never sees a first version without units or with placeholder limits."""

from __future__ import annotations

import asyncio
import json

import pytest

from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import SEEDS, UNITS, all_units, observing, running_bridge

PUMP = "homeassistant/device/nastec_vasco/config"


@pytest.mark.asyncio
async def test_discovery_at_start_is_published_once_with_units_and_limits(
    mosquitto: Broker,
) -> None:
    sim = all_units()
    unit = UNITS["nastec_vasco"]
    sim.set_value(unit, "unit", "psi")
    sim.set_value(unit, "min_motor_frequency", 25)
    sim.set_value(unit, "max_motor_frequency", 100)
    async with (
        observing(mosquitto, "homeassistant/device/+/config") as observer,
        running_bridge(mosquitto, sim) as bridge,
    ):
        await eventually(lambda: all(p.health.online for p in bridge.engine.devices.values()), 20)
        await eventually(lambda: not bridge.discovery.pending, 10)
        await asyncio.sleep(2)  # several fast polls later: nothing republished
        published = [m for m in observer.log if m.topic.startswith("homeassistant/device/")]
    per_device = [m.topic for m in published]
    assert sorted(per_device) == sorted(
        {f"homeassistant/device/{d}/config" for d in SEEDS} | {"homeassistant/device/modbus/config"}
    ), "each device's discovery once"
    (pump,) = [json.loads(m.payload)["cmps"] for m in published if m.topic == PUMP]
    assert pump["actual_value"]["unit_of_measurement"] == "psi"
    assert (pump["operating_frequency"]["min"], pump["operating_frequency"]["max"]) == (25, 100)


@pytest.mark.asyncio
async def test_home_assistant_online_and_a_new_unit_still_republish(mosquitto: Broker) -> None:
    sim = all_units()
    unit = UNITS["nastec_vasco"]
    async with (
        observing(mosquitto, PUMP) as observer,
        running_bridge(mosquitto, sim) as bridge,
    ):
        await eventually(lambda: not bridge.discovery.pending, 20)
        await eventually(lambda: len(observer.log) == 1)
        sim.set_value(unit, "unit", "psi")  # changed on the keypad: units follow
        await eventually(lambda: len(observer.log) == 2, 10)
        assert (
            json.loads(observer.log[-1].payload)["cmps"]["set_value"]["unit_of_measurement"]
            == "psi"
        )
        await observer.client.publish("homeassistant/status", "online")
        await eventually(lambda: len(observer.log) == 3, 10)
