"""Issue 25's acceptance check against a real Home Assistant: alarms that automations can
use directly (``make test-ha`` runs it once per supported version).

A pump (nastec_vasco: alarm bits) and a drive (vacon_nx: alarm bits and a fault code)
simulated, the bridge in this process, Home Assistant's MQTT integration on the same
private broker, with ``automation`` and ``device_automation`` loaded.

- ``device_automation/trigger/list`` lists, for each device, exactly the device triggers
  its discovery publishes (two per alarm, ``<key>_other`` of a fault code included), with
  type raised/cleared and the alarm's name as subtype; Home Assistant's frontend labels
  them ``"Dry running" raised`` (MQTT has no translation for these types: it quotes the
  subtype and adds the type);
- an automation made through Home Assistant's config API on the "Dry running" raised
  trigger runs exactly once when the simulator raises the alarm, not again when the
  bridge restarts with the alarm still on, not on the clear, and once more on the next
  raise;
- the ``alarm_events`` event entity's state (the time of the last event) changes on each
  raise and clear with ``event_type`` ``alarm_dry_running_raised`` / ``_cleared``, and
  stays put over the restart;
- Home Assistant logs no warning or error about the bridge's topics, the event entity,
  the triggers or the automation.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import urllib.request
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from bridge.config import LoadedConfig
from bridge.modbus.simulator import Simulator
from tests.ha import homeassistant
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket
from tests.ha.test_home_assistant import BASE, PREFIX, bridge_running, problems, site_config
from tests.integration.harness import serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(600)]

# Loaded at the start with no automations; once Home Assistant is up the test points
# ``automation`` at automations.yaml, the file the config API writes (an ``!include`` of
# a file that does not exist yet would stop the start), and the API's reload reads it.
AUTOMATION_LOADED = "automation: []\ndevice_automation:\n"
AUTOMATION_FILE = "automation: !include automations.yaml\n"
SETTLE = 120.0  # s for Home Assistant to take in the two devices
STEP = 60.0  # s for a raise or a clear to reach Home Assistant (a new venv starts slowly)
QUIET = 6.0  # s of several polls (0.5 s) and, after a restart, the bridge's discovery
POLL = {"fast": 0.5, "slow": 5.0}
RUNS_TOPIC = "test/alarm_automation"
AUTOMATION_ID = "dry_running_raised"
ALARM, NAME = "alarm_dry_running", "Dry running"
# Loggers of what the test makes besides the MQTT entities (OUR_LOGGERS has those)
TRIGGER_LOGGERS = (
    "homeassistant.components.automation",
    "homeassistant.components.device_automation",
    "homeassistant.components.event",
    "homeassistant.helpers.script",
    "homeassistant.helpers.trigger",
    "homeassistant.components.config",
)


@dataclass(frozen=True, slots=True)
class Device:
    id: str
    name: str
    mapping: str
    unit: int


PUMP = Device("borehole_pump", "Borehole pump", "nastec_vasco", 1)
DRIVE = Device("main_drive", "Main drive", "vacon_nx", 4)


@pytest.fixture(scope="module", autouse=True)
def automation_loaded() -> Iterator[None]:
    """conftest.py's Home Assistant with ``automation`` and ``device_automation`` in its
    configuration.yaml (autouse: set up before ``hass`` starts it)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            homeassistant, "CONFIGURATION", homeassistant.CONFIGURATION + AUTOMATION_LOADED
        )
        yield


def devices_config(broker: Broker, port: int) -> LoadedConfig:
    return site_config(
        broker,
        port,
        [
            {"id": d.id, "name": d.name, "bus": "demo", "unit": d.unit}
            | {"mapping": d.mapping, "poll": POLL}
            for d in (PUMP, DRIVE)
        ],
    )


def components(observer: Observer, device: Device) -> dict[str, dict[str, Any]]:
    """The components of the device's retained discovery config ({} before it comes)."""
    payload = observer.retained.get(f"{PREFIX}/device/{device.id}/config")
    return dict(json.loads(payload)["cmps"]) if payload else {}


def published_triggers(observer: Observer, device: Device) -> set[tuple[str, str]]:
    """(type, subtype) of every device trigger the device's discovery publishes."""
    return {
        (c["type"], c["subtype"])
        for c in components(observer, device).values()
        if c["platform"] == "device_automation"
    }


def label(trigger: dict[str, Any]) -> str:
    """The label Home Assistant's frontend shows for an MQTT device trigger whose type
    MQTT has no translation for (``localizeDeviceAutomationTrigger``)."""
    return f'"{trigger["subtype"]}" {trigger["type"]}'


async def until(check: Callable[[], Awaitable[str]], timeout: float) -> None:
    """Wait until ``check()`` returns "" (it returns what is still wrong), bounded."""
    wrong = "not checked"
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(timeout):
            while wrong := await check():
                await asyncio.sleep(0.5)
    assert not wrong, f"after {timeout} s: {wrong}"


