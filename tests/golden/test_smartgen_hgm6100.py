"""Golden frames of the SmartGen HGM6110 / HGM6120 mapping (devices/smartgen_hgm6100.md §10).

Every request is built from the mapping's points (never a hard-coded wire address); every
documented reply is decoded through the mapping and the codec. All frames printed in the seed
carry a valid CRC; the computed frames of §10 cover every FC05 command with the printed ON value
0x00FF and with the standard 0xFF00 (a per-device protocol override).
"""

from __future__ import annotations

import itertools

import pytest

from bridge.core.codec import encode
from bridge.core.entity import Table
from bridge.core.guard import Guard
from bridge.core.mapping import Point
from bridge.core.request import Read, Write
from bridge.modbus.frame import FrameError, build_frame, parse_frame
from tests.golden.frames import decoded, hexbytes, image_from, read_of, request_frame, shipped

MAPPING = shipped("smartgen_hgm6100")
POINTS = MAPPING.points()
CAN_POINTS = MAPPING.points({"can": "yes"})
HGM6110_POINTS = MAPPING.points({"model": "hgm6110"})
STANDARD_ON = MAPPING.model_copy(
    update={"protocol": MAPPING.protocol.model_copy(update={"coil_on_value": 0xFF00})}
)
STANDARD_POINTS = STANDARD_ON.points()


def press_frame(points: dict[str, Point], key: str, unit: int = 1) -> bytes:
    """The FC05 frame the bridge sends when the button ``key`` is pressed."""
    (write,) = encode(points[key], "PRESS", {})
    return build_frame(write, unit)


# --- seed §3.2: FC01 read 40 bits from 0000 ---------------------------------------------

FC01_REQUEST = "01 01 00 00 00 28 3C 14"
FC01_REPLY = "01 01 05 07 01 00 00 01 E4 AE"
FC01_SET = {
    "common_alarm",  # bit 0
    "common_warning",  # bit 1
    "common_shutdown",  # bit 2
    "alarm_emergency_stop",  # bit 8
    "warning_input",  # bit 32
}


def _fc01_read() -> Read:
    return read_of(POINTS, "common_alarm", "warning_overpower")


def test_fc01_read_40_bits_request() -> None:
    read = _fc01_read()
    assert (read.table, read.address, read.count) == (Table.COIL, 0, 40)
    assert request_frame(read) == hexbytes(FC01_REQUEST)


def test_fc01_reply_decodes_bits_0_1_2_8_32() -> None:
    read = _fc01_read()
    image = image_from(read, hexbytes(FC01_REPLY))
    in_read = {
        key: point
        for key, point in POINTS.items()
        if point.table is Table.COIL and point.entity.readable and point.address in read.span
    }
    assert in_read.keys() >= FC01_SET
    assert len(in_read) == 39  # 40 bits minus reserved 0005
    for key in in_read:
        assert decoded(POINTS, key, image) is (key in FC01_SET), key


# --- seed §3.3: FC03 read 0024–0025 (battery, D+) -----------------------------------------


def test_fc03_read_battery_and_charger_voltage() -> None:
    read = read_of(POINTS, "battery_voltage", "charger_voltage")
    assert request_frame(read) == hexbytes("01 03 00 18 00 02 44 0C")
    image = image_from(read, hexbytes("01 03 04 01 12 00 00 5B CA"))
    assert decoded(POINTS, "battery_voltage", image) == 27.4
    assert decoded(POINTS, "charger_voltage", image) == 0.0


# --- seed §3.4: FC05 remote AUTO with 0x00FF, reply = echo --------------------------------


def test_fc05_auto_request_and_echo() -> None:
    (write,) = encode(POINTS["command_auto"], "PRESS", {})
    assert write == Write(5, Table.COIL, 3, (0x00FF,))
    frame = build_frame(write, 1)
    assert frame == hexbytes("01 05 00 03 00 FF 7D 8A")
    echo = parse_frame(hexbytes("01 05 00 03 00 FF 7D 8A"))
    assert (echo.function_code, echo.address, echo.registers) == (5, 3, [0x00FF])


