"""The device of ``bench/peers.py``: the simulator behind a relay that logs every request.

Run as its own process (``peers.py serve``): the simulated Nastec VASCO (unit 1, with a
latency per transaction) and a dead unit (2) on one simulator port, and in front of it a
Modbus TCP relay on the port the bridges use. The relay passes bytes through unchanged
and writes one line per request it forwards, ``<time.monotonic()> <unit> <function>
<address>``, so the bench sees every bridge's requests the same way (CLOCK_MONOTONIC is
shared by the processes of one machine).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from peer_configs import DEAD_UNIT, MAPPING, PERIOD, UNIT

from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator

MBAP = 7  # transaction, protocol, length (2 bytes each), unit


@dataclass(frozen=True)
class Request:
    at: float
    unit: int
    function: int
    address: int


async def serve(port: int, latency: float, log_path: Path) -> None:
    """The simulator on a free port, the relay on ``port``, until cancelled."""
    mapping = load_mapping(builtin_mapping_path(MAPPING))
    sim = Simulator(
        [
            SimulatedUnit(UNIT, mapping, quirks=Quirks(latency=latency)),
            SimulatedUnit(DEAD_UNIT, mapping, quirks=Quirks(dead=True)),
        ],
        tick=PERIOD,
    )
    with log_path.open("a", buffering=1) as log:
        async with asyncio.TaskGroup() as group:
            group.create_task(sim.serve_tcp("127.0.0.1", 0))
            await sim.ready.wait()

            async def relay(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
                await _relay(reader, writer, sim.port, log)

            server = await asyncio.start_server(relay, "127.0.0.1", port)
            async with server:
                await server.serve_forever()


async def _relay(
    reader: asyncio.StreamReader, writer: asyncio.StreamWriter, target: int, log: TextIO
) -> None:
    """One bridge connection: forward both ways, log each request."""
    try:
        sim_reader, sim_writer = await asyncio.open_connection("127.0.0.1", target)
    except OSError:
        writer.close()
        return
    try:
        async with asyncio.TaskGroup() as group:
            group.create_task(_forward(reader, sim_writer, log))
            group.create_task(_forward(sim_reader, writer, None))
    except* (OSError, EOFError):
        pass
    finally:
        for end in (writer, sim_writer):
            end.close()
            with contextlib.suppress(OSError):
                await end.wait_closed()


async def _forward(
    reader: asyncio.StreamReader, writer: asyncio.StreamWriter, log: TextIO | None
) -> None:
    pending = b""
    while chunk := await reader.read(4096):
        writer.write(chunk)
        if log is not None:
            pending = _log_requests(pending + chunk, log)
    raise EOFError  # one side closed: end the other direction too


def _log_requests(data: bytes, log: TextIO) -> bytes:
    """Log every whole Modbus TCP request in ``data``; return the incomplete rest."""
    while len(data) >= MBAP + 1:
        end = 6 + int.from_bytes(data[4:6], "big")
        if len(data) < end:
            break
        address = int.from_bytes(data[8:10], "big") if end >= 10 else -1
        log.write(f"{time.monotonic():.6f} {data[6]} {data[7]} {address}\n")
        data = data[end:]
    return data


def read_requests(log_path: Path) -> list[Request]:
    """The requests the relay logged."""
    found = []
    for line in log_path.read_text().splitlines():
        at, unit, function, address = line.split()
        found.append(Request(float(at), int(unit), int(function), int(address)))
    return found
