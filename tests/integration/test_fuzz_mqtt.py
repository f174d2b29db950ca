"""Fuzzing the running bridge: random /set messages through a real Mosquitto.

One bridge serves the five seed devices of one simulator for the whole test; each
Hypothesis example publishes one message on a /set topic (a device's JSON form or one
entity's plain form, of a real device or of none) and waits, bounded, until every
command the message carries has an outcome. Per message: the bridge is still running;
every command is written (``done``), skipped as unchanged, or refused with exactly one
message on ``<base>/<device>/error``; and every write the simulator received holds a
value within the entity's declared limits (static min/max, an enum label of the mapping,
0/ON for coils). The pure path is fuzzed in tests/unit/test_fuzz_commands.py; this is
the same contract end to end.
"""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest
import pytest_asyncio
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

from bridge.app import Bridge
from bridge.core.codec import decode
from bridge.core.commands import parse_set
from bridge.core.entity import Table
from bridge.core.mapping import Point
from bridge.core.request import Write
from bridge.core.simulation import number_range
from bridge.errors import CodecError, ValueRejectedError
from bridge.modbus.simulator import Simulator
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import UNITS, Observer, all_units, bridge_config, observing
from tests.unit.test_fuzz_commands import (
    HOSTILE,
    JSON_VALUES,
    MAPPINGS,
    TOPICS,
    at_write_address,
    plain_payloads,
)

POINTS = {name: MAPPINGS[name].points() for name in UNITS}  # the config sets no options
NOWHERE = "nowhere"  # a device the bridge does not have
KEYS = st.text(st.sampled_from("abcdefghijklmnopqrstuvwxyz_0123456789"), min_size=1, max_size=12)


@dataclass
class Running:
    bridge: Bridge
    task: asyncio.Task[None]
    sim: Simulator
    observer: Observer


@pytest_asyncio.fixture
async def running(mosquitto: Broker) -> AsyncIterator[Running]:
    """The bridge with all five seeds, online; shared by every example of a test."""
    sim = all_units()
    async with serving_tcp(sim) as port, observing(mosquitto, "modbus/#") as observer:
        bridge = Bridge(bridge_config(mosquitto, port))
        task = asyncio.create_task(bridge.run())
        try:
            await eventually(
                lambda: all(
                    observer.retained.get(f"modbus/{name}/availability") == b"online"
                    for name in UNITS
                ),
                timeout=20,
            )
            yield Running(bridge, task, sim, observer)
        finally:
            await cancel(task)


# --- messages ------------------------------------------------------------------------------


def sensible(point: Point | None) -> st.SearchStrategy[object]:
    """Values a user would send for this entity (most pass; limits read from registers,
    guards and the EEPROM rate limit still refuse some)."""
    if point is None:
        return JSON_VALUES
    entity = point.entity
    if entity.press is not None:
        return st.just("PRESS")
    if entity.kind == "enum":
        return st.sampled_from(list((entity.enum or {}).values()))
    if entity.kind == "bool":
        return st.sampled_from(["ON", "OFF", True, False])
    if entity.kind == "text":
        return st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=4)
    low, high = number_range(point)
    return st.floats(low, high).map(lambda v: round(v, entity.decimals))


@st.composite
def messages(draw: st.DrawFn) -> tuple[str, bytes]:
    """A /set message: (topic, payload)."""
    device = draw(st.sampled_from([*UNITS, *UNITS, NOWHERE]))
    points = POINTS.get(device, {})
    writable = sorted(k for k, p in points.items() if p.entity.writable)
    known = st.sampled_from(writable) if writable else KEYS
    if draw(st.booleans()):  # <base>/<device>/<key>/set, a plain value
        key = draw(st.one_of(known, known, st.sampled_from(sorted(points) or ["x"]), KEYS))
        point = points.get(key)
        if point is None:
            return TOPICS.set(device, key), draw(st.binary(max_size=20))
        plain = sensible(point).map(lambda v: (v if isinstance(v, str) else json.dumps(v)).encode())
        payload = draw(st.one_of(plain, plain, plain_payloads(point)))
        return TOPICS.set(device, key), payload
    keys = draw(st.lists(st.one_of(known, known, KEYS), min_size=1, max_size=3, unique=True))
    document = {k: draw(st.one_of(sensible(points.get(k)), JSON_VALUES)) for k in keys}
    as_json = st.just(json.dumps(document).encode())
    payload = draw(
        st.one_of(as_json, as_json, as_json, st.binary(max_size=30), st.sampled_from(HOSTILE))
    )
    return TOPICS.set(device), payload


