"""Golden frames of the soft-starter controller (document soft_starter.md §6).

The manual prints no frame with a CRC: S1/S2 instantiate its frame-format example and
D1-D12 are the document's derived fixtures (CRC16/Modbus computed, slave address 1).
Requests are built from the mapping's points, never from hard-coded wire addresses.
Responses marked "derived here" are not in the document: they are the device's
documented reply layout (§2.3) filled with example values, CRC computed the same way.
"""

from __future__ import annotations

import itertools

import pytest

from bridge.core.codec import decode, encode
from bridge.core.entity import Table
from bridge.core.request import Read, Write
from bridge.errors import ValueRejectedError
from bridge.modbus.frame import FrameError, build_frame, exception_code, parse_frame
from tests.golden.frames import decoded, hexbytes, image_from, read_of, request_frame, shipped

MAPPING = shipped("soft_starter")
POINTS = MAPPING.points()


def _image(*pairs: tuple[str, int]) -> dict[tuple[Table, int], int]:
    """Register image holding ``raw`` at the wire address of each named point."""
    return {(POINTS[key].table, POINTS[key].address): raw for key, raw in pairs}


# --- reads: request bytes from the mapping ------------------------------------------------

READS = [
    # id, keys covered by the read, documented request
    ("S1", ("soft_start_mode",), "01 03 10 01 00 01 D1 0A"),
    (
        "D4",
        (
            "phase_u_current",
            "phase_v_current",
            "phase_w_current",
            "leakage_resistance",
            "voltage",
            "fault_status",
        ),
        "01 03 10 31 00 06 90 C7",
    ),
    ("D5", ("fault_status",), "01 03 10 36 00 01 60 C4"),
    ("D6", ("motor_run",), "01 03 10 30 00 01 80 C5"),
    ("D7", ("control_mode",), "01 03 10 19 00 01 51 0D"),
]


@pytest.mark.parametrize(("keys", "frame"), [r[1:] for r in READS], ids=[r[0] for r in READS])
def test_read_requests(keys: tuple[str, ...], frame: str) -> None:
    read = read_of(POINTS, *keys)
    assert read.count <= MAPPING.protocol.max_read_registers
    assert request_frame(read) == hexbytes(frame)


# Replies derived here (documented layout, example values, CRC16/Modbus computed).
REPLIES = [
    # id, keys, reply, expected values
    ("S1-reply", ("soft_start_mode",), "01 03 02 00 01 79 84", {"soft_start_mode": "ramp"}),
    (
        "D4-reply",
        (
            "phase_u_current",
            "phase_v_current",
            "phase_w_current",
            "leakage_resistance",
            "voltage",
            "fault_status",
        ),
        "01 03 0C 00 0C 00 0D 00 0C 01 F4 01 7C 00 00 48 90",
        {
            "phase_u_current": 12,
            "phase_v_current": 13,
            "phase_w_current": 12,
            "leakage_resistance": 500,
            "voltage": 380,
            "fault_status": "no_fault",
            "fault": False,
        },
    ),
    (
        "D5-reply",
        ("fault_status",),
        "01 03 02 00 0E 39 80",
        {"fault_status": "communication_error", "fault": True},
    ),
    ("D6-reply", ("motor_run",), "01 03 02 00 01 79 84", {"motor_run": True}),
    ("D7-reply", ("control_mode",), "01 03 02 00 02 39 85", {"control_mode": "communication"}),
    (
        "run-time-reply",
        ("current_run_time",),
        "01 03 04 00 1E 00 05 5A 36",
        {"current_run_time": 5 * 60 + 30},
    ),
]


@pytest.mark.parametrize(
    ("keys", "reply", "expected"), [r[1:] for r in REPLIES], ids=[r[0] for r in REPLIES]
)
def test_read_replies_decode(
    keys: tuple[str, ...], reply: str, expected: dict[str, object]
) -> None:
    image = image_from(read_of(POINTS, *keys), hexbytes(reply))
    assert {key: decoded(POINTS, key, image) for key in expected} == expected


def test_run_time_request_reads_minutes_then_hours() -> None:
    read = read_of(POINTS, "current_run_time")
    assert request_frame(read) == hexbytes("01 03 10 2A 00 02 E1 03")
    assert read_of(POINTS, "cumulative_run_time").address == read.address + 2


# --- writes: encode through the mapping, then frame ---------------------------------------

WRITES = [
    # id, key, value, image before the write, documented frame
    ("S2", "soft_start_mode", "ramp", {}, "01 06 10 01 00 01 1D 0A"),
    ("D1", "motor_run", True, {"motor_run": 0}, "01 06 10 30 00 01 4C C5"),
    ("D2", "motor_run", False, {"motor_run": 1}, "01 06 10 30 00 00 8D 05"),
    ("D3", "fault_reset", "PRESS", {}, "01 06 10 2E 00 00 ED 03"),
    ("D8", "control_mode", "communication", {}, "01 06 10 19 00 02 DD 0C"),
    ("D12", "factory_reset", "PRESS", {}, "01 06 10 2F 00 00 BC C3"),
]


