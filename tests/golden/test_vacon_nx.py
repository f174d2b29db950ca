"""Golden frames of the Vacon NX OPTC2/C8 Modbus board (devices/vacon_nx.md §8).

Every request is built from the mapping's points (ID as printed, ``offset: -1``), every
documented reply is decoded through the mapping and the codec. The manual prints two reply
CRCs wrong and one byte count wrong: those frames must be rejected, the corrected ones parse.
FC03 and FC04 read the same data on this board; the mapping uses the holding table, so an
FC04 read is the mapping's read with the table replaced, and its reply is decoded as holding.
"""

from __future__ import annotations

import itertools

import pytest

from bridge.core.address import to_wire
from bridge.core.codec import Image, encode
from bridge.core.entity import Table
from bridge.core.request import Read, Write
from bridge.core.state import active_alarms
from bridge.errors import ValueRejectedError
from bridge.modbus.frame import FrameError, build_frame, exception_code, parse_frame
from tests.golden.frames import decoded, hexbytes, image_from, read_of, request_frame, shipped

MAPPING = shipped("vacon_nx")
POINTS = MAPPING.points()

PD_OUT = (
    "status_word",
    "fieldbus_control",
    "actual_speed",
    "output_frequency",
    "motor_speed",
    "motor_current",
    "motor_torque",
    "motor_power",
    "motor_voltage",
    "dc_link_voltage",
    "active_fault_code",
)


def as_input(read: Read) -> Read:
    """The same read sent with FC04 (the board answers FC03 and FC04 alike)."""
    return Read(Table.INPUT, read.address, read.count)


def as_holding(image: Image) -> dict[tuple[Table, int], int]:
    """An FC04 reply image keyed as the holding registers the mapping decodes."""
    return {(Table.HOLDING, address): value for (_, address), value in image.items()}


def control_word(value: int) -> dict[tuple[Table, int], int]:
    """Register image holding the control word (ID 2001) as last read."""
    return {(Table.HOLDING, POINTS["run"].address): value}


def frames_of(writes: tuple[Write, ...]) -> list[bytes]:
    return [build_frame(write, 1) for write in writes]


def assembled(*pairs: tuple[str, object]) -> Write:
    """One FC16 write of consecutive points, each value encoded through the mapping."""
    image = control_word(0)
    words: list[int] = []
    first = POINTS[pairs[0][0]].write_address
    for offset, (key, value) in enumerate(pairs):
        point = POINTS[key]
        assert point.write_address == first + offset, key
        (write,) = encode(point, value, image)
        words.extend(write.values)
    return Write(16, Table.HOLDING, first, tuple(words))


# --- reads ---------------------------------------------------------------------------------

READS = [
    pytest.param(
        ("run", "control_word_general", "speed_reference"),
        False,
        "01 03 07 D0 00 03 05 46",
        id="read-holding-42001-42003",
    ),
    pytest.param(("run",), True, "01 04 07 D0 00 01 31 47", id="read-input-32001"),
    pytest.param(
        ("run", "control_word_general", "speed_reference"),
        True,
        "01 04 07 D0 00 03 B0 86",
        id="read-input-32001-qty3-note-a",
    ),
    pytest.param(
        ("actual_speed", "output_frequency"), True, "01 04 08 36 00 02 93 A5", id="example-2-read"
    ),
    pytest.param(PD_OUT, False, "01 03 08 34 00 0B 47 A3", id="computed-poll-2101-2111-fc03"),
    pytest.param(PD_OUT, True, "01 04 08 34 00 0B F2 63", id="computed-poll-2101-2111-fc04"),
    pytest.param(("fault_code",), False, "01 03 00 62 00 01 25 D4", id="computed-fault-code-99"),
]


@pytest.mark.parametrize(("keys", "fc04", "frame"), READS)
def test_read_request(keys: tuple[str, ...], fc04: bool, frame: str) -> None:
    read = read_of(POINTS, *keys)
    if fc04:
        read = as_input(read)
    assert request_frame(read) == hexbytes(frame)
    assert parse_frame(hexbytes(frame), response=False).function_code == read.function


def test_example_2_reply_decodes_speed_and_frequency() -> None:
    read = as_input(read_of(POINTS, "actual_speed", "output_frequency"))
    image = as_holding(image_from(read, hexbytes("01 04 04 13 88 09 C4 78 E9")))
    assert decoded(POINTS, "actual_speed", image) == 50.0
    assert decoded(POINTS, "output_frequency", image) == 25.0


