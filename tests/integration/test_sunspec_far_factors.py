"""SunSpec curve points far from their scale factors, end to end (bridge/core/bracket.py):
a DER device with model 705's volt-var curves (eight curves of eight points: the later
curves lie more than 125 registers from the factors at the model's top) served by the
simulator over loopback TCP, its mapping built over the bus, the real engine polling it.

Every curve point is published with the value pysunspec2 computes from the same registers
(the far ones read bracketed: the factor, the point's read, the factor again). When the
device moves a factor between the two reads of it (the simulator changes the registers
right after answering the point's read), the point is not published that pass: never the
old raw value scaled by the new factor, and the device's health counts it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from bridge.config import TcpBus
from bridge.core.entity import Table
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Read
from bridge.modbus.commission import open_bus
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Simulator, SunSpecUnit
from bridge.sunspec.image import build_image
from bridge.sunspec.mapping import BuiltMapping, build_from_device
from tests.integration.harness import (
    FAST_POLICY,
    Recorder,
    config,
    eventually,
    running,
    serving_tcp,
    tcp_bus,
)
from tests.sunspec_devices import built_model, common
from tests.sunspec_reference import differences, expected_values, reference_models

UNIT = 1
DER = {
    "name": "der_705",
    "models": [
        common("DER Inverter 8k", "DER-705"),
        built_model(705, instances=8),  # 8 curves of 8 points
        {"ID": 65535, "L": 0},
    ],
}


async def built_over_the_bus(port: int) -> tuple[BuiltMapping, Any]:
    bus = tcp_bus(port) | {"timeout": 1.0}
    async with open_bus(TcpBus(**bus)) as submit:

        async def read(address: int, count: int) -> tuple[int, ...]:
            return await submit(UNIT, Read(Table.HOLDING, address, count), 1.0)

        chain, built = await build_from_device(read)
    return built, chain


def engine_for(built: BuiltMapping, port: int, tmp_path: Path, recorder: Recorder) -> Engine:
    path = tmp_path / "der_705.yaml"
    path.write_text(built.yaml(), encoding="utf-8")
    device = {
        "id": "der",
        "bus": "tcp",
        "unit": UNIT,
        "mapping": str(path),
        "poll": {"fast": 0.1, "slow": 0.2},
    }
    return Engine(
        config([tcp_bus(port) | {"timeout": 1.0}], [device]), recorder, policy=FAST_POLICY
    )


def far_keys(built: BuiltMapping) -> list[str]:
    mapping = built.mapping()
    plan = plan_reads(mapping.points().values(), limits_for(mapping))
    return [key for bracket in plan.bracketed for key in bracket.keys]


@pytest.mark.asyncio
async def test_curve_points_far_from_their_factors_are_published_as_pysunspec2_reads(
    tmp_path: Path,
) -> None:
    image = build_image(DER)
    sim = Simulator([SunSpecUnit(UNIT, image)], tick=0)
    async with serving_tcp(sim) as port:
        built, chain = await built_over_the_bus(port)
        far = far_keys(built)
        assert len(far) > 40 and not [s for s in built.skipped if s.reason != "padding"]
        wanted = expected_values(built, reference_models(image, chain, DER))
        assert sum(1 for key in far if wanted[key] is not None) > 30  # implemented ones
        recorder = Recorder()
        engine = engine_for(built, port, tmp_path, recorder)
        poller = engine.devices["der"]
        async with running(engine):
            await eventually(
                lambda: all(k in poller.values for k, v in wanted.items() if v is not None), 30
            )
            assert differences(poller.values, wanted) == []
            assert poller.scaled_values_held == 0
    assert not sim.writes


@pytest.mark.asyncio
async def test_a_factor_moved_between_its_two_reads_never_scales_the_old_value(
    tmp_path: Path,
) -> None:
    image = build_image(DER)
    sim = Simulator([SunSpecUnit(UNIT, image)], tick=0)
    async with serving_tcp(sim) as port:
        built, _ = await built_over_the_bus(port)
        points = built.mapping().points()
        key = [k for k in far_keys(built) if points[k].count == 1][-1]  # the last curve's
        point = points[key]
        assert point.scale_source is not None
        value_at, factor_at = point.address, point.scale_source.address
        sim.set_registers(UNIT, {factor_at: 0xFFFF, value_at: 2301})  # 230.1 at 10**-1
        recorder = Recorder()
        engine = engine_for(built, port, tmp_path, recorder)
        poller = engine.devices["der"]
        async with running(engine):
            await eventually(lambda: poller.values.get(key) == 230.1, 30)
            moved: list[int] = []

            def move_factor(address: int, count: int) -> dict[int, int]:
                """Right after the point's read is answered, the device takes a new moment:
                4567 at 10**-2 (its factor read before the point said -1)."""
                if moved or not address <= value_at < address + count or factor_at == address:
                    return {}
                moved.append(address)
                return {factor_at: 0xFFFE, value_at: 4567}

            sim.after_read(UNIT, move_factor)
            await eventually(lambda: poller.values.get(key) == 45.67, 30)
            held = poller.scaled_values_held
        published = [u.values[key] for u in recorder.of("der") if key in u.changed]
    assert moved
    # 2301 read under -1 and checked against -2 after it: neither 23.01 nor anything else
    assert set(published) == {230.1, 45.67}, published
    assert published[-1] == 45.67
    assert held >= 1  # the pass that read -1 before the point and -2 after it held it
