"""The bridge against a real Home Assistant (see conftest.py: ``make test-ha`` runs this
module once per supported version): the five seed devices simulated, the bridge in this
process, Home Assistant's MQTT integration on the same private broker.

- every component gets the entity id its discovery asks for (``default_entity_id``), and
  every entity id README.md, docs/ and examples/ name exists;
- over a start, a config change (a device renamed, another's id changed) and a stop that
  removes the devices (as the demo's does), Home Assistant logs no warning and no error
  about the bridge's topics, devices or entities, and keeps no device of ours after the
  stop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.cli.demo import SEEDS
from bridge.config import LoadedConfig, load_config_data
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket, LogRecord
from tests.integration.harness import cancel, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = (".yaml", ".yml", ".json", ".md")
DOCUMENTS = [
    ROOT / "README.md",
    *sorted((ROOT / "docs").glob("*.md")),
    *sorted(p for p in (ROOT / "examples").rglob("*") if p.suffix in EXAMPLES),
]
PLATFORMS = ("sensor", "binary_sensor", "switch", "number", "select", "button", "text", "event")
ENTITY_ID = re.compile(rf"\b(?:{'|'.join(PLATFORMS)})\.[a-z0-9_]+\b")
PREFIX = "homeassistant"
BASE = "modbus"
SETTLE = 180.0  # seconds for Home Assistant to take in 450 entities (or drop them)
# Loggers whose warnings are about what a discovery config or a state does in Home
# Assistant; a record from any other logger counts when it names our topics or devices.
OUR_LOGGERS = (
    "homeassistant.components.mqtt",
    "homeassistant.helpers.template",
    "homeassistant.helpers.entity",
    "homeassistant.helpers.entity_registry",
    "homeassistant.helpers.device_registry",
    *(f"homeassistant.components.{platform}" for platform in PLATFORMS),
)


# Home Assistant before 2026.11 publishes an empty config on a removed device's topic for
# each of its disabled entities and then warns that it has nothing left to clean up for
# it ("No device components to cleanup for <device>", one per disabled entity: 2025.10.4
# and 2026.9.4 alike; 2026.11 no longer does). Nothing a publisher can avoid short of
# never removing a device, so counted apart, and only on those versions.
HA_REMOVAL_ECHO = "No device components to cleanup for "
FIXED_REMOVAL_ECHO = (2026, 11)


def release(version: str) -> tuple[int, int]:
    year, month, *_ = version.split(".")
    return int(year), int(month)


def documented_entity_ids() -> dict[str, list[str]]:
    """Every entity id the docs and examples name, with the files naming it."""
    found: dict[str, list[str]] = {}
    for path in DOCUMENTS:
        for entity_id in ENTITY_ID.findall(path.read_text(encoding="utf-8")):
            found.setdefault(entity_id, []).append(str(path.relative_to(ROOT)))
    return found


def site_config(broker: Broker, port: int, devices: list[dict[str, Any]]) -> LoadedConfig:
    data = {
        "mqtt": {"url": broker.url, "base_topic": BASE, "discovery_prefix": PREFIX},
        "bridge": {"health_interval": 2.0},
        "buses": [
            {"id": "demo", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
            | {"timeout": 0.5}
        ],
        "devices": devices,
    }
    return load_config_data(data, Path("ha-test.yaml"))


def seed_devices(**renamed: tuple[str, str]) -> list[dict[str, Any]]:
    """The demo's devices; ``renamed`` gives a device (by id) a new id and name."""
    devices = []
    for seed in SEEDS:
        device_id, name = renamed.get(seed.id, (seed.id, seed.name))
        devices.append(
            {"id": device_id, "name": name, "bus": "demo", "unit": seed.unit}
            | {"mapping": seed.mapping, "poll": {"fast": 1.0, "slow": 10.0}}
        )
    return devices


@contextlib.asynccontextmanager
async def bridge_running(
    config: LoadedConfig, *, remove_on_stop: bool = False
) -> AsyncIterator[Bridge]:
    bridge = Bridge(config, remove_on_stop=remove_on_stop)
    task = asyncio.create_task(bridge.run())
    try:
        yield bridge
    finally:
        await cancel(task, within=15)


