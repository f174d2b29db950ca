"""Golden frames of the P2-series inverter (device document p2_vfd.md, section 6).

R1/R3 are the manual's RTU example (CRC computed by the document), A1/A3/A4 its ASCII
example (LRC printed and verified), D1-D20 frames the document derived. R2 is the reply
with F9.05 = 0 (2-byte byte count): the bridge's FC03 reply PDU decodes both forms.
"""

from __future__ import annotations

import pytest

from bridge.core.address import to_wire
from bridge.core.codec import encode
from bridge.core.entity import Table
from bridge.errors import ValueRejectedError
from bridge.modbus.frame import FrameError, build_frame, exception_code, parse_frame
from tests.golden.frames import decoded, hexbytes, image_from, read_of, request_frame, shipped

MAPPING = shipped("p2_vfd")
POINTS = MAPPING.points()
EXAMPLE_POINTS = MAPPING.points({"ascii_example_registers": "exposed"})


def _image(key: str, raw: int) -> dict[tuple[Table, int], int]:
    """A register image holding ``raw`` at the point's own wire address."""
    point = POINTS[key]
    return {(point.table, point.address): raw}


# --- manual frames ------------------------------------------------------------------------


def test_r1_r3_read_f0_01_f0_02() -> None:
    read = read_of(POINTS, "parameter_f0_01", "parameter_f0_02")
    assert request_frame(read) == hexbytes("01 03 F0 01 00 02 A6 CB")
    image = image_from(read, hexbytes("01 03 04 13 88 00 00 7E 9D"))
    assert decoded(POINTS, "parameter_f0_01", image) == 5000
    assert decoded(POINTS, "parameter_f0_02", image) == 0


def test_r2_non_standard_byte_count_decodes_like_r3() -> None:
    """F9.05 = 0 answers with a 2-byte byte count (00 04); it decodes to R3's values."""
    read = read_of(POINTS, "parameter_f0_01", "parameter_f0_02")
    image = image_from(read, hexbytes("01 03 00 04 13 88 00 00 C7 A9"))
    assert decoded(POINTS, "parameter_f0_01", image) == 5000
    assert decoded(POINTS, "parameter_f0_02", image) == 0


def test_r2_with_a_broken_crc_is_still_rejected() -> None:
    with pytest.raises(FrameError):
        parse_frame(hexbytes("01 03 00 04 13 88 00 00 C7 AA"))


@pytest.mark.parametrize(
    "request_text",
    [
        pytest.param(":010300040002F6\r\n", id="A1"),
        pytest.param(":010300040002F6\r\n", id="A3"),
    ],
)
def test_a1_a3_ascii_request(request_text: str) -> None:
    read = read_of(EXAMPLE_POINTS, "ascii_example_0004", "ascii_example_0005")
    assert request_frame(read, framer="ascii") == request_text.encode("ascii")


def test_a4_ascii_response() -> None:
    read = read_of(EXAMPLE_POINTS, "ascii_example_0004", "ascii_example_0005")
    image = image_from(read, b":01030413881388C2\r\n", framer="ascii")
    assert decoded(EXAMPLE_POINTS, "ascii_example_0004", image) == 5000
    assert decoded(EXAMPLE_POINTS, "ascii_example_0005", image) == 5000


def test_ascii_frame_with_wrong_lrc_is_rejected() -> None:
    with pytest.raises(FrameError):
        parse_frame(b":01030413881388C3\r\n", "ascii")


def test_ascii_example_registers_hidden_by_default() -> None:
    assert "ascii_example_0004" not in POINTS
    assert "ascii_example_0005" not in POINTS


# --- derived write frames -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("key", "value", "frame"),
    [
        pytest.param("command", "forward_run", "01 06 20 00 00 01 43 CA", id="D1"),
        pytest.param("reverse_run", "PRESS", "01 06 20 00 00 02 03 CB", id="D2"),
        pytest.param("command", "forward_jog", "01 06 20 00 00 03 C2 0B", id="D3"),
        pytest.param("reverse_jog", "PRESS", "01 06 20 00 00 04 83 C9", id="D4"),
        pytest.param("command", "coast_stop", "01 06 20 00 00 05 42 09", id="D5"),
        pytest.param("command", "stop", "01 06 20 00 00 06 02 08", id="D6"),
        pytest.param("stop", "PRESS", "01 06 20 00 00 06 02 08", id="D6-button"),
        pytest.param("command", "fault_reset", "01 06 20 00 00 07 C3 C8", id="D7"),
        pytest.param("fault_reset", "PRESS", "01 06 20 00 00 07 C3 C8", id="D7-button"),
        pytest.param("set_value", 50.0, "01 06 10 00 13 88 80 5C", id="D8"),
        pytest.param("set_value", -50.0, "01 06 10 00 EC 78 C1 E8", id="D9"),
        pytest.param("password_verification", 12345, "01 06 1F 00 30 39 5A 0C", id="D15"),
        pytest.param("lock_parameters", "PRESS", "01 06 1F 01 55 AA 60 F1", id="D17"),
    ],
)
def test_write_frames(key: str, value: object, frame: str) -> None:
    (write,) = encode(POINTS[key], value, {})
    assert build_frame(write, 1) == hexbytes(frame)


