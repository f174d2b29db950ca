"""The SunSpec walk against in-memory register images (a pure function of its reads):
the same chain and common model pysunspec2's own scan finds in the same registers, its
requests counted, and bounded on malformed chains."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sunspec2.modbus import client as ss_client
from sunspec2.modbus import modbus as ss_modbus

from bridge.errors import (
    DeviceExceptionError,
    DeviceTimeoutError,
    NotSunSpecError,
    SunSpecChainError,
)
from bridge.sunspec.image import DeviceImageError, build_image
from bridge.sunspec.models import load_model
from bridge.sunspec.walk import (
    END,
    MARKER,
    Chain,
    ChainModel,
    WalkLimits,
    request_bound,
    text,
    walk,
)
from tests.sunspec_devices import every_image


class Registers:
    """Holding registers in memory: a read of any absent register is refused (02), as a
    device refuses it; every read is logged."""

    def __init__(self, registers: dict[int, int], silent: bool = False) -> None:
        self.registers = registers
        self.silent = silent
        self.reads: list[tuple[int, int]] = []

    async def read(self, address: int, count: int) -> list[int]:
        self.reads.append((address, count))
        if self.silent:
            raise DeviceTimeoutError("no answer")
        span = range(address, address + count)
        if any(a not in self.registers for a in span):
            raise DeviceExceptionError(2, "illegal data address", "fail")
        return [self.registers[a] for a in span]


class Reference(ss_client.SunSpecModbusClientDevice):
    """pysunspec2's scan over the same registers."""

    def __init__(self, registers: dict[int, int]) -> None:
        super().__init__()
        self.registers = registers

    def read(self, addr: float, count: float, op: Any = None) -> bytes:
        span = range(int(addr), int(addr + count))  # pysunspec2 passes floats at times
        if any(a not in self.registers for a in span):
            raise ss_modbus.ModbusClientException("illegal data address")
        return b"".join(self.registers[a].to_bytes(2, "big") for a in span)


def run(registers: Registers, **kwargs: Any) -> Chain:
    return asyncio.run(walk(registers.read, **kwargs))


def chain_registers(base: int, models: list[tuple[int, int]], end: bool = True) -> dict[int, int]:
    """A marker at ``base`` and models of (id, length) with zero bodies, then the end."""
    words = list(MARKER)
    for model_id, length in models:
        words += [model_id, length] + [0] * length
    if end:
        words += [END, 0]
    return {base + i: w for i, w in enumerate(words)}


IMAGES = every_image()


@pytest.mark.parametrize("name", sorted(IMAGES))
@pytest.mark.parametrize("base", [40000, 50000, 0])
def test_the_chain_and_common_model_are_pysunspec2_s(name: str, base: int) -> None:
    registers = build_image(IMAGES[name], base).registers
    chain = run(Registers(registers))
    reference = Reference(registers)
    reference.scan()
    assert chain.base == reference.base_addr == base
    assert [(m.id, m.address, m.length) for m in chain.models] == [
        (m.model_id, m.model_addr, m.model_len) for m in reference.model_list
    ]
    common = reference.common[0]
    assert chain.common is not None
    assert (
        chain.common.manufacturer,
        chain.common.model,
        chain.common.options,
        chain.common.version,
        chain.common.serial_number,
        chain.common.device_address,
    ) == (
        common.Mn.value,
        common.Md.value,
        common.Opt.value,
        common.Vr.value,
        common.SN.value,
        common.DA.value,
    )
    tried = [40000, 50000, 0].index(base) + 1
    assert chain.requests == tried + len(chain.models)


def test_requests_stay_within_the_read_limit() -> None:
    registers = build_image(IMAGES["device_1547"], 40000).registers
    bus = Registers(registers)
    small = asyncio.run(walk(bus.read, limits=WalkLimits(read_limit=8)))
    assert all(count <= 8 for _, count in bus.reads)
    assert small.models == run(Registers(registers)).models
    # the marker, model 1's 66 registers in 9 reads, then one header per model
    assert small.requests == len(bus.reads) == 1 + 9 + len(small.models)