@pytest.mark.parametrize(
    ("key", "value", "before", "frame"), [w[1:] for w in WRITES], ids=[w[0] for w in WRITES]
)
def test_write_frames(key: str, value: object, before: dict[str, int], frame: str) -> None:
    writes = encode(POINTS[key], value, _image(*before.items()))
    assert len(writes) == 1
    assert writes[0].function == 6  # FC06: the device range-checks it, FC16 does not
    assert build_frame(writes[0], 1) == hexbytes(frame)


def test_s2_reply_is_an_echo() -> None:
    reply = parse_frame(hexbytes("01 06 10 01 00 01 1D 0A"))
    assert (reply.function_code, reply.address, reply.registers) == (6, 0x1001, [1])
    assert reply.address == POINTS["soft_start_mode"].address


def test_guarded_writes_are_dangerous() -> None:
    dangerous = {key for key, point in POINTS.items() if point.entity.dangerous}
    assert {"control_mode", "factory_reset", "clear_cumulative_run_time"} <= dangerous
    assert {"start_control", "bypass_output", "rated_current", "overload_threshold"} <= dangerous
    assert not POINTS["motor_run"].entity.dangerous
    assert not POINTS["fault_reset"].entity.dangerous
    assert not POINTS["factory_reset"].entity.idempotent


def test_device_range_is_checked_before_the_wire() -> None:
    with pytest.raises(ValueRejectedError):
        encode(POINTS["overload_threshold"], 250, {})
    with pytest.raises(ValueRejectedError):
        encode(POINTS["control_mode"], "remote", {})


# --- exception replies (D9-D11) -----------------------------------------------------------

EXCEPTIONS = [
    # id, reply, function code of the reply, exception code, bridge action
    ("D9", "01 83 02 C0 F1", 0x83, 2, "refused"),
    ("D10", "01 83 04 40 F3", 0x83, 4, "retry"),
    ("D11", "01 86 03 02 61", 0x86, 3, "refused"),
]


@pytest.mark.parametrize(
    ("reply", "function", "code", "action"),
    [e[1:] for e in EXCEPTIONS],
    ids=[e[0] for e in EXCEPTIONS],
)
def test_exception_replies(reply: str, function: int, code: int, action: str) -> None:
    pdu = parse_frame(hexbytes(reply))
    assert pdu.function_code == function
    assert exception_code(pdu) == code
    assert MAPPING.protocol.exceptions[code].action == action


def test_exception_reply_carries_no_values() -> None:
    read = read_of(POINTS, "fault_status")
    with pytest.raises(FrameError):
        image_from(read, hexbytes("01 83 02 C0 F1"))


@pytest.mark.parametrize(
    "frame", ["01 03 10 01 00 01 D1 0B", "01 83 04 40 F4"], ids=["S1-bad-crc", "D10-bad-crc"]
)
def test_corrupted_crc_is_rejected(frame: str) -> None:
    with pytest.raises(FrameError):
        parse_frame(hexbytes(frame), response=not frame.startswith("01 03 10"))


# --- protocol rules -----------------------------------------------------------------------


def test_protocol_rules() -> None:
    protocol = MAPPING.protocol
    assert protocol.function_codes == (3, 6, 16)
    assert protocol.max_read_registers == 6
    assert not protocol.readable_gaps
    assert set(protocol.exceptions) == {1, 2, 3, 4}
    assert (protocol.serial.baudrate, protocol.serial.parity, protocol.serial.stopbits) == (
        9600,
        "N",
        2,
    )
    assert protocol.keepalive is not None and protocol.keepalive.interval < 60
    reserved = protocol.reserved[0]
    assert (reserved.start, reserved.end) == (0x1026, 0x1029)
    assert MAPPING.status == "fault_status"


def test_every_register_is_mapped() -> None:
    """0x1001-0x1036: every address is an entity or reserved (document §3)."""
    covered: set[int] = set()
    for mapping_options in _option_combinations():
        for point in MAPPING.points(mapping_options).values():
            covered.update(point.span)
    reserved = set(range(0x1026, 0x102A))
    assert covered | reserved == set(range(0x1001, 0x1037))
    assert not covered & reserved


def test_fault_codes() -> None:
    entity = POINTS["fault_status"].entity
    assert entity.alarm and entity.normal == (0,)
    assert sorted(entity.enum or {}) == list(range(15))


# --- derived views ------------------------------------------------------------------------

