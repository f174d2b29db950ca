"""Control safety end to end (issue 11): the bridge as a hostile or careless MQTT client and
a faulty device would attack it, through a real Mosquitto, the simulator and ``Bridge.run()``.

Retained commands never run; a button is pressed only by PRESS; a multi-key /set is all or
nothing; expiry holds (the publisher's too, and behind a flood); a compound write is
finished at shutdown and undone when its second frame fails; oversized, binary and NaN
payloads are refused without harm; floods of /get and Home Assistant ``online`` neither
starve polling nor multiply publishing. Waits are bounded; nothing asserts wall-clock time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator
from typing import Any

import aiomqtt
import pytest
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from bridge import state_publisher as state_publisher_module
from bridge.app import Bridge
from bridge.core.entity import Table
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Quirks, Simulator
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import (
    UNITS,
    Observer,
    all_units,
    bridge_config,
    observing,
    state_of,
)

NASTEC, SMARTGEN, VACON, STARTER, P2 = (
    UNITS[n] for n in ("nastec_vasco", "smartgen_hgm6100", "vacon_nx", "soft_starter", "p2_vfd")
)
SIGN_REGISTER, SET_VALUE = 0x4B, 0x33  # Nastec indexes 0x4C and 0x34 on the wire (N - 1)


def safety_config(broker: Broker, port: int, mqtt: dict[str, Any], bridge: dict[str, Any]) -> Any:
    return bridge_config(broker, port, {"health_interval": 0} | bridge, **mqtt)


@contextlib.asynccontextmanager
async def bridged(
    broker: Broker,
    sim: Simulator,
    mqtt: dict[str, Any] | None = None,
    bridge: dict[str, Any] | None = None,
) -> AsyncIterator[tuple[Bridge, asyncio.Task[None]]]:
    async with serving_tcp(sim) as port:
        running = Bridge(safety_config(broker, port, mqtt or {}, bridge or {}))
        task = asyncio.create_task(running.run())
        try:
            yield running, task
        finally:
            await cancel(task)


async def all_online(observer: Observer) -> None:
    await eventually(
        lambda: all(
            observer.retained.get(f"modbus/{device}/availability") == b"online" for device in UNITS
        ),
        timeout=20,
    )


def errors(observer: Observer, device: str, since: int = 0) -> list[dict[str, Any]]:
    return [json.loads(m.payload) for m in observer.after(since, f"modbus/{device}/error")]


def writes_to(sim: Simulator, unit: int) -> list[Any]:
    return [w for u, w in sim.writes if u == unit]


@contextlib.asynccontextmanager
async def raw_client(broker: Broker, version: str = "5") -> AsyncIterator[aiomqtt.Client]:
    """A plain client for what the bridge's own client never sends (properties, retain)."""
    protocol = aiomqtt.ProtocolVersion.V5 if version == "5" else aiomqtt.ProtocolVersion.V311
    async with aiomqtt.Client(
        broker.host, broker.port, protocol=protocol, identifier=f"attacker-{version}"
    ) as client:
        yield client


# --- 1. retained commands and requests are never executed -----------------------------

RETAINED_COMMANDS = [
    ("modbus/vacon_nx/run/set", "ON"),
    ("modbus/smartgen_hgm6100/generator_breaker/set", "ON"),
    ("modbus/smartgen_hgm6100/set", '{"command_start": "PRESS"}'),
    ("modbus/soft_starter/motor_run/set", "ON"),
    ("modbus/bridge/request/device/write", '{"device": "p2_vfd", "address": 4096, "values": [1]}'),
]


@pytest.mark.asyncio
@pytest.mark.parametrize("version", ["5", "3.1.1"])
async def test_retained_commands_and_requests_are_never_executed(
    mosquitto: Broker, version: str
) -> None:
    sim = all_units()
    async with raw_client(mosquitto, version) as attacker:
        for topic, payload in RETAINED_COMMANDS:
            await attacker.publish(topic, payload, qos=1, retain=True)
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, {"version": version}, {"allow_raw_writes": True}),
    ):
        await all_online(observer)
        await asyncio.sleep(1.5)  # the old bridge wrote them about 1 s after the start
        assert sim.writes == []
        if version == "3.1.1":  # delivered, and refused with a reason
            for device in ("vacon_nx", "smartgen_hgm6100", "soft_starter"):
                await eventually(lambda d=device: errors(observer, d))
                assert all(
                    "retained message refused" in e["error"] for e in errors(observer, device)
                )
            await eventually(lambda: observer.after(0, "modbus/bridge/response/device/write"))
            answer = json.loads(observer.after(0, "modbus/bridge/response/device/write")[0].payload)
            assert "retained message refused" in answer["error"]
        # a retained publish while the bridge listens: refused on MQTT 5 (retain as published)
        if version == "5":
            seen = len(observer.log)
            async with raw_client(mosquitto) as attacker:
                await attacker.publish("modbus/vacon_nx/reverse/set", "ON", qos=1, retain=True)
            await eventually(lambda: errors(observer, "vacon_nx", seen))
            assert "retained message refused" in errors(observer, "vacon_nx", seen)[0]["error"]
        await asyncio.sleep(0.3)
        assert sim.writes == []