def commands_in(topic: str, payload: bytes) -> int:
    """How many outcomes the message must have: one per command, or one refusal."""
    target = TOPICS.parse_command(topic)
    assert target is not None
    try:
        return len(parse_set(payload, target.key))
    except ValueRejectedError:
        return 1


def outcomes(running: Running, device: str) -> int:
    """Errors published for ``device`` plus the commands it wrote or skipped."""
    errors = len(running.observer.after(0, f"modbus/{device}/error"))
    poller = running.bridge.engine.devices.get(device)
    if poller is None:
        return errors
    return errors + poller.writes.done + poller.writes.skipped_unchanged


# --- what reached the simulator ------------------------------------------------------------


def check_write(sim: Simulator, unit: int, write: Write) -> None:
    """The write puts a value within the declared limits of every entity it touches."""
    name = next(n for n, u in UNITS.items() if u == unit)
    points = POINTS[name]
    table = Table.COIL if write.function in (5, 15) else Table.HOLDING
    touched = [
        p
        for p in _writers(points)
        if p.table is table
        and p.write_address <= write.address < p.write_address + p.count
        and (write.function == 5 or len(write.values) in (1, p.count))
    ]
    assert touched, f"{name}: {write} writes where no entity of the mapping writes"
    if write.function == 5:
        assert write.values in ((0,), (touched[0].coil_on_value,)), f"{name}: {write}"
        return
    image = dict(sim.image(unit))
    for offset, word in enumerate(write.values):
        assert 0 <= word <= 0xFFFF
        image[(table, write.address + offset)] = word
    for point in touched:
        entity = point.entity
        if entity.press is not None or entity.pulse or point.write_address != write.address:
            continue
        try:
            value = decode(at_write_address(point), image)
        except CodecError:
            continue  # a word the device keeps elsewhere (a sign register) is not in the image
        where = f"{name}.{point.key} <- {write}"
        if entity.kind == "enum":
            assert value in (entity.enum or {}).values(), f"{where}: {value!r}"
        elif entity.kind == "number":
            assert isinstance(value, int | float) and math.isfinite(value), f"{where}: {value!r}"
            assert entity.min is None or value >= entity.min, f"{where}: {value} < {entity.min}"
            assert entity.max is None or value <= entity.max, f"{where}: {value} > {entity.max}"


def _writers(points: dict[str, Point]) -> list[Point]:
    """Writable points and the sign bits they write with them."""
    found = [p for p in points.values() if p.entity.writable]
    return found + [p.sign for p in found if p.sign is not None]


# --- the test -----------------------------------------------------------------------------------


@pytest.mark.asyncio
@settings(
    max_examples=100,
    deadline=None,
    phases=(Phase.explicit, Phase.reuse, Phase.generate),  # no shrinking: the state moves on
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(message=messages())
@example(message=("modbus/vacon_nx/pd_in_1/set", b"1" + b"0" * 400))  # beyond any float
@example(message=("modbus/vacon_nx/set", b'{"pd_in_1":' * 1200))  # deeper than json can go
@example(message=("modbus/vacon_nx/pd_in_1/set", b"[" * 3000))
@example(message=("modbus/nowhere/set", b'{"a": 1, "b": 2}'))
@example(message=("modbus/vacon_nx/set", b'{"pd_in_5": 0.0, "pd_in_8": 0.0}'))
async def test_random_set_messages_through_mosquitto(
    running: Running, message: tuple[str, bytes]
) -> None:
    topic, payload = message
    device = topic.split("/")[1]
    expected = outcomes(running, device) + commands_in(topic, payload)
    written = len(running.sim.writes)
    await running.observer.client.publish(topic, payload)
    await eventually(lambda: outcomes(running, device) >= expected, timeout=10)
    await asyncio.sleep(0.05)  # a second outcome of the same command would show now
    assert outcomes(running, device) == expected, f"{topic} {payload[:80]!r}"
    assert not running.task.done(), "the bridge stopped"
    for unit, write in running.sim.writes[written:]:
        check_write(running.sim, unit, write)
