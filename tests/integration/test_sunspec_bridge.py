"""A SunSpec device without a mapping file of its own, end to end: the bridge's walk and
``read_chain`` over the bus, the mapping built from them (bridge/sunspec/mapping.py), and
the real engine polling the simulated devices with it over loopback TCP and RTU on a pty
pair. Every entity the engine publishes is what pysunspec2 computes from the same
registers (tests/sunspec_reference.py); every point the image leaves unimplemented is
None."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from bridge.config import SerialBus, TcpBus
from bridge.core.entity import Table
from bridge.core.request import Read
from bridge.modbus.commission import Submit, open_bus
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Simulator, SunSpecUnit
from bridge.sunspec.image import DeviceImage, build_image
from bridge.sunspec.mapping import BuiltMapping, build_from_device
from tests.integration.harness import (
    FAST_POLICY,
    Recorder,
    config,
    eventually,
    running,
    serving_serial,
    serving_tcp,
    tcp_bus,
)
from tests.sunspec_devices import every_image
from tests.sunspec_reference import differences, expected_values, reference_models

IMAGES = every_image()
PLACES = {  # unit: (image, base)
    1: ("device_1547", 40000),
    2: ("inverter_123", 50000),
    3: ("inverter_mppt", 0),
    4: ("meter", 40000),
    5: ("battery", 50000),
}
BAUD = 115200


def images() -> dict[int, DeviceImage]:
    return {unit: build_image(IMAGES[name], base, name) for unit, (name, base) in PLACES.items()}


async def built_over_the_bus(submit: Submit, unit: int) -> tuple[BuiltMapping, Any]:
    """Walk the unit, read its models, build its mapping: all over the bus."""

    async def read(address: int, count: int) -> tuple[int, ...]:
        return await submit(unit, Read(Table.HOLDING, address, count), 1.0)

    chain, built = await build_from_device(read)
    return built, chain


async def published_equals_pysunspec2(tmp_path: Path, bus: dict[str, Any]) -> None:
    served = images()
    builds = {}
    async with open_bus(_bus_model(bus)) as submit:
        for unit in PLACES:
            builds[unit] = await built_over_the_bus(submit, unit)
    devices = []
    for unit, (name, _) in PLACES.items():
        path = tmp_path / f"{name}.yaml"
        path.write_text(builds[unit][0].yaml(), encoding="utf-8")
        devices.append(
            {
                "id": name,
                "bus": bus["id"],
                "unit": unit,
                "mapping": str(path),
                "poll": {"fast": 0.2, "slow": 0.5},
            }
        )
    wanted = {
        name: expected_values(builds[unit][0], _reference(served[unit], builds[unit][1], name))
        for unit, (name, _) in PLACES.items()
    }
    recorder = Recorder()
    engine = Engine(config([bus], devices), recorder, policy=FAST_POLICY)
    async with running(engine):
        await eventually(lambda: all(_all_read(engine, n, w) for n, w in wanted.items()), 30)
    for name, want in wanted.items():
        values = engine.devices[name].values
        assert differences(values, want) == [], name  # a key never published: None
        assert any(v is None for v in want.values()), name
        published = {k for u in recorder.of(name) for k in u.changed}
        assert {k for k, v in want.items() if v is not None} <= published, name


def _all_read(engine: Engine, name: str, wanted: dict[str, Any]) -> bool:
    """Every point the image implements has a value (an unimplemented counter is never
    published: the counter guard holds a reading that is not a number)."""
    values = engine.devices[name].values
    return all(key in values for key, value in wanted.items() if value is not None)


def _reference(image: DeviceImage, chain: Any, name: str) -> list[Any]:
    return reference_models(image, chain, IMAGES[name])


def _bus_model(bus: dict[str, Any]) -> TcpBus | SerialBus:
    if bus["transport"] == "tcp":
        return TcpBus(**bus)
    return SerialBus(**bus)


@pytest.mark.asyncio
async def test_over_tcp_every_entity_published_is_pysunspec2s_value(tmp_path: Path) -> None:
    sim = Simulator([SunSpecUnit(unit, image) for unit, image in images().items()], tick=0)
    async with serving_tcp(sim) as port:
        await published_equals_pysunspec2(tmp_path, tcp_bus(port) | {"timeout": 1.0})
    assert not sim.writes


@pytest.mark.asyncio
async def test_over_rtu_every_entity_published_is_pysunspec2s_value(tmp_path: Path) -> None:
    sim = Simulator([SunSpecUnit(unit, image) for unit, image in images().items()], tick=0)
    async with serving_serial(sim, baudrate=BAUD) as port:
        bus = {"id": "rs485", "transport": "rtu", "port": port, "baudrate": BAUD, "timeout": 1.0}
        await published_equals_pysunspec2(tmp_path, bus)
    assert not sim.writes
