"""SunSpec devices on the simulator, over loopback TCP and RTU on a pty pair: the bridge's
walk finds the chain and common model pysunspec2's own Modbus client finds on the same
bus, and every point pysunspec2 reads back is the image's value.

Five devices share one bus: pysunspec2's test devices (the 1547 DER models 701-713, an
inverter with model 129's curves) and three built from the model definitions (an inverter
with four MPPTs in model 160, a meter of model 203, a battery of models 124 and 802),
their markers at 40000, 50000 and 0. pysunspec2 talks Modbus with its own client (its
sockets, its serial port, its framing), so it is an independent reader of the same wire.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest
from sunspec2.modbus import client as ss_client
from sunspec2.modbus import modbus as ss_modbus

from bridge.config import SerialBus, TcpBus
from bridge.core.entity import Table
from bridge.core.request import Read
from bridge.errors import DeviceExceptionError
from bridge.modbus.commission import Submit, open_bus
from bridge.modbus.simulator import Simulator, SunSpecUnit
from bridge.sunspec.image import DeviceImage, build_image
from bridge.sunspec.walk import Chain, walk
from tests.integration.harness import serving_serial, serving_tcp
from tests.sunspec_devices import comparable, every_image, expected_values, mismatches

IMAGES = every_image()
PLACES = {  # unit: (image, base)
    1: ("device_1547", 40000),
    2: ("inverter_123", 50000),
    3: ("inverter_mppt", 0),
    4: ("meter", 40000),
    5: ("battery", 50000),
}
BAUD = 19200


def built() -> dict[int, DeviceImage]:
    return {unit: build_image(IMAGES[name], base, name) for unit, (name, base) in PLACES.items()}


def bus_simulator(images: dict[int, DeviceImage]) -> Simulator:
    return Simulator([SunSpecUnit(unit, image) for unit, image in images.items()], tick=0)


def tcp_bus(port: int) -> TcpBus:
    return TcpBus(id="tcp", transport="tcp", host="127.0.0.1", tcp_port=port, timeout=1.0)


def reader(submit: Submit, unit: int) -> Callable[[int, int], Any]:
    async def read(address: int, count: int) -> tuple[int, ...]:
        return await submit(unit, Read(Table.HOLDING, address, count), 1.0)

    return read


def in_memory(registers: dict[int, int]) -> Callable[[int, int], Any]:
    async def read(address: int, count: int) -> list[int]:
        if not all(a in registers for a in range(address, address + count)):
            raise DeviceExceptionError(2, "illegal data address", "fail")
        return [registers[a] for a in range(address, address + count)]

    return read


def check_against_reference(chain: Chain, reference: Any, unit: int) -> None:
    """The walk's chain and common model are pysunspec2's; every model's values are the
    image's."""
    assert chain.base == reference.base_addr == PLACES[unit][1]
    assert [(m.id, m.address, m.length) for m in chain.models] == [
        (m.model_id, m.model_addr, m.model_len) for m in reference.model_list
    ]
    common = reference.common[0]
    assert chain.common is not None
    assert (chain.common.manufacturer, chain.common.model, chain.common.serial_number) == (
        common.Mn.value,
        common.Md.value,
        common.SN.value,
    )
    assert (chain.common.version, chain.common.options, chain.common.device_address) == (
        common.Vr.value,
        common.Opt.value,
        common.DA.value,
    )
    for model in reference.model_list:
        assert not model.error_info, model.error_info
    read_back = [comparable(m.get_dict()) for m in reference.model_list]
    image = IMAGES[PLACES[unit][0]]
    expected = [comparable(v) for v in expected_values(image)]
    assert read_back == expected
    given = [m for m in image["models"] if m["ID"] != 0xFFFF]
    assert mismatches(given, read_back) == []
    assert any(v is not None for m in read_back for k, v in m.items() if k not in {"ID", "L"})


def scan_tcp(port: int, unit: int) -> Any:
    device = ss_client.SunSpecModbusClientDeviceTCP(
        slave_id=unit, ipaddr="127.0.0.1", ipport=port, timeout=2
    )
    try:
        device.scan()
    finally:
        device.disconnect()
    return device


def scan_rtu(port: str, unit: int) -> Any:
    device = ss_client.SunSpecModbusClientDeviceRTU(unit, port, baudrate=BAUD, timeout=2)
    try:
        device.open()
        device.scan()
    finally:
        device.client.close()
        device.close()
        ss_modbus.modbus_rtu_client_remove(port)
    return device


