"""Issue 37's check against a real Home Assistant: the demo's home site and every device of
the library (``make test-ha`` runs it once per supported version).

The bridge in this process, Home Assistant's MQTT integration, ``energy`` and the recorder
on the same private broker:

- the home site as ``demo --site home`` configures it (bridge/cli/demo.py's
  ``site_data``: its meter, hybrid inverter and wallbox on an RS-485 line through a
  virtual cable, its heat pump on Modbus TCP, the gateway on) and every other library
  mapping (meters, inverters, batteries, chargers, heat pumps) at a unit of its own on a
  second Modbus TCP bus: every entity of every device arrives;
- each of the home site's controls, set from Home Assistant (a number's value, a
  select's option, a switch), reaches the simulated device;
- every energy counter of every library device (device class ``energy``, state class
  ``total_increasing``; the simulator counts at real rates) is a device consumption of
  the energy preferences: Home Assistant's own validation (``energy/validate``) finds
  nothing wrong with any of them (statistics defined, unit, device and state class
  accepted), and the recorder compiles a 5-minute statistic for each whose ``sum`` is a
  number, never below zero;
- Home Assistant logs no warning or error about the bridge's topics or the devices.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from bridge.cli.demo import simulated_unit, site_data
from bridge.cli.demo_site import LAN_BUS, SERIAL_BUS, SITES, Command, SeedDevice
from bridge.config import load_config_data
from bridge.core.mapping import Mapping, library_index, shipped_library
from bridge.modbus.simulator import Simulator
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket
from tests.ha.test_alarm_triggers import until
from tests.ha.test_counter_statistics import compiled, recording, waited
from tests.ha.test_home_assistant import BASE, PREFIX, bridge_running, discovered, problems
from tests.integration.harness import serving_serial, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing
from tests.ports import free_port

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(1500)]

HA_INTEGRATIONS = ("recorder", "energy")  # conftest.py's hass loads them for this module
HOME = SITES["home"]
LIBRARY_BUS = "library"
SETTLE = 420.0  # s for Home Assistant to take in every library device's entities
STEP = 60.0
ENABLE = 150.0  # s for an enabled entity to get a state (Home Assistant reloads after 30 s)


def library_devices() -> list[SeedDevice]:
    """Every library mapping (mappings/library/; the seeds have tests of their own) the
    home site does not already have, at units 1, 2, ..."""
    home = {d.mapping for d in HOME.devices}
    index = library_index()
    names = [n for n, path in index.items() if "library" in path.parts and n not in home]
    return [
        SeedDevice(name, name.replace("_", " ").title(), name, unit, LIBRARY_BUS)
        for unit, name in enumerate(names, start=1)
    ]


def energy_counters(mapping: Mapping) -> list[str]:
    """The keys of the mapping's energy counters (the energy dashboard's statistics), with
    its default options (as the config gives none)."""
    points = mapping.points(mapping.default_options())
    return [
        key
        for key, point in points.items()
        if point.entity.ha.device_class == "energy"
        and point.entity.ha.state_class == "total_increasing"
    ]


def simulator(devices: list[SeedDevice]) -> Simulator:
    """The devices as the demo serves them (the home's PV inverter: a SunSpec image)."""
    return Simulator([simulated_unit(d) for d in devices], tick=1.0)


def config(broker: Broker, where: dict[str, str], others: list[SeedDevice], state: Path) -> Any:
    """The home site's config as the demo writes it, with the library bus added."""
    mqtt = {"url": broker.url, "base_topic": BASE, "discovery_prefix": PREFIX}
    data = site_data(HOME, mqtt, where, free_port(), free_port())
    data["bridge"] |= {"health_interval": 2.0, "state_dir": str(state)}
    host, _, port = where[LIBRARY_BUS].rpartition(":")
    data["buses"].append(
        {"id": LIBRARY_BUS, "transport": "tcp", "host": host, "tcp_port": int(port)}
        | {"timeout": 0.5}
    )
    data["devices"] += [
        {"id": d.id, "name": d.name, "bus": d.bus, "unit": d.unit, "mapping": d.mapping}
        for d in others
    ]
    return load_config_data(data, state.parent / "ha-library.yaml")


async def set_from_home_assistant(
    socket: HomeAssistantSocket, entity_id: str, payload: str
) -> None:
    domain = entity_id.split(".", maxsplit=1)[0]
    if domain == "number":
        service, data = "set_value", {"value": float(payload)}
    elif domain == "select":
        service, data = "select_option", {"option": payload}
    elif domain == "switch":
        service, data = ("turn_on" if payload == "ON" else "turn_off"), {}
    else:
        raise AssertionError(f"{entity_id}: no service for a {domain} control")
    await socket.call(
        "call_service",
        domain=domain,
        service=service,
        service_data=data,
        target={"entity_id": entity_id},
    )


def reached(value: object, payload: str) -> bool:
    """The simulated device's value is what the control asked for."""
    if isinstance(value, bool):
        return value is (payload == "ON")
    if isinstance(value, int | float):
        return float(value) == float(payload)
    return value == payload


async def test_the_home_site_and_every_library_device_in_home_assistant(
    hass: HomeAssistant, ha_broker: Broker, tmp_path: Path
) -> None:
    start = len(hass.log_records())
    since = (datetime.now(UTC) - timedelta(minutes=10)).isoformat()
    others = library_devices()
    sims = {
        SERIAL_BUS: simulator(list(HOME.on(SERIAL_BUS))),
        LAN_BUS: simulator(list(HOME.on(LAN_BUS))),
        LIBRARY_BUS: simulator(others),
    }
    library = shipped_library()
    every = [*HOME.devices, *others]
    counters = [
        f"{BASE}_{d.id}_{key}"
        for d in every
        if d.image is None  # the SunSpec inverter's energy: tests/ha/test_sunspec.py
        for key in energy_counters(library[d.mapping])
    ]
    assert counters, "no energy counter in the library"
    socket = await hass.websocket()
    try:
        await recording(socket)
    finally:
        await socket.close()
    async with (
        serving_serial(sims[SERIAL_BUS]) as serial_end,
        serving_tcp(sims[LAN_BUS]) as lan_port,
        serving_tcp(sims[LIBRARY_BUS]) as library_port,
    ):
        where = {SERIAL_BUS: serial_end, LAN_BUS: f"127.0.0.1:{lan_port}"}
        where[LIBRARY_BUS] = f"127.0.0.1:{library_port}"
        async with (
            observing(ha_broker, f"{PREFIX}/device/+/config") as observer,
            bridge_running(config(ha_broker, where, others, tmp_path / "state")),
        ):

            async def published() -> str:
                found = {topic.split("/")[2] for topic in observer.retained}
                missing = {d.id for d in every} - found
                return f"no discovery config for {sorted(missing)}" if missing else ""

            await waited(published, STEP)
            # what the bridge offers Home Assistant (secrets and guarded buttons are not)
            unique_ids = set(discovered(observer))
            assert set(counters) <= unique_ids, set(counters) - unique_ids
            ids: dict[str, str] = {}

            async def arrived() -> str:
                ids.update(await registry(hass))
                missing = unique_ids - ids.keys()
                return f"{len(missing)} of {len(unique_ids)} entities missing" if missing else ""

            await waited(arrived, SETTLE, every=5.0)
            socket = await hass.websocket()  # a new one: Home Assistant was busy until now
            try:
                controls = [ids[f"{BASE}_{c.device}_{c.key}"] for c in HOME.controls]
                await enabled(socket, controls)
                for control in HOME.controls:
                    await control_reaches_the_device(socket, sims, ids, control)
                # the counters a user gets (a per-phase one is offered disabled), at least
                # one of every device that has counters
                offered = {
                    e["entity_id"] for e in await socket.entities() if e["disabled_by"] is None
                }
                stats = [ids[u] for u in counters if ids[u] in offered]
                owner = {
                    u: d.id for d in every for u in counters if u.startswith(f"{BASE}_{d.id}_")
                }
                short = set(owner.values()) - {owner[u] for u in counters if ids[u] in offered}
                assert not short, f"no energy counter offered enabled: {sorted(short)}"
                rows = await compiled(socket, stats, since, time.time())
                issues = await energy_issues(socket, stats)
                states = await socket.states()
            finally:
                await socket.close()
    assert issues == {}, issues
    unknown = [e for e in stats if states[e]["state"] in ("unknown", "unavailable")]
    assert not unknown, unknown
    sums = {e: rows[e][-1]["sum"] for e in stats}
    assert all(isinstance(v, int | float) and v >= 0 for v in sums.values()), sums
    words = (f"{BASE}/", f"{PREFIX}/", *(d.id for d in every))
    found = problems(hass.log_records()[start:], words)
    assert not found, f"{len(found)} warnings and errors:\n" + "\n".join(found[:40])


async def registry(hass: HomeAssistant) -> dict[str, str]:
    """The MQTT entities Home Assistant registered, unique id -> entity id, on a socket of
    its own (Home Assistant busy taking in a thousand entities may drop a slow one)."""
    socket = await hass.websocket()
    try:
        return {e["unique_id"]: e["entity_id"] for e in await socket.entities()}
    finally:
        await socket.close()


async def enabled(socket: HomeAssistantSocket, entity_ids: list[str]) -> None:
    """Enable the controls Home Assistant lists disabled, as a user does (a control that
    changes how a device runs is offered disabled: the mapping's ``dangerous``); Home
    Assistant reloads the MQTT entry 30 s later and they get a state."""
    registry = {e["entity_id"]: e for e in await socket.entities()}
    for entity_id in entity_ids:
        if registry[entity_id].get("disabled_by") is not None:
            await socket.call(
                "config/entity_registry/update", entity_id=entity_id, disabled_by=None
            )


async def control_reaches_the_device(
    socket: HomeAssistantSocket,
    sims: dict[str, Simulator],
    ids: dict[str, str],
    control: Command,
) -> None:
    """Set ``control`` from Home Assistant; the simulated device takes it."""
    device = next(d for d in HOME.devices if d.id == control.device)
    entity_id = ids[f"{BASE}_{device.id}_{control.key}"]

    async def available() -> str:
        state = (await socket.states()).get(entity_id, {}).get("state")
        return "" if state not in (None, "unavailable") else f"{entity_id} is {state}"

    await until(available, ENABLE)
    await set_from_home_assistant(socket, entity_id, control.payload)
    sim = sims[device.bus]

    async def taken() -> str:
        value = sim.value(device.unit, control.key)
        return "" if reached(value, control.payload) else f"{control}: the device has {value!r}"

    await until(taken, STEP)


async def energy_issues(socket: HomeAssistantSocket, entity_ids: list[str]) -> dict[str, Any]:
    """Home Assistant's validation of the energy preferences with each of ``entity_ids``
    as a device's consumption: the issues it finds, by entity."""
    devices = [{"stat_consumption": e} for e in entity_ids]
    await socket.call("energy/save_prefs", device_consumption=devices)
    found = await socket.call("energy/validate")
    return {e: list(i) for e, i in zip(entity_ids, found["device_consumption"], strict=True) if i}
