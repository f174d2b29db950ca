"""Issue 36's check against a real Home Assistant: a SunSpec inverter with no mapping file
of ours (``make test-ha`` runs it once per supported version).

An inverter with four MPPTs (tests/sunspec_devices.py: models 1, 103, 120, 160) served by
the simulator as a SunSpec device image and configured as ``mapping: sunspec`` (the
bridge walks it, builds its mapping and caches it: bridge/sunspec_devices.py), the bridge
in this process, Home Assistant's MQTT
integration, ``energy``, the recorder and ``device_automation`` on the same private broker:

- every entity of the built mapping arrives, and Home Assistant lists the device
  triggers its event bits publish;
- an automation on "Ground fault" raised (model 103's Evt1 bit 0) runs once when the
  simulator sets the bit;
- the lifetime energy (103's WH, an ``acc32`` scaled by WH_SF) as the energy dashboard's
  solar production: once the recorder has compiled a 5-minute period, Home Assistant's
  own validation of the energy preferences (``energy/validate``) finds nothing wrong
  (its statistics defined, device class, unit and state class accepted) and the
  period's ``sum`` grew by exactly the energy the simulator counted (kWh: Wh / 1000);
- Home Assistant logs no warning or error about the bridge's topics or the device.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from bridge.config import LoadedConfig, load_config_data
from bridge.core.mapping import load_mapping
from bridge.modbus.simulator import Simulator, SunSpecUnit
from bridge.sunspec.image import build_image
from bridge.sunspec.mapping import build_mapping
from tests.ha import homeassistant
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket
from tests.ha.test_alarm_triggers import (
    AUTOMATION_LOADED,
    RUNS_TOPIC,
    Device,
    listed_triggers,
    make_automation,
    runs,
    until,
)
from tests.ha.test_counter_statistics import compiled, entity_of, recording
from tests.ha.test_home_assistant import BASE, PREFIX, bridge_running, problems
from tests.integration.harness import serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing
from tests.sunspec_devices import every_image
from tests.sunspec_reference import walked

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(900)]

HA_INTEGRATIONS = ("recorder", "energy")  # conftest.py's hass loads them for this module
INVERTER = Device("sunspec_inverter", "SunSpec inverter", "", 3)
EVENT, ENERGY, ENERGY_SF = "inverter_three_phase_evt1_ground_fault", "inverter_three_phase_wh", 0
SETTLE = 180.0  # s for Home Assistant to take in some 200 entities
STEP = 60.0
START_WH = 2_000_000  # Wh on the counter when the bridge starts: the statistics' zero point
STEPS_WH = (2_000_500, 2_003_000, 2_010_000)  # what it counts to, in steps


@pytest.fixture(scope="module", autouse=True)
def automation_loaded() -> Iterator[None]:
    """conftest.py's Home Assistant with ``automation`` and ``device_automation``."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            homeassistant, "CONFIGURATION", homeassistant.CONFIGURATION + AUTOMATION_LOADED
        )
        yield


def quiet_inverter() -> dict[str, Any]:
    """The test inverter's image with no event bit set and its energy at ``START_WH``."""
    device = every_image()["inverter_mppt"]
    for model in device["models"]:
        if model["ID"] == 103:
            model.update({"Evt1": 0, "Evt2": 0, "EvtVnd1": 0, "EvtVnd2": 0})
            model.update({"EvtVnd3": 0, "EvtVnd4": 0, "WH": START_WH, "WH_SF": ENERGY_SF})
        if model["ID"] == 160:
            model["Evt"] = 0
            for module in model.get("module", []):
                module["DCEvt"] = 0
    return device


