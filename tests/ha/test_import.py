"""An imported Home Assistant ``modbus:`` block against a real Home Assistant.

One simulated device (the simulator serving the imported mapping, values set), one YAML:
Home Assistant's own modbus integration reads it, and the bridge reads it with what
``import ha`` made of the same YAML; every converted entity shows the same state in both.
Then the switch-over as the README tells it: the ``modbus:`` block removed and Home
Assistant restarted, the entity a ``unique_id`` kept in the registry removed, the bridge
started: its entities take the entity ids Home Assistant's modbus had, and the recorder's
history of each goes on under the same id.
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.cli import main
from bridge.config import load_config
from bridge.core.mapping import load_mapping
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket
from tests.ha.test_counter_statistics import recording, waited
from tests.ha.test_home_assistant import bridge_running
from tests.integration.harness import serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(900)]
HA_INTEGRATIONS = ("recorder", "history")
BASE = "imported"
MODBUS = """\
modbus:
  - name: Boiler
    type: tcp
    host: 127.0.0.1
    port: {port}
    sensors:
      - {{name: Water temperature, address: 3, slave: 1, scale: 0.1, precision: 1,
         unit_of_measurement: "°C", device_class: temperature, state_class: measurement,
         scan_interval: 2}}
      - {{name: Flow rate, address: 10, slave: 1, data_type: uint32, swap: word, scale: 0.01,
         precision: 2, unit_of_measurement: "m³/h", scan_interval: 2}}
      - {{name: Serial number, address: 20, slave: 1, data_type: string, count: 4,
         scan_interval: 2}}
      - {{name: Pressure, address: 30, slave: 1, unique_id: boiler_pressure, scale: 0.01,
         precision: 2, unit_of_measurement: bar, device_class: pressure, scan_interval: 2}}
    binary_sensors:
      - {{name: Burner fault, address: 4, slave: 1, input_type: discrete_input,
         scan_interval: 2}}
    switches:
      - {{name: Circulation pump, address: 5, slave: 1, write_type: coil, verify: {{}},
         scan_interval: 2}}
"""
VALUES = {  # key -> the value the simulated device holds
    "water_temperature": 61.5,
    "flow_rate": 1234.56,
    "serial_number": "BX120745",
    "pressure": 1.85,
    "burner_fault": True,
    "circulation_pump": True,
}
ENTITY_IDS = {
    "water_temperature": "sensor.water_temperature",
    "flow_rate": "sensor.flow_rate",
    "serial_number": "sensor.serial_number",
    "pressure": "sensor.pressure",
    "burner_fault": "binary_sensor.burner_fault",
    "circulation_pump": "switch.circulation_pump",
}


def imported(tmp_path: Path, port: int, broker: Broker, prefix: str, modbus: str = MODBUS) -> Path:
    """``import ha`` of the block (``modbus``, its ``{port}`` filled in), pointed at the
    test's broker (discovery on ``prefix``)."""
    source = tmp_path / "configuration.yaml"
    source.write_text(modbus.format(port=port), encoding="utf-8")
    out = tmp_path / f"bridge-{prefix}"
    assert main(["import", "ha", str(source), "--out", str(out)]) == 0
    config = out / "config.yaml"
    data = yaml.safe_load(config.read_text(encoding="utf-8"))
    data["mqtt"] = {"url": broker.url, "base_topic": BASE, "discovery_prefix": prefix}
    config.write_text(yaml.safe_dump(data), encoding="utf-8")
    return config


def same(key: str, ha_state: str, bridge_value: Any) -> bool:
    """Home Assistant's state and the bridge's value are the same reading."""
    if isinstance(bridge_value, bool):
        return ha_state == ("on" if bridge_value else "off")
    if isinstance(bridge_value, int | float):
        try:
            return math.isclose(float(ha_state), bridge_value, abs_tol=0.006)
        except ValueError:
            return False
    return ha_state == bridge_value


async def compare(socket: HomeAssistantSocket, document: dict[str, Any]) -> str:
    states = await socket.states()
    wrong = []
    for key, entity_id in ENTITY_IDS.items():
        ha_state = states.get(entity_id, {}).get("state")
        if key not in document or ha_state is None or not same(key, ha_state, document[key]):
            wrong.append(f"{key}: Home Assistant {ha_state!r}, bridge {document.get(key)!r}")
    return "; ".join(wrong)


async def history(socket: HomeAssistantSocket, since: str) -> dict[str, list[dict[str, Any]]]:
    answer = await socket.call(
        "history/history_during_period",
        start_time=since,
        entity_ids=list(ENTITY_IDS.values()),
        minimal_response=False,
        no_attributes=True,
    )
    return dict(answer)


