"""A SunSpec device's poll with the mapping the bridge builds, against the bus minimum.

Run: ``PYTHONPATH=. .venv/bin/python bench/sunspec_poll.py``

Per device image of the tests (tests/sunspec_devices.py, the marker at 40000): the
mapping built from its walk (``bridge/sunspec/mapping.py``), and the reads the planner
(``bridge/core/planner.py``) makes of it, at 125 registers per read, for a pass of every
entity (the first one, or a ``get``), a pass of the entities due every ``fast`` interval
(measurements) and of those due every ``slow`` one (settings, ratings, scale factors),
the exponent reads of bracketed values included; each as requests / registers / wire ms
on Modbus RTU at 9600 8N1 (turnaround 0, ``bridge/core/timing.py``). The minimum: the
models' registers in reads of 125, one model after the other (ceil(registers / 125)).
Beside it what pysunspec2 reads to refresh the device
(``SunSpecModbusClientDevice.read``: every model whole, each in reads of at most 125).
The once-only reads (the walk and ``read_chain`` at start) are not in any pass.
"""

from __future__ import annotations

import asyncio
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the SunSpec test devices

from bridge.core.entity import Table
from bridge.core.mapping import Point
from bridge.core.planner import ReadLimits, limits_for, plan_reads
from bridge.core.request import Read
from bridge.core.timing import LinkTiming
from bridge.sunspec.image import build_image
from bridge.sunspec.mapping import build_mapping
from bridge.sunspec.walk import Chain, walk
from tests.sunspec_devices import every_image

TIMING = LinkTiming.for_serial(9600, "N", 1, 8)
LIMIT = 125


def figures(reads: tuple[Read, ...] | list[Read]) -> str:
    seconds = sum(TIMING.read_cost(r) for r in reads)
    return f"{len(reads)} / {sum(r.count for r in reads)} / {seconds * 1000:.0f}"


def plan(wanted: list[Point], limits: ReadLimits) -> str:
    """The plan's reads and the exponent reads its bracketed values add (a point too far
    from its scale factor for one read: bridge/core/bracket.py)."""
    planned = plan_reads(wanted, limits)
    return figures([*planned.reads, *planned.extra])


def walked(registers: dict[int, int]) -> Chain:
    async def read(address: int, count: int) -> list[int]:
        return [registers[a] for a in range(address, address + count)]

    return asyncio.run(walk(read))


def model_reads(chain: Chain) -> list[Read]:
    """Every model whole, each in reads of at most 125 (pysunspec2's refresh)."""
    reads = []
    for m in chain.models:
        for start in range(m.address, m.end, LIMIT):
            reads.append(Read(Table.HOLDING, start, min(LIMIT, m.end - start)))
    return reads


def main() -> None:
    print("A SunSpec device's poll, marker at 40000, 125 registers per read, RTU 9600 8N1.")
    print("Each cell: requests / registers / ms.\n")
    print("| device | entities | every entity | fast | slow | minimum | pysunspec2 read |")
    print("| --- | ---: | --- | --- | --- | --- | --- |")
    for name, device in every_image().items():
        image = build_image(device, 40000, name)
        chain = walked(image.registers)
        mapping = build_mapping(chain, image.registers).mapping()
        points = list(mapping.points().values())
        limits = limits_for(mapping)
        fast = [p for p in points if p.entity.poll_spec == "fast"]
        slow = [p for p in points if p.entity.poll_spec == "slow"]
        span = chain.models[-1].end - chain.models[0].address
        first = chain.models[0].address
        minimum = [
            Read(Table.HOLDING, a, min(LIMIT, first + span - a))
            for a in range(first, first + span, LIMIT)
        ]
        assert len(minimum) == math.ceil(span / LIMIT)
        print(
            f"| {name} | {len(points)} | {plan(points, limits)} | {plan(fast, limits)} | "
            f"{plan(slow, limits)} | "
            f"{figures(minimum)} | {figures(model_reads(chain))} |"
        )


if __name__ == "__main__":
    main()