# --- 2. a button is pressed only by PRESS, a switch only by its words -------------------

NOT_PRESSES = [
    ("modbus/smartgen_hgm6100/command_start/set", "OFF"),
    ("modbus/smartgen_hgm6100/command_start/set", "false"),
    ("modbus/smartgen_hgm6100/command_start/set", "0"),
    ("modbus/smartgen_hgm6100/generator_breaker/set", "toggle"),
    ("modbus/smartgen_hgm6100/set", '{"command_start": false}'),
    ("modbus/smartgen_hgm6100/set", '{"command_auto": "ON"}'),
    ("modbus/vacon_nx/fault_reset/set", "0"),
    ("modbus/vacon_nx/run/set", "PRESS"),
    ("modbus/vacon_nx/run/set", "open"),
    ("modbus/vacon_nx/set", '{"run": "yes"}'),
    ("modbus/soft_starter/fault_reset/set", "OFF"),
]


@pytest.mark.asyncio
async def test_only_press_presses_a_button_and_only_on_off_turns_a_switch(
    mosquitto: Broker,
) -> None:
    sim = all_units()
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim):
        await all_online(observer)
        for topic, payload in NOT_PRESSES:
            await observer.client.publish(topic, payload)
        await eventually(
            lambda: (
                sum(
                    len(errors(observer, d))
                    for d in ("smartgen_hgm6100", "vacon_nx", "soft_starter")
                )
                == len(NOT_PRESSES)
            )
        )
        await asyncio.sleep(0.3)
        assert sim.writes == []
        await observer.client.publish("modbus/smartgen_hgm6100/command_auto/set", "PRESS")
        await observer.client.publish("modbus/vacon_nx/run/set", "ON")
        await eventually(lambda: writes_to(sim, SMARTGEN) and writes_to(sim, VACON))
        await state_of(observer, "vacon_nx", "run", True)


# --- 3. a multi-key /set is all or nothing ----------------------------------------------


@pytest.mark.asyncio
async def test_a_multi_key_set_writes_everything_or_nothing(mosquitto: Broker) -> None:
    sim = all_units()
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim):
        await all_online(observer)
        refused = [
            {"operating_frequency": 42, "nonsense": 1},
            {"operating_frequency": 42, "unit": "furlong"},
            {"operating_frequency": 42, "modbus_address": 7},  # guarded
            {"delta_start": 1.5, "operating_frequency": 9999},  # out of range
        ]
        for items in refused:
            await observer.client.publish("modbus/nastec_vasco/set", json.dumps(items))
        await eventually(lambda: len(errors(observer, "nastec_vasco")) == 2 * len(refused))
        await asyncio.sleep(0.3)
        assert writes_to(sim, NASTEC) == []
        reasons = {e["key"]: e["error"] for e in errors(observer, "nastec_vasco")[:2]}
        assert "no such entity" in reasons["nonsense"]
        assert reasons["operating_frequency"].startswith("not written")
        await observer.client.publish(
            "modbus/nastec_vasco/set", json.dumps({"operating_frequency": 42, "delta_start": 1.5})
        )
        await state_of(observer, "nastec_vasco", "operating_frequency", 42)
        await state_of(observer, "nastec_vasco", "delta_start", 1.5)


@pytest.mark.asyncio
async def test_two_bit_fields_of_one_word_in_one_command(mosquitto: Broker) -> None:
    """Both bits land in one frame (one EEPROM write): each key is encoded over the word
    the keys before it leave."""
    sim = all_units()
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim):
        await all_online(observer)
        await observer.client.publish(
            "modbus/nastec_vasco/set",
            json.dumps({"sign_compensation": "ON", "sign_compensation_set_2": "ON"}),
        )
        await state_of(observer, "nastec_vasco", "sign_compensation", True)
        await state_of(observer, "nastec_vasco", "sign_compensation_set_2", True)
        assert [w.address for w in writes_to(sim, NASTEC)] == [SIGN_REGISTER]


