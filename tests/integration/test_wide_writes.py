"""A 64-bit setting written through the engine to the simulator: one FC16 of its four
registers (never two frames of a half value each), read back exactly."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.core.request import Write
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.integration.harness import config, running, serving_tcp, tcp_bus

pytestmark = pytest.mark.asyncio
WIDE = """
manufacturer: Test
model: Wide
description: 64-bit settings and a half-float setting
source: {title: test}
entities:
  limit: {name: Limit, address: 10, type: u64, access: rw, word_order: little}
  gain: {name: Gain, address: 20, type: f64, access: rw}
  setpoint: {name: Setpoint, address: 30, type: f16, access: rw}
"""


async def test_64_bit_and_half_float_settings_are_written_whole(tmp_path: Path) -> None:
    path = tmp_path / "wide.yaml"
    path.write_text(WIDE, encoding="utf-8")
    sim = Simulator([SimulatedUnit(1, load_mapping(path))])
    async with serving_tcp(sim) as port:
        device = {"id": "wide", "bus": "tcp", "unit": 1, "mapping": str(path)}
        engine = Engine(config([tcp_bus(port)], [device]))
        async with running(engine, pollers=False):
            assert await engine.write("wide", "limit", (1 << 64) - 2) == (1 << 64) - 2
            assert await engine.write("wide", "gain", 0.1) == 0.1
            assert await engine.write("wide", "setpoint", 21.5) == 21.5
    assert [w for _, w in sim.writes] == [
        Write(16, Table.HOLDING, 10, (0xFFFE, 0xFFFF, 0xFFFF, 0xFFFF)),  # low word first
        Write(16, Table.HOLDING, 20, (0x3FB9, 0x9999, 0x9999, 0x999A)),
        Write(6, Table.HOLDING, 30, (0x4D60,)),
    ]
    assert sim.value(1, "limit") == (1 << 64) - 2