def sunspec_config(broker: Broker, port: int, device: dict[str, Any], state: Path) -> LoadedConfig:
    """test_home_assistant's site with the one device, its state (the SunSpec cache) in
    ``state``."""
    data = {
        "mqtt": {"url": broker.url, "base_topic": BASE, "discovery_prefix": PREFIX},
        "bridge": {"health_interval": 2.0, "state_dir": str(state)},
        "buses": [
            {"id": "demo", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
            | {"timeout": 0.5}
        ],
        "devices": [device],
    }
    return load_config_data(data, state.parent / "ha-test.yaml")


def _number(state: str) -> float | None:
    try:
        return float(state)
    except ValueError:
        return None


async def energy_issues(socket: HomeAssistantSocket, entity_id: str) -> list[dict[str, Any]]:
    """Home Assistant's validation of the energy preferences with ``entity_id`` as the
    solar production: the issues it finds for that source."""
    source = {"type": "solar", "stat_energy_from": entity_id, "config_entry_solar_forecast": None}
    await socket.call("energy/save_prefs", energy_sources=[source])
    found = await socket.call("energy/validate")
    return list(found["energy_sources"][0])


async def test_a_sunspec_inverter_in_home_assistant(
    hass: HomeAssistant, ha_broker: Broker, tmp_path: Path
) -> None:
    start = len(hass.log_records())
    since = (datetime.now(UTC) - timedelta(minutes=10)).isoformat()
    image = build_image(quiet_inverter(), 40000, "inverter")
    chain = await asyncio.to_thread(walked, image)  # walked() runs its own event loop
    built = build_mapping(chain, image.registers)
    path = tmp_path / "expected.yaml"  # what the bridge will build: addresses and names
    path.write_text(built.yaml(), encoding="utf-8")
    mapping = load_mapping(path)
    event = mapping.entities[EVENT]
    energy_address = mapping.entities[ENERGY].address
    assert event.bit == 0 and mapping.entities[ENERGY].type.value == "u32"
    sim = Simulator([SunSpecUnit(INVERTER.unit, image)], tick=0.0)
    device = {"id": INVERTER.id, "name": INVERTER.name, "bus": "demo", "unit": INVERTER.unit}
    device |= {"mapping": "sunspec", "poll": {"fast": 0.5, "slow": 5.0}}
    socket = await hass.websocket()
    try:
        await recording(socket)
        async with (
            serving_tcp(sim) as port,
            observing(ha_broker, f"{PREFIX}/#", f"{BASE}/#", RUNS_TOPIC) as observer,
            bridge_running(sunspec_config(ha_broker, port, device, tmp_path / "state")),
        ):
            unique_ids = {f"{BASE}_{INVERTER.id}_{key}" for key in mapping.entities}

            async def arrived() -> str:
                known = {e["unique_id"] for e in await socket.entities()}
                missing = unique_ids - known
                return f"{len(missing)} of {len(unique_ids)} entities missing" if missing else ""

            await until(arrived, SETTLE)
            triggers = await listed_triggers(socket, INVERTER)
            names = {t["subtype"] for t in triggers if t["type"] == "raised"}
            assert event.name in names, sorted(names)
            (trigger,) = [
                t for t in triggers if (t["type"], t["subtype"]) == ("raised", event.name)
            ]
            await make_automation(hass, socket, trigger)

            energy = await entity_of(socket, f"{BASE}_{INVERTER.id}_{ENERGY}")
            for wh in STEPS_WH:  # the inverter produces; each step reaches Home Assistant
                sim.set_registers(
                    INVERTER.unit, {energy_address: wh >> 16, energy_address + 1: wh & 0xFFFF}
                )

                async def shown(wh: int = wh) -> str:
                    state = (await socket.states())[energy]["state"]
                    return "" if _number(state) == wh else f"{energy}: {state}, not {wh}"

                await until(shown, STEP)

            sim.set_registers(INVERTER.unit, {event.address: 1 << event.bit})

            async def ran() -> str:
                return "" if len(runs(observer)) == 1 else f"runs: {runs(observer)}"

            await until(ran, STEP)
            assert runs(observer) == [f"{event.name} raised"]

            rows = await compiled(socket, [energy], since, time.time())
            issues = await energy_issues(socket, energy)
            await asyncio.sleep(1.0)
    finally:
        await socket.close()
    assert issues == [], issues
    grown = rows[energy][-1]["sum"]
    assert grown == pytest.approx(STEPS_WH[-1] - START_WH), rows[energy]
    words = (f"{BASE}/", f"{PREFIX}/", INVERTER.id, RUNS_TOPIC)
    found = problems(hass.log_records()[start:], words)
    assert not found, f"{len(found)} warnings and errors:\n" + "\n".join(found[:40])
