"""The seed devices as they behave on a real line (issue 12), end to end: a real Mosquitto,
the simulator with the device's quirk switched on, and ``Bridge.run()``.

Each test runs only the devices it needs, with the device fields it needs (a password,
``allow_dangerous_writes``). Waits are bounded; nothing asserts wall-clock time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.core.entity import PollClass, Table
from bridge.core.protocol import Keepalive
from bridge.core.request import Read
from bridge.errors import ModbusError
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.scheduler import Priority
from bridge.modbus.simulator import Quirks, Simulator
from bridge.mqtt.session import MqttClient
from tests.integration.harness import (
    Recorder,
    cancel,
    config,
    eventually,
    running,
    serving_tcp,
    simulator,
    tcp_bus,
)
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

H = Table.HOLDING


def device(name: str, unit: int = 1, **fields: Any) -> dict[str, Any]:
    return {
        "id": name,
        "bus": "tcp",
        "unit": unit,
        "mapping": name,
        "poll": {"fast": 0.5, "slow": 5},
    } | fields


@contextlib.asynccontextmanager
async def bridged(
    broker: Broker,
    sim: Simulator,
    devices: list[dict[str, Any]],
    bridge: dict[str, Any] | None = None,
) -> AsyncIterator[Bridge]:
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {
                "url": broker.url,
                "base_topic": "modbus",
                "command_expiry": 3,
                "output": "both",  # the plain per-key topics too
            },
            "bridge": {"health_interval": 0} | (bridge or {}),
            "buses": [
                {
                    "id": "tcp",
                    "transport": "tcp",
                    "host": "127.0.0.1",
                    "tcp_port": port,
                    "timeout": 0.5,
                }
            ],
            "devices": devices,
        }
        running = Bridge(load_config_data(data, Path("seed-behaviours.yaml")))
        task = asyncio.create_task(running.run())
        try:
            yield running
        finally:
            await cancel(task)


def errors(observer: Observer, device_id: str, since: int = 0) -> list[dict[str, Any]]:
    return [json.loads(m.payload) for m in observer.after(since, f"modbus/{device_id}/error")]


def writes_to(sim: Simulator, unit: int) -> list[Any]:
    return [w for u, w in sim.writes if u == unit]


async def online(observer: Observer, *device_ids: str) -> None:
    await eventually(
        lambda: all(
            observer.retained.get(f"modbus/{d}/availability") == b"online" for d in device_ids
        ),
        timeout=20,
    )


# --- item 4: a negative speed reference is guarded like reverse run ------------------------

P2_SET_VALUE = 0x1000
VACON_SPEED_REFERENCE = 2002  # ID 2003


@pytest.mark.asyncio
async def test_a_negative_speed_reference_is_refused_unless_dangerous_writes_are_allowed(
    mosquitto: Broker,
) -> None:
    """P2 1000H and Vacon 2003: -10 % is refused over MQTT and as a raw write (nothing on
    the wire), +25 % is written; a P2 that allows dangerous writes takes -10 %."""
    sim = simulator((1, "p2_vfd"), (2, "vacon_nx"), (3, "p2_vfd"))
    devices = [
        device("p2_vfd", 1),
        device("vacon_nx", 2),
        device("p2_reversible", 3, mapping="p2_vfd", allow_dangerous_writes=True),
    ]
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, devices, {"allow_raw_writes": True}),
    ):
        await online(observer, "p2_vfd", "vacon_nx", "p2_reversible")
        await observer.client.publish("modbus/p2_vfd/set_value/set", "-10")
        await observer.client.publish("modbus/vacon_nx/set", '{"speed_reference": -0.01}')
        await eventually(lambda: errors(observer, "p2_vfd") and errors(observer, "vacon_nx"))
        for device_id, key in (("p2_vfd", "set_value"), ("vacon_nx", "speed_reference")):
            [error] = errors(observer, device_id)
            assert error["key"] == key
            assert "a value below 0 is a guarded write" in error["error"], error
        raw = json.dumps({"device": "p2_vfd", "address": P2_SET_VALUE, "values": [0xEC78]})
        await observer.client.publish("modbus/bridge/request/device/write", raw)
        await eventually(lambda: observer.after(0, "modbus/bridge/response/device/write"))
        answer = json.loads(observer.after(0, "modbus/bridge/response/device/write")[0].payload)
        assert answer["status"] == "error" and "guarded" in answer["error"], answer
        await asyncio.sleep(0.3)
        assert sim.writes == []
        await observer.client.publish("modbus/p2_vfd/set_value/set", "25")
        await observer.client.publish("modbus/vacon_nx/speed_reference/set", "0")
        await observer.client.publish("modbus/p2_reversible/set_value/set", "-10")
        await eventually(lambda: len(sim.writes) == 3)
        assert {(u, w.address, w.values) for u, w in sim.writes} == {
            (1, P2_SET_VALUE, (2500,)),
            (2, VACON_SPEED_REFERENCE, (0,)),
            (3, P2_SET_VALUE, (0xFC18,)),  # -1000 = -10.00 %
        }


# --- item 12: a value read is never dropped in Home Assistant --------------------------------


def discovery_component(observer: Observer, device_id: str, key: str) -> dict[str, Any]:
    """The component as retained now; empty while the config is not out yet."""
    topic = f"homeassistant/device/{device_id}/config"
    if topic not in observer.retained:
        return {}
    component: dict[str, Any] = observer.json(topic)["cmps"][key]
    return component


@pytest.mark.asyncio
async def test_values_home_assistant_would_drop_are_published_and_admitted(
    mosquitto: Broker,
) -> None:
    """A soft-start time reading 0 (range 1-200) and a fault code the mapping has no label for
    (23): the state carries both, the discovery payload admits both (number range, enum
    option) before the state arrives, the unknown code is an active alarm and is counted in
    the health report, which is retained so a late subscriber (Home Assistant subscribing
    after discovery) has it at once."""
    sim = simulator((1, "soft_starter"))
    sim.set_value(1, "soft_start_time", 0)
    async with (
        observing(mosquitto, "modbus/#", "homeassistant/#") as observer,
        bridged(mosquitto, sim, [device("soft_starter")], {"health_interval": 0.5}),
    ):
        await online(observer, "soft_starter")
        topic = "modbus/soft_starter"
        await eventually(lambda: topic in observer.retained)
        assert observer.json(topic)["soft_start_time"] == 0
        await eventually(
            lambda: discovery_component(observer, "soft_starter", "soft_start_time").get("min") == 0
        )
        number = discovery_component(observer, "soft_starter", "soft_start_time")
        assert (number["min"], number["max"]) == (0, 200)
        seen = len(observer.log)
        sim.set_value(1, "fault_status", "code_23")
        await eventually(lambda: observer.json(topic)["fault_status"] == "code_23", timeout=10)
        assert "fault_status_23" in observer.json(topic)["alarms"]
        await eventually(lambda: observer.retained[f"{topic}/fault_status"] == b"code_23")
        options = discovery_component(observer, "soft_starter", "fault_status")["options"]
        assert options[-1] == "code_23"
        config_at = max(
            i for i, m in enumerate(observer.log) if m.topic.endswith("soft_starter/config")
        )
        first_state = min(
            i
            for i, m in enumerate(observer.log)
            if i >= seen and m.topic == topic and json.loads(m.payload)["fault_status"] == "code_23"
        )
        assert config_at < first_state  # the payload admits the code before the state says it
        await eventually(
            lambda: any(
                json.loads(m.payload)["devices"]["soft_starter"]["unknown_codes"] >= 1
                for m in observer.after(seen, "modbus/bridge/health")
                if m.payload
            )
        )
        config = MqttConfig(url=mosquitto.url)
        async with MqttClient(config, will_topic="late/state", client_id="late") as late:
            await late.subscribe("modbus/bridge/health")
            async with asyncio.timeout(5):
                first = await anext(late.messages())
            assert first.retain  # sent at subscription, not one health interval later
            assert "soft_starter" in json.loads(first.payload)["devices"]


# --- item 8: the P2 password unlock -------------------------------------------------------

P2_PASSWORD = 12345  # devices doc §9 frame D15: 01 06 1F 00 30 39 5A 0C
UNLOCK = 0x1F00


def password_writes(sim: Simulator, unit: int = 1) -> list[Any]:
    return [w for w in writes_to(sim, unit) if w.address == UNLOCK]


@pytest.mark.asyncio
async def test_a_locked_p2_is_unlocked_once_with_its_password(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """The drive answers 07 to everything until 12345 is written to 1F00H (echo 8888H): the
    bridge writes it once, the device comes online with its values, and the password is in
    no MQTT message and no log line; locked again later, it is unlocked again, once."""
    caplog.set_level(logging.DEBUG)
    monkeypatch.setenv("P2_PASSWORD", str(P2_PASSWORD))
    sim = simulator((1, "p2_vfd"), password=P2_PASSWORD)
    async with (
        observing(mosquitto, "modbus/#", "homeassistant/#") as observer,
        bridged(mosquitto, sim, [device("p2_vfd", password_env="P2_PASSWORD")]) as running,
    ):
        await online(observer, "p2_vfd")
        await eventually(lambda: "status" in observer.json("modbus/p2_vfd"))
        assert observer.json("modbus/p2_vfd")["status"] == "running_forward"
        assert [(w.function, w.values) for w in password_writes(sim)] == [(6, (P2_PASSWORD,))]
        assert sim.image(1)[(H, UNLOCK)] == 0x8888  # the echo the bridge got
        poller = running.engine.devices["p2_vfd"]
        sim.set_quirks(1, Quirks(password=P2_PASSWORD))  # power cycle: locked again
        polls = poller.health.requests
        await eventually(lambda: poller.health.requests > polls + 10)
        assert len(password_writes(sim)) == 2
        assert poller.health.online is True
        info = observer.retained["modbus/bridge/info"].decode()
        assert "P2_PASSWORD" in info  # the variable's name, never its value
    secret = str(P2_PASSWORD)
    assert not any(secret in m.payload.decode(errors="replace") for m in observer.log)
    assert secret not in caplog.text
    assert "unlocked with its password" in caplog.text


@pytest.mark.asyncio
async def test_a_wrong_p2_password_puts_the_device_in_error_without_a_second_try(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Exception 01 to the password write: one write, the device offline with the reason
    in the log once, and polls that follow never write the password again."""
    monkeypatch.setenv("P2_PASSWORD", "4321")
    sim = simulator((1, "p2_vfd"), password=P2_PASSWORD)
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, [device("p2_vfd", password_env="P2_PASSWORD")]) as running,
    ):
        poller = running.engine.devices["p2_vfd"]
        await eventually(lambda: observer.retained.get("modbus/p2_vfd/availability") == b"offline")
        requests = poller.health.requests
        await eventually(lambda: poller.health.requests > requests, timeout=15)  # a probe
        assert [w.values for w in password_writes(sim)] == [(4321,)]
    errors = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert [r.getMessage().split(":")[1].strip() for r in errors] == ["wrong password"]
    assert caplog.text.count("offline (wrong password") == 1
    assert "4321" not in caplog.text


