"""A hybrid inverter package's switches, Home Assistant's modbus against the bridge.

The YAML is shaped like the community packages for hybrid inverters: raw sensors of the
work mode, the export limit and the backup state, and a switch on each of those same
registers (Home Assistant allows that, the packages do it all the time). One simulated
device (the simulator serving what ``import ha`` made of the YAML, every write request
it receives recorded); its backup state register follows the backup command register,
as the inverter's does.

1. Home Assistant's own modbus integration reads the YAML: each switch is turned on, reads
   back on through ``verify``, is turned off; the words it wrote are recorded.
2. The ``modbus:`` block removed, the bridge runs the import of the same YAML and Home
   Assistant takes it in by MQTT discovery: the same service calls, the same states read
   back, the raw sensors on the switches' registers follow, and the bridge writes exactly
   the words Home Assistant's modbus wrote. Neither run leaves a warning in Home
   Assistant's log.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from bridge.config import load_config
from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.core.request import Write
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket, LogRecord, parse_log
from tests.ha.test_counter_statistics import waited
from tests.ha.test_home_assistant import bridge_running, problems
from tests.ha.test_import import BASE, imported, same
from tests.integration.harness import serving_tcp
from tests.integration.mosquitto import Broker

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(900)]
DEVICE = "hybrid_inverter"
STEP = 60.0  # s for a switch's state and its register's sensor to show a write
DISCOVERY = 120.0  # s for the bridge's entities to be in Home Assistant (a new venv is slow)
MODBUS = """\
modbus:
  - name: Hybrid inverter
    type: tcp
    host: 127.0.0.1
    port: {port}
    sensors:
      - name: Battery level
        address: 4098
        slave: 1
        unit_of_measurement: "%"
        device_class: battery
        state_class: measurement
        scan_interval: 5
      - name: Grid power
        address: 4100
        slave: 1
        unit_of_measurement: W
        device_class: power
        state_class: measurement
        scan_interval: 5
      - name: Work mode  # 0 self use, 1 feed-in first, 2 force charge
        address: 8448
        slave: 1
        data_type: uint16
        scan_interval: 5
      - name: Export limit mode
        address: 8452
        slave: 1
        data_type: uint16
        scan_interval: 5
      - name: Backup state
        address: 8465
        slave: 1
        data_type: uint16
        scan_interval: 5
    switches:
      - name: Force charge
        address: 8448
        slave: 1
        write_type: holding
        command_on: 2
        command_off: 0
        scan_interval: 5
        verify:
          state_on: 2
          state_off: [0, 1]
      - name: Export limit
        address: 8452
        slave: 1
        write_type: holding
        scan_interval: 5
        verify:
      - name: Backup mode
        address: 8464
        slave: 1
        write_type: holding
        command_on: 0x0100
        command_off: 0x0200
        scan_interval: 5
        verify:
          address: 8465
          state_on: 1
          state_off: 0
"""
BACKUP_COMMAND, BACKUP_STATE = 8464, 8465
START = {"battery_level": 76, "grid_power": -1200, "work_mode": 1, "export_limit_mode": 0}
START |= {"backup_state": 0}


@dataclass(frozen=True)
class Switch:
    key: str
    sensor: str  # the raw sensor on the register the switch's state is read from
    on: int  # what that sensor reads once the switch is on, and off
    off: int


SWITCHES = (
    Switch("force_charge", "work_mode", 2, 0),
    Switch("export_limit", "export_limit_mode", 1, 0),
    Switch("backup_mode", "backup_state", 1, 0),
)
# what Home Assistant's modbus writes for them: FC06, command_on then command_off
HA_WRITES = [
    (1, Write(6, Table.HOLDING, address, (word,)))
    for address, on, off in ((8448, 2, 0), (8452, 1, 0), (BACKUP_COMMAND, 0x0100, 0x0200))
    for word in (on, off)
]


def backup_follows(unit: int, write: Write) -> dict[tuple[Table, int], int]:
    """The inverter's backup state register shows the last backup command: 1 on, 0 off."""
    if unit != 1 or write.table is not Table.HOLDING or write.address != BACKUP_COMMAND:
        return {}
    return {(Table.HOLDING, BACKUP_STATE): {0x0100: 1, 0x0200: 0}.get(write.values[0], 0)}


def device(tmp_path: Path, broker: Broker) -> Simulator:
    """The simulated inverter, serving the import's mapping, at its start values."""
    probe = imported(tmp_path, 502, broker, "unused", MODBUS)
    mapping = load_mapping(probe.parent / "mappings" / f"{DEVICE}.yaml")
    dropped = [key for key in [*START, *(s.key for s in SWITCHES)] if key not in mapping.entities]
    assert not dropped, f"the import dropped {dropped}: {probe.parent / 'import-report.txt'}"
    sim = Simulator([SimulatedUnit(1, mapping)], tick=0.0)  # values stay still
    sim.reactions.append(backup_follows)
    at_start(sim)
    return sim


def at_start(sim: Simulator) -> None:
    for key, value in START.items():
        sim.set_value(1, key, value)


