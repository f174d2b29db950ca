"""``modbus-mqtt-bridge simulate`` as a user runs it: serves, answers, stops cleanly."""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.config import TcpBus
from bridge.core.entity import Table
from bridge.core.request import Read
from bridge.modbus.transport import Transport
from bridge.sunspec.walk import walk
from tests.ports import free_port
from tests.sunspec_devices import built_devices


@pytest.mark.asyncio
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
async def test_simulate_serves_two_units_and_stops_cleanly(stop: signal.Signals) -> None:
    port = free_port()
    command = [
        sys.executable,
        "-m",
        "bridge.cli",
        "simulate",
        "--mapping",
        "soft_starter",
        "--unit",
        "1",
        "--mapping",
        "nastec_vasco",
        "--unit",
        "2",
        "--tcp",
        f"127.0.0.1:{port}",
        "--tick",
        "0",
        "--dead",
        "3",
    ]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as process:
        try:
            assert process.stdout is not None
            line = await asyncio.wait_for(asyncio.to_thread(process.stdout.readline), 20)
            assert line.startswith("serving soft_starter unit 1, nastec_vasco unit 2 on tcp")
            transport = Transport(TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port))
            await transport.open()
            # the pump's actual value, 4.0 (its mapping's simulate hint)
            assert await transport.execute(2, Read(Table.HOLDING, 0x97, 1), 1.0) == (40,)
            assert await transport.execute(1, Read(Table.HOLDING, 0x1036, 1), 1.0) == (0,)
            transport.close()
            process.send_signal(stop)
            assert await asyncio.wait_for(asyncio.to_thread(process.wait), 10) == 0
        finally:
            if process.poll() is None:
                process.kill()


def test_simulate_refuses_an_unknown_mapping() -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "bridge.cli",
            "simulate",
            "--mapping",
            "nope",
            "--unit",
            "1",
            "--pty",
        ],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2
    assert "no shipped mapping of that name" in result.stderr


def test_simulate_refuses_an_option_no_mapping_has() -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "bridge.cli",
            "simulate",
            "--mapping",
            "smartgen_hgm6100",
            "--unit",
            "1",
            "--pty",
            "-o",
            "modle=hgm6110",
        ],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2
    assert "--option modle: no simulated mapping has it" in result.stderr


@pytest.mark.asyncio
async def test_simulate_serves_a_sunspec_device_image_beside_a_mapping(tmp_path: Path) -> None:
    image = tmp_path / "meter.json"
    image.write_text(json.dumps(built_devices()["meter"]))
    port = free_port()
    command = [
        *[sys.executable, "-m", "bridge.cli", "simulate", "--tcp", f"127.0.0.1:{port}"],
        *["--mapping", "soft_starter", "--unit", "1", "--sunspec", f"4={image}@50000"],
    ]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as process:
        try:
            assert process.stdout is not None
            line = await asyncio.wait_for(asyncio.to_thread(process.stdout.readline), 20)
            assert line.startswith(f"serving soft_starter unit 1, sunspec {image}@50000 unit 4")
            transport = Transport(TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port))
            await transport.open()

            async def read(address: int, count: int) -> tuple[int, ...]:
                return await transport.execute(4, Read(Table.HOLDING, address, count), 1.0)

            chain = await walk(read)
            transport.close()
            assert (chain.base, chain.model_ids) == (50000, (1, 203))
            assert chain.common is not None
            assert chain.common.serial_number == "MTR-7"
            process.send_signal(signal.SIGINT)
            assert await asyncio.wait_for(asyncio.to_thread(process.wait), 10) == 0
        finally:
            if process.poll() is None:
                process.kill()


def test_simulate_refuses_a_bad_sunspec_image(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"models": [{"ID": 4242}]}))
    result = subprocess.run(
        [
            *[sys.executable, "-m", "bridge.cli", "simulate", "--pty"],
            *["--sunspec", f"1={bad}", "--sunspec", "x=nowhere.json", "--sunspec", "2=/nope.json"],
        ],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2
    assert f"--sunspec 1={bad}: device image 'bad.json', model 4242" in result.stderr
    assert "--sunspec x=nowhere.json: UNIT and BASE are numbers" in result.stderr
    assert "--sunspec 2=/nope.json: /nope.json:" in result.stderr
    nothing = subprocess.run(
        [sys.executable, "-m", "bridge.cli", "simulate", "--pty"],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert nothing.returncode == 2
    assert "give at least one --mapping (with --unit) or --sunspec" in nothing.stderr