def discovered(observer: Observer) -> dict[str, tuple[str, str]]:
    """The components of the retained device configs: unique_id -> (platform,
    default_entity_id)."""
    components = {}
    for topic, payload in observer.retained.items():
        if topic.startswith(f"{PREFIX}/device/") and payload:
            for component in json.loads(payload)["cmps"].values():
                if component["platform"] == "device_automation":
                    continue  # a device trigger is no entity (tests/ha/test_alarm_triggers.py)
                components[component["unique_id"]] = (
                    component["platform"],
                    component["default_entity_id"],
                )
    return components


async def until(check: Callable[[], Awaitable[str]], timeout: float = SETTLE) -> None:
    """Wait until ``check()`` returns "" (it returns what is still wrong), bounded."""
    wrong = "not checked"
    async with asyncio.timeout(timeout):
        while True:
            wrong = await check()
            if not wrong:
                return
            await asyncio.sleep(1.0)
    raise AssertionError(wrong)  # pragma: no cover (the timeout raises first)


async def settled(
    socket: HomeAssistantSocket, observer: Observer, timeout: float = SETTLE
) -> dict[str, str]:
    """Wait until Home Assistant's MQTT entities are exactly the discovered components;
    return unique_id -> entity_id."""
    registry: dict[str, str] = {}

    async def check() -> str:
        registry.clear()
        registry.update({e["unique_id"]: e["entity_id"] for e in await socket.entities()})
        expected = discovered(observer)
        missing = sorted(set(expected) - set(registry))
        extra = sorted(set(registry) - set(expected))
        if not expected or missing or extra:
            return f"{len(expected)} discovered, missing {missing[:5]}, extra {extra[:5]}"
        return ""

    try:
        await until(check, timeout)
    except TimeoutError:
        await check()
        raise AssertionError(await check()) from None
    return dict(registry)


def problems(records: list[LogRecord], words: tuple[str, ...]) -> list[str]:
    """Home Assistant's warnings and errors about the bridge: from the MQTT integration,
    templates, entities and registries, or naming one of ``words`` (topics, ids)."""
    return [
        str(record)
        for record in records
        if record.level in ("WARNING", "ERROR", "CRITICAL")
        and (record.logger.startswith(OUR_LOGGERS) or any(w in record.message for w in words))
    ]


async def test_entity_ids_are_the_ones_asked_for_and_the_documented_ones_exist(
    hass: HomeAssistant, ha_broker: Broker
) -> None:
    sim = simulator(*((seed.unit, seed.mapping) for seed in SEEDS))
    socket = await hass.websocket()
    try:
        async with (
            serving_tcp(sim) as port,
            observing(ha_broker, f"{PREFIX}/#") as observer,
        ):
            async with bridge_running(
                site_config(ha_broker, port, seed_devices()), remove_on_stop=True
            ):
                registry = await settled(socket, observer)
                asked = discovered(observer)
                wrong = {
                    unique_id: (registry[unique_id], entity_id)
                    for unique_id, (_, entity_id) in asked.items()
                    if registry[unique_id] != entity_id
                }
                print(f"Home Assistant {hass.version}: {len(registry)} entities")
                assert not wrong, f"{len(wrong)} of {len(asked)} ids differ: {wrong}"
                existing = set(registry.values())
                documented = documented_entity_ids()
                absent = {e: files for e, files in documented.items() if e not in existing}
                assert documented
                assert not absent, f"documented entity ids that do not exist: {absent}"
            await until(lambda: _none_left(socket))
    finally:
        await socket.close()


async def ours(socket: HomeAssistantSocket) -> list[dict[str, Any]]:
    """The bridge's devices in Home Assistant's device registry (MQTT identifiers that
    start with the base topic)."""
    return [
        device
        for device in await socket.devices()
        if any(
            domain == "mqtt" and identifier.startswith(f"{BASE}_")
            for domain, identifier in device["identifiers"]
        )
    ]