async def registry_device(socket: HomeAssistantSocket, device: Device) -> str:
    """The device's id in Home Assistant's device registry."""
    identifier = ["mqtt", f"{BASE}_{device.id}"]
    found = [d["id"] for d in await socket.devices() if identifier in d["identifiers"]]
    assert len(found) == 1, f"{device.id}: {found}"
    return str(found[0])


async def listed_triggers(socket: HomeAssistantSocket, device: Device) -> list[dict[str, Any]]:
    """The MQTT device triggers Home Assistant lists for the device (the list also has
    the triggers of its entities: a binary sensor turned on, a sensor's value changed)."""
    device_id = await registry_device(socket, device)
    listed = await socket.call("device_automation/trigger/list", device_id=device_id)
    return [t for t in listed if t["domain"] == "mqtt"]


async def settled(socket: HomeAssistantSocket, observer: Observer) -> None:
    """Wait until Home Assistant has both devices' entities and lists their triggers."""

    async def check() -> str:
        unique_ids = {e["unique_id"] for e in await socket.entities()}
        for device in (PUMP, DRIVE):
            asked = {c.get("unique_id") for c in components(observer, device).values()} - {None}
            if not asked or asked - unique_ids:
                return f"{device.id}: {len(asked - unique_ids)} of {len(asked)} entities missing"
            if not {d["name"] for d in await socket.devices()} >= {device.name}:
                return f"{device.id}: no device"
            listed = await listed_triggers(socket, device)
            if len(listed) != len(published_triggers(observer, device)):
                return f"{device.id}: {len(listed)} triggers listed"
        return ""

    await until(check, SETTLE)


@contextlib.asynccontextmanager
async def pump_and_drive(
    hass: HomeAssistant, ha_broker: Broker, sim: Simulator
) -> AsyncIterator[tuple[HomeAssistantSocket, Observer, LoadedConfig]]:
    """``sim`` served, an observer of the discovery, the bridge's topics and the test
    topic, and a websocket; the bridge is the caller's to run."""
    socket = await hass.websocket()
    try:
        async with (
            serving_tcp(sim) as port,
            observing(ha_broker, f"{PREFIX}/#", f"{BASE}/#", RUNS_TOPIC) as observer,
        ):
            yield socket, observer, devices_config(ha_broker, port)
    finally:
        await socket.close()


def our_problems(hass: HomeAssistant, start: int) -> list[str]:
    """Warnings and errors since record ``start`` about the bridge's topics and devices,
    the MQTT entities (test_home_assistant's ``problems``), or from the loggers of the
    event entity, device triggers and automations."""
    records = hass.log_records()[start:]
    words = (f"{BASE}/", f"{PREFIX}/", PUMP.id, DRIVE.id, RUNS_TOPIC, "value_json", "trigger")
    found = problems(records, words)
    found += [
        str(r)
        for r in records
        if r.level in ("WARNING", "ERROR", "CRITICAL")
        and r.logger.startswith(TRIGGER_LOGGERS)
        and str(r) not in found
    ]
    return found


async def test_the_triggers_home_assistant_lists_are_the_published_ones(
    hass: HomeAssistant, ha_broker: Broker
) -> None:
    start = len(hass.log_records())
    sim = simulator((PUMP.unit, PUMP.mapping), (DRIVE.unit, DRIVE.mapping))
    async with (
        pump_and_drive(hass, ha_broker, sim) as (socket, observer, config),
        bridge_running(config),
    ):
        await settled(socket, observer)
        for device in (PUMP, DRIVE):
            listed = await listed_triggers(socket, device)
            published = published_triggers(observer, device)
            print(
                f"Home Assistant {hass.version}, {device.id}: {len(listed)} triggers:",
                ", ".join(sorted(label(t) for t in listed)),
            )
            print(f"  e.g. {listed[0]}")
            pairs = [(t["type"], t["subtype"]) for t in listed]
            assert sorted(pairs) == sorted(published)
            assert len(pairs) == len(set(pairs))
        pump = {label(t) for t in await listed_triggers(socket, PUMP)}
        assert {'"Dry running" raised', '"Dry running" cleared'} <= pump
        drive = {label(t) for t in await listed_triggers(socket, DRIVE)}
        assert '"Fault code: other code" raised' in drive
    found = our_problems(hass, start)
    assert not found, f"{len(found)} warnings and errors:\n" + "\n".join(found[:40])


def post(hass: HomeAssistant, path: str, body: dict[str, Any]) -> Any:
    request = urllib.request.Request(
        hass.url + path,
        data=json.dumps(body).encode(),
        headers={"Authorization": f"Bearer {hass.token}", "Content-Type": "application/json"},
    )
    with urllib.request.urlopen(request, timeout=60) as answer:
        return json.loads(answer.read())


