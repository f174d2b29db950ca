"""An imported mapping runs in the simulator like any other: ``simulate`` serves it, and
what the simulator holds reads back through the imported mapping as the value set."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.config import TcpBus
from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.core.request import Read
from bridge.modbus.simulator import SimulatedUnit, Simulator
from bridge.modbus.transport import Transport
from tests.integration.harness import serving_tcp
from tests.ports import free_port

pytestmark = pytest.mark.asyncio
HA_YAML = """\
modbus:
  - name: Heat pump
    type: tcp
    host: 127.0.0.1
    port: 502
    sensors:
      - {name: Flow temperature, address: 7, slave: 3, data_type: int32, swap: word_byte,
         scale: 0.01, precision: 2, unit_of_measurement: "°C", device_class: temperature}
    switches:
      - {name: Heating, address: 2, slave: 3, write_type: coil, verify: {}}
"""


def imported(tmp_path: Path) -> Path:
    source = tmp_path / "configuration.yaml"
    source.write_text(HA_YAML, encoding="utf-8")
    assert main(["import", "ha", str(source), "--out", str(tmp_path / "out")]) == 0
    return tmp_path / "out" / "mappings" / "heat_pump.yaml"


async def test_the_simulator_serves_an_imported_mapping(tmp_path: Path) -> None:
    mapping = load_mapping(imported(tmp_path))
    sim = Simulator([SimulatedUnit(3, mapping)], tick=0.0)
    sim.set_value(3, "flow_temperature", -12.34)
    sim.set_value(3, "heating", True)
    async with serving_tcp(sim) as port:
        transport = Transport(TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port))
        await transport.open()
        try:
            words = await transport.execute(3, Read(Table.HOLDING, 7, 2), 1.0)
            bits = await transport.execute(3, Read(Table.COIL, 2, 1), 1.0)
        finally:
            transport.close()
    points = mapping.points()
    image = {(Table.HOLDING, 7): words[0], (Table.HOLDING, 8): words[1], (Table.COIL, 2): bits[0]}
    assert decode(points["flow_temperature"], image) == -12.34
    assert decode(points["heating"], image) is True
    # word_byte: Home Assistant reads the bytes of -1234 (0xFFFFFB2E) reversed
    assert tuple(words) == (0x2EFB, 0xFFFF)


async def test_simulate_runs_an_imported_mapping_from_the_command_line(tmp_path: Path) -> None:
    path = imported(tmp_path)
    port = free_port()
    command = [sys.executable, "-m", "bridge.cli", "simulate", "--mapping", str(path)]
    command += ["--unit", "3", "--tcp", f"127.0.0.1:{port}", "--tick", "0"]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as process:
        try:
            assert process.stdout is not None
            line = await asyncio.wait_for(asyncio.to_thread(process.stdout.readline), 20)
            assert line == f"serving {path} unit 3 on tcp 127.0.0.1:{port}\n"
            transport = Transport(TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port))
            await transport.open()
            assert len(await transport.execute(3, Read(Table.HOLDING, 7, 2), 1.0)) == 2
            transport.close()
            process.send_signal(signal.SIGINT)
            assert await asyncio.wait_for(asyncio.to_thread(process.wait), 10) == 0
        finally:
            if process.poll() is None:
                process.kill()