@pytest.mark.asyncio
async def test_a_locked_p2_without_a_password_says_what_to_configure(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    sim = simulator((1, "p2_vfd"), password=P2_PASSWORD)
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, [device("p2_vfd")]),
    ):
        await eventually(lambda: observer.retained.get("modbus/p2_vfd/availability") == b"offline")
    assert password_writes(sim) == []
    assert "set devices.p2_vfd.password_env or devices.p2_vfd.password_file" in caplog.text


# --- item 9: the Smartgen breakers are switches with a desired state -----------------------

GEN_TOGGLE, GEN_ON_LOAD = 5, 7  # FC05 0005 close/open, FC01 0007 generator on load


def smartgen_device(**fields: Any) -> dict[str, Any]:
    return device(
        "smartgen_hgm6100",
        protocol={"min_request_interval": 0.05},
        allow_dangerous_writes=True,
        **fields,
    )


@pytest.mark.asyncio
async def test_a_breaker_switch_toggles_only_towards_the_state_asked_for(
    mosquitto: Broker,
) -> None:
    """Refused with the reason outside manual mode and while remote control is locked; in
    manual mode ON sends one toggle and the breaker closes, ON again sends nothing, OFF right
    after is refused (never twice within 2 s), OFF later opens it with one toggle."""
    sim = simulator((1, "smartgen_hgm6100"))
    topic = "modbus/smartgen_hgm6100/generator_breaker/set"
    async with (
        observing(mosquitto, "modbus/#", "homeassistant/#") as observer,
        bridged(mosquitto, sim, [smartgen_device()]),
    ):
        await online(observer, "smartgen_hgm6100")
        config = "homeassistant/device/smartgen_hgm6100/config"  # discovery follows the state
        await eventually(lambda: config in observer.retained, 10)
        cmps = observer.json(config)["cmps"]
        assert cmps["generator_breaker"]["platform"] == "switch"
        assert cmps["generator_breaker"]["value_template"] == "{{ value_json.generator_on_load }}"
        await observer.client.publish(topic, "ON")
        await eventually(lambda: errors(observer, "smartgen_hgm6100"))
        [refused] = errors(observer, "smartgen_hgm6100")
        assert "Manual mode (manual_mode) reads off, needs on" in refused["error"], refused
        sim.set_value(1, "manual_mode", True)
        sim.set_value(1, "remote_lock", True)
        await observer.client.publish(topic, "ON")
        await eventually(lambda: len(errors(observer, "smartgen_hgm6100")) == 2)
        assert (
            "(remote_lock) reads on, needs off" in errors(observer, "smartgen_hgm6100")[1]["error"]
        )
        assert writes_to(sim, 1) == []
        sim.set_value(1, "remote_lock", False)
        await observer.client.publish(topic, "ON")
        await eventually(lambda: writes_to(sim, 1))
        await eventually(lambda: observer.json("modbus/smartgen_hgm6100")["generator_on_load"])
        seen = len(observer.log)
        await observer.client.publish(topic, "ON")  # already closed: nothing to send
        await observer.client.publish(topic, "OFF")  # within 2 s of the toggle: refused
        await eventually(lambda: errors(observer, "smartgen_hgm6100", seen))
        [early] = errors(observer, "smartgen_hgm6100", seen)
        assert early["value"] == "OFF" and "not again within 2 s" in early["error"], early
        assert [(w.address, w.values) for w in writes_to(sim, 1)] == [(GEN_TOGGLE, (0x00FF,))]
        await asyncio.sleep(2.0)
        await observer.client.publish(topic, "OFF")
        await eventually(lambda: len(writes_to(sim, 1)) == 2)
        await eventually(lambda: not observer.json("modbus/smartgen_hgm6100")["generator_on_load"])
        assert sim.image(1)[(Table.COIL, GEN_ON_LOAD)] == 0
        assert len(errors(observer, "smartgen_hgm6100", seen)) == 1


