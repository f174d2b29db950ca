"""identify against the real simulator: the five seeds and a SunSpec marker at random units
(seeded), each told correctly, read-only (no write on the wire), within the stated bound
of requests per unit, and an absent unit costs one timeout."""

from __future__ import annotations

import random
from collections import Counter

import pytest

from bridge.config import SerialBus, TcpBus
from bridge.core.fingerprint import probe_read
from bridge.core.identify import SUNSPEC_BASES, Identity, request_bound
from bridge.core.mapping import (
    Mapping,
    builtin_mapping_names,
    builtin_mapping_path,
    load_mapping,
    parse_mapping,
)
from bridge.core.request import Read, Write
from bridge.modbus.commission import Submit, open_bus
from bridge.modbus.identify import identify, identify_unit, sunspec_base
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from tests.integration.harness import serving_serial, serving_tcp

SEEDS = builtin_mapping_names()
LIBRARY = {name: load_mapping(builtin_mapping_path(name)) for name in SEEDS}
SUNSPEC_ONLY = """
manufacturer: Test
model: SunSpec marker
description: a unit holding nothing but the SunSpec marker at 40000
source: {title: tests}
entities:
  marker: {name: Marker, address: 40000, type: ascii, count: 2}
"""
TIMEOUT = 0.3


def bus_of(sim: Simulator, seed: int) -> tuple[dict[str, int], int]:
    """The seeds and the SunSpec unit at random distinct units; a unit nobody holds."""
    rng = random.Random(seed)
    units = rng.sample(range(1, 248), len(SEEDS) + 2)
    return dict(zip([*SEEDS, "sunspec"], units, strict=False)), units[-1]


def simulated(placed: dict[str, int]) -> Simulator:
    marker = parse_mapping(SUNSPEC_ONLY, "sunspec_only.yaml")
    specs = [
        SimulatedUnit(unit, marker if name == "sunspec" else LIBRARY[name])
        for name, unit in placed.items()
    ]
    sim = Simulator(specs, tick=0.0)
    sim.set_value(placed["sunspec"], "marker", "SunS")
    # the Nastec's Modbus address register reads the address it answers at, as on the device
    sim.set_value(placed["nastec_vasco"], "modbus_address", placed["nastec_vasco"])
    return sim