# --- 6. guarded words and bits, beside harmless ones --------------------------------------


@pytest.mark.asyncio
async def test_a_shared_command_word_takes_its_harmless_words_and_refuses_the_guarded(
    mosquitto: Broker,
) -> None:
    """The P2's 2000H: stop (6) is written, reverse run (2) and reverse jog (4) are refused
    without allow_dangerous_writes, also spelled as a raw register write."""
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, bridge={"allow_raw_writes": True}),
    ):
        await all_online(observer)
        await observer.client.publish("modbus/p2_vfd/reverse_run/set", "PRESS")
        await observer.client.publish("modbus/p2_vfd/set", '{"reverse_jog": "PRESS"}')
        await eventually(lambda: len(errors(observer, "p2_vfd")) == 2)
        assert all("guarded write" in e["error"] for e in errors(observer, "p2_vfd"))
        raw = json.dumps({"device": "p2_vfd", "address": 0x2000, "values": [2]})
        await observer.client.publish("modbus/bridge/request/device/write", raw)
        await eventually(lambda: observer.after(0, "modbus/bridge/response/device/write"))
        answer = json.loads(observer.after(0, "modbus/bridge/response/device/write")[0].payload)
        assert answer["status"] == "error" and "guarded" in answer["error"]
        await asyncio.sleep(0.3)
        assert writes_to(sim, P2) == []
        await observer.client.publish("modbus/p2_vfd/stop/set", "PRESS")
        await eventually(lambda: writes_to(sim, P2))
        assert [(w.address, w.values) for w in writes_to(sim, P2)] == [(0x2000, (6,))]


# --- 4. expiry holds ---------------------------------------------------------------------


@pytest.mark.asyncio
async def test_the_publishers_message_expiry_is_honoured(mosquitto: Broker) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/soft_starter/#") as observer,
        bridged(mosquitto, sim, {"command_expiry": 60}) as (bridge, _),
    ):
        starter = bridge.engine.devices["soft_starter"]
        await eventually(lambda: starter.health.online is True, timeout=20)
        sim.set_quirks(STARTER, Quirks(latency=0.3))  # each command takes about a second
        properties = Properties(PacketTypes.PUBLISH)
        properties.MessageExpiryInterval = 1
        keys = {
            "soft_stop_time": 11,
            "kick_start_time": 3,
            "overload_time": 9,
            "soft_start_time": 7,
        }
        async with raw_client(mosquitto) as publisher:
            for key, value in keys.items():
                await publisher.publish(
                    f"modbus/soft_starter/{key}/set", str(value), qos=1, properties=properties
                )
        await eventually(lambda: errors(observer, "soft_starter"), timeout=10)
        await asyncio.sleep(2.0)  # anything late would have been written by now
        expired = {e["key"] for e in errors(observer, "soft_starter") if "expired" in e["error"]}
        assert expired
        addresses = {
            "soft_stop_time": 0x1006,
            "kick_start_time": 0x100C,
            "overload_time": 0x1012,
            "soft_start_time": 0x1005,
        }
        written = {w.address for w in writes_to(sim, STARTER)}
        assert not {addresses[k] for k in expired} & written


@pytest.mark.asyncio
async def test_a_flood_of_home_assistant_online_neither_delays_commands_nor_multiplies(
    mosquitto: Broker,
) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/#", "homeassistant/device/#") as observer,
        bridged(mosquitto, sim, {"command_expiry": 3}),
    ):
        await all_online(observer)
        await eventually(  # discovery follows the values
            lambda: all(f"homeassistant/device/{d}/config" in observer.retained for d in UNITS)
        )
        await asyncio.sleep(0.5)
        seen = len(observer.log)
        async with raw_client(mosquitto) as flooder:
            for _ in range(200):
                await flooder.publish("homeassistant/status", "online", qos=0)
            await flooder.publish("modbus/vacon_nx/run/set", "ON", qos=1)
        await state_of(observer, "vacon_nx", "run", True)
        assert not errors(observer, "vacon_nx")
        await asyncio.sleep(1.5)
        configs = [m for m in observer.log[seen:] if m.topic.startswith("homeassistant/device/")]

        assert len(configs) <= 3 * len(UNITS)  # one republish (plus one that was pending)