# --- item 10: tear-free 32-bit counters on one-register-per-read devices -------------------

ELECTRIC_LIFE_HIGH = 0xAA  # Nastec idx 0xAB (high word), 0xAC (low word)


@pytest.mark.asyncio
async def test_a_counter_rolling_over_between_its_two_reads_is_read_again() -> None:
    """The Nastec reads one register per request. Its power-on counter stands at 0x0000FFFF
    and counts one second right after its high word is read, so the low word comes back as
    0x0000: the pair read is 0 instead of 65536. The bridge reads the high word again, sees
    it moved, reads low and high again and publishes 65537, never the torn 0."""
    sim = simulator((1, "nastec_vasco"), count_on_read=ELECTRIC_LIFE_HIGH)
    sim.set_value(1, "electric_life", 0xFFFF)
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("nastec_vasco")]), recorder := Recorder())
        async with running(engine, pollers=False):
            nastec = engine.devices["nastec_vasco"]
            values = await nastec.read_now(["electric_life", "inverter_life"])
            assert values["electric_life"] == 0x10001, hex(values["electric_life"] or 0)
            assert sim.value(1, "electric_life") == 0x10002  # counted at each high read
            published = [u.values.get("electric_life") for u in recorder.of("nastec_vasco")]
            assert 0 not in published
            await nastec.poll([PollClass.SLOW])
            assert nastec.values["electric_life"] == sim.value(1, "electric_life") - 1