class Counting:
    """Counts the requests sent per unit (the simulator logs only units that answer)."""

    def __init__(self, submit: Submit) -> None:
        self.submit = submit
        self.sent: Counter[int] = Counter()

    async def __call__(self, unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        self.sent[unit] += 1
        return await self.submit(unit, request, timeout)


def check_bus(sim: Simulator, placed: dict[str, int], found: list[Identity]) -> None:
    by_unit = {identity.unit: identity for identity in found}
    assert sorted(by_unit) == sorted(placed.values())
    for name, unit in placed.items():
        identity = by_unit[unit]
        if name == "sunspec":
            assert identity.sunspec_base == 40000
            assert identity.summary() == "SunSpec device (marker at base 40000)"
        else:
            assert identity.sunspec_base is None
            assert identity.best == name, (name, identity.as_dict())
            assert identity.matches[0].like is not LIBRARY[name].fingerprint.identifies  # type: ignore[union-attr]
    assert sim.writes == []
    per_unit = Counter(unit for unit, _, _ in sim.requests)
    bound = request_bound(LIBRARY)
    assert all(count <= bound for count in per_unit.values()), per_unit
    assert per_unit[placed["sunspec"]] == 2  # scan's probe and the marker at 40000
    assert {code for _, code, _ in sim.requests} <= {1, 2, 3, 4}


@pytest.mark.asyncio
@pytest.mark.parametrize("seed", [1, 2])
async def test_identify_tells_every_seed_and_the_sunspec_marker_over_tcp(seed: int) -> None:
    placed, absent = bus_of(Simulator([]), seed)
    sim = simulated(placed)
    units = sorted([*placed.values(), absent])
    async with serving_tcp(sim) as port:
        bus = TcpBus(id="tcp", transport="tcp", host="127.0.0.1", tcp_port=port, timeout=TIMEOUT)
        async with open_bus(bus) as submit:
            counting = Counting(submit)
            found = await identify(counting, units, LIBRARY, TIMEOUT, "tcp")
    check_bus(sim, placed, found)
    assert counting.sent[absent] == 1  # one probe, one timeout, nothing more
    per_unit = Counter(unit for unit, _, _ in sim.requests)
    assert all(counting.sent[u] == per_unit[u] for u in placed.values())
    nastec = next(i for i in found if i.unit == placed["nastec_vasco"])
    assert nastec.matches[0].level == "high"
    assert nastec.as_dict()["config"] == (
        f"- id: nastec_vasco_{nastec.unit}\n  bus: tcp\n  unit: {nastec.unit}\n"
        "  mapping: nastec_vasco\n"
    )


@pytest.mark.asyncio
async def test_identify_over_rtu_on_a_pty() -> None:
    placed, _ = bus_of(Simulator([]), 3)
    sim = simulated(placed)
    async with serving_serial(sim, baudrate=38400) as port:
        bus = SerialBus(id="rs485", transport="rtu", port=port, baudrate=38400, timeout=TIMEOUT)
        async with open_bus(bus) as submit:
            found = await identify(submit, sorted(placed.values()), LIBRARY, TIMEOUT, "rs485")
    check_bus(sim, placed, found)


def test_each_probe_reads_within_its_mappings_limits_and_function_codes() -> None:
    for name, mapping in LIBRARY.items():
        assert mapping.fingerprint is not None, name
        for probe in mapping.fingerprint.probes:
            read = probe_read(probe, mapping.entities, mapping.protocol)
            assert read.table.read_function in mapping.protocol.function_codes
            limit = _limit(mapping, read)
            assert read.count <= limit, (name, read)


def _limit(mapping: Mapping, read: Read) -> int:
    protocol = mapping.protocol
    return protocol.max_read_bits if read.table.is_bits else protocol.max_read_registers


@pytest.mark.asyncio
async def test_the_sunspec_marker_at_each_base() -> None:
    for base in SUNSPEC_BASES:
        text = SUNSPEC_ONLY.replace("address: 40000", f"address: {base}")
        sim = Simulator([SimulatedUnit(5, parse_mapping(text, "m.yaml"))], tick=0.0)
        sim.set_value(5, "marker", "SunS")
        async with serving_tcp(sim) as port:
            bus = TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port, timeout=TIMEOUT)
            async with open_bus(bus) as submit:
                assert await sunspec_base(submit, 5, TIMEOUT) == base
                identity = await identify_unit(submit, 5, LIBRARY, TIMEOUT, "t")
        assert identity is not None and identity.best == "sunspec"
        assert identity.requests == 1 + SUNSPEC_BASES.index(base) + 1
        assert sim.writes == []


@pytest.mark.asyncio
async def test_a_unit_that_goes_silent_is_left_after_two_unanswered_reads() -> None:
    sim = Simulator([SimulatedUnit(4, LIBRARY["vacon_nx"])], tick=0.0)
    async with serving_tcp(sim) as port:
        bus = TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port, timeout=TIMEOUT)
        async with open_bus(bus) as submit:

            async def dies_after_the_probe(
                unit: int, request: Read | Write, timeout: float
            ) -> tuple[int, ...]:
                values = await submit(unit, request, timeout)
                sim.set_quirks(4, Quirks(dead=True))  # the unit answers once, then never
                return values

            identity = await identify_unit(dies_after_the_probe, 4, LIBRARY, TIMEOUT, "t")
    assert identity is not None
    assert identity.requests == 3  # the probe, then two reads unanswered
    assert identity.note == "stopped: 2 reads went unanswered"
    assert identity.matches == ()
    assert sim.writes == []