def test_corrupted_crc_is_rejected() -> None:
    """All printed frames verify; a flipped CRC byte of the seed example must not parse."""
    with pytest.raises(FrameError):
        parse_frame(hexbytes("01 03 04 01 12 00 00 5B CB"))
    parse_frame(hexbytes("01 03 04 01 12 00 00 5B CA"))


# --- §10 computed frames: every FC05 command, 0x00FF (as mapped) and 0xFF00 (override) ----

COMMANDS = [
    # (id, key, 0x00FF frame, 0xFF00 frame)
    ("start", "command_start", "01 05 00 00 00 FF 8D 8A", "01 05 00 00 FF 00 8C 3A"),
    ("stop", "command_stop", "01 05 00 01 00 FF DC 4A", "01 05 00 01 FF 00 DD FA"),
    ("test", "command_test", "01 05 00 02 00 FF 2C 4A", "01 05 00 02 FF 00 2D FA"),
    ("auto", "command_auto", "01 05 00 03 00 FF 7D 8A", "01 05 00 03 FF 00 7C 3A"),
    ("manual", "command_manual", "01 05 00 04 00 FF CC 4B", "01 05 00 04 FF 00 CD FB"),
]
BREAKERS = [
    # (id, key, state key, 0x00FF frame, 0xFF00 frame)
    (
        "gen_breaker_toggle",
        "generator_breaker",
        "generator_on_load",
        "01 05 00 05 00 FF 9D 8B",
        "01 05 00 05 FF 00 9C 3B",
    ),
    (
        "mains_breaker_toggle",
        "mains_breaker",
        "mains_on_load",
        "01 05 00 06 00 FF 6D 8B",
        "01 05 00 06 FF 00 6C 3B",
    ),
]


@pytest.mark.parametrize(
    ("key", "printed_on"), [(c[1], c[2]) for c in COMMANDS], ids=[c[0] for c in COMMANDS]
)
def test_fc05_command_as_printed(key: str, printed_on: str) -> None:
    assert press_frame(POINTS, key) == hexbytes(printed_on)


@pytest.mark.parametrize(
    ("key", "standard_on"), [(c[1], c[3]) for c in COMMANDS], ids=[c[0] for c in COMMANDS]
)
def test_fc05_command_standard_on_value(key: str, standard_on: str) -> None:
    assert press_frame(STANDARD_POINTS, key) == hexbytes(standard_on)


@pytest.mark.parametrize(
    ("key", "frame"),
    [
        ("command_hgm6110_5", "01 05 00 05 00 FF 9D 8B"),
        ("command_hgm6110_6", "01 05 00 06 00 FF 6D 8B"),
    ],
    ids=["hgm6110_cmd_0005", "hgm6110_cmd_0006"],
)
def test_fc05_hgm6110_commands(key: str, frame: str) -> None:
    assert press_frame(HGM6110_POINTS, key) == hexbytes(frame)


def test_smartgen_cloud_frames_with_ff00() -> None:
    """[S1]: SmartGen's module sends the standard ON value to unit 0 (module-side convention)."""
    assert press_frame(STANDARD_POINTS, "command_auto", unit=0) == hexbytes(
        "00 05 00 03 FF 00 7D EB"
    )
    closed = {(Table.COIL, 6): 0}  # mains_on_load: open, the cloud closes it
    (write,) = encode(STANDARD_POINTS["mains_breaker"], "ON", closed)
    assert build_frame(write, 0) == hexbytes("00 05 00 06 FF 00 6D EA")


@pytest.mark.parametrize(
    ("key", "state", "printed_on", "standard_on"),
    [b[1:] for b in BREAKERS],
    ids=[b[0] for b in BREAKERS],
)
def test_a_breaker_is_a_switch_that_toggles_only_when_its_state_differs(
    key: str, state: str, printed_on: str, standard_on: str
) -> None:
    """Seed Tbl 10 rows 0005/0006 (HGM6120) are close/open toggles: ON closes an open
    breaker with one FC05 (the ON word), ON on a closed one sends nothing; likewise OFF."""
    point = POINTS[key]
    source = POINTS[state]
    assert point.state_source is not None and point.state_source.key == state
    assert point.entity.component.value == "switch"
    for value, held, frame in (("ON", 0, printed_on), ("OFF", 1, printed_on)):
        image = {(Table.COIL, source.address): held}
        (write,) = encode(point, value, image)
        assert build_frame(write, 1) == hexbytes(frame)
        (standard,) = encode(STANDARD_POINTS[key], value, image)
        assert build_frame(standard, 1) == hexbytes(standard_on)
        assert encode(point, value, {(Table.COIL, source.address): 1 - held}) == ()