# --- item 11: watchdogs are fed even when the bus is busy ---------------------------------


def with_keepalive(loaded: Any, device_id: str, interval: float) -> Any:
    """The device's mapping with its watchdog interval shortened (20 s is long for a test)."""
    mapping = loaded.mappings[device_id]
    keepalive = Keepalive(interval=interval)
    protocol = mapping.protocol.model_copy(update={"keepalive": keepalive})
    loaded.mappings[device_id] = mapping.model_copy(update={"protocol": protocol})
    return loaded


@contextlib.asynccontextmanager
async def watched_starter(
    interval: float, *, polled: Callable[[Any], Any] = lambda loaded: loaded
) -> AsyncIterator[tuple[Simulator, Engine, DevicePoller]]:
    """A soft starter with a communication watchdog of ``interval`` seconds (its mapping
    changed by ``polled`` too), polled by a running engine until it is online."""
    sim = simulator((1, "soft_starter"))
    async with serving_tcp(sim) as port:
        loaded = config([tcp_bus(port, timeout=0.3)], [device("soft_starter")])
        engine = Engine(polled(with_keepalive(loaded, "soft_starter", interval)))
        async with running(engine):
            starter = engine.devices["soft_starter"]
            await eventually(lambda: starter.health.online is True)
            yield sim, engine, starter


