"""The whole bridge end to end: a real Mosquitto, the simulator, and `Bridge.run()`."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.core.codec import limits_of
from bridge.core.entity import Table
from bridge.modbus.simulator import Quirks, Simulator
from bridge.mqtt.session import Message, MqttClient
from tests.integration.harness import cancel, eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker

SEEDS = ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100")
UNITS = {name: unit for unit, name in enumerate(SEEDS, start=1)}
H = Table.HOLDING


class Observer:
    """A second MQTT client that records everything under a few filters."""

    def __init__(self, client: MqttClient) -> None:
        self.client = client
        self.retained: dict[str, bytes] = {}
        self.log: list[Message] = []

    async def run(self) -> None:
        async for message in self.client.messages():
            self.log.append(message)
            self.retained[message.topic] = message.payload

    def json(self, topic: str) -> Any:
        return json.loads(self.retained[topic])

    def after(self, index: int, topic: str) -> list[Message]:
        return [m for m in self.log[index:] if m.topic == topic]


@contextlib.asynccontextmanager
async def observing(broker: Broker, *filters: str) -> AsyncIterator[Observer]:
    config = MqttConfig(url=broker.url)
    async with MqttClient(config, will_topic="observer/state", client_id="observer") as client:
        observer = Observer(client)
        task = asyncio.create_task(observer.run())
        await client.subscribe(*filters)
        try:
            yield observer
        finally:
            await cancel(task)


def bridge_config(
    broker: Broker, port: int, bridge: dict[str, Any] | None = None, **mqtt: Any
) -> Any:
    devices = [
        {
            "id": name,
            "name": name.replace("_", " ").title(),
            "bus": "tcp",
            "unit": unit,
            "mapping": name,
            "poll": {"fast": 0.5, "slow": 5},
            "protocol": {"min_request_interval": 0.05} if name == "smartgen_hgm6100" else {},
        }
        for name, unit in UNITS.items()
    ]
    data = {
        "mqtt": {"url": broker.url, "base_topic": "modbus", "command_expiry": 3} | mqtt,
        "bridge": bridge or {},
        "buses": [
            {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port, "timeout": 0.5}
        ],
        "devices": devices,
    }
    return load_config_data(data, Path("e2e.yaml"))


@contextlib.asynccontextmanager
async def running_bridge(broker: Broker, sim: Simulator, **mqtt: Any) -> AsyncIterator[Bridge]:
    async with serving_tcp(sim) as port:
        bridge = Bridge(bridge_config(broker, port, **mqtt))
        task = asyncio.create_task(bridge.run())
        try:
            yield bridge
        finally:
            await cancel(task)


def all_units(**quirks: Any) -> Simulator:
    return simulator(*((unit, name) for name, unit in UNITS.items()), **quirks)


async def state_of(observer: Observer, device: str, key: str, expected: object) -> None:
    topic = f"modbus/{device}"
    await eventually(
        lambda: topic in observer.retained and observer.json(topic).get(key) == expected, timeout=10
    )


@pytest.mark.asyncio
async def test_discovery_availability_and_state_for_every_device(mosquitto: Broker) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/#", "homeassistant/#") as observer,
        running_bridge(mosquitto, sim) as bridge,
    ):
        await eventually(
            lambda: all(
                f"modbus/{d}/availability" in observer.retained
                and observer.retained[f"modbus/{d}/availability"] == b"online"
                for d in SEEDS
            ),
            timeout=20,
        )
        # the devices' availability goes out before the bridge's online (values first)
        await eventually(lambda: observer.retained.get("modbus/bridge/state") == b"online", 10)
        await eventually(
            lambda: (
                "modbus/bridge/devices" in observer.retained
                and all(
                    d["state"] == "online"
                    for d in json.loads(observer.retained["modbus/bridge/devices"])
                )
            )
        )
        listing = {d["id"]: d for d in observer.json("modbus/bridge/devices")}
        assert set(listing) == set(SEEDS)
        for name, unit in UNITS.items():
            poller = bridge.engine.devices[name]
            await eventually(
                lambda p=poller: all(
                    k in p.values for k, pt in p.points.items() if pt.entity.readable
                ),
                timeout=20,
            )
            topic = f"homeassistant/device/{name}/config"
            await eventually(lambda t=topic: t in observer.retained)  # after the first poll
            config = observer.json(topic)
            assert config["device"]["identifiers"] == [f"modbus_{name}"]
            assert config["origin"]["name"] == "modbus-mqtt-bridge"
            assert config["availability_mode"] == "all"
            for key, component in config["cmps"].items():
                if component["platform"] == "device_automation":  # an alarm's trigger
                    assert component["topic"] == f"modbus/{name}/event", key
                    continue
                # the device's own entities, and its health sensors (their unique ids from
                # when they sat on the bridge's device, kept so their history stays)
                owners = (f"modbus_{name}_", f"modbus_bridge_device_{name}_")
                assert component["unique_id"].startswith(owners), key
                assert "object_id" not in component, key
                # the health sensors read the bridge's health report, the alarm events
                # entity the device's events
                topics = (f"modbus/{name}", "modbus/bridge/health", f"modbus/{name}/event")
                assert component.get("state_topic", f"modbus/{name}") in topics, key
            await eventually(  # units and limits read from registers land in discovery
                lambda p=poller, t=topic: (
                    observer.json(t) == json.loads(bridge.discovery.discovery_for(p)[0].payload)
                )
            )
            keys = [
                k for k, p in poller.points.items() if p.entity.readable and not p.entity.secret
            ]
            await eventually(
                lambda n=name, u=unit, ks=keys: (
                    f"modbus/{n}" in observer.retained
                    and all(observer.json(f"modbus/{n}").get(k) == sim.value(u, k) for k in ks)
                )
            )
            assert isinstance(observer.json(f"modbus/{name}")["alarms"], list)


@pytest.mark.asyncio
async def test_commands_round_trip_and_refusals_write_nothing(mosquitto: Broker) -> None:
    sim = all_units()
    async with observing(mosquitto, "modbus/#") as observer, running_bridge(mosquitto, sim):
        await eventually(
            lambda: (
                observer.retained.get("modbus/vacon_nx/availability") == b"online"
                and observer.retained.get("modbus/nastec_vasco/availability") == b"online"
            ),
            timeout=20,
        )
        publish = observer.client.publish
        # number (plain), select (JSON /set), switch, button
        await publish("modbus/nastec_vasco/operating_frequency/set", "42")
        await state_of(observer, "nastec_vasco", "operating_frequency", 42)
        await publish("modbus/soft_starter/set", json.dumps({"soft_start_mode": "ramp"}))
        await state_of(observer, "soft_starter", "soft_start_mode", "ramp")
        await publish("modbus/vacon_nx/run/set", "ON")
        await state_of(observer, "vacon_nx", "run", True)
        await publish("modbus/smartgen_hgm6100/command_auto/set", "PRESS")
        await eventually(lambda: any(w.function == 5 for _, w in sim.writes))
        assert sim.value(UNITS["nastec_vasco"], "operating_frequency") == 42
        written = len(sim.writes)
        errors_before = len(observer.log)
        await publish("modbus/nastec_vasco/operating_frequency/set", "9999")  # out of range
        await publish("modbus/nastec_vasco/set", "{not json")  # malformed
        await publish("modbus/nastec_vasco/unit/set", "furlong")  # unknown label
        await publish("modbus/nastec_vasco/modbus_address/set", "7")  # guarded
        await publish("modbus/nowhere/set", '{"x": 1}')  # no such device
        await eventually(
            lambda: len(observer.after(errors_before, "modbus/nastec_vasco/error")) == 4
        )
        errors = [
            json.loads(m.payload)
            for m in observer.after(errors_before, "modbus/nastec_vasco/error")
        ]
        assert {e["key"] for e in errors} == {"operating_frequency", None, "unit", "modbus_address"}
        assert all(e["error"] for e in errors)
        await eventually(lambda: observer.after(errors_before, "modbus/nowhere/error"))
        await asyncio.sleep(0.5)
        assert len(sim.writes) == written


@pytest.mark.asyncio
async def test_get_reads_now(mosquitto: Broker) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/#") as observer,
        running_bridge(mosquitto, sim, output="both"),
    ):
        await eventually(
            lambda: observer.retained.get("modbus/soft_starter/availability") == b"online",
            timeout=20,
        )
        sim.set_value(UNITS["soft_starter"], "phase_u_current", 77)
        await observer.client.publish("modbus/soft_starter/get", '{"phase_u_current": ""}')
        await state_of(observer, "soft_starter", "phase_u_current", 77)
        await eventually(
            lambda: observer.retained.get("modbus/soft_starter/phase_u_current") == b"77"
        )


@pytest.mark.asyncio
@pytest.mark.parametrize(
    ("output", "discovery"), [("json", "device"), ("values", "off"), ("both", "device")]
)
async def test_output_chooses_the_device_json_the_plain_values_or_both(
    mosquitto: Broker, output: str, discovery: str
) -> None:
    sim = all_units()
    device = "soft_starter"
    async with (
        observing(mosquitto, "modbus/#") as observer,
        running_bridge(mosquitto, sim, output=output, discovery=discovery) as bridge,
    ):
        poller = bridge.engine.devices[device]
        await eventually(lambda: poller.values.get("phase_u_current") is not None, timeout=20)
        sim.set_value(UNITS[device], "phase_u_current", 77)
        await observer.client.publish(f"modbus/{device}/get", '{"phase_u_current": ""}')
        plain = f"modbus/{device}/phase_u_current"
        if output == "json":
            await state_of(observer, device, "phase_u_current", 77)
        else:
            await eventually(lambda: observer.retained.get(plain) == b"77")
        await asyncio.sleep(0.3)
        values = [t for t in observer.retained if t.count("/") == 2 and "/bridge/" not in t]
        kept = {t for t in values if not t.endswith(("/availability", "/get", "/error"))}
        assert bool(kept) == (output != "json"), sorted(kept)[:5]
        assert (f"modbus/{device}" in observer.retained) == (output != "values")
        if output != "values":  # compact: no space after separators
            assert b", " not in observer.retained[f"modbus/{device}"]
            assert b'":' in observer.retained[f"modbus/{device}"]


@pytest.mark.asyncio
async def test_availability_says_nothing_until_a_device_has_answered_or_given_up(
    mosquitto: Broker,
) -> None:
    """A slow first poll is not a false "offline": the first availability a device gets is
    "online" with its values, or "offline" once it stopped answering (the Vacon, dead)."""
    sim = all_units()
    sim.set_quirks(UNITS["nastec_vasco"], Quirks(latency=0.02))  # 113 reads: a slow first poll
    sim.set_quirks(UNITS["vacon_nx"], Quirks(dead=True))
    async with observing(mosquitto, "modbus/#") as observer, running_bridge(mosquitto, sim):
        await eventually(
            lambda: (
                observer.retained.get("modbus/nastec_vasco/availability") == b"online"
                and observer.retained.get("modbus/vacon_nx/availability") == b"offline"
            ),
            timeout=30,
        )
        pump = [m.payload for m in observer.after(0, "modbus/nastec_vasco/availability")]
        drive = [m.payload for m in observer.after(0, "modbus/vacon_nx/availability")]
        assert (pump, drive) == ([b"online"], [b"offline"])
        assert "modbus/nastec_vasco" in observer.retained  # its values came with it


@pytest.mark.asyncio
async def test_commands_to_an_offline_device_are_refused(mosquitto: Broker) -> None:
    sim = all_units()
    sim.set_quirks(UNITS["vacon_nx"], Quirks(dead=True))
    async with (
        observing(mosquitto, "modbus/#") as observer,
        running_bridge(mosquitto, sim) as bridge,
    ):
        await eventually(
            lambda: bridge.engine.devices["vacon_nx"].health.online is False, timeout=20
        )
        await eventually(
            lambda: observer.retained.get("modbus/vacon_nx/availability") == b"offline"
        )
        await observer.client.publish("modbus/vacon_nx/run/set", "ON")
        await eventually(lambda: observer.after(0, "modbus/vacon_nx/error"))
        error = json.loads(observer.after(0, "modbus/vacon_nx/error")[0].payload)
        assert "offline" in error["error"]
        assert bridge.engine.devices["vacon_nx"].writes.rejected == 1
        sim.set_quirks(UNITS["vacon_nx"], Quirks())
        await asyncio.sleep(1.0)
        assert not [w for unit, w in sim.writes if unit == UNITS["vacon_nx"]]


@pytest.mark.asyncio
async def test_broker_restart_and_home_assistant_birth(mosquitto: Broker) -> None:
    sim = all_units()
    async with running_bridge(mosquitto, sim):
        async with observing(mosquitto, "modbus/#", "homeassistant/#") as observer:
            await eventually(
                lambda: observer.retained.get("modbus/p2_vfd/availability") == b"online", timeout=20
            )
        mosquitto.restart()  # persistence off: every retained message is gone
        async with observing(mosquitto, "modbus/#", "homeassistant/#") as observer:
            await eventually(
                lambda: (
                    observer.retained.get("modbus/bridge/state") == b"online"
                    and "homeassistant/device/p2_vfd/config" in observer.retained
                    and "modbus/p2_vfd" in observer.retained
                ),
                timeout=30,
            )
            seen = len(observer.log)
            await observer.client.publish("homeassistant/status", "online")
            await eventually(lambda: observer.after(seen, "homeassistant/device/vacon_nx/config"))
            await observer.client.publish("modbus/p2_vfd/set_value/set", "25")
            await eventually(lambda: any(w.address == 0x1000 for _, w in sim.writes))


@pytest.mark.asyncio
async def test_stale_discovery_is_cleared_at_start(mosquitto: Broker) -> None:
    sim = all_units()
    stale = {
        "device": {"identifiers": ["modbus_old_pump"], "name": "Old"},
        "origin": {"name": "modbus-mqtt-bridge"},
        "cmps": {},
    }
    foreign = {"device": {"identifiers": ["zigbee2mqtt_0x1"]}, "cmps": {}}
    async with observing(mosquitto, "homeassistant/#") as observer:
        await observer.client.publish(
            "homeassistant/device/old_pump/config", json.dumps(stale), retain=True
        )
        await observer.client.publish(
            "homeassistant/device/lamp/config", json.dumps(foreign), retain=True
        )
        async with running_bridge(mosquitto, sim):
            await eventually(
                lambda: observer.retained.get("homeassistant/device/old_pump/config") == b"",
                timeout=20,
            )
            assert json.loads(observer.retained["homeassistant/device/lamp/config"]) == foreign


def pick_writes(poller: Any) -> dict[str, tuple[str, object]]:
    """One safe entity per writable kind of a device, with a valid new value for it."""
    chosen: dict[str, tuple[str, object]] = {}
    for key, point in poller.points.items():
        entity = point.entity
        kind = entity.component.value
        if kind in chosen or not entity.writable or entity.dangerous or entity.secret:
            continue
        if any(  # a command the device does not accept in its present mode
            poller.values.get(k) not in (v if isinstance(v, list) else [v])
            for k, v in entity.requires.items()
        ):
            continue
        current = poller.values.get(key)
        if kind == "button":
            chosen[kind] = (key, "PRESS")
        elif kind == "switch" and isinstance(current, bool):
            chosen[kind] = (key, "OFF" if current else "ON")
        elif kind == "select" and entity.enum and current is not None:
            others = [label for label in entity.enum.values() if label != current]
            if others:
                chosen[kind] = (key, others[0])
        elif kind == "number" and isinstance(current, int | float) and entity.readable:
            low, high = limits_of(point, poller.image)
            step = entity.step or entity.scale
            candidate = current + step if high is None or current + step <= high else current - step
            if (low is None or candidate >= low) and entity.verify:
                chosen[kind] = (key, round(candidate, entity.decimals))
    return chosen


@pytest.mark.asyncio
@pytest.mark.parametrize("name", SEEDS)
async def test_every_writable_kind_round_trips(mosquitto: Broker, name: str) -> None:
    sim = all_units()
    unit = UNITS[name]
    async with (
        observing(mosquitto, f"modbus/{name}/#", f"modbus/{name}") as observer,
        running_bridge(mosquitto, sim) as bridge,
    ):
        poller = bridge.engine.devices[name]
        await eventually(
            lambda: all(k in poller.values for k, p in poller.points.items() if p.entity.readable),
            timeout=20,
        )
        writes = pick_writes(poller)
        assert writes, name
        for kind, (key, value) in writes.items():
            before = len(sim.writes)
            await observer.client.publish(f"modbus/{name}/{key}/set", str(value))
            await eventually(lambda b=before: len(sim.writes) > b, timeout=10)
            if kind != "button" and poller.points[key].entity.readable:
                expected = {"ON": True, "OFF": False}.get(str(value), value)
                await eventually(lambda k=key, e=expected: sim.value(unit, k) == e)
                await state_of(observer, name, key, expected)
        numbers = [
            k
            for k, p in poller.points.items()
            if p.entity.component.value == "number"
            and p.entity.writable
            and not p.entity.dangerous
            and not p.entity.secret
        ]
        written = len(sim.writes)
        seen = len(observer.log)
        read_only = [k for k, p in poller.points.items() if not p.entity.writable]
        target = numbers[0] if numbers else read_only[0]  # out of range, or not writable
        await observer.client.publish(f"modbus/{name}/{target}/set", "1e12")  # out of range
        await observer.client.publish(f"modbus/{name}/set", "not json")  # malformed
        await eventually(lambda: len(observer.after(seen, f"modbus/{name}/error")) == 2)
        await asyncio.sleep(0.3)
        assert len(sim.writes) == written


@pytest.mark.asyncio
async def test_a_command_that_cannot_run_in_time_is_dropped_not_run_late(
    mosquitto: Broker,
) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/soft_starter/#") as observer,
        running_bridge(mosquitto, sim, command_expiry=0.4) as bridge,
    ):
        starter = bridge.engine.devices["soft_starter"]
        await eventually(lambda: starter.health.online is True, timeout=20)
        sim.set_quirks(UNITS["soft_starter"], Quirks(latency=0.3))  # a slow device
        seen = len(observer.log)
        for key, value in (("soft_stop_time", 11), ("kick_start_time", 3), ("overload_time", 9)):
            await observer.client.publish(f"modbus/soft_starter/{key}/set", str(value))
        await eventually(lambda: observer.after(seen, "modbus/soft_starter/error"), timeout=10)
        await asyncio.sleep(1.5)  # anything late would have been written by now
        errors = [json.loads(m.payload) for m in observer.after(seen, "modbus/soft_starter/error")]
        assert all("expired" in e["error"] for e in errors)
        expired = {e["key"] for e in errors}
        written = {w.address for u, w in sim.writes if u == UNITS["soft_starter"]}
        addresses = {"soft_stop_time": 0x1006, "kick_start_time": 0x100C, "overload_time": 0x1012}
        assert expired
        assert not {addresses[k] for k in expired} & written
        assert starter.writes.expired == len(expired)