async def _none_left(socket: HomeAssistantSocket) -> str:
    entities = await socket.entities()
    return f"{len(entities)} MQTT entities left" if entities else ""


async def test_no_warning_or_error_over_start_config_change_and_stop(
    hass: HomeAssistant, ha_broker: Broker
) -> None:
    start = len(hass.log_records())
    sim = simulator(*((seed.unit, seed.mapping) for seed in SEEDS))
    renamed = {"fan_drive": ("supply_fan", "Supply fan"), "genset": ("genset", "Standby genset")}
    words = (f"{BASE}/", f"{PREFIX}/", *(s.id for s in SEEDS), "supply_fan", "value_json")
    socket = await hass.websocket()
    try:
        async with (
            serving_tcp(sim) as port,
            observing(ha_broker, f"{PREFIX}/#") as observer,
        ):
            async with bridge_running(site_config(ha_broker, port, seed_devices())):
                await settled(socket, observer)
            changed = site_config(ha_broker, port, seed_devices(**renamed))
            async with bridge_running(changed, remove_on_stop=True):
                registry = await settled(socket, observer)
                await asyncio.sleep(5)  # a few health reports on the changed config
                names = {d["name"] for d in await ours(socket)}
                assert {"Supply fan", "Standby genset"} <= names
                assert "Fan drive" not in names
            await until(lambda: _none_left(socket))
            left = [d["name"] for d in await ours(socket)]
            assert not left, f"devices left after the stop: {left}"
        await asyncio.sleep(3)  # what Home Assistant logs about the removal
        found = problems(hass.log_records()[start:], words)
        echoes = [line for line in found if HA_REMOVAL_ECHO in line]
        if release(hass.version) < FIXED_REMOVAL_ECHO:
            found = [line for line in found if HA_REMOVAL_ECHO not in line]
        print(
            f"Home Assistant {hass.version}: {len(registry)} entities, {len(found)} problems"
            f" ({len(echoes)} removal echoes)"
        )
        assert not found, f"{len(found)} warnings and errors:\n" + "\n".join(found[:40])
    finally:
        await socket.close()


async def test_a_command_select_shows_what_the_drive_does_not_the_last_choice(
    hass: HomeAssistant, ha_broker: Broker
) -> None:
    """select.fan_drive_command (write-only, P2 2000H) follows the drive's status word:
    forward_run while it runs forward, stop once it stands by, whichever stop was chosen
    (coast_stop is no state of its own); Home Assistant logs nothing about it."""
    sim = simulator(*((seed.unit, seed.mapping) for seed in SEEDS))
    socket = await hass.websocket()
    command, status = "select.fan_drive_command", "sensor.fan_drive_status"

    async def available() -> str:
        state = (await socket.states()).get(command, {}).get("state")
        return "" if state not in (None, "unavailable") else f"{command} is {state}"

    async def choose(option: str) -> None:
        await until(available, 60)  # discovered is not yet available (its first state)
        await socket.call(
            "call_service",
            domain="select",
            service="select_option",
            service_data={"option": option},
            target={"entity_id": command},
        )

    def shown(select: str, drive: str) -> Callable[[], Awaitable[str]]:
        async def check() -> str:
            states = await socket.states()
            now = (states[command]["state"], states[status]["state"])
            return "" if now == (select, drive) else f"{command}, {status}: {now}"

        return check

    start = len(hass.log_records())
    try:
        async with (
            serving_tcp(sim) as port,
            observing(ha_broker, f"{PREFIX}/#") as observer,
        ):
            async with bridge_running(
                site_config(ha_broker, port, seed_devices()), remove_on_stop=True
            ):
                await settled(socket, observer)
                await choose("forward_run")
                await until(shown("forward_run", "running_forward"), 60)
                await choose("coast_stop")
                await until(shown("stop", "standby"), 60)
            await until(lambda: _none_left(socket))
    finally:
        await socket.close()
    found = problems(hass.log_records()[start:], (command, "fan_drive"))
    assert not [p for p in found if HA_REMOVAL_ECHO not in p], found
