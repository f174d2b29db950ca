"""identify against the real simulator: the five seeds and three SunSpec devices (an
inverter with four MPPTs, a meter, a battery; markers at 50000, 40000 and 0) at random units
(seeded), each told correctly, read-only (no write on the wire), within the stated bound
of requests per unit, and an absent unit costs one timeout."""

from __future__ import annotations

import random
from collections import Counter

import pytest

from bridge.config import SerialBus, TcpBus
from bridge.core.fingerprint import probe_read
from bridge.core.identify import Identity
from bridge.core.mapping import (
    Mapping,
    builtin_mapping_names,
    builtin_mapping_path,
    load_mapping,
)
from bridge.core.request import Read, Write
from bridge.modbus.commission import Submit, open_bus
from bridge.modbus.identify import identify, identify_unit, request_bound
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator, SunSpecUnit
from bridge.sunspec.image import DeviceImage, build_image
from bridge.sunspec.walk import BASES
from tests.integration.harness import serving_serial, serving_tcp
from tests.sunspec_devices import every_image

SEEDS = builtin_mapping_names()
LIBRARY = {name: load_mapping(builtin_mapping_path(name)) for name in SEEDS}
IMAGES = every_image()
SUNSPEC = {  # three SunSpec devices: the image, the base of its marker, what its common model says
    "inverter_mppt": (50000, "Three Phase 10k", "INV-0042"),
    "meter": (40000, "Meter 3P", "MTR-7"),
    "battery": (0, "Battery 10", "BAT-2026"),
}
TIMEOUT = 0.3


def bus_of(sim: Simulator, seed: int) -> tuple[dict[str, int], int]:
    """The seeds and the SunSpec devices at random distinct units; a unit nobody holds."""
    rng = random.Random(seed)
    names = [*SEEDS, *SUNSPEC]
    units = rng.sample(range(1, 248), len(names) + 1)
    return dict(zip(names, units, strict=False)), units[-1]


def simulated(placed: dict[str, int]) -> Simulator:
    specs: list[SimulatedUnit | SunSpecUnit] = [
        SimulatedUnit(unit, LIBRARY[name]) for name, unit in placed.items() if name in LIBRARY
    ]
    for name, (base, _, _) in SUNSPEC.items():
        specs.append(SunSpecUnit(placed[name], build_image(IMAGES[name], base, name)))
    sim = Simulator(specs, tick=0.0)
    # the Nastec's Modbus address register reads the address it answers at, as on the device
    sim.set_value(placed["nastec_vasco"], "modbus_address", placed["nastec_vasco"])
    # the ABB B23's type designation reads its model, as on the meter
    sim.set_value(placed["abb_b23"], "type_designation", "B23")
    # the Sungrow inverters' device type code reads their model, as on the inverter
    sim.set_value(placed["sungrow_sh_rt"], "device_type_code", "SH10RT")
    sim.set_value(placed["sungrow_sg_rt"], "device_type_code", "SG10RT")
    # the Stiebel ISG's controller identification reads its WPM model, as on the device
    sim.set_value(placed["stiebel_isg"], "controller_id", "wpm_3i")
    # the Terra AC's 4000h reads its connector type and rated power, as on the charger
    sim.set_value(placed["abb_terra_ac"], "model_code", "type_2_socket_22_kw")
    # the Ethernet EM24's identification code reads its model, as on the meter
    sim.set_value(placed["carlo_gavazzi_em24_e1"], "model_code", "EM24DINAV23XE1X")
    # the Saia ALE3's type rows read its order number, as on the meter
    sim.set_value(placed["saia_ale3"], "type_designation", "ALE3D5FD10C3A0")
    # the Huawei SUN2000's model string reads its model, as on the inverter
    sim.set_value(placed["huawei_sun2000"], "model_name", "SUN2000-5KTL-M1")
    # the Deye hybrid's device type register reads its family's code, as on the inverter
    sim.set_value(placed["deye_hybrid"], "device_type", "lv_three_phase_hybrid")
    # the SolaX X3-Hybrid G4's serial number and machine type read an X3 G4's
    sim.set_value(placed["solax_x3_hybrid"], "serial_number", "H34A10I1234567")
    sim.set_value(placed["solax_x3_hybrid"], "machine_type", "x3")
    # the GoodWe ET's serial number carries its model tag (ETU), as on the inverter
    sim.set_value(placed["goodwe_et"], "serial_number", "95010ETU224W0001")
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
        if name in SUNSPEC:
            base, model, serial = SUNSPEC[name]
            found = identity.sunspec
            assert found is not None and found.note is None, identity.as_dict()
            assert (found.base, found.model, found.serial_number) == (base, model, serial)
            ids = tuple(m["ID"] for m in IMAGES[name]["models"] if m["ID"] != 0xFFFF)
            assert found.models == ids
            assert identity.best == "sunspec"
        else:
            assert identity.sunspec is None
            assert identity.best == name, (name, identity.as_dict())
            assert identity.matches[0].like is not LIBRARY[name].fingerprint.identifies  # type: ignore[union-attr]
    assert sim.writes == []
    per_unit = Counter(unit for unit, _, _ in sim.requests)
    bound = request_bound(LIBRARY)
    assert all(count <= bound for count in per_unit.values()), per_unit
    # scan's probe, the marker at each base up to the device's (with the common model's
    # header), the common model's body (with the next header), the next header after each
    # other model
    for name, (base, _, _) in SUNSPEC.items():
        models = sum(1 for m in IMAGES[name]["models"] if m["ID"] != 0xFFFF)
        assert per_unit[placed[name]] == 1 + BASES.index(base) + 1 + 1 + models - 1
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
async def test_a_sunspec_marker_with_a_broken_chain_is_told_with_a_note() -> None:
    """The marker at 50000, then a model 1 whose length runs past register 65535: a
    SunSpec device all the same, the walk's complaint as its note, nothing written."""
    image = DeviceImage(50000, (0x5375, 0x6E53, 1, 0xFF00, 0, 0))
    sim = Simulator([SunSpecUnit(5, image)], tick=0.0)
    async with serving_tcp(sim) as port:
        bus = TcpBus(id="t", transport="tcp", host="127.0.0.1", tcp_port=port, timeout=TIMEOUT)
        async with open_bus(bus) as submit:
            identity = await identify_unit(submit, 5, LIBRARY, TIMEOUT, "t")
    assert identity is not None and identity.best == "sunspec"
    assert identity.sunspec is not None and identity.sunspec.base == 50000
    assert "runs past register 65535" in (identity.sunspec.note or "")
    assert identity.requests == 1 + 2  # the probe, 40000 refused, 50000's marker and header
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
    assert identity.requests == 2  # the probe, then the SunSpec marker's read unanswered
    assert identity.note == "stopped: the SunSpec marker's read went unanswered"
    assert identity.matches == ()
    assert sim.writes == []
