"""Golden frames of the ABB B23/B24 mapping (User Manual 2CMC485003M0201 rev. A, chapter 9).

Requests are function 3 at the start register printed in the tables (sent as is); replies
hold integers most significant register first, at the tables' resolutions; a quantity the
meter does not have reads all 0xFFFF (unsigned) or 0x7FFF then 0xFFFF (signed): null.
"""

from __future__ import annotations

import pytest

from bridge.core.entity import Table
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Read
from bridge.modbus.frame import build_frame
from tests.golden.frames import decoded, image_from, read_of, shipped
from tests.golden.test_eastron_meters import with_crc

B23 = shipped("abb_b23")
POINTS = B23.points()


@pytest.mark.parametrize(
    ("key", "start", "count"),
    [("energy_import", 0x5000, 4), ("voltage_l1", 0x5B00, 2), ("frequency", 0x5B2C, 1)],
)
def test_requests_are_function_3_at_the_printed_register(key: str, start: int, count: int) -> None:
    read = read_of(POINTS, key)
    assert read == Read(Table.HOLDING, start, count)
    assert build_frame(read, 1) == with_crc(f"01 03 {start:04X} {count:04X}")


@pytest.mark.parametrize(
    ("key", "words", "value"),
    [
        ("energy_import", "00 00 00 00 00 12 D6 87", 12345.67),  # 0.01 kWh
        ("voltage_l1", "00 00 08 FC", 230.0),  # 0.1 V
        ("current_l1", "00 00 02 8A", 6.5),  # 0.01 A
        ("power", "FF FC 2F 70", -2500.0),  # 0.01 W, exporting
        ("frequency", "13 88", 50.0),  # 0.01 Hz
        ("power_factor", "FC 18", -1.0),  # 0.001
        ("energy_export", "FF FF FF FF FF FF FF FF", None),  # not available
        ("voltage_l2", "FF FF FF FF", None),
        ("power_l3", "7F FF FF FF", None),
        ("power_factor_l3", "7F FF", None),
        ("frequency", "FF FF", None),
    ],
)
def test_integer_replies_decode(key: str, words: str, value: float | None) -> None:
    read = read_of(POINTS, key)
    size = len(bytes.fromhex(words))
    reply = with_crc(f"01 03 {size:02X} {words}")
    got = decoded(POINTS, key, image_from(read, reply))
    assert got == (value if value is None else pytest.approx(value))


def test_every_planned_read_stays_within_125_registers_and_holding() -> None:
    plan = plan_reads(B23.points().values(), limits_for(B23))
    assert plan.unplannable == ()
    for read in plan.reads:
        assert read.table is Table.HOLDING and read.count <= 125, read
