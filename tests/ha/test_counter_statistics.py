"""Issue 26's acceptance check against a real Home Assistant's recorder: counters you can
trust (``make test-ha`` runs it once per supported version).

The genset's energy counter (smartgen_hgm6100, kWh as two words of radix 10000,
``total_increasing``) counts in steps the test sets in the simulator, and between the steps
misreads on demand (bridge/core/simulation_counter.py): a single 0, a torn read, one
digit of jitter, a reboot that reads 0 twice; then the meter is reset for good and counts
again from 0. The bridge (bridge/core/counters.py) holds every misread back and publishes
the reset once three lower readings confirm it. Home Assistant's long-term statistics
(``recorder/statistics_during_period``, the 5-minute ``sum`` the recorder compiles 10 s
after each 5-minute boundary) must grow by exactly the energy the simulator counted:
0 phantom kWh through the misreads, and after the reset the new count added with no jump
(Home Assistant starts a new cycle at a drop below 90 %: its new value counts in full).

A control in the same window shows that the check can see a phantom: a second
``total_increasing`` sensor, discovered by the test on the same broker, is sent the
readings as a bridge without the guard would have published them, misreads included. Its
sum must be what Home Assistant's rule (``ha_sum``) makes of them: thousands of kWh more
than counted.

Duration: Home Assistant's start (10-60 s), the counter's story and the control (about
70 s), then the wait until the 5-minute period the story ended in is compiled (0-5 min,
plus 10 s): 1.5-7 minutes a version (2.8-5.5 min seen on 2025.10.4 and 2026.11.0).
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Awaitable, Callable, Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from bridge.config import LoadedConfig, load_config_data
from bridge.core.simulation_counter import REBOOT_READS
from bridge.modbus.simulator import Simulator
from bridge.mqtt.session import MqttClient
from tests.ha.homeassistant import HomeAssistant, HomeAssistantSocket
from tests.ha.test_home_assistant import bridge_running
from tests.integration.harness import serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(900)]

HA_CACHE = Path.home() / ".cache" / "modbus-mqtt-bridge" / "ha-forky"  # as in conftest.py
PREFIX = "homeassistant"
BASE = "modbus"
GENSET, DEVICE, KEY = 5, "genset", "energy"
POLL = 0.5  # s, fast and slow alike: the energy counter is a slow point
START = 12345  # kWh when the bridge starts: Home Assistant's zero point
# The counter's story: a number counts to that many kWh, a name is a fault of the simulator
# (a misread, or "reset": the meter cleared for good, counting again from 0).
STORY: tuple[int | str, ...] = (
    12350, "zero", 12357, "tear", 12360, "jitter", 12370, "reboot", 12380, "reset", 4, 9
)  # fmt: skip
MISREADS = {"zero": 1, "tear": 1, "jitter": 1, "reboot": REBOOT_READS}  # reads answered wrong
RADIX = 10000  # the counter's low word: a torn read answers it as 0 (kWh - kWh % RADIX)
PERIOD = 300  # s: the recorder's short-term statistics
COMPILED_AFTER = 10  # s after a period's end the recorder compiles it
COMPILE_BOUND = 120.0  # s beyond that before giving up
STEP_BOUND = 20.0  # s for a step to reach Home Assistant
CONTROL_UNIQUE_ID = "counter_statistics_raw_energy"
CONTROL_TOPIC = "counter_statistics/raw_energy"


HA_INTEGRATIONS = ("recorder",)  # conftest.py's hass loads it for this module only


def produced(story: Sequence[int | str], start: float) -> float:
    """The energy the simulator counted: every rise a step makes (from 0 after a reset)."""
    total, value = 0.0, start
    for step in story:
        if step == "reset":
            value = 0
        elif isinstance(step, int):
            total, value = total + step - value, step
    return total


def counted(story: Sequence[int | str], start: int) -> list[int]:
    """The values the counter really went through (what the bridge must publish)."""
    values = [start]
    for step in story:
        if isinstance(step, int) or step == "reset":
            values.append(0 if step == "reset" else int(step))
    return values


def raw_readings(story: Sequence[int | str], start: int) -> list[int]:
    """What a bridge without the guard would publish, one value per reading that differs
    from the one before (Home Assistant records changes only)."""
    readings, value = [start], start
    for step in story:
        if isinstance(step, int):
            value = step
            readings.append(value)
        elif step == "reset":
            value = 0
            readings.append(value)
        else:
            wrong = {"zero": 0, "reboot": 0, "tear": value - value % RADIX, "jitter": value - 1}
            readings += [wrong[step], value]
    return [v for i, v in enumerate(readings) if i == 0 or v != readings[i - 1]]


def ha_sum(states: Sequence[float]) -> float:
    """Home Assistant's ``sum`` of a total_increasing sensor over ``states`` (its
    sensor/recorder.py): the first state is the zero point; a state below 90 % of the one
    before starts a new cycle from 0, in which the new state counts in full."""
    total, zero, last = 0.0, float(states[0]), float(states[0])
    for state in states[1:]:
        if state < 0.9 * last:
            total, zero = total + last - zero, 0.0
        last = state
    return total + last - zero


def genset_config(broker: Broker, port: int) -> LoadedConfig:
    device = {"id": DEVICE, "name": "Genset", "bus": "sim", "unit": GENSET}
    data = {
        "mqtt": {"url": broker.url, "base_topic": BASE, "discovery_prefix": PREFIX},
        "bridge": {"health_interval": 0.5},
        "buses": [
            {"id": "sim", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
            | {"timeout": 0.5}
        ],
        "devices": [
            device
            | {"mapping": "smartgen_hgm6100", "poll": {"fast": POLL, "slow": POLL}}
            | {"protocol": {"min_request_interval": 0.05}}
        ],
    }
    return load_config_data(data, Path("counter-statistics.yaml"))


async def waited(check: Callable[[], Awaitable[str]], bound: float, every: float = 0.2) -> None:
    """Wait until ``check()`` returns "" (it returns what is still wrong), asking ``every``
    seconds; after ``bound`` seconds fail with what it returned last."""
    wrong = "not checked"
    try:
        async with asyncio.timeout(bound):
            while wrong := await check():
                await asyncio.sleep(every)
    except TimeoutError:
        raise AssertionError(f"after {bound:.0f} s: {wrong}") from None


async def recording(socket: HomeAssistantSocket) -> None:
    """Wait until Home Assistant's recorder records (bounded)."""

    async def check() -> str:
        info = await socket.call("recorder/info")
        return "" if info["recording"] else f"Home Assistant's recorder: {info}"

    await waited(check, 60, every=1.0)