def test_breaker_toggles_are_guarded() -> None:
    gen, mains = POINTS["generator_breaker"], POINTS["mains_breaker"]
    for point in (gen, mains):
        assert not point.entity.idempotent
        assert point.entity.dangerous
        assert point.entity.write_interval == 2.0
        assert point.entity.requires == {"remote_lock": False, "manual_mode": True}
    guard = Guard.of(POINTS.values())
    for coil in (5, 6):  # seed Tbl 10: 0005 generator, 0006 mains close/open (HGM6120)
        assert guard.dangerous_in(Table.COIL, coil, (0x00FF,)) == [coil]
    assert "mains_breaker" not in HGM6110_POINTS
    assert "command_hgm6110_5" not in POINTS


def test_every_remote_command_requires_remote_control_not_locked() -> None:
    """Doc §9.6: with FC01 0004 (remote lock) at 1 commands are echoed, not executed."""
    for options in ({}, {"model": "hgm6110"}):
        writable = [p for p in MAPPING.points(options).values() if p.entity.writable]
        assert len(writable) == 7
        for point in writable:
            assert point.entity.requires.get("remote_lock") is False, point.key
    assert POINTS["command_start"].entity.requires["manual_mode"] is True  # acts in manual


# --- §10 computed frames: block reads ------------------------------------------------------

BLOCKS = [
    ("read_0000_0055", ("mains_voltage_ua", "generator_load"), "01 03 00 00 00 38 44 18"),
    ("read_0000_0044", ("mains_voltage_ua", "run_minutes"), "01 03 00 00 00 2D 85 D7"),
    ("read_0046_0055", ("start_count", "generator_load"), "01 03 00 2E 00 0A A5 C4"),
]


@pytest.mark.parametrize(
    ("keys", "frame"), [(b[1], b[2]) for b in BLOCKS], ids=[b[0] for b in BLOCKS]
)
def test_block_reads(keys: tuple[str, ...], frame: str) -> None:
    read = read_of(POINTS, *keys)
    assert read.count <= MAPPING.protocol.max_read_registers
    assert request_frame(read) == hexbytes(frame)


def test_block_0000_0055_covers_every_non_ecu_value() -> None:
    low = [k for k, p in POINTS.items() if p.table is Table.HOLDING and p.address < 56]
    read = read_of(POINTS, *low)
    assert (read.address, read.count) == (0, 56)
    assert request_frame(read) == hexbytes("01 03 00 00 00 38 44 18")


def test_read_all_82_bits() -> None:
    bits = [k for k, p in CAN_POINTS.items() if p.table is Table.COIL and p.entity.readable]
    read = read_of(CAN_POINTS, *bits)
    assert (read.address, read.count) == (0, MAPPING.protocol.max_read_bits)
    assert request_frame(read) == hexbytes("01 01 00 00 00 52 BD F7")


def test_read_0000_0124_frame() -> None:
    """§10 lists the 125-register frame (CAN variants); the mapping itself stays at ≤ 56."""
    registers = [k for k, p in CAN_POINTS.items() if p.table is Table.HOLDING]
    read = read_of(CAN_POINTS, *registers)
    assert (read.address, read.count) == (0, 125)
    assert request_frame(read) == hexbytes("01 03 00 00 00 7D 85 EB")


# --- decoding rules: scales, sentinel, counters, status ------------------------------------


def _holding(**words: int) -> dict[tuple[Table, int], int]:
    return {(Table.HOLDING, int(addr[1:])): value for addr, value in words.items()}


@pytest.mark.parametrize(
    ("option", "raw", "value"),
    [("0.1", 500, 50.0), ("0.01", 5000, 50.0)],
    ids=["table_0.1Hz", "note1_5000x0.01Hz"],
)
def test_frequency_scale_option(option: str, raw: int, value: float) -> None:
    points = MAPPING.points({"frequency_scale": option})
    image = _holding(r6=raw, r13=raw)
    assert decoded(points, "generator_frequency", image) == value
    assert decoded(points, "mains_frequency", image) == value