async def hog(engine: Engine, unit: int) -> None:
    """Commissioning on the same bus: reads on request to a unit that never answers."""
    scheduler = engine.schedulers["tcp"]
    while True:
        with contextlib.suppress(ModbusError):
            await scheduler.submit(unit, Read(H, 0, 1), timeout=0.3, priority=Priority.READ_NOW)


@pytest.mark.asyncio
async def test_a_soft_starter_hears_from_the_bridge_while_commissioning_holds_the_bus() -> None:
    """Reads on request to a silent unit go before polls: without the keepalive read, the
    soft starter would get no request at all while they last (its watchdog then stops the
    motor). With it, the starter is read again and again, ahead of them."""
    async with watched_starter(1.0) as (_, engine, starter):
        hogs = [asyncio.create_task(hog(engine, 9)) for _ in range(2)]
        try:
            await asyncio.sleep(0.5)  # the hog's reads queue ahead of every poll
            answered = starter.health.requests - starter.health.timeouts
            await eventually(
                lambda: starter.health.requests - starter.health.timeouts >= answered + 3,
                timeout=15,
            )
        finally:
            for task in hogs:
                await cancel(task)
        assert starter.health.online is True


def polled_once(loaded: Any, device_id: str = "soft_starter") -> Any:
    """The device's mapping with every entity read once at start-up: no poll block left."""
    mapping = loaded.mappings[device_id]
    entities = {
        key: entity.model_copy(update={"poll": PollClass.ONCE})
        for key, entity in mapping.entities.items()
    }
    loaded.mappings[device_id] = mapping.model_copy(update={"entities": entities})
    return loaded


@pytest.mark.timeout(30)  # a spinning keepalive would block the loop: the signal ends it
@pytest.mark.asyncio
async def test_a_keepalive_with_nothing_to_read_leaves_the_event_loop_alone() -> None:
    """Every entity read once: the keepalive finds no block to read. It must wait, not spin
    (a loop that never awaits would freeze the whole bridge)."""
    async with watched_starter(0.2, polled=polled_once) as (_, _, starter):
        assert starter.plan_of(PollClass.FAST) == () == starter.plan_of(PollClass.SLOW)
        requests = starter.health.requests
        await asyncio.sleep(1.0)  # five keepalive intervals: returns only if the loop runs
        assert starter.health.requests == requests  # nothing to read, nothing sent
        assert starter.health.online is True


@pytest.mark.asyncio
async def test_a_watchdog_that_could_not_be_fed_is_reported_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    async with watched_starter(0.6) as (sim, _, _):
        sim.set_quirks(1, Quirks(dead=True))
        await eventually(lambda: "longer than its communication watchdog" in caplog.text)
        sim.set_quirks(1, Quirks())
        await eventually(lambda: "its watchdog is fed" in caplog.text, timeout=15)
    assert caplog.text.count("longer than its communication watchdog allows") == 1
