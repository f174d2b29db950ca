"""Golden frames of the Nastec VASCO / VASCO Solar / MIDA mapping (devices/nastec_vasco.md §6).

G1-G4 are printed in the manual (all four CRCs verify); D1-D9 are derived in the device
document with the same addressing rule (wire = Modbus index - 1). Every request is built
from the mapping's points, never from a hard-coded wire address.
"""

from __future__ import annotations

import itertools

import pytest

from bridge.core.codec import decode, encode, limits_of, unit_of
from bridge.core.entity import Table
from bridge.core.guard import Guard
from bridge.core.mapping import Point
from bridge.core.request import Read, Write
from bridge.errors import ValueRejectedError
from bridge.modbus.frame import FrameError, build_frame, parse_frame
from tests.golden.frames import decoded, hexbytes, image_from, read_of, request_frame, shipped

MAPPING = shipped("nastec_vasco")
POINTS = MAPPING.points()
H = Table.HOLDING

UNIT_BAR = 0  # Unit register (idx 0x58) raw value for "bar"


def word(key: str, raw: int) -> dict[tuple[Table, int], int]:
    """A one-register image entry at the wire address of ``key``."""
    return {(H, POINTS[key].address): raw}


# --- G1-G4: frames printed in the manual --------------------------------------------------


def test_g1_g2_actual_value() -> None:
    read = read_of(POINTS, "actual_value")
    assert request_frame(read) == hexbytes("01 03 00 97 00 01 35 E6")
    image = image_from(read, hexbytes("01 03 02 00 23 F9 9D")) | word("unit", UNIT_BAR)
    assert decoded(POINTS, "actual_value", image) == 3.5
    assert unit_of(POINTS["actual_value"], image) == "bar"


def test_g3_set_value_positive_writes_magnitude_only() -> None:
    image = word("sign_set_value", 0x0000) | word("unit", UNIT_BAR)
    writes = encode(POINTS["set_value"], 4.5, image)
    assert writes == (Write(6, H, POINTS["set_value"].address, (45,)),)
    assert build_frame(writes[0], 1) == hexbytes("01 06 00 33 00 2D B9 D8")


def test_g3_negative_set_value_writes_sign_first() -> None:
    boolean_word_1 = 0x0004  # autorestart ON, every sign positive
    image = word("sign_set_value", boolean_word_1) | word("unit", UNIT_BAR)
    sign_write, magnitude_write = encode(POINTS["set_value"], -4.5, image)
    assert sign_write == Write(6, H, POINTS["sign_set_value"].address, (0x2004,))
    assert build_frame(sign_write, 1) == hexbytes("01 06 00 4B 20 04 E1 DF")
    assert build_frame(magnitude_write, 1) == hexbytes("01 06 00 33 00 2D B9 D8")


def test_g4_write_echo_parses() -> None:
    pdu = parse_frame(hexbytes("01 06 00 33 00 2D B9 D8"))
    assert pdu.function_code == 6
    assert pdu.address == POINTS["set_value"].address
    assert pdu.registers == [45]


def test_crc_bytes_in_printed_order_only() -> None:
    """The manual labels the CRC bytes high/low the wrong way round; the printed order is right."""
    parse_frame(hexbytes("01 03 00 97 00 01 35 E6"), response=False)
    with pytest.raises(FrameError):
        parse_frame(hexbytes("01 03 00 97 00 01 E6 35"), response=False)
    with pytest.raises(FrameError):
        parse_frame(hexbytes("01 03 02 00 23 9D F9"))


# --- D1-D9: derived frames ------------------------------------------------------------------


def _word_read(key: str, offset: int) -> Read:
    point = POINTS[key]
    return Read(point.table, point.address + offset, 1)


@pytest.mark.parametrize(
    ("read", "frame"),
    [
        pytest.param(read_of(POINTS, "status"), "01 03 00 A0 00 01 84 28", id="D1"),
        pytest.param(
            read_of(POINTS, "alarm_motor_overcurrent"), "01 03 00 A1 00 01 D5 E8", id="D2"
        ),
        pytest.param(read_of(POINTS, "unit"), "01 03 00 57 00 01 35 DA", id="D3"),
        pytest.param(read_of(POINTS, "sign_set_value"), "01 03 00 4B 00 01 F4 1C", id="D4"),
        pytest.param(_word_read("electric_life", 0), "01 03 00 AA 00 01 A4 2A", id="D7"),
        pytest.param(_word_read("electric_life", 1), "01 03 00 AB 00 01 F5 EA", id="D8"),
        pytest.param(read_of(POINTS, "electric_life"), "01 03 00 AA 00 02 E4 2B", id="D9"),
    ],
)
def test_derived_reads(read: Read, frame: str) -> None:
    assert request_frame(read) == hexbytes(frame)