def test_a_configured_base_is_the_only_one_read() -> None:
    registers = chain_registers(1000, [(1, 66), (103, 50)])
    bus = Registers(registers)
    chain = asyncio.run(walk(bus.read, bases=(1000,)))
    assert chain.base == 1000
    assert chain.model_ids == (1, 103)
    assert chain.models[1] == ChainModel(103, 1070, 50)
    assert chain.models[1].end == 1122
    with pytest.raises(NotSunSpecError, match="no SunSpec marker at 40000, 50000, 0"):
        run(Registers(registers))


def test_no_marker_is_not_sunspec_after_one_request_per_base() -> None:
    registers = dict.fromkeys(range(10), 0) | dict.fromkeys(range(40000, 40010), 0x1234)
    bus = Registers(registers)
    with pytest.raises(NotSunSpecError, match=r"\(3 requests\)"):
        run(bus)
    assert bus.reads == [(40000, 4), (50000, 4), (0, 4)]


def test_a_silent_unit_costs_one_request() -> None:
    bus = Registers({}, silent=True)
    with pytest.raises(DeviceTimeoutError):
        run(bus)
    assert len(bus.reads) == 1


def test_the_common_model_s_unimplemented_points_read_unknown() -> None:
    registers = chain_registers(40000, [(1, 66)])
    registers[40004] = 0x4142  # Mn "AB", the rest NUL
    registers[40004 + 64] = 0xFFFF  # DA unimplemented
    common = run(Registers(registers)).common
    assert common is not None
    assert common.manufacturer == "AB"
    assert (common.model, common.serial_number, common.device_address) == (None, None, None)


def test_a_common_model_longer_than_its_definition_is_read_as_far_as_defined() -> None:
    assert load_model(1).fixed_length == 66
    registers = chain_registers(40000, [(1, 3000), (103, 50)])
    registers[40002 + 50] = 0x5A00  # SN "Z"
    bus = Registers(registers)
    chain = run(bus)
    assert chain.model_ids == (1, 103)
    assert chain.common is not None
    assert chain.common.serial_number == "Z"
    assert bus.reads[:3] == [(40000, 4), (40004, 66), (43004, 2)]


def test_a_legacy_common_model_of_65_registers_is_read() -> None:
    registers = chain_registers(40000, [(1, 65), (101, 50)])
    registers[40004 + 64] = 7
    chain = run(Registers(registers))
    assert chain.model_ids == (1, 101)
    assert chain.common is not None
    assert chain.common.device_address == 7


def test_no_common_model_leaves_it_unknown() -> None:
    chain = run(Registers(chain_registers(40000, [(103, 50)])))
    assert (chain.model_ids, chain.common) == ((103,), None)


def test_an_end_marker_without_its_length_ends_the_chain() -> None:
    registers = chain_registers(40000, [(1, 66), (103, 50)], end=False)
    registers[40000 + 2 + 68 + 52] = END  # the ID alone: its L is refused
    bus = Registers(registers)
    chain = run(bus)
    assert chain.model_ids == (1, 103)
    assert bus.reads[-2:] == [(40122, 2), (40122, 1)]


def test_a_chain_running_past_65535_is_refused() -> None:
    registers = chain_registers(50000, [(1, 66), (103, 20000)])
    with pytest.raises(SunSpecChainError, match="model 103 at 50070, length 20000: runs past"):
        run(Registers(registers))
    # a length that would bring the chain round to its first model (at 2, wrapped): the
    # only loop a chain can make, as addresses only grow
    looping = chain_registers(0, [(1, 66), (64001, 65536 - 70)])
    with pytest.raises(SunSpecChainError, match="runs past register 65535"):
        run(Registers(looping), limits=WalkLimits(max_registers=70_000))


def test_a_model_that_ends_at_65535_has_no_end_marker() -> None:
    registers = chain_registers(65000, [(1, 66), (64001, 65536 - 65070 - 2)], end=False)
    with pytest.raises(SunSpecChainError, match="no end marker"):
        run(Registers(registers), bases=(65000,))


def test_too_many_models_or_registers_are_refused() -> None:
    registers = chain_registers(40000, [(1, 66)] + [(64001, 3)] * 10)
    with pytest.raises(SunSpecChainError, match="more than 5 models"):
        run(Registers(registers), limits=WalkLimits(max_models=5))
    with pytest.raises(SunSpecChainError, match="passes 100 registers"):
        run(Registers(registers), limits=WalkLimits(max_registers=100))
    bus = Registers(registers)
    assert len(asyncio.run(walk(bus.read, limits=WalkLimits(max_models=11))).models) == 11


