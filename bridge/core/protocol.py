"""A device's Modbus protocol rules, declared in the header of its mapping file, and the
function code a write uses under them (``write_function``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from bridge.core.address import Addressing, PrintedAddress
from bridge.core.duration import Duration
from bridge.core.entity import Entity, Table

ALL_FUNCTION_CODES = (1, 2, 3, 4, 5, 6, 15, 16)


class ExceptionMeaning(BaseModel):
    """What a device means by one exception code, and what the bridge does about it.

    ``action``: ``fail`` (count as an error), ``retry`` (a transmission error: send again),
    ``busy`` (retry later, not a sign of death), ``refused`` (the address or value is not
    allowed: remember and do not retry), ``locked`` (the device needs an unlock first).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    action: Literal["fail", "retry", "busy", "refused", "locked"] = "fail"
    description: str | None = None


class Keepalive(BaseModel):
    """A device that needs traffic at least every ``interval`` (a communication watchdog)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    interval: Duration = Field(gt=0)
    note: str | None = None


class Unlock(BaseModel):
    """A device locked by a user password: it answers every request with an exception of
    action ``locked`` until the password is written (FC06) to ``address``. The bridge then
    writes the device's configured password once and sends the request again; an answer of
    ``wrong_password`` to that write means the password is wrong (the device is put in
    error, no second try). ``success``: the code the device answers on success, in the
    write's echo or read from ``address`` afterwards. ``lock``: where a lock command goes."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    address: PrintedAddress
    success: int | None = Field(None, ge=0, le=0xFFFF)
    wrong_password: int = Field(1, ge=1, le=255, description="exception code of a wrong password")
    lock: PrintedAddress | None = Field(
        None,
        description="the register a lock command is written to: refused while the bridge "
        "holds the password (it would unlock the device again at once)",
    )


class Segment(BaseModel):
    """An address range a read may not cross, with an optional tighter read limit."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    table: Table = Table.HOLDING
    start: PrintedAddress
    end: PrintedAddress
    max_read_registers: int | None = Field(None, ge=1, le=125)


class Reserved(BaseModel):
    """Addresses the manual marks reserved or unreadable: never read, never written."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    table: Table = Table.HOLDING
    start: PrintedAddress
    end: PrintedAddress | None = None
    note: str | None = None


class SerialDefaults(BaseModel):
    """The device's factory serial settings (for docs, `check` hints and `scan`)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    baudrate: int = 9600
    parity: Literal["N", "E", "O"] = "N"
    stopbits: Literal[1, 2] = 1
    bytesize: Literal[7, 8] = 8


class Protocol(BaseModel):
    """Per-device protocol limits and quirks. A device config may override the numbers."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    addressing: Addressing = Addressing()
    function_codes: tuple[int, ...] = ALL_FUNCTION_CODES
    max_read_registers: int = Field(125, ge=1, le=125)
    max_read_bits: int = Field(2000, ge=1, le=2000)
    max_write_registers: int = Field(123, ge=1, le=123)
    readable_gaps: bool = Field(True, description="may a read span addresses not in the map")
    coil_on_value: int = Field(0xFF00, ge=0, le=0xFFFF, description="FC05 ON value")
    exceptions: dict[int, ExceptionMeaning] = Field(default_factory=dict)
    min_request_interval: Duration = Field(0.0, description="silence between two requests")
    response_timeout: Duration = Field(1.0, gt=0)
    keepalive: Keepalive | None = None
    unlock: Unlock | None = Field(None, description="password unlock (the device's password)")
    eeprom_write_interval: Duration = Field(
        10.0, description="least time between two writes of one EEPROM-backed register"
    )
    segments: tuple[Segment, ...] = ()
    reserved: tuple[Reserved, ...] = ()
    serial: SerialDefaults = SerialDefaults()
    transports: tuple[Literal["rtu", "ascii", "tcp", "rtu-over-tcp"], ...] = ("rtu",)


def write_function(entity: Entity, protocol: Protocol) -> int:
    """The function code a write of ``entity`` uses: explicit, else by table and width."""
    if entity.write_function is not None:
        return entity.write_function
    supported = protocol.function_codes
    if entity.table is Table.COIL:
        return 5 if 5 in supported else 15
    if entity.register_count == 1 and 6 in supported:
        return 6
    return 16


class OptionSpec(BaseModel):
    """A per-device choice between model variants (selected in the config)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    description: str
    choices: tuple[str, ...] = Field(min_length=1)
    default: str