async def walk_every_unit(sim: Simulator, submit: Submit) -> dict[int, Chain]:
    chains = {}
    for unit in PLACES:
        sim.requests.clear()
        chains[unit] = await walk(reader(submit, unit))
        assert len(sim.requests) == chains[unit].requests
    return chains


@pytest.mark.asyncio
async def test_over_tcp_the_walk_and_pysunspec2_read_the_same_devices() -> None:
    sim = bus_simulator(built())
    async with serving_tcp(sim) as port:
        async with open_bus(tcp_bus(port)) as submit:
            chains = await walk_every_unit(sim, submit)
        for unit in PLACES:
            reference = await asyncio.to_thread(scan_tcp, port, unit)
            check_against_reference(chains[unit], reference, unit)
    assert chains[3].model_ids == (1, 103, 120, 160)
    assert chains[4].model_ids == (1, 203)
    assert chains[5].model_ids == (1, 124, 802)
    assert chains[1].model_ids == (1, *range(701, 714))


@pytest.mark.asyncio
async def test_over_rtu_on_a_pty_the_walk_and_pysunspec2_read_the_same_devices() -> None:
    sim = bus_simulator(built())
    async with serving_serial(sim, baudrate=BAUD) as port:
        bus = SerialBus(id="rs485", transport="rtu", port=port, baudrate=BAUD, timeout=1.0)
        async with open_bus(bus) as submit:
            chains = await walk_every_unit(sim, submit)
        for unit in PLACES:
            reference = await asyncio.to_thread(scan_rtu, port, unit)
            check_against_reference(chains[unit], reference, unit)


@pytest.mark.asyncio
async def test_over_rtu_over_tcp_the_walk_finds_what_it_finds_in_the_registers() -> None:
    """pysunspec2 has no RTU over TCP: the reference is the walk of the same registers in
    memory (tests/unit/test_sunspec_walk.py checks that one against pysunspec2's scan)."""
    images = built()
    sim = bus_simulator(images)
    bus = TcpBus(id="t", transport="rtu-over-tcp", host="127.0.0.1", tcp_port=1, timeout=1.0)
    async with (
        serving_tcp(sim, "rtu") as port,
        open_bus(bus.model_copy(update={"tcp_port": port})) as submit,
    ):
        chains = await walk_every_unit(sim, submit)
    for unit, image in images.items():
        assert chains[unit] == await walk(in_memory(image.registers))
        assert chains[unit].base == PLACES[unit][1]


@pytest.mark.asyncio
async def test_reads_outside_the_image_are_refused_like_a_device_refuses_them() -> None:
    images = built()
    sim = bus_simulator(images)
    meter = images[4]
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        whole = await submit(4, Read(Table.HOLDING, meter.base, 100), 1.0)
        assert list(whole) == list(meter.words[:100])
        last = meter.base + len(meter.words) - 1
        assert await submit(4, Read(Table.HOLDING, last, 1), 1.0) == (0,)  # the end's L
        for address, count in ((meter.base - 1, 2), (last, 2), (1000, 1)):
            with pytest.raises(DeviceExceptionError) as refused:
                await submit(4, Read(Table.HOLDING, address, count), 1.0)
            assert refused.value.code == 2
        with pytest.raises(DeviceExceptionError) as wrong_table:
            await submit(4, Read(Table.INPUT, meter.base, 2), 1.0)
        assert wrong_table.value.code == 1


@pytest.mark.asyncio
async def test_a_register_set_by_the_test_is_what_the_next_read_answers() -> None:
    images = built()
    sim = bus_simulator(images)
    meter = images[4]
    at = meter.base + 10
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        sim.set_registers(4, {at: 0x1234, at + 1: 0})
        assert await submit(4, Read(Table.HOLDING, at, 2), 1.0) == (0x1234, 0)
    for bad, message in (({meter.base - 1: 1}, "outside"), ({at: 0x10000}, "16-bit")):
        with pytest.raises(ValueError, match=message):
            sim.set_registers(4, bad)
    with pytest.raises(KeyError, match="unit 9 is not a SunSpec unit"):
        sim.set_registers(9, {at: 1})


def test_unit_ids_stay_unique_across_mapping_and_sunspec_units() -> None:
    image = built()[4]
    with pytest.raises(ValueError, match="unique"):
        Simulator([SunSpecUnit(4, image), SunSpecUnit(4, image)])
    with pytest.raises(ValueError, match=r"outside 0\.\.255"):
        Simulator([SunSpecUnit(300, image)])
