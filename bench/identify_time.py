"""``identify``'s requests and time per unit on Modbus RTU at 9600 8N1, a whole bus swept.

Run: ``.venv/bin/python bench/identify_time.py``

The bus of the identify test (tests/integration/test_identify.py): every shipped mapping
simulated at a unit of its own, three SunSpec devices (an inverter with four MPPTs, a
meter, a battery: tests/sunspec_devices.py) and the rest of units 1-247 absent.
``identify`` runs over loopback TCP against the simulator (bridge/modbus/identify.py, the
CLI's 0.2 s ``--timeout`` for a unit's first answer); each request it sends is logged and
costed as RTU at 9600 8N1 with a device turnaround of 0 (``bridge/core/timing.py``: a
refused read counted as a full answer: an upper bound). An absent unit costs its one
timeout; the total is what sweeping ``--units 1-247`` takes on such a line, the silence of
the absent units included.
"""

from __future__ import annotations

import asyncio
import random
import sys
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the test bus and devices

from bridge.config import TcpBus
from bridge.core.mapping import shipped_library
from bridge.core.request import Read, Write
from bridge.core.timing import LinkTiming
from bridge.modbus.commission import Submit, open_bus
from bridge.modbus.identify import identify, request_bound
from tests.integration.harness import serving_tcp
from tests.integration.test_identify import simulated  # identifying registers set as on the devices

TIMING = LinkTiming.for_serial(9600, "N", 1, 8)
TIMEOUT = 0.2  # s: the CLI's default wait for a unit's first answer
SUNSPEC = {"inverter_mppt": 50000, "meter": 40000, "battery": 0}
UNITS = range(1, 248)


def placed(seed: int = 1) -> dict[str, int]:
    names = [*shipped_library(), *SUNSPEC]
    rng = random.Random(seed)  # noqa: S311 - where the devices sit, not a secret
    return dict(zip(names, rng.sample(list(UNITS), len(names)), strict=True))


async def sweep(units: dict[str, int]) -> tuple[dict[int, list[Read]], dict[int, str]]:
    sim = simulated(units)
    sent: dict[int, list[Read]] = defaultdict(list)
    found: dict[int, str] = {}
    async with serving_tcp(sim) as port:
        bus = TcpBus(id="b", transport="tcp", host="127.0.0.1", tcp_port=port, timeout=TIMEOUT)
        async with open_bus(bus) as submit:

            async def logged(unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
                assert isinstance(request, Read)
                sent[unit].append(request)
                return await submit(unit, request, timeout)

            logging: Submit = logged
            for identity in await identify(logging, UNITS, shipped_library(), TIMEOUT, "b"):
                found[identity.unit] = identity.best or "?"
    assert sim.writes == []
    return sent, found


def main() -> None:
    units = placed()
    sent, found = asyncio.run(sweep(units))
    print(f"identify --units 1-247 at RTU 9600 8N1, --timeout {TIMEOUT} s, turnaround 0")
    print(f"stated bound: {request_bound(shipped_library())} requests per unit\n")
    print("| device | unit | told | requests | wire ms |")
    print("| --- | ---: | --- | ---: | ---: |")
    total = 0.0
    for name, unit in sorted(units.items(), key=lambda item: item[1]):
        seconds = sum(TIMING.read_cost(r) for r in sent[unit])
        total += seconds
        told = found.get(unit, "-")
        print(f"| {name} | {unit} | {told} | {len(sent[unit])} | {seconds * 1000:.0f} |")
    absent = [u for u in UNITS if u not in units.values()]
    asked = Counter(len(sent[u]) for u in absent)
    silence = len(absent) * TIMEOUT
    print(
        f"\n{len(absent)} absent units, requests each: {dict(asked)}: {silence:.1f} s of timeouts"
    )
    print(f"devices {total:.2f} s + absent {silence:.1f} s = {total + silence:.1f} s for the sweep")


if __name__ == "__main__":
    main()
