"""The SunSpec walk's requests and wire time at 9600 bit/s, against pysunspec2's scan.

Run: ``.venv/bin/python bench/sunspec_walk.py``

Per device image of the tests (tests/sunspec_devices.py: pysunspec2's two test devices and
the three built ones; the marker at 40000, the usual first base): the requests the walk
sends (``bridge/sunspec/walk.py``) and the wire time they take on Modbus RTU at 9600 8N1
with a device turnaround of 0 (``bridge/core/timing.py``: request and response characters
and two t3.5 silences per read; a refused read counted as a full answer, which it is not:
an upper bound). Beside it, pysunspec2's scan of the same registers
(``SunSpecModbusClientDevice.scan``): without reading the models (``full_model_read=False``:
its walk alone) and as it scans by default (every model read whole). Reads are counted in
memory: the same requests a bus would carry, without a bus's latency.
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path
from typing import Any

from sunspec2.modbus import client as ss_client

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the SunSpec test devices

from bridge.core.entity import Table
from bridge.core.request import Read
from bridge.core.timing import LinkTiming
from bridge.errors import DeviceExceptionError
from bridge.sunspec.image import build_image
from bridge.sunspec.walk import walk
from tests.sunspec_devices import every_image

TIMING = LinkTiming.for_serial(9600, "N", 1, 8)


class Logged(ss_client.SunSpecModbusClientDevice):
    """pysunspec2's scan over registers in memory, its reads logged."""

    def __init__(self, registers: dict[int, int]) -> None:
        super().__init__()
        self.registers = registers
        self.reads: list[Read] = []

    def read(self, addr: float, count: float, op: Any = None) -> bytes:  # noqa: ARG002
        read = Read(Table.HOLDING, int(addr), int(count))
        self.reads.append(read)
        span = range(read.address, read.address + read.count)
        if any(a not in self.registers for a in span):
            raise ss_client.SunSpecModbusClientException("illegal data address")
        return b"".join(self.registers[a].to_bytes(2, "big") for a in span)


def figures(reads: list[Read]) -> str:
    seconds = sum(TIMING.read_cost(r) for r in reads)
    return f"{len(reads)} / {sum(TIMING.read_bytes(r) for r in reads)} / {seconds * 1000:.1f}"


def ours(registers: dict[int, int]) -> list[Read]:
    reads: list[Read] = []

    async def read(address: int, count: int) -> list[int]:
        reads.append(Read(Table.HOLDING, address, count))
        span = range(address, address + count)
        if any(a not in registers for a in span):
            raise DeviceExceptionError(2, "illegal data address", "fail")
        return [registers[a] for a in span]

    asyncio.run(walk(read))
    return reads


def theirs(registers: dict[int, int], full: bool) -> list[Read]:
    device = Logged(registers)
    device.scan(connect=False, full_model_read=full)
    return device.reads


def main() -> None:
    print("SunSpec walk, marker at 40000, RTU 9600 8N1, turnaround 0.")
    print("Each cell: requests / bytes on the wire / ms.\n")
    print(
        "| device | models | registers | walk | pysunspec2 scan, walk only | "
        "pysunspec2 scan, models read |"
    )
    print("| --- | ---: | ---: | --- | --- | --- |")
    for name, device in every_image().items():
        image = build_image(device, 40000, name)
        registers = image.registers
        models = sum(1 for m in device["models"] if m["ID"] != 0xFFFF)
        print(
            f"| {name} | {models} | {len(image.words)} | {figures(ours(registers))} | "
            f"{figures(theirs(registers, False))} | {figures(theirs(registers, True))} |"
        )


if __name__ == "__main__":
    main()