@pytest.mark.asyncio
async def test_a_sustained_flood_of_home_assistant_online_republishes_once_per_gap(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``online`` every 0.2 s for 3 s: one republish at its start, then none until
    ``HA_REPUBLISH_GAP`` (shortened to 2.5 s here) has passed since it."""
    monkeypatch.setattr(state_publisher_module, "HA_REPUBLISH_GAP", 2.5)
    sim = all_units()
    config = "homeassistant/device/vacon_nx/config"
    async with (
        observing(mosquitto, "modbus/#", "homeassistant/device/#") as observer,
        bridged(mosquitto, sim),
    ):
        await all_online(observer)
        await eventually(lambda: config in observer.retained)
        await asyncio.sleep(0.5)
        seen = len(observer.log)
        async with raw_client(mosquitto) as flooder:
            for _ in range(15):
                await flooder.publish("homeassistant/status", "online", qos=0)
                await asyncio.sleep(0.2)

        def sent() -> list[Any]:
            return [m for m in observer.log[seen:] if m.topic == config]

        await eventually(lambda: len(sent()) >= 2)  # the republish the gap let through
        await asyncio.sleep(1.0)  # and no other: the flood is over
        assert len(sent()) == 2  # at the start, and once the gap had passed


# --- 5. a compound write is never left half done ----------------------------------------


@pytest.mark.asyncio
async def test_a_stop_between_sign_and_magnitude_finishes_the_write(mosquitto: Broker) -> None:
    sim = all_units()
    sim.set_value(NASTEC, "set_value", 3.0)
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim) as (_, task):
        await all_online(observer)
        sim.set_quirks(NASTEC, Quirks(latency=0.4))
        await observer.client.publish("modbus/nastec_vasco/set_value/set", "-0.5")
        await eventually(lambda: any(w.address == SIGN_REGISTER for w in writes_to(sim, NASTEC)))
        task.cancel()  # SIGTERM: until_stopped cancels Bridge.run()
        await cancel(task)
    assert sim.value(NASTEC, "set_value") == -0.5
    assert [w.address for w in writes_to(sim, NASTEC)] == [SIGN_REGISTER, SET_VALUE]


@pytest.mark.asyncio
async def test_a_failed_magnitude_puts_the_sign_back_and_says_what_the_device_holds(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    sim = all_units()
    sim.set_value(NASTEC, "set_value", 3.0)
    async with observing(mosquitto, "modbus/#") as observer, bridged(mosquitto, sim):
        await all_online(observer)
        sim.set_quirks(NASTEC, Quirks(failing_writes=frozenset({SET_VALUE})))
        with caplog.at_level(logging.ERROR, logger="bridge"):
            await observer.client.publish("modbus/nastec_vasco/set_value/set", "-0.5")
            await eventually(lambda: errors(observer, "nastec_vasco"))
        (error,) = errors(observer, "nastec_vasco")
        assert "written only in part" in error["error"]
        assert "undone again" in error["error"]
        assert "set_value=3.0" in error["error"]
        assert sim.value(NASTEC, "set_value") == 3.0
        assert [w.address for w in writes_to(sim, NASTEC)] == [
            SIGN_REGISTER,
            SET_VALUE,
            SIGN_REGISTER,
        ]
        assert "written only in part" in caplog.text


# --- 8. nothing a client sends ends the bridge ---------------------------------------------


@pytest.mark.asyncio
@pytest.mark.parametrize("version", ["5", "3.1.1"])
async def test_oversized_binary_and_nan_payloads_are_refused_harmlessly(
    mosquitto: Broker, version: str
) -> None:
    sim = all_units()
    huge = bytes(range(128, 256)) * (6 * 1024 * 1024 // 128)  # 6 MB, not UTF-8
    large = b"\xff" * 200_000
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, {"version": version}) as (_, task),
    ):
        await all_online(observer)
        async with raw_client(mosquitto) as attacker:
            await attacker.publish("modbus/nastec_vasco/set", huge, qos=1)
            await attacker.publish("modbus/nastec_vasco/set", large, qos=1)
            await attacker.publish("modbus/nastec_vasco/operating_frequency/set", large, qos=1)
            await attacker.publish("modbus/bridge/request/device/read", large, qos=1)
            await attacker.publish("modbus/bridge/request/device/scan", huge, qos=1)
            await attacker.publish("modbus/nastec_vasco/set", '{"operating_frequency": NaN}')
            await attacker.publish("modbus/nastec_vasco/operating_frequency/set", "Infinity")
        await eventually(lambda: len(observer.after(0, "modbus/nastec_vasco/error")) >= 4)
        await eventually(lambda: observer.after(0, "modbus/bridge/response/device/read"))
        for message in observer.after(0, "modbus/nastec_vasco/error"):
            assert len(message.payload) < 1000
            json.loads(message.payload, parse_constant=_no_constants)  # strict JSON
        refusals = [e["error"] for e in errors(observer, "nastec_vasco")]
        assert sum("at most 65536 bytes" in r for r in refusals) >= 2
        answer = observer.after(0, "modbus/bridge/response/device/read")[0]
        assert "at most 65536 bytes" in json.loads(answer.payload)["error"]
        assert not task.done()
        await observer.client.publish("modbus/nastec_vasco/operating_frequency/set", "42")
        await state_of(observer, "nastec_vasco", "operating_frequency", 42)


def _no_constants(name: str) -> None:
    raise AssertionError(f"not JSON: bare {name}")


# --- 10. floods cannot starve polling -------------------------------------------------------


@pytest.mark.asyncio
async def test_a_flood_of_get_does_not_starve_the_other_devices(mosquitto: Broker) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/p2_vfd", "modbus/p2_vfd/#") as observer,
        bridged(mosquitto, sim) as (bridge, _),
    ):
        p2 = bridge.engine.devices["p2_vfd"]
        await eventually(
            lambda: observer.retained.get("modbus/p2_vfd/availability") == b"online", timeout=20
        )
        sim.set_quirks(NASTEC, Quirks(latency=0.01))  # a little bus time per request
        async with raw_client(mosquitto) as flooder:
            for _ in range(500):
                await flooder.publish("modbus/nastec_vasco/get", "", qos=0)
        polled = p2.health.requests
        sim.set_value(P2, "output_current", 123)
        await state_of(observer, "p2_vfd", "output_current", 123)
        await eventually(lambda: p2.health.requests >= polled + 6, timeout=5)
        # every /get is handled by now or soon: all but the few that started a read joined one
        await eventually(lambda: bridge.dispatcher.counters.coalesced >= 450, timeout=10)


@pytest.mark.asyncio
async def test_refusals_are_counted_in_health(mosquitto: Broker) -> None:
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim, bridge={"health_interval": 0.5}),
    ):
        await all_online(observer)
        async with raw_client(mosquitto) as flooder:
            for _ in range(300):
                await flooder.publish("modbus/nastec_vasco/set", "not json", qos=0)
        await eventually(
            lambda: (
                "modbus/bridge/health" in observer.retained
                and observer.json("modbus/bridge/health").get("messages", {}).get("refused", 0)
                >= 300
            ),
            timeout=10,
        )
        report = observer.json("modbus/bridge/health")["messages"]
        assert set(report) == {"commands", "refused", "coalesced", "dropped"}
        process = observer.json("modbus/bridge/health")["process"]
        assert process["tasks"] > 0 and process["outbox"] >= 0  # the soak's slopes read these


def test_the_simulated_sign_register_is_where_the_mapping_says() -> None:
    """The wire addresses the tests above watch are the mapping's (no silent drift)."""
    points = load_mapping(builtin_mapping_path("nastec_vasco")).points({})
    assert points["set_value"].address == SET_VALUE
    assert points["set_value"].sign is not None
    assert (points["set_value"].sign.table, points["set_value"].sign.address) == (
        Table.HOLDING,
        SIGN_REGISTER,
    )


@pytest.mark.asyncio
async def test_an_unexpected_error_in_one_command_is_reported_and_the_bridge_goes_on(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A defect reached by one message (here planted in one device's write path) is logged,
    answered on ``/error`` and leaves every other device and command working."""
    sim = all_units()
    async with (
        observing(mosquitto, "modbus/#") as observer,
        bridged(mosquitto, sim) as (bridge, task),
    ):
        await all_online(observer)

        async def broken(*_: object, **__: object) -> None:
            raise RuntimeError("a defect")

        monkeypatch.setattr(bridge.engine.devices["vacon_nx"], "write_many", broken)
        await observer.client.publish("modbus/vacon_nx/run/set", "ON")
        await eventually(lambda: errors(observer, "vacon_nx"))
        assert errors(observer, "vacon_nx")[0]["error"] == "internal error: RuntimeError"
        assert "a defect" in caplog.text
        await observer.client.publish("modbus/nastec_vasco/operating_frequency/set", "42")
        await state_of(observer, "nastec_vasco", "operating_frequency", 42)
        assert not task.done()