async def entity_of(socket: HomeAssistantSocket, unique_id: str) -> str:
    """The entity id Home Assistant gave the MQTT entity ``unique_id`` (waited for)."""
    found: dict[str, str] = {}

    async def check() -> str:
        found.update({e["unique_id"]: e["entity_id"] for e in await socket.entities()})
        return "" if unique_id in found else f"no entity with unique_id {unique_id}"

    await waited(check, 60)
    return found[unique_id]


async def shown(socket: HomeAssistantSocket, entity_id: str, value: float) -> None:
    """Wait until Home Assistant's state of ``entity_id`` is ``value``."""

    async def check() -> str:
        state = str((await socket.states()).get(entity_id, {}).get("state"))
        try:
            return "" if float(state) == value else f"{entity_id} is {state}, not {value}"
        except ValueError:
            return f"{entity_id} is {state}, not {value}"

    await waited(check, STEP_BOUND)


def lower_readings(observer: Observer) -> int:
    """The genset's counter readings below the published value so far, held back or
    published as a reset (its health report)."""
    payload = observer.retained.get(f"{BASE}/bridge/health")
    if not payload:
        return 0
    health = json.loads(payload)["devices"][DEVICE]
    return int(health["counter_readings_held"]) + int(health["counter_resets"])


def published(observer: Observer) -> list[float]:
    """Every energy value the genset's documents carried, in order, repeats dropped."""
    values: list[float] = []
    for message in observer.log:
        if message.topic == f"{BASE}/{DEVICE}" and message.payload:
            value = json.loads(message.payload).get(KEY)
            if value is not None and (not values or values[-1] != value):
                values.append(value)
    return values