def test_a_model_id_0_is_a_chain_without_end() -> None:
    registers = chain_registers(40000, [(1, 66), (103, 50)], end=False)
    registers |= {40122: 0, 40123: 0}
    with pytest.raises(SunSpecChainError, match="model id 0 at 40122"):
        run(Registers(registers))


def test_a_read_refused_in_the_chain_is_a_chain_error() -> None:
    registers = chain_registers(40000, [(1, 66), (103, 50)])
    del registers[40100]  # inside model 103: its end is found, the next header is not read
    assert run(Registers(registers)).model_ids == (1, 103)
    del registers[40123]  # the end marker's L and ID both refused
    del registers[40122]
    with pytest.raises(SunSpecChainError, match="a read was refused"):
        run(Registers(registers))


def test_a_short_answer_is_refused() -> None:
    async def short(address: int, count: int) -> list[int]:
        return [*MARKER, 1, 66][:count] if address == 40000 else [0] * (count - 1)

    with pytest.raises(SunSpecChainError, match="68 registers at 40004 answered 67"):
        asyncio.run(walk(short))


def test_bounds_of_the_walk_itself_are_checked() -> None:
    bus = Registers({})
    with pytest.raises(ValueError, match="read_limit 3"):
        asyncio.run(walk(bus.read, limits=WalkLimits(read_limit=3)))
    with pytest.raises(ValueError, match="base 65533"):
        asyncio.run(walk(bus.read, bases=(65533,)))


@pytest.mark.parametrize(
    ("words", "expected"),
    [
        ([0x4142, 0x4300, 0, 0], "ABC"),
        ([0x2041, 0x4220, 0x2020], "AB"),
        ([0, 0x4142], None),
        ([0, 0, 0], None),
        ([0x2020], None),
        ([], None),
    ],
)
def test_strings(words: list[int], expected: str | None) -> None:
    assert text(words) == expected


@settings(max_examples=60, deadline=None)
@given(
    base=st.sampled_from([40000, 50000, 0]),
    models=st.lists(
        st.tuples(st.integers(2, 0xFFFE), st.integers(0, 300)), min_size=0, max_size=12
    ),
    limit=st.integers(4, 125),
)
def test_any_chain_is_walked_exactly(base: int, models: list[tuple[int, int]], limit: int) -> None:
    registers = chain_registers(base, models)
    bus = Registers(registers)
    chain = asyncio.run(walk(bus.read, limits=WalkLimits(read_limit=limit)))
    assert [(m.id, m.length) for m in chain.models] == models
    assert chain.requests == len(bus.reads) == [40000, 50000, 0].index(base) + 1 + len(models)
    assert all(count <= limit for _, count in bus.reads)


@settings(max_examples=80, deadline=None)
@given(
    words=st.lists(st.integers(0, 0xFFFF), min_size=0, max_size=400),
    limit=st.integers(4, 125),
    max_models=st.integers(1, 20),
    refused=st.sets(st.integers(0, 399), max_size=5),
)
def test_whatever_a_device_answers_the_requests_stay_bounded(
    words: list[int], limit: int, max_models: int, refused: set[int]
) -> None:
    """Random registers behind a marker (some refused): the walk ends, with a chain or a
    clear error, within its stated number of requests, each within the read limit."""
    registers = {40000 + i: w for i, w in enumerate([*MARKER, *words]) if i - 2 not in refused}
    bus = Registers(registers)
    limits = WalkLimits(read_limit=limit, max_models=max_models)
    try:
        chain = asyncio.run(walk(bus.read, limits=limits))
    except (NotSunSpecError, SunSpecChainError):
        pass
    else:
        assert len(chain.models) <= max_models
        assert chain.requests == len(bus.reads)
    assert len(bus.reads) <= request_bound(limits=limits)
    assert all(count <= limit for _, count in bus.reads)


def test_an_image_that_does_not_fit_is_refused() -> None:
    with pytest.raises(DeviceImageError, match="registers from 65000"):
        build_image(IMAGES["device_1547"], 65000)
    with pytest.raises(DeviceImageError, match="model 4242"):
        build_image({"models": [{"ID": 4242}]})
    with pytest.raises(DeviceImageError, match="no models"):
        build_image({"name": "x"})