def shows(socket: HomeAssistantSocket, wanted: dict[str, Any]) -> Callable[[], Awaitable[str]]:
    """A check: Home Assistant's state of each entity id is the value ``wanted`` names
    (True/False: on/off)."""

    async def check() -> str:
        states = await socket.states()
        wrong = [
            f"{entity_id} is {states.get(entity_id, {}).get('state')!r}, not {value!r}"
            for entity_id, value in wanted.items()
            if not same(entity_id, str(states.get(entity_id, {}).get("state")), value)
        ]
        return "; ".join(wrong)

    return check


async def switched(socket: HomeAssistantSocket, ids: dict[str, str]) -> None:
    """From the start values, each switch turned on and off by Home Assistant's service
    calls; after each, the switch and the sensor on its register show the device's state."""
    await waited(shows(socket, {ids[k]: v for k, v in START.items()}), STEP, every=0.5)
    await waited(shows(socket, {ids[s.key]: False for s in SWITCHES}), STEP, every=0.5)
    for switch in SWITCHES:
        steps = (("turn_on", True, switch.on), ("turn_off", False, switch.off))
        for service, state, reading in steps:
            await socket.call(
                "call_service",
                domain="switch",
                service=service,
                target={"entity_id": ids[switch.key]},
            )
            wanted = {ids[switch.key]: state, ids[switch.sensor]: reading}
            await waited(shows(socket, wanted), STEP, every=0.5)


def entity_ids() -> dict[str, str]:
    """Home Assistant's modbus entities: named after their YAML names (no unique_id)."""
    sensors = {key: f"sensor.{key}" for key in START}
    return sensors | {s.key: f"switch.{s.key}" for s in SWITCHES}


async def bridge_ids(socket: HomeAssistantSocket) -> dict[str, str]:
    """The entity ids Home Assistant gave the bridge's entities (waited for)."""
    unique_ids = {key: f"{BASE}_{DEVICE}_{key}" for key in [*START, *(s.key for s in SWITCHES)]}
    registry: dict[str, str] = {}

    async def check() -> str:
        registry.update({e["unique_id"]: e["entity_id"] for e in await socket.entities()})
        missing = sorted(u for u in unique_ids.values() if u not in registry)
        return f"not in the entity registry: {missing}" if missing else ""

    await waited(check, DISCOVERY, every=0.5)
    return {key: registry[unique_id] for key, unique_id in unique_ids.items()}


def our_problems(records: list[LogRecord]) -> list[str]:
    """Warnings and errors of Home Assistant's modbus, its MQTT entities and anything
    naming the inverter or the bridge's topics."""
    words = (DEVICE, "Hybrid inverter", f"{BASE}/", *(s.key for s in SWITCHES))
    modbus = [
        str(r)
        for r in records
        if r.level in ("WARNING", "ERROR", "CRITICAL")
        and r.logger.startswith("homeassistant.components.modbus")
    ]
    return modbus + [p for p in problems(records, words) if p not in modbus]


def last_run(hass: HomeAssistant) -> list[LogRecord]:
    """The records of Home Assistant's run before its last start (it keeps that log as
    home-assistant.log.1), stop included."""
    previous = hass.config_dir / "home-assistant.log.1"
    assert previous.exists(), "Home Assistant kept no log of its previous run"
    return parse_log(previous.read_text(errors="replace"))


async def test_a_packages_switches_write_the_same_words_through_the_bridge(
    hass: HomeAssistant, ha_broker: Broker, tmp_path: Path
) -> None:
    sim = device(tmp_path, ha_broker)
    async with serving_tcp(sim) as port:
        # 1. Home Assistant's own modbus integration
        mark = len(sim.writes)  # from the start: no write but the service calls' own
        hass.extra_yaml = MODBUS.format(port=port)
        hass.write_configuration()
        await asyncio.to_thread(hass.restart)
        socket = await hass.websocket()
        try:
            await switched(socket, entity_ids())
            by_home_assistant = sim.writes[mark:]
        finally:
            await socket.close()
        assert by_home_assistant == HA_WRITES
        # 2. the bridge with the import, Home Assistant by MQTT discovery
        at_start(sim)
        hass.extra_yaml = ""
        hass.write_configuration()
        await asyncio.to_thread(hass.restart)
        first_run = last_run(hass)
        socket = await hass.websocket()
        try:
            config = load_config(imported(tmp_path, port, ha_broker, "homeassistant", MODBUS))
            mark = len(sim.writes)
            async with bridge_running(config):
                ids = await bridge_ids(socket)
                await switched(socket, ids)
                by_the_bridge = sim.writes[mark:]
        finally:
            await socket.close()
    assert by_the_bridge == by_home_assistant
    await asyncio.sleep(3)  # what Home Assistant logs about the bridge leaving
    found = our_problems(first_run) + our_problems(hass.log_records())
    print(
        f"Home Assistant {hass.version}: 3 switches on and off, {len(by_the_bridge)} writes "
        f"alike: {[(w.address, w.values) for _, w in by_the_bridge]}"
    )
    assert not found, f"{len(found)} warnings and errors:\n" + "\n".join(found[:40])