async def play(
    socket: HomeAssistantSocket, sim: Simulator, observer: Observer, entity_id: str
) -> None:
    """The story through the bridge: each count shown by Home Assistant, each misread
    read (and held) by the bridge, the reset confirmed and shown as 0."""
    for step in STORY:
        if isinstance(step, int):
            sim.set_value(GENSET, KEY, step)
            await shown(socket, entity_id, step)
        elif step == "reset":
            sim.counter_fault(GENSET, KEY, step)
            await shown(socket, entity_id, 0)
        else:
            before = lower_readings(observer)
            sim.counter_fault(GENSET, KEY, step)

            async def read(before: int = before, step: str = step) -> str:
                return "" if lower_readings(observer) > before else f"{step} not read yet"

            await waited(read, STEP_BOUND)
            # the rest of the misreads read, and what a published one would take to show
            await asyncio.sleep((MISREADS[step] + 2) * POLL)


async def play_control(socket: HomeAssistantSocket, client: MqttClient) -> str:
    """The control sensor discovered and sent the raw readings; its entity id."""
    config = {
        "name": "Raw energy",
        "unique_id": CONTROL_UNIQUE_ID,
        "state_topic": CONTROL_TOPIC,
        "unit_of_measurement": "kWh",
        "device_class": "energy",
        "state_class": "total_increasing",
    }
    await client.publish(f"{PREFIX}/sensor/{CONTROL_UNIQUE_ID}/config", json.dumps(config))
    entity_id = await entity_of(socket, CONTROL_UNIQUE_ID)
    for value in raw_readings(STORY, START):  # retained: the entity may subscribe late
        await client.publish(CONTROL_TOPIC, str(value), retain=True)
        await shown(socket, entity_id, value)
    return entity_id


async def compiled(
    socket: HomeAssistantSocket, entity_ids: list[str], since: str, ended: float
) -> dict[str, list[dict[str, Any]]]:
    """The 5-minute statistics of ``entity_ids`` once the recorder has compiled the period
    ``ended`` (epoch seconds) falls in, bounded."""
    period = int(ended // PERIOD) * PERIOD
    await asyncio.sleep(max(period + PERIOD + COMPILED_AFTER - time.time(), 0))
    rows: dict[str, list[dict[str, Any]]] = {}

    async def check() -> str:
        rows.clear()
        rows.update(await socket.statistics(entity_ids, since))
        missing = [
            e for e in entity_ids if not any(r["start"] >= period * 1000 for r in rows.get(e, []))
        ]
        if not missing:
            return ""
        start = datetime.fromtimestamp(period, UTC)
        return f"the period from {start:%H:%M} UTC is not compiled for {missing}: {rows}"

    await waited(check, COMPILE_BOUND, every=5.0)
    return rows


async def test_misreads_put_no_phantom_energy_in_the_statistics(
    hass: HomeAssistant, ha_broker: Broker
) -> None:
    began = time.monotonic()
    since = (datetime.now(UTC) - timedelta(minutes=10)).isoformat()
    expected = produced(STORY, START)
    sim = simulator((GENSET, "smartgen_hgm6100"))
    sim.set_value(GENSET, KEY, START)
    socket = await hass.websocket()
    try:
        await recording(socket)
        async with (
            serving_tcp(sim) as port,
            observing(ha_broker, f"{BASE}/#") as observer,
            bridge_running(genset_config(ha_broker, port)),
        ):
            energy = await entity_of(socket, f"{BASE}_{DEVICE}_{KEY}")
            await shown(socket, energy, START)
            await play(socket, sim, observer, energy)
            control = await play_control(socket, observer.client)
            rows = await compiled(socket, [energy, control], since, time.time())
        series = published(observer)
    finally:
        await socket.close()
    grown, raw_grown = rows[energy][-1]["sum"], rows[control][-1]["sum"]
    print(
        f"Home Assistant {hass.version}: counted {expected:g} kWh; {energy} sum grew"
        f" {grown:g} kWh ({grown - expected:g} phantom); raw readings' sum grew {raw_grown:g}"
        f" kWh ({raw_grown - expected:g} phantom); {time.monotonic() - began:.0f} s;"
        f" {len(rows[energy])} periods"
    )
    assert grown == expected, f"{grown - expected:g} phantom kWh: {rows[energy]}"
    assert rows[energy][-1]["state"] == STORY[-1]
    assert series == counted(STORY, START)
    assert raw_grown == ha_sum(raw_readings(STORY, START)), rows[control]
    assert raw_grown > expected + START  # the control sees phantoms