@pytest.mark.parametrize(
    ("value", "frame"),
    [
        pytest.param(True, "01 06 00 32 00 01 E9 C5", id="D5-start"),
        pytest.param(False, "01 06 00 32 00 00 28 05", id="D6-stop"),
    ],
)
def test_start_stop(value: bool, frame: str) -> None:
    (write,) = encode(POINTS["start_stop"], value, {})  # a whole 0/1 word: no read needed
    assert build_frame(write, 1) == hexbytes(frame)


# --- decoding the registers the frames read --------------------------------------------------


@pytest.mark.parametrize(
    ("raw", "state", "combo"),
    [
        pytest.param(0x0000, "off", False, id="off"),
        pytest.param(0x0006, "running", False, id="running"),
        pytest.param(0x0086, "running", True, id="running-combo"),
        pytest.param(0x0003, "no_water", False, id="no-water"),
        pytest.param(0x008A, "stopping_digital_input", True, id="soft-stop-di-combo"),
        pytest.param(0x000B, "code_11", False, id="undefined-11"),
    ],
)
def test_status_byte(raw: int, state: str | None, combo: bool) -> None:
    image = word("status", raw)
    assert MAPPING.status == "status"
    assert decoded(POINTS, "status", image) == state
    assert decoded(POINTS, "combo_mode", image) is combo


def test_alarm_word_bits() -> None:
    alarms = {k: p for k, p in POINTS.items() if p.entity.alarm}
    assert len(alarms) == 16
    assert {p.entity.bit for p in alarms.values()} == set(range(16))
    image = word("alarm_motor_overcurrent", 0x8009)  # bits 0, 3, 15
    active = {k for k, p in alarms.items() if decode(p, image)}
    assert active == {"alarm_motor_overcurrent", "alarm_dry_running", "alarm_cpu"}


@pytest.mark.parametrize(
    ("raw", "label"),
    [(0, "motor_overcurrent"), (9, "igbt_trip"), (15, "cpu_alarm"), (0xFFFF, None)],
)
def test_alarm_history(raw: int, label: str | None) -> None:
    assert decoded(POINTS, "alarm_history_1", word("alarm_history_1", raw)) == label


def test_electric_life_u32_high_word_first() -> None:
    read = read_of(POINTS, "electric_life")
    image = {(H, read.address): 0x0001, (H, read.address + 1): 0x0002}
    assert decoded(POINTS, "electric_life", image) == 65538


def test_negative_set_value_decodes() -> None:
    image = word("set_value", 45) | word("sign_set_value", 1 << 13) | word("unit", UNIT_BAR)
    assert decoded(POINTS, "set_value", image) == -4.5
    assert decoded(POINTS, "set_value_2", image | word("set_value_2", 45)) == 4.5


@pytest.mark.parametrize(
    ("key", "bit"),
    [
        ("min_value_sensor", 0),
        ("min_alarm_value", 7),
        ("compensation_set_2", 10),
        ("compensation", 11),
        ("set_value_2", 12),
        ("set_value", 13),
    ],
)
def test_sign_bits(key: str, bit: int) -> None:
    sign = POINTS[key].sign
    assert sign is not None
    assert sign.address == POINTS["sign_set_value"].address
    assert sign.entity.bit == bit


@pytest.mark.parametrize(
    ("raw", "unit"),
    [(0, "bar"), (3, "m³/h"), (4, "L/min"), (5, "gal/min"), (6, "°C"), (8, "K"), (13, "%")],
)
def test_unit_register(raw: int, unit: str) -> None:
    image = word("unit", raw)
    unit_keys = [k for k, p in POINTS.items() if p.unit_source is not None]
    assert len(unit_keys) == 13
    assert all(POINTS[k].entity.ha.device_class is None for k in unit_keys)
    assert unit_of(POINTS["actual_value"], image) == unit


def test_mac_address_ascii() -> None:
    read = read_of(POINTS, "mac_address")
    assert read.count == 6
    text = b"A4C138F2019E"
    image = {(H, read.address + i): int.from_bytes(text[2 * i : 2 * i + 2]) for i in range(6)}
    assert decoded(POINTS, "mac_address", image) == "A4C138F2019E"