def test_d20_forward_run_ascii() -> None:
    (write,) = encode(POINTS["command"], "forward_run", {})
    assert build_frame(write, 1, "ascii") == b":010620000001D8\r\n"


def test_d16_password_accepted_echo_parses() -> None:
    """The drive may answer the password write with 8888H instead of echoing it."""
    pdu = parse_frame(hexbytes("01 06 1F 00 88 88 E8 78"))
    assert pdu.address == POINTS["password_verification"].write_address
    assert pdu.registers == [0x8888]


def test_reverse_is_not_a_command_choice() -> None:
    """Reverse run/jog exist only as the dangerous buttons (reverse is opt-in)."""
    with pytest.raises(ValueRejectedError):
        encode(POINTS["command"], 2, {})
    assert POINTS["reverse_run"].entity.dangerous
    assert POINTS["reverse_jog"].entity.dangerous


def test_set_value_limits() -> None:
    with pytest.raises(ValueRejectedError):
        encode(POINTS["set_value"], 100.01, {})
    (write,) = encode(POINTS["set_value"], -100, {})
    assert write.values == (0xD8F0,)


# --- derived read frames ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("keys", "frame"),
    [
        pytest.param(("status",), "01 03 30 00 00 01 8B 0A", id="D10"),
        pytest.param(("fault_code",), "01 03 80 00 00 01 AD CA", id="D11"),
        pytest.param(("set_speed", "analog_input_ai2"), "01 03 10 01 00 0B 51 0D", id="D12"),
        pytest.param(("pid_setpoint", "multi_speed_stage"), "01 03 10 10 00 03 00 CE", id="D13"),
        pytest.param(("torque_direction", "device_code"), "01 03 10 15 00 02 D1 0F", id="D14"),
    ],
)
def test_read_frames(keys: tuple[str, ...], frame: str) -> None:
    read = read_of(POINTS, *keys)
    assert read.count <= MAPPING.protocol.max_read_registers
    assert request_frame(read) == hexbytes(frame)


@pytest.mark.parametrize(
    ("raw", "status", "running"),
    [
        (1, "running_forward", True),
        (2, "running_reverse", True),
        (3, "standby", False),
        (4, "fault", False),
    ],
)
def test_status_word(raw: int, status: str, running: bool) -> None:
    image = _image("status", raw)
    assert decoded(POINTS, "status", image) == status
    assert decoded(POINTS, "running", image) is running


@pytest.mark.parametrize(
    ("raw", "label"),
    [
        (0x00, "no_fault"),
        (0x06, "overcurrent_constant_speed"),
        (0x0D, "reserved_0d"),
        (0x16, "pid_feedback_lost"),
        (0x17, "code_23"),  # reserved in the manual: published by its number, never lost
    ],
)
def test_fault_code(raw: int, label: str | None) -> None:
    image = _image("fault_code", raw)
    assert decoded(POINTS, "fault_code", image) == label


def test_set_value_decodes_signed() -> None:
    image = _image("set_value", 0xEC78)
    assert decoded(POINTS, "set_value", image) == -50.0


# --- exception replies --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("frame", "code", "action"),
    [
        pytest.param("01 83 07 00 F2", 7, "locked", id="D18"),
        pytest.param("01 86 06 C2 62", 6, "refused", id="D19"),
    ],
)
def test_exception_replies(frame: str, code: int, action: str) -> None:
    assert exception_code(parse_frame(hexbytes(frame))) == code
    assert MAPPING.protocol.exceptions[code].action == action


def test_every_exception_code_is_mapped() -> None:
    actions = {code: meaning.action for code, meaning in MAPPING.protocol.exceptions.items()}
    assert actions == {
        1: "fail",
        2: "refused",
        3: "retry",
        4: "refused",
        5: "refused",
        6: "refused",
        7: "locked",
        8: "busy",
    }


# --- addressing rule (source examples) ----------------------------------------------------


@pytest.mark.parametrize(
    ("printed", "wire"),
    [
        ("F3.01", 0xF301),
        ("E3.05", 0xA305),
        ("F0.08", 0xF008),
        ("F5.07", 0xF507),
        ("F9.05", 0xF905),
        ("y0.01", 0xC001),
        ("d0.00", 0x7000),
    ],
)
def test_parameter_addresses(printed: str, wire: int) -> None:
    assert to_wire(printed, MAPPING.protocol.addressing) == wire


def test_every_option_combination_and_button() -> None:
    for mode in MAPPING.options["control_mode"].choices:
        for shown in MAPPING.options["ascii_example_registers"].choices:
            points = MAPPING.points({"control_mode": mode, "ascii_example_registers": shown})
            for point in points.values():
                if point.entity.press is not None:
                    (write,) = encode(point, "PRESS", {})
                    assert write.function == 6
    torque = MAPPING.points({"control_mode": "torque"})
    assert torque["set_value"].entity.name == "Torque set value"
