"""A hybrid-inverter package's switches (tests/importer/data/ha_fixtures/
hybrid_inverter_package.yaml), each on a register a sensor reads too, against a real Home
Assistant: its own modbus integration and the bridge, with what ``import ha`` made of
the same YAML, drive one simulated inverter. Each switch is turned on and off from Home
Assistant through both; the bridge writes the same register words as Home Assistant's
modbus does, reads them back (``verify``), and the raw sensor of the register follows.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.cli import main
from bridge.config import load_config
from bridge.core.mapping import load_mapping
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket
from tests.ha.test_counter_statistics import waited
from tests.ha.test_home_assistant import bridge_running
from tests.integration.harness import serving_tcp
from tests.integration.mosquitto import Broker

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(900)]
PACKAGE = Path(__file__).parents[1] / "importer/data/ha_fixtures/hybrid_inverter_package.yaml"
BASE = "shared"
SWITCHES = {  # switch key -> the raw sensor of its register
    "inverter_work_mode_backup": "inverter_work_mode_raw",
    "inverter_export_limit": "inverter_export_limit_raw",
    "inverter_backup_mode": "inverter_backup_mode_raw",
    "inverter_fan": "inverter_fan_speed_raw",
    "inverter_light": "inverter_light_raw",
}
PLATFORM = {"inverter_fan": "fan", "inverter_light": "light"}  # in Home Assistant's modbus


def modbus_block(port: int) -> dict[str, Any]:
    """The package's ``modbus:`` (anchors resolved), at the simulator, read every 2 s."""
    (hub,) = yaml.safe_load(PACKAGE.read_text(encoding="utf-8"))["modbus"]
    hub |= {"host": "127.0.0.1", "port": port}
    for kind in ("sensors", "switches", "fans", "lights"):
        for entity in hub[kind]:
            entity["scan_interval"] = 2
    return {"modbus": [hub]}


def imported(tmp_path: Path, port: int, broker: Broker) -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    source = tmp_path / "package.yaml"
    source.write_text(yaml.safe_dump(modbus_block(port)), encoding="utf-8")
    out = tmp_path / "bridge"
    assert main(["import", "ha", str(source), "--out", str(out)]) == 0
    config = out / "config.yaml"
    data = yaml.safe_load(config.read_text(encoding="utf-8"))
    data["mqtt"] = {"url": broker.url, "base_topic": BASE}
    for device in data["devices"]:
        device["poll"] = {"fast": 1, "slow": 2}
    config.write_text(yaml.safe_dump(data), encoding="utf-8")
    return config


async def switched(
    socket: HomeAssistantSocket, sim: Simulator, entity_id: str, service: str
) -> list[tuple[int, int, tuple[int, ...]]]:
    """Turn ``entity_id`` on or off from Home Assistant; the (function, address, words) written."""

    async def available() -> str:
        shown = (await socket.states()).get(entity_id, {}).get("state")
        return "" if shown in ("on", "off") else f"{entity_id}: {shown!r}"

    await waited(available, 60, every=0.5)
    before = len(sim.writes)
    domain = entity_id.split(".", maxsplit=1)[0]
    await socket.call(
        "call_service", domain=domain, service=service, target={"entity_id": entity_id}
    )
    state = "on" if service == "turn_on" else "off"

    async def done() -> str:
        shown = (await socket.states()).get(entity_id, {}).get("state")
        if len(sim.writes) == before or shown != state:
            return f"{entity_id}: {shown!r}, {len(sim.writes) - before} writes"
        return ""

    await waited(done, 60, every=0.5)
    return [(w.function, w.address, w.values) for _, w in sim.writes[before:]]


async def test_a_packages_switches_write_the_same_words_through_the_bridge(
    hass: HomeAssistant, ha_broker: Broker, tmp_path: Path
) -> None:
    probe = imported(tmp_path / "probe", 502, ha_broker)
    mapping = load_mapping(next((probe.parent / "mappings").glob("*.yaml")))
    sim = Simulator([SimulatedUnit(1, mapping)], tick=0.0)
    for key in SWITCHES:
        sim.set_value(1, key, False)
    async with serving_tcp(sim) as port:
        hass.extra_yaml = yaml.safe_dump(modbus_block(port))
        hass.write_configuration()
        await asyncio.to_thread(hass.restart)
        socket = await hass.websocket()
        try:
            words: dict[str, dict[str, Any]] = {}
            for key in SWITCHES:  # Home Assistant's own modbus
                words[key] = {
                    s: await switched(socket, sim, f"{PLATFORM.get(key, 'switch')}.{key}", s)
                    for s in ("turn_on", "turn_off")
                }
            config = load_config(imported(tmp_path / "bridge", port, ha_broker))
            async with bridge_running(config):

                async def discovered() -> str:
                    ids = {e["unique_id"] for e in await socket.entities()}
                    missing = [k for k in SWITCHES if f"{BASE}_hybrid_inverter_{k}" not in ids]
                    return f"not discovered: {missing}" if missing else ""

                await waited(discovered, 60)
                mqtt = {e["unique_id"]: e["entity_id"] for e in await socket.entities()}
                for key, raw in SWITCHES.items():
                    entity_id = mqtt[f"{BASE}_hybrid_inverter_{key}"]
                    raw_id = mqtt[f"{BASE}_hybrid_inverter_{raw}"]
                    on = await switched(socket, sim, entity_id, "turn_on")
                    assert on == words[key]["turn_on"], key

                    async def raw_follows(raw_id: str = raw_id, word: int = on[0][2][0]) -> str:
                        shown = (await socket.states()).get(raw_id, {}).get("state")
                        return "" if shown == str(word) else f"{raw_id}: {shown!r}, not {word}"

                    await waited(raw_follows, 30, every=0.5)
                    off = await switched(socket, sim, entity_id, "turn_off")
                    assert off == words[key]["turn_off"], key
        except AssertionError:
            print(hass.tail(80))
            raise
        finally:
            await socket.close()
    print(f"Home Assistant {hass.version}: five switches, the same words through the bridge")