def test_process_data_out_block_fits_its_segment() -> None:
    read = read_of(POINTS, *PD_OUT)
    (segment,) = [s for s in MAPPING.protocol.segments if s.name == "process data out"]
    rule = MAPPING.protocol.addressing
    assert read.address == to_wire(segment.start, rule)
    assert read.count == segment.max_read_registers == 11


# --- printed frames with a wrong CRC or byte count ------------------------------------------

MISPRINTS = [
    pytest.param("01 84 02 AE C1", "01 84 02 C2 C1", id="exception-reply"),
    pytest.param("01 10 07 D0 00 03 F1 01", "01 10 07 D0 00 03 80 85", id="example-1-reply"),
    pytest.param(
        "01 04 02 13 88 09 C4 F0 E9", "01 04 04 13 88 09 C4 78 E9", id="example-2-reply-count"
    ),
]


@pytest.mark.parametrize(("printed", "corrected"), MISPRINTS)
def test_misprinted_reply_is_rejected_and_corrected_parses(printed: str, corrected: str) -> None:
    with pytest.raises(FrameError):
        parse_frame(hexbytes(printed))
    parse_frame(hexbytes(corrected))


def test_exception_example_illegal_data_address() -> None:
    rule = MAPPING.protocol.addressing
    address = to_wire(6001, rule)  # the manual's "6000 (0x1770)": ID 6001
    assert not any(
        to_wire(s.start, rule) <= address <= to_wire(s.end, rule) for s in MAPPING.protocol.segments
    )
    assert request_frame(Read(Table.INPUT, address, 5)) == hexbytes("01 04 17 70 00 05 34 66")
    code = exception_code(parse_frame(hexbytes("01 84 02 C2 C1")))
    assert code == 2
    assert MAPPING.protocol.exceptions[code].action == "refused"


def test_vacon_100_reference_exception_parses() -> None:
    # [V5]: slave device failure (04) from a Vacon 100; the NX board lists 01, 02, 03, 06 only.
    assert exception_code(parse_frame(hexbytes("01 84 04 42 C3"))) == 4
    assert 4 not in MAPPING.protocol.exceptions


# --- writes ---------------------------------------------------------------------------------

SINGLE_WRITES = [
    pytest.param("run", True, 0x0000, ["01 06 07 D0 00 01 48 87"], id="fc06-run-forward"),
    pytest.param("run", False, 0x0001, ["01 06 07 D0 00 00 89 47"], id="computed-stop"),
    pytest.param("reverse", True, 0x0001, ["01 06 07 D0 00 03 C9 46"], id="computed-run-reverse"),
    pytest.param(
        "fault_reset",
        "PRESS",
        0x0000,
        ["01 06 07 D0 00 04 88 84", "01 06 07 D0 00 00 89 47"],
        id="computed-fault-reset-edge",
    ),
    pytest.param(
        "speed_reference", 50.0, 0x0000, ["01 06 07 D2 13 88 25 D1"], id="computed-speed-50"
    ),
]


@pytest.mark.parametrize(("key", "value", "word", "frames"), SINGLE_WRITES)
def test_single_register_write(key: str, value: object, word: int, frames: list[str]) -> None:
    writes = encode(POINTS[key], value, control_word(word))
    assert frames_of(writes) == [hexbytes(f) for f in frames]


def test_fault_reset_pulse_keeps_run_and_direction() -> None:
    writes = encode(POINTS["fault_reset"], "PRESS", control_word(0x0003))
    assert [w.values for w in writes] == [(0x0007,), (0x0003,)]


MULTI_WRITES = [
    pytest.param(
        (("run", True), ("control_word_general", 0x0010)),
        "01 10 07 D0 00 02 04 00 01 00 10 88 CF",
        id="fc16-42001-42002",
    ),
    pytest.param(
        (("run", True), ("control_word_general", 0), ("speed_reference", 50.0)),
        "01 10 07 D0 00 03 06 00 01 00 00 13 88 C8 CB",
        id="example-1-run-gcw0-speed-50",
    ),
]


@pytest.mark.parametrize(("pairs", "frame"), MULTI_WRITES)
def test_fc16_write(pairs: tuple[tuple[str, object], ...], frame: str) -> None:
    write = assembled(*pairs)
    assert build_frame(write, 1) == hexbytes(frame)
    request = parse_frame(hexbytes(frame), response=False)
    assert (request.address, request.registers) == (write.address, list(write.values))


def test_example_1_corrected_reply_echoes_the_write() -> None:
    write = assembled(("run", True), ("control_word_general", 0), ("speed_reference", 50.0))
    reply = parse_frame(hexbytes("01 10 07 D0 00 03 80 85"))
    assert (reply.address, reply.count) == (write.address, len(write.values))