def test_current_and_power_scale_options() -> None:
    image = _holding(r14=123, r26=0xFFF6, r52=45)
    assert decoded(POINTS, "generator_current_a", image) == 123
    assert decoded(POINTS, "active_power", image) == -10
    scaled = MAPPING.points({"current_scale": "0.1", "power_scale": "0.1"})
    assert decoded(scaled, "generator_current_a", image) == 12.3
    assert decoded(scaled, "active_power", image) == -1.0
    assert decoded(scaled, "active_power_a", image) == 4.5


def test_sentinel_32766_is_unknown() -> None:
    image = _holding(r17=32766, r24=32766, r19=0x7FFE)
    assert decoded(POINTS, "coolant_temperature", image) is None
    assert decoded(POINTS, "battery_voltage", image) is None
    assert decoded(POINTS, "oil_pressure", image) is None


def test_counters_radix_10000_and_fuel_radix_65536() -> None:
    image = _holding(r42=1, r43=2345, r46=0, r47=17, r48=12, r49=9999, r68=1, r69=2)
    assert decoded(POINTS, "run_hours", image) == 12345
    assert decoded(POINTS, "start_count", image) == 17
    assert decoded(POINTS, "energy", image) == 129999
    assert decoded(CAN_POINTS, "ecu_fuel_total", image) == 65538


def test_genset_status_is_the_mapping_status() -> None:
    assert MAPPING.status == "genset_status"
    assert decoded(POINTS, "genset_status", _holding(r34=9)) == "normal_running"
    assert decoded(POINTS, "genset_status", _holding(r34=14)) == "stop_failure"


# --- every option combination loads; every button's press encodes ---------------------------


def _combinations() -> list[dict[str, str]]:
    names = list(MAPPING.options)
    choices = [MAPPING.options[name].choices for name in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*choices)]


@pytest.mark.parametrize("options", _combinations(), ids=lambda o: "-".join(o.values()))
def test_every_option_combination_resolves_and_presses(options: dict[str, str]) -> None:
    points = MAPPING.points(options)
    buttons = [p for p in points.values() if p.entity.press is not None]
    assert len(buttons) == (5 if options["model"] == "hgm6120" else 7)
    for point in buttons:
        (write,) = encode(point, "PRESS", {})
        assert write.function == 5
        assert write.values == (0x00FF,)
    assert ("mains_voltage_ua" in points) is (options["model"] == "hgm6120")
    assert ("ecu_fuel_total" in points) is (options["can"] == "yes")


# --- phase angles 0092–0097: every model measures them, not only CAN variants ---------------

PHASE_ANGLES = [f"generator_phase_angle_u{p}" for p in "abc"]
MAINS_ANGLES = [f"mains_phase_angle_u{p}" for p in "abc"]


@pytest.mark.parametrize("can", ["no", "yes"])
def test_phase_angles_are_not_can_values(can: str) -> None:
    """Seed rows 0092–0097 ("UA … 0~360 … °") carry the generator/mains prefixes, not the
    CAN-only remark of 0082–0091: present whatever the can option, mains ones on HGM6120."""
    points = MAPPING.points({"can": can})
    read = read_of(points, *PHASE_ANGLES, *MAINS_ANGLES)
    assert request_frame(read) == hexbytes("01 03 00 5C 00 06 05 DA")
    image = _holding(r92=0, r93=120, r94=240, r95=359, r96=32766, r97=1)
    assert [decoded(points, k, image) for k in PHASE_ANGLES + MAINS_ANGLES] == [
        0, 120, 240, 359, None, 1,
    ]  # fmt: skip
    hgm6110 = MAPPING.points({"can": can, "model": "hgm6110"})
    assert all(k in hgm6110 for k in PHASE_ANGLES)
    assert not any(k in hgm6110 for k in MAINS_ANGLES)
    assert ("ecu_engine_speed" in points) is (can == "yes")  # 0082–0091 stay CAN-only