async def test_home_assistant_modbus_and_the_bridge_agree_then_the_bridge_takes_over(
    hass: HomeAssistant, ha_broker: Broker, tmp_path: Path
) -> None:
    since = (datetime.now(UTC) - timedelta(minutes=1)).isoformat()
    probe = imported(tmp_path, 502, ha_broker, "unused")
    mapping = load_mapping(probe.parent / "mappings" / "boiler.yaml")
    sim = Simulator([SimulatedUnit(1, mapping)], tick=0.0)
    for key, value in VALUES.items():
        sim.set_value(1, key, value)
    async with serving_tcp(sim) as port:
        # 1. both read the device: Home Assistant's modbus, the bridge (no discovery yet)
        hass.extra_yaml = MODBUS.format(port=port)
        hass.write_configuration()
        await asyncio.to_thread(hass.restart)
        socket = await hass.websocket()
        try:
            await recording(socket)
            side = load_config(imported(tmp_path, port, ha_broker, "elsewhere"))
            async with observing(ha_broker, f"{BASE}/boiler") as observer, bridge_running(side):

                async def agree() -> str:
                    payload = observer.retained.get(f"{BASE}/boiler")
                    return await compare(socket, json.loads(payload) if payload else {})

                await waited(agree, 120, every=1.0)
            registry = {e["entity_id"]: e for e in await socket.call("config/entity_registry/list")}
        finally:
            await socket.close()
        modbus = {
            k: (e["unique_id"], e["platform"])
            for k, e in registry.items()
            if e["platform"] == "modbus"
        }
        assert modbus == {"sensor.pressure": ("boiler_pressure", "modbus")}  # the one unique_id
        assert "sensor.water_temperature" not in registry  # no unique_id: not registered
        # 2. the switch-over: modbus: removed, Home Assistant restarted
        hass.extra_yaml = ""
        hass.write_configuration()
        switched = time.time()
        await asyncio.to_thread(hass.restart)
        socket = await hass.websocket()
        try:
            left = {e["entity_id"]: e for e in await socket.call("config/entity_registry/list")}
            held = "sensor.pressure" in left  # the README's step 3: removed if still there
            if held:
                assert left["sensor.pressure"]["platform"] == "modbus"
                await socket.call("config/entity_registry/remove", entity_id="sensor.pressure")
            config = load_config(imported(tmp_path, port, ha_broker, "homeassistant"))
            async with bridge_running(config):

                async def taken_over() -> str:
                    mqtt = {e["unique_id"]: e["entity_id"] for e in await socket.entities()}
                    ids = {k: mqtt.get(f"{BASE}_boiler_{k}") for k in ENTITY_IDS}
                    return "" if ids == ENTITY_IDS else f"entity ids {ids}"

                await waited(taken_over, 60)
                await waited(lambda: bridge_shows(socket), 60, every=1.0)

                async def recorded() -> str:  # before and after the switch, one id each
                    return both_sides(await history(socket, since), switched)

                await waited(recorded, 60, every=1.0)
        finally:
            await socket.close()
    kept = "kept" if held else "did not keep"
    print(
        f"Home Assistant {hass.version}: six entities agreed and were taken over; the registry "
        f"{kept} the modbus entity with a unique_id after its YAML was removed"
    )


async def bridge_shows(socket: HomeAssistantSocket) -> str:
    states = await socket.states()
    wrong = [
        f"{entity_id}: {states.get(entity_id, {}).get('state')!r}"
        for key, entity_id in ENTITY_IDS.items()
        if not same(key, str(states.get(entity_id, {}).get("state")), VALUES[key])
    ]
    return "; ".join(wrong)


def both_sides(rows: dict[str, list[dict[str, Any]]], switched: float) -> str:
    """What the recorder lacks: for each entity id, a state from before the switch-over
    (Home Assistant's modbus) and one from after (the bridge)."""
    wrong = []
    for key, entity_id in ENTITY_IDS.items():
        times = [row.get("lu", row.get("last_updated")) for row in rows.get(entity_id, [])]
        stamps = [
            t if isinstance(t, float) else datetime.fromisoformat(t).timestamp() for t in times
        ]
        if not any(t < switched for t in stamps):
            wrong.append(f"{key}: nothing recorded before the switch")
        if not any(t > switched for t in stamps):
            wrong.append(f"{key}: nothing recorded after the switch")
    return "; ".join(wrong)