# --- options, variants and buttons -----------------------------------------------------------


def test_every_option_combination_resolves() -> None:
    names = list(MAPPING.options)
    choices = [MAPPING.options[name].choices for name in names]
    for combo in itertools.product(*choices):
        points = MAPPING.points(dict(zip(names, combo, strict=True)))
        assert set(points) == set(MAPPING.entities)


@pytest.mark.parametrize(
    ("application", "key", "name", "value", "raw"),
    [
        ("all_in_one_basic", "pd_in_1", "Process data in 1", 1234, 1234),
        ("multipurpose", "pd_in_1", "Torque reference", -25.5, -255 & 0xFFFF),
        ("multipurpose", "pd_in_2", "Free analogue input", 12.34, 1234),
        ("pid_pump_fan", "pd_in_1", "PID reference", 50.0, 5000),
        ("pid_pump_fan", "pd_in_3", "PID actual value 2", 99.99, 9999),
    ],
)
def test_application_variants_of_process_data_in(
    application: str, key: str, name: str, value: float, raw: int
) -> None:
    point = MAPPING.points({"application": application})[key]
    assert point.entity.name == name
    (write,) = encode(point, value, {})
    assert write.values == (raw,)


@pytest.mark.parametrize(
    ("application", "key", "limits"),
    [
        ("all_in_one_basic", "pd_in_1", (-32768, 32767)),
        ("multipurpose", "pd_in_1", (-3276.8, 3276.7)),
        ("multipurpose", "pd_in_2", (-327.68, 327.67)),
        ("pid_pump_fan", "pd_in_1", (-327.68, 327.67)),
        ("pid_pump_fan", "pd_in_2", (-327.68, 327.67)),
        ("pid_pump_fan", "pd_in_3", (-327.68, 327.67)),
    ],
)
def test_process_data_in_limits_follow_the_application_scale(
    application: str, key: str, limits: tuple[float, float]
) -> None:
    """An Integer 16 word at 0.1 % holds -3276.8..3276.7 %, at 0.01 % -327.68..327.67 %: the
    ends are written as the register's ends, one step beyond is refused before the wire."""
    point = MAPPING.points({"application": application})[key]
    assert (point.entity.min, point.entity.max) == limits
    assert encode(point, limits[0], {})[0].values == (0x8000,)
    assert encode(point, limits[1], {})[0].values == (0x7FFF,)
    step = point.entity.step or 1
    for beyond in (limits[0] - step, limits[1] + step):
        with pytest.raises(ValueRejectedError, match="outside"):
            encode(point, beyond, {})


def test_monitor_current_resolution_option() -> None:
    image = {(Table.HOLDING, POINTS["monitor_motor_current"].address): 1234}
    assert decoded(POINTS, "monitor_motor_current", image) == 123.4
    fine = MAPPING.points({"current_resolution": "0.01 A"})
    assert decoded(fine, "monitor_motor_current", image) == 12.34


@pytest.mark.parametrize(
    ("raw", "label", "alarms"),
    [
        (0, "no_fault", []),
        (53, "fieldbus_fault", ["fieldbus_fault"]),  # seed ch. 8 row 53
        (1, "code_1", ["fault_code_1"]),  # an overcurrent: no label in the seed, still a fault
        (2, "code_2", ["fault_code_2"]),
    ],
)
def test_fault_code_is_published_as_a_number_and_a_label(
    raw: int, label: str, alarms: list[str]
) -> None:
    """ID 99 holds any NX fault number: "Fault number" is the number, "Fault code" its label
    where the seed names it (code_<n> otherwise), and a fault without a label is an alarm."""
    read = read_of(POINTS, "fault_number")
    assert read == read_of(POINTS, "fault_code")
    assert request_frame(read) == hexbytes("01 03 00 62 00 01 25 D4")  # §8 "Read fault code"
    image = {(Table.HOLDING, read.address): raw, (Table.HOLDING, 2110): raw}
    assert decoded(POINTS, "fault_number", image) == raw
    assert decoded(POINTS, "fault_code", image) == label
    assert decoded(POINTS, "active_fault_code", image) == raw  # PD Out 8
    values = {key: decoded(POINTS, key, image) for key in ("fault_number", "fault_code")}
    assert active_alarms(POINTS, values) == alarms


def test_every_button_press_encodes() -> None:
    buttons = [p for p in POINTS.values() if p.entity.press is not None]
    assert buttons
    for point in buttons:
        assert encode(point, "PRESS", control_word(0))
