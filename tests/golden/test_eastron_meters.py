"""Golden frames of the Eastron SDM630 and SDM120 mappings (SDM630 protocol V1.8, 1.1-1.2).

The document's own example (Amps 1: start 0006, 2 registers; Amps 2: start 0008) is built
from the mapping's points, its CRC checked against CRC-16/MODBUS computed here; replies
holding IEEE 754 floats decode to their values, a NaN to null; every planned read is an
even count from an even address within 80 registers (1.1: an odd count is refused), and
every entity's comment names the document's 3X register number for its wire address.
"""

from __future__ import annotations

import re

import pytest

from bridge.core.codec import encode
from bridge.core.entity import Table
from bridge.core.mapping import builtin_mapping_path
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Read
from bridge.modbus.frame import build_frame
from tests.golden.frames import decoded, hexbytes, image_from, read_of, shipped

SDM630 = shipped("eastron_sdm630")
POINTS = SDM630.points()
METERS = ["eastron_sdm630", "eastron_sdm120"]


def crc16_modbus(data: bytes) -> bytes:
    """CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF), low byte first."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc.to_bytes(2, "little")


def with_crc(text: str) -> bytes:
    body = hexbytes(text)
    return body + crc16_modbus(body)


@pytest.mark.parametrize(("key", "start"), [("current_l1", 0x0006), ("current_l2", 0x0008)])
def test_the_documents_example_requests(key: str, start: int) -> None:
    read = read_of(POINTS, key)
    assert read == Read(Table.INPUT, start, 2)
    assert build_frame(read, 1) == with_crc(f"01 04 00 {start:02X} 00 02")


@pytest.mark.parametrize(
    ("key", "words", "value"),
    [
        ("voltage_l1", "43 66 00 00", 230.0),
        ("frequency", "42 48 00 00", 50.0),
        ("power", "C5 1C 40 00", -2500.0),  # exporting
        ("energy_import", "47 C3 50 00", 100000.0),
        ("power_factor", "3F 40 00 00", 0.75),
        ("voltage_l1", "7F C0 00 00", None),  # NaN: unknown
    ],
)
def test_float_replies_decode(key: str, words: str, value: float | None) -> None:
    read = read_of(POINTS, key)
    reply = with_crc(f"01 04 04 {words}")
    assert decoded(POINTS, key, image_from(read, reply)) == value


@pytest.mark.parametrize("name", METERS)
def test_every_planned_read_is_even_and_within_80_registers(name: str) -> None:
    mapping = shipped(name)
    limits = limits_for(mapping)
    plan = plan_reads(mapping.points().values(), limits)
    assert plan.unplannable == ()
    for read in plan.reads:
        assert read.address % 2 == 0 and read.count % 2 == 0, read
        assert read.count <= mapping.protocol.max_read_registers <= 80, read


@pytest.mark.parametrize("name", METERS)
def test_every_comment_names_the_documents_register_number(name: str) -> None:
    text = builtin_mapping_path(name).read_text(encoding="utf-8")
    rows = re.findall(r"address: 0x([0-9A-F]{4})  # (\d{5})", text)
    mapping = shipped(name)
    assert len(rows) == len(mapping.entities)
    for wire, printed in rows:
        base = 30001 if printed.startswith("3") else 40001
        assert int(wire, 16) + base == int(printed), (wire, printed)


def test_the_demand_period_is_written_with_fc16_as_a_float() -> None:
    """1.3: "Each parameter is held in two consecutive 4X registers ... Function Code 16 is
    used to write"; 15 minutes is the float 0x41700000."""
    point = POINTS["demand_period"]
    assert not point.entity.dangerous
    (write,) = encode(point, 15, {})
    assert build_frame(write, 1) == with_crc("01 10 00 02 00 02 04 41 70 00 00")