def test_combo_address_sentinel() -> None:
    assert decoded(POINTS, "combo_address_active", word("combo_address_active", 0x00FF)) is None
    assert decoded(POINTS, "combo_address_active", word("combo_address_active", 3)) == 3


# --- dynamic limits (§5 "Range checks") ------------------------------------------------------


def test_operating_frequency_within_motor_limits() -> None:
    image = word("min_motor_frequency", 30) | word("max_motor_frequency", 50)
    point = POINTS["operating_frequency"]
    assert limits_of(point, image) == (30, 50)
    (write,) = encode(point, 45, image)
    assert write.values == (45,)
    for value in (25, 55):
        with pytest.raises(ValueRejectedError):
            encode(point, value, image)


def test_rated_motor_current_limited_by_device_maximum() -> None:
    image = word("rated_motor_current_max", 120)  # 12.0 A
    point = POINTS["rated_motor_current"]
    assert encode(point, 12.0, image)[0].values == (120,)
    with pytest.raises(ValueRejectedError):
        encode(point, 12.1, image)


def test_max_motor_frequency_limited_by_rated_frequency() -> None:
    image = word("rated_motor_frequency", 50) | word("min_motor_frequency", 30)
    with pytest.raises(ValueRejectedError):
        encode(POINTS["max_motor_frequency"], 60, image)


# --- options ---------------------------------------------------------------------------------


def test_every_option_combination_loads() -> None:
    names = list(MAPPING.options)
    for combo in itertools.product(*(MAPPING.options[n].choices for n in names)):
        chosen = dict(zip(names, combo, strict=True))
        points = MAPPING.points(chosen)
        present = (
            "pcb_temperature" if chosen["register_9f"] == "pcb_temperature" else "input_current"
        )
        assert present in points
        assert ({"pcb_temperature", "input_current"} - {present}).isdisjoint(points)
        assert ("digital_input_1_manual_reset" in points) == (chosen["family"] == "mida")
        assert ("digital_input_3_contact" in points) == (chosen["family"] == "vasco")
        assert ("mppt_voltage_gap" in points) == (chosen["pv_input"] == "present")


def test_register_9f_input_current() -> None:
    points = MAPPING.points({"register_9f": "input_current"})
    read = read_of(points, "input_current")
    assert request_frame(read) == hexbytes("01 03 00 9E 00 01 E5 E4")
    assert decode(points["input_current"], {(H, read.address): 123}) == 12.3


def test_guarded_writes() -> None:
    entities = MAPPING.entities
    for key in ("modbus_address", "modbus_baudrate", "modbus_data_format", "rotation_sense"):
        assert entities[key].dangerous
    passwords = [k for k in entities if k.startswith("password_")]
    assert len(passwords) == 6
    assert all(entities[k].secret and entities[k].dangerous for k in passwords)


PROTECTION_SETTINGS = [
    # what scales the pressure feedback
    "sensor_full_scale",
    "min_value_sensor",
    "sign_min_value_sensor",
    "offset_input_1",
    "offset_input_2",
    "offset_input_3",
    "offset_input_4",
    # the min/max pressure alarms, the dry-run protection, restarts, input polarity
    "min_alarm_value",
    "sign_min_alarm_value",
    "max_alarm_value",
    "dry_run_power_factor",
    "autorestart",
    "digital_input_1_contact",
    "digital_input_2_contact",
    "digital_input_3_contact",
    "digital_input_4_contact",
]


@pytest.mark.parametrize("key", PROTECTION_SETTINGS)
def test_feedback_scaling_and_protection_settings_are_guarded(key: str) -> None:
    """Like the soft starter's protection thresholds: each can mis-scale the pressure
    feedback or switch the dry-run / over-pressure protection off."""
    assert MAPPING.entities[key].dangerous
    guard = Guard.of(POINTS.values())
    point = POINTS[key]
    held = {(p.table, a): 0 for p in POINTS.values() for a in p.span}
    written = encode(point, _other_value(point), held)
    assert written
    assert any(guard.dangerous_changed(w.table, w.address, w.values, held) for w in written)


def _other_value(point: Point) -> object:
    entity = point.entity
    if entity.enum is not None:
        return list(entity.enum.values())[1]
    if entity.kind == "bool":
        return True
    return entity.max