async def make_automation(
    hass: HomeAssistant, socket: HomeAssistantSocket, trigger: dict[str, Any]
) -> str:
    """An automation (through the config API) that publishes the event's name and state
    on RUNS_TOPIC each time ``trigger`` fires, queued (a second run is never dropped);
    its entity id once Home Assistant runs it."""
    configuration = hass.config_dir / "configuration.yaml"
    text = configuration.read_text()
    if AUTOMATION_LOADED in text:
        configuration.write_text(text.replace("automation: []\n", AUTOMATION_FILE))
    automation = {
        "alias": "Dry running raised",
        "mode": "queued",
        "triggers": [trigger],
        "actions": [
            {
                "action": "mqtt.publish",
                "data": {
                    "topic": RUNS_TOPIC,
                    "payload": "{{ trigger.payload_json.name }} {{ trigger.payload_json.transition }}",
                },
            }
        ],
    }
    answer = post(hass, f"/api/config/automation/config/{AUTOMATION_ID}", automation)
    assert answer == {"result": "ok"}
    entity_id = ""

    async def check() -> str:
        nonlocal entity_id
        for state in (await socket.states()).values():
            if state["attributes"].get("id") == AUTOMATION_ID and state["state"] == "on":
                entity_id = state["entity_id"]
                return ""
        return "no automation running"

    await until(check, STEP)
    # Home Assistant 2026.11 shows the automation on, then detaches and attaches its
    # triggers again when its entity id is settled (automation/entity.py: "reattach"): a
    # raise in between is never seen. Several seconds for that before anything is raised.
    await asyncio.sleep(QUIET)
    return entity_id


def runs(observer: Observer) -> list[str]:
    return [m.payload.decode() for m in observer.log if m.topic == RUNS_TOPIC]


async def test_an_automation_on_a_trigger_runs_once_per_raise_and_not_on_a_restart(
    hass: HomeAssistant, ha_broker: Broker
) -> None:
    start = len(hass.log_records())
    sim = simulator((PUMP.unit, PUMP.mapping), (DRIVE.unit, DRIVE.mapping))
    async with pump_and_drive(hass, ha_broker, sim) as (socket, observer, config):
        async with bridge_running(config):
            await settled(socket, observer)
            entity = components(observer, PUMP)["alarm_events"]["default_entity_id"]
            (trigger,) = [
                t
                for t in await listed_triggers(socket, PUMP)
                if (t["type"], t["subtype"]) == ("raised", NAME)
            ]
            automation = await make_automation(hass, socket, trigger)

            async def available() -> str:
                state = (await socket.states())[entity]["state"]
                return f"{entity}: {state}" if state == "unavailable" else ""

            await until(available, STEP)
            before = (await socket.states())[entity]

            def event_is(kind: str, after: str) -> Callable[[], Awaitable[str]]:
                async def check() -> str:
                    state = (await socket.states())[entity]
                    shown = (state["state"], state["attributes"].get("event_type"))
                    done = shown[0] != after and shown[1] == f"{ALARM}_{kind}"
                    return "" if done else f"{entity}: {shown}"

                return check

            async def runs_are(count: int) -> str:
                return "" if len(runs(observer)) == count else f"runs: {runs(observer)}"

            sim.raise_fault(PUMP.unit, ALARM)
            await until(lambda: runs_are(1), STEP)
            await until(event_is("raised", before["state"]), STEP)
            raised = (await socket.states())[entity]
            await asyncio.sleep(QUIET)
            assert runs(observer) == [f"{NAME} raised"]
        restart = len(observer.log)
        async with bridge_running(config):
            # the new bridge has read the pump and still sees the alarm
            await until(lambda: still_raised(observer, restart), STEP)
            await asyncio.sleep(QUIET)
            assert runs(observer) == [f"{NAME} raised"], "ran again on the restart"
            after_restart = (await socket.states())[entity]
            assert (after_restart["state"], after_restart["attributes"]["event_type"]) == (
                raised["state"],
                f"{ALARM}_raised",
            )
            sim.clear_faults(PUMP.unit)
            await until(event_is("cleared", raised["state"]), STEP)
            cleared = (await socket.states())[entity]
            sim.raise_fault(PUMP.unit, ALARM)
            await until(lambda: runs_are(2), STEP)
            await until(event_is("raised", cleared["state"]), STEP)
            await asyncio.sleep(QUIET)
            assert runs(observer) == [f"{NAME} raised"] * 2
            final = (await socket.states())[entity]
            shown = (await socket.states())[automation]
            print(
                f"Home Assistant {hass.version}: {automation} ran {len(runs(observer))} times,"
                f" last_triggered {shown['attributes'].get('last_triggered')};"
                f" {entity}: {before['state']} -> {raised['state']} (raised)"
                f" -> {cleared['state']} (cleared) -> {final['state']} (raised),"
                f" attributes {final['attributes']}"
            )
            assert shown["attributes"].get("last_triggered")
            assert raised["attributes"]["name"] == NAME
    found = our_problems(hass, start)
    assert not found, f"{len(found)} warnings and errors:\n" + "\n".join(found[:40])


async def still_raised(observer: Observer, since: int) -> str:
    """Nothing once a state document of the pump published after log index ``since``
    lists the alarm; else what they list."""
    topic = f"{BASE}/{PUMP.id}"
    documents = [json.loads(m.payload) for m in observer.log[since:] if m.topic == topic]
    if documents and ALARM in documents[-1].get("alarms", []):
        return ""
    return f"{topic} since the restart: {[d.get('alarms') for d in documents]}"