PROTECTIONS = [
    # id, protection view, raw threshold, enabled. The seed's 以下 ("below") and 以上 ("above")
    # include the number itself: the printed boundary value switches the protection off.
    ("overvoltage-0", "overvoltage_protection", 0, False),
    ("overvoltage-100", "overvoltage_protection", 100, False),  # "100 以下为关闭"
    ("overvoltage-101", "overvoltage_protection", 101, True),
    ("overvoltage-150", "overvoltage_protection", 150, True),
    ("undervoltage-0", "undervoltage_protection", 0, True),
    ("undervoltage-99", "undervoltage_protection", 99, True),
    ("undervoltage-100", "undervoltage_protection", 100, False),  # "100 以上为关闭"
    ("overload-100", "overload_protection", 100, False),
    ("overload-110", "overload_protection", 110, False),  # "110 以下为关闭"
    ("overload-111", "overload_protection", 111, True),
    ("overload-200", "overload_protection", 200, True),
    ("undercurrent-30", "undercurrent_protection", 30, True),
    ("undercurrent-89", "undercurrent_protection", 89, True),
    ("undercurrent-90", "undercurrent_protection", 90, False),  # "90 以上为关闭"
    ("undercurrent-100", "undercurrent_protection", 100, False),
    ("imbalance-0", "current_imbalance_protection", 0, False),
    ("imbalance-10", "current_imbalance_protection", 10, False),  # "10 以下为关闭"
    ("imbalance-11", "current_imbalance_protection", 11, True),
    ("imbalance-60", "current_imbalance_protection", 60, True),
]


@pytest.mark.parametrize(
    ("key", "raw", "enabled"), [p[1:] for p in PROTECTIONS], ids=[p[0] for p in PROTECTIONS]
)
def test_protection_enabled_views(key: str, raw: int, enabled: bool) -> None:
    assert decoded(POINTS, key, _image((key, raw))) is enabled


def test_run_time_clear_buttons() -> None:
    for key in ("clear_current_run_time", "clear_cumulative_run_time"):
        point = POINTS[key]
        (write,) = encode(point, "PRESS", {})
        assert write == Write(16, Table.HOLDING, point.address, (0, 0))
        assert len(write.values) <= MAPPING.protocol.max_write_registers
    (write,) = encode(POINTS["clear_current_run_time"], "PRESS", {})
    assert build_frame(write, 1) == hexbytes("01 10 10 2A 00 02 04 00 00 00 00 BC 08")


def test_separate_run_time_option() -> None:
    points = MAPPING.points({"run_time_format": "separate"})
    assert "current_run_time" not in points
    image = {(Table.HOLDING, 0x102A): 30, (Table.HOLDING, 0x102B): 5}
    assert decode(points["current_run_minutes"], image) == 30
    assert decode(points["current_run_hours"], image) == 5


def test_kick_time_option() -> None:
    image = _image(("kick_start_time", 25))
    assert decoded(POINTS, "kick_start_time", image) == 25
    tenths = MAPPING.points({"kick_time_scale": "0.1 s"})
    assert decode(tenths["kick_start_time"], image) == 2.5
    (write,) = encode(tenths["kick_start_time"], 2.5, image)
    assert write.values == (25,)


@pytest.mark.parametrize(
    ("option", "limits", "step", "top", "beyond"),
    [("1 s", (0, 50), 1, 50, 51), ("0.1 s", (0, 5.0), 0.1, 5.0, 5.1)],
)
def test_kick_time_range_is_the_printed_0_50_in_register_units(
    option: str, limits: tuple[float, float], step: float, top: float, beyond: float
) -> None:
    """Seed row 0x100C "0~50": 0-50 raw, i.e. 0-5.0 s when the register counts 0.1 s."""
    point = MAPPING.points({"kick_time_scale": option})["kick_start_time"]
    assert (point.entity.min, point.entity.max, point.entity.step) == (*limits, step)
    assert encode(point, top, {})[0].values == (50,)
    with pytest.raises(ValueRejectedError, match="outside"):
        encode(point, beyond, {})


def test_current_limit_option() -> None:
    percent = MAPPING.points({"current_limit_unit": "%"})["starting_current_limit"].entity
    assert percent.unit == "%" and percent.ha.device_class is None
    assert POINTS["starting_current_limit"].entity.unit == "A"


# --- every option combination loads and every button encodes ------------------------------


def _option_combinations() -> list[dict[str, str]]:
    names = list(MAPPING.options)
    choices = [MAPPING.options[name].choices for name in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*choices)]


@pytest.mark.parametrize(
    "options", _option_combinations(), ids=lambda o: "/".join(o.values()).replace(" ", "")
)
def test_option_combinations_load_and_buttons_encode(options: dict[str, str]) -> None:
    points = MAPPING.points(options)
    for point in points.values():
        if point.entity.press is not None:
            assert encode(point, "PRESS", {})
        if point.entity.readable:
            read = Read(point.table, point.address, point.count)
            assert read.count <= MAPPING.protocol.max_read_registers
