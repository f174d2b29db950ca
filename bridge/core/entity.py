"""One entity of a mapping: where its value lives, how it is typed, and how Home Assistant shows it.

An entity is a value a user sees (a sensor, a setting, an alarm bit, a command). Any
number of entities may share a register: bit and nibble fields of one status word, a
whole word next to its bits, a raw word beside its switch and select (``overlap``). Field
checks that need no other entity live here; cross-entity checks (references, overlaps,
function codes) live in ``checks.py`` and ``overlap.py``.

One piece, at about 550 lines: it is the schema of a mapping file's entity, and a reader
checking a row against it needs the field, its enum and its check side by side. The
enums (``Table``, ``DataType``, ...) are the field types; the ``_check_*`` functions are
the entity's own validator, split by subject only to stay readable, and run in
``Entity``'s ``model_validator``. Moving either out would leave the model saying less
than what it accepts.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from enum import StrEnum
from functools import cached_property
from typing import Annotated, Any, Self

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from bridge.core.address import PrintedAddress
from bridge.core.duration import Duration, parse_duration


class Table(StrEnum):
    """The four Modbus data tables."""

    HOLDING = "holding"
    INPUT = "input"
    COIL = "coil"
    DISCRETE = "discrete"

    @property
    def is_bits(self) -> bool:
        return self in (Table.COIL, Table.DISCRETE)

    @property
    def read_function(self) -> int:
        return {"coil": 1, "discrete": 2, "holding": 3, "input": 4}[self.value]


class DataType(StrEnum):
    """Register types. 32-bit types span two registers, 64-bit types four (``word_order``
    little: the four words in reverse, Home Assistant's ``swap: word``); ``f16`` is a
    half-precision float in one register; ``ascii`` spans ``count``."""

    U16 = "u16"
    S16 = "s16"
    U32 = "u32"
    S32 = "s32"
    F32 = "f32"
    F16 = "f16"
    U64 = "u64"
    S64 = "s64"
    F64 = "f64"
    ASCII = "ascii"
    BOOL = "bool"

    @property
    def is_float(self) -> bool:
        return self in (DataType.F16, DataType.F32, DataType.F64)


class Access(StrEnum):
    READ = "r"
    READ_WRITE = "rw"
    WRITE = "w"


class PollClass(StrEnum):
    FAST = "fast"
    SLOW = "slow"
    ONCE = "once"


MAX_EXPONENT = 10  # a scale_by exponent beyond +-10 (0x8000: not implemented) reads unknown
MIN_INTERVAL = 0.1  # seconds: the shortest own interval (a bus answers in tens of ms)
MAX_INTERVAL = 31 * 86400.0  # seconds: 31 days, the longest own interval (a weekly read fits)

PollSpec = PollClass | float


def parse_poll(value: object) -> PollSpec:
    """``fast``/``slow``/``once`` or an interval (``10``, ``"10s"``, ``"1m"``) within
    ``MIN_INTERVAL``..``MAX_INTERVAL``; raise ValueError with the accepted forms."""
    if isinstance(value, PollClass):
        return value
    if isinstance(value, str) and value in PollClass.__members__.values():
        return PollClass(value)
    try:
        seconds = parse_duration(value)
    except ValueError as exc:
        raise ValueError(f"poll must be fast, slow, once or an interval: {exc}") from None
    if not MIN_INTERVAL <= seconds <= MAX_INTERVAL:
        raise ValueError(
            f"a poll interval must be within {MIN_INTERVAL:g} s and {MAX_INTERVAL:.0f} s "
            f"(31 days), not {seconds:.10g} s"
        )
    return seconds


class Component(StrEnum):
    """Home Assistant MQTT platforms the bridge publishes."""

    SENSOR = "sensor"
    BINARY_SENSOR = "binary_sensor"
    NUMBER = "number"
    SELECT = "select"
    SWITCH = "switch"
    BUTTON = "button"
    TEXT = "text"


class Confidence(StrEnum):
    """How sure the device document is of a row; ``low`` rows stay disabled in Home Assistant."""

    HIGH = "high"
    MEDIUM = "medium"
    LOW = "low"


class Order(StrEnum):
    BIG = "big"
    LITTLE = "little"


_STATE_CLASSES = ("measurement", "measurement_angle", "total", "total_increasing")
_CATEGORIES = ("config", "diagnostic")
_WIDTH = {DataType.U32: 2, DataType.S32: 2, DataType.F32: 2}
_WIDTH |= {DataType.U64: 4, DataType.S64: 4, DataType.F64: 4}
_UNKNOWN_LABEL = re.compile(r"^code_-?\d+$")  # codec.unknown_code


class Presentation(BaseModel):
    """Home Assistant presentation of one entity. Unset fields are derived (see Entity)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    component: Component | None = None
    device_class: str | None = None
    state_class: str | None = Field(None, pattern="^(" + "|".join(_STATE_CLASSES) + ")$")
    entity_category: str | None = Field(None, pattern="^(" + "|".join(_CATEGORIES) + ")$")
    icon: str | None = Field(None, pattern=r"^mdi:[a-z0-9-]+$")
    enabled: bool | None = Field(None, description="enabled by default in Home Assistant")
    enabled_reason: str | None = Field(
        None,
        min_length=1,
        description="why a diagnostic entity (or a dangerous setting) is enabled by default: "
        "the first thing to look at when something is wrong",
    )
    display_precision: int | None = Field(None, ge=0, le=6)
    mode: str | None = Field(None, pattern="^(auto|box|slider)$", description="number mode")
    entity_id: str | None = Field(
        None,
        pattern=r"^[a-z0-9_]+$",
        max_length=200,
        description="the entity id asked of Home Assistant, after the platform (default "
        "<device>_<key>): an imported entity keeps the id Home Assistant's modbus gave it",
    )


class Simulation(BaseModel):
    """How the simulator (``simulate``, ``demo``) shows an entity, where its device class
    and unit do not say it (``bridge/core/simulation_range.py`` has the table): the range
    a measurement moves in and its typical value, a counter's rate, or the entity whose
    value it shows (a set value in use follows the set value)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    min: float | None = None
    max: float | None = None
    typical: float | None = None
    per_hour: float | None = Field(None, ge=0, description="a counter's rise per running hour")
    follows: str | None = Field(None, description="key of the entity whose value this shows")
    state: str | None = Field(
        None, description="the option an enum starts at (what a running device shows)"
    )

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        low = self.min if self.min is not None else float("-inf")
        high = self.max if self.max is not None else float("inf")
        if low > high or not low <= (self.typical if self.typical is not None else low) <= high:
            raise ValueError("needs min <= typical <= max")
        return self


class RawRange(BaseModel):
    """Inclusive range of raw values, for ``on_when``."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    min: int | None = None
    max: int | None = None


class SwitchWords(BaseModel):
    """The words a switch on a register writes for ON and OFF, and the words it reads as
    on or off, when they are not 1 and 0 (a relay module that takes 0x0100 to close and
    0x0200 to open). A word read that is in neither list is published as unknown: the
    switch's state is not guessed. Commands stay ON/OFF; only these words are written."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    write_on: int = Field(ge=0, le=0xFFFF, description="the word written for ON")
    write_off: int = Field(ge=0, le=0xFFFF, description="the word written for OFF")
    read_on: tuple[Annotated[int, Field(ge=0, le=0xFFFF)], ...] | None = Field(
        None, min_length=1, max_length=16, description="words read as on (default: write_on)"
    )
    read_off: tuple[Annotated[int, Field(ge=0, le=0xFFFF)], ...] | None = Field(
        None, min_length=1, max_length=16, description="words read as off (default: write_off)"
    )

    @model_validator(mode="after")
    def _distinct(self) -> Self:
        if self.write_on == self.write_off:
            raise ValueError("write_on and write_off are different words")
        if set(self.on_words) & set(self.off_words):
            raise ValueError("a word cannot read as both on and off")
        return self

    @property
    def on_words(self) -> tuple[int, ...]:
        return self.read_on if self.read_on is not None else (self.write_on,)

    @property
    def off_words(self) -> tuple[int, ...]:
        return self.read_off if self.read_off is not None else (self.write_off,)

    def state(self, word: int) -> bool | None:
        """On, off, or None (unknown) for a word that is neither."""
        if word in self.on_words:
            return True
        return False if word in self.off_words else None


class ReadingLimits(BaseModel):
    """Limits a reading is shown within (Home Assistant's sensor ``min_value`` and
    ``max_value``): a value below ``min`` reads ``min``, above ``max`` reads ``max``."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    min: float | None = Field(None, allow_inf_nan=False)
    max: float | None = Field(None, allow_inf_nan=False)

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        if self.min is None and self.max is None:
            raise ValueError("give min, max or both")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"min {self.min} is above max {self.max}")
        return self


class StateLink(BaseModel):
    """Where a write-only select's state is read: an enum entity's label, shown as one of
    the select's options (the drive's status ``standby`` as the command ``stop``). A label
    not listed shows the select's state as unknown: a command word the device does not
    read back has no state of its own to remember."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    entity: str = Field(description="key of a readable enum entity")
    labels: dict[str, str] = Field(
        min_length=1, description="a label of that entity -> the option it shows"
    )


class Variant(BaseModel):
    """Field values that replace the entity's own for some device option values.

    Used where a real device may differ from the manual's reading (Smartgen frequency at
    0.1 Hz or 0.01 Hz): the key stays the same, the option picks the reading.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    when: dict[str, str | list[str]] = Field(min_length=1)
    name: str | None = None
    scale: float | None = None
    offset: float | None = None
    precision: int | None = None
    unit: str | None = None
    word_radix: int | None = None
    min: float | None = None
    max: float | None = None
    step: float | None = None
    confidence: Confidence | None = None
    note: str | None = None
    ha: Presentation | None = None

    def overrides(self) -> dict[str, Any]:
        """The fields this variant sets; ``ha`` fields merge into the entity's own, and an
        explicit ``null`` there clears one (a device class that no longer fits)."""
        fields = self.model_dump(exclude={"when", "ha"}, exclude_none=True, exclude_unset=True)
        if self.ha is not None:
            fields["ha"] = self.ha.model_dump(exclude_unset=True)
        return fields


class Entity(BaseModel):
    """One named value of a device. Addresses are written as printed in the manual."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, description="entity name without the device name")
    address: PrintedAddress
    table: Table = Table.HOLDING
    type: DataType | None = Field(
        None, description="default: bool on bit tables, else u16; bool on a register: 0/1 word"
    )
    count: int | None = Field(None, ge=1, le=125, description="registers of an ascii value")
    word_order: Order = Order.BIG
    byte_order: Order = Order.BIG
    word_radix: int = Field(65536, ge=2, le=65536, description="u32 = high * radix + low")
    bit: int | None = Field(None, ge=0, le=15, description="lowest bit of a bit/nibble field")
    width: int | None = Field(None, ge=1, le=16, description="bits in the field (default 1)")
    scale: float = 1.0
    scale_by: str | None = Field(
        None,
        description="key of an s16 entity of the same table holding a power-of-ten exponent "
        "(a SunSpec sunssf): value = raw x 10**exponent x scale + offset, both read in one "
        "request; an exponent outside -10..10 (0x8000: not implemented) reads unknown",
    )
    offset: float = 0.0
    precision: int | None = Field(None, ge=0, le=6, description="decimals; default from scale")
    unit: str | None = None
    unit_from: str | None = Field(None, description="key of an enum entity whose label is unit")
    sign_from: str | None = Field(None, description="key of a 1-bit entity: 1 = negative")
    enum: dict[int, str] | None = None
    sentinels: dict[int, str] = Field(
        default_factory=dict, description="raw (unsigned) values meaning 'unknown', with reason"
    )
    on_when: RawRange | None = Field(None, description="boolean: raw value within this range")
    words: SwitchWords | None = Field(
        None,
        description="a switch on a register: the words it writes for ON/OFF and reads as "
        "on/off, when not 1 and 0 (another word reads as unknown)",
    )
    clamp: ReadingLimits | None = Field(
        None, description="a read-only number: a reading outside {min, max} shows the limit"
    )
    zero_suppress: float | None = Field(
        None,
        ge=0,
        allow_inf_nan=False,
        description="a read-only number: a reading whose size is at most this shows 0",
    )
    min: float | None = None
    max: float | None = None
    min_from: str | None = Field(None, description="key of the entity holding the lower limit")
    max_from: str | None = Field(None, description="key of the entity holding the upper limit")
    step: float | None = Field(None, gt=0)
    access: Access = Access.READ
    write_address: PrintedAddress | None = None
    write_function: int | None = Field(None, description="5, 6, 15 or 16; default by table")
    press: bool | int | float | str | None = Field(None, description="value a button writes")
    pulse: bool = Field(False, description="write the bit 1 then 0 (rising-edge commands)")
    verify: bool = Field(True, description="read back after a write")
    verify_delay: Duration | None = Field(
        None,
        gt=0,
        le=60,
        description="wait this long after a write before reading it back (a device that "
        "takes time to act; Home Assistant's verify delay); the bus serves others meanwhile",
    )
    idempotent: bool = Field(True, description="false: never retried after a timeout (toggles)")
    toggle_of: str | None = Field(
        None,
        description="a write-only coil that toggles the state of this boolean entity: a "
        "switch whose ON/OFF is sent (as the ON word) only when the state read differs",
    )
    state_from: StateLink | None = Field(
        None,
        description="a write-only select's state, read from an enum entity (label -> "
        "option); without it the select shows no state",
    )
    write_interval: Duration | None = Field(
        None,
        gt=0,
        description="least time between two writes (a toggle is never sent twice within)",
    )
    requires: dict[str, bool | str | list[str]] = Field(
        default_factory=dict,
        description="entity key -> the value(s) it must read for a write to be sent "
        "(a controller in the mode that accepts remote commands)",
    )
    eeprom: bool = Field(False, description="non-volatile: skip unchanged writes, rate limit")
    dangerous: bool = Field(False, description="write only when the config allows it")
    dangerous_below: float | None = Field(
        None,
        description="a value below this is a guarded write, like a dangerous one (a negative "
        "speed reference runs the motor in reverse)",
    )
    confirm_reset: int | None = Field(
        None,
        ge=1,
        le=100,
        description="a counter: lower readings in a row that confirm a reset (default 3)",
    )
    secret: bool = Field(False, description="never published (passwords)")
    alarm: bool = Field(False, description="an alarm: bool when on, enum when not normal")
    normal: tuple[int, ...] = Field((0,), description="raw enum values that are not an alarm")
    poll: Annotated[PollClass | float, BeforeValidator(parse_poll)] | None = Field(
        None,
        description="fast, slow, once or its own interval (seconds, or '10s', '5m'; "
        "0.1 s to 31 days); default: slow when writable, else fast",
    )
    confidence: Confidence = Confidence.HIGH
    when: dict[str, str | list[str]] = Field(
        default_factory=dict, description="present only for these device option values"
    )
    variants: tuple[Variant, ...] = Field((), description="first matching variant applies")
    note: str | None = None
    simulate: Simulation | None = Field(
        None, description="the simulator's range, typical value or counter rate, or follows"
    )
    ha: Presentation = Presentation()

    def with_variant(self, variant: Variant) -> Entity:
        """This entity with a variant's fields applied (validated again)."""
        data = self.model_dump(exclude_unset=True, exclude={"variants"})
        overrides = variant.overrides()
        if "ha" in overrides:
            overrides["ha"] = data.get("ha", {}) | overrides["ha"]
        return Entity.model_validate(data | overrides)

    # --- derived facts (computed once per entity: they are read on every decode) ------

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False) -> Self:
        """A copy whose derived facts are computed again (a copy with ``update`` would
        otherwise keep the ones of the original)."""
        copy = super().model_copy(update=update, deep=deep)
        for name in _DERIVED:
            copy.__dict__.pop(name, None)
        return copy

    @cached_property
    def data_type(self) -> DataType:
        if self.type is not None:
            return self.type
        return DataType.BOOL if self.table.is_bits else DataType.U16

    @cached_property
    def register_count(self) -> int:
        """Registers (or bits) the value spans on the wire."""
        if self.data_type is DataType.ASCII:
            return self.count or 1
        return _WIDTH.get(self.data_type, 1)

    @cached_property
    def field_width(self) -> int | None:
        """Bits of a bit/nibble field, or None for a whole value."""
        if self.bit is None:
            return None
        return self.width or 1

    @cached_property
    def readable(self) -> bool:
        return self.access is not Access.WRITE

    @cached_property
    def writable(self) -> bool:
        return self.access is not Access.READ

    @cached_property
    def kind(self) -> str:
        """What the decoded value is: ``bool``, ``enum``, ``text`` or ``number``."""
        if self.enum is not None:
            return "enum"
        if self.data_type is DataType.ASCII:
            return "text"
        if self.data_type is DataType.BOOL or self.on_when is not None or self.field_width == 1:
            return "bool"
        return "number"

    @cached_property
    def component(self) -> Component:
        """The Home Assistant platform, from ``ha.component`` or derived from kind and access."""
        if self.ha.component is not None:
            return self.ha.component
        if self.press is not None:
            return Component.BUTTON
        readonly = {"bool": Component.BINARY_SENSOR}
        writable = {
            "bool": Component.SWITCH,
            "enum": Component.SELECT,
            "text": Component.TEXT,
            "number": Component.NUMBER,
        }
        table = writable if self.writable else readonly
        return table.get(self.kind, Component.SENSOR)

    @cached_property
    def poll_spec(self) -> PollClass | float:
        """``poll``, else ``slow`` when writable, ``fast`` when not (bridge/core/schedule.py
        turns it into seconds)."""
        if self.poll is not None:
            return self.poll
        return PollClass.SLOW if self.writable else PollClass.FAST

    @cached_property
    def poll_class(self) -> PollClass | None:
        """The named poll class, or None when the entity has an interval of its own."""
        spec = self.poll_spec
        return spec if isinstance(spec, PollClass) else None

    @cached_property
    def shown_as_diagnostic(self) -> bool:
        """Diagnostic, or a dangerous setting: Home Assistant shows it read-only, as a
        diagnostic sensor, until the device allows dangerous writes (changed when the
        device is commissioned, not in daily use)."""
        category = self.ha.entity_category
        return category == "diagnostic" or (category == "config" and self.dangerous)

    @cached_property
    def enabled_by_default(self) -> bool:
        """``ha.enabled``, else: enabled unless low confidence or shown as diagnostic."""
        if self.ha.enabled is not None:
            return self.ha.enabled
        return self.confidence is not Confidence.LOW and not self.shown_as_diagnostic

    @cached_property
    def decimals(self) -> int:
        """Decimals of the engineering value: ``precision`` or those of scale and offset."""
        if self.precision is not None:
            return self.precision
        return max(_decimals_of(self.scale), _decimals_of(self.offset))

    # --- checks that need only this entity -----------------------------------------

    @model_validator(mode="after")
    def _check_fields(self) -> Self:
        problems = [check(self) for check in _FIELD_CHECKS]
        errors = [p for p in problems if p]
        if errors:
            raise ValueError("; ".join(errors))
        return self


_DERIVED = (
    "data_type",
    "register_count",
    "field_width",
    "readable",
    "writable",
    "kind",
    "component",
    "poll_spec",
    "poll_class",
    "shown_as_diagnostic",
    "enabled_by_default",
    "decimals",
)


def _decimals_of(number: float) -> int:
    text = repr(float(number))
    if "e-" in text:
        return int(text.split("e-")[1])
    fraction = text.split(".")[1].rstrip("0") if "." in text else ""
    return len(fraction)


def _check_table_type(e: Entity) -> str | None:
    if e.table.is_bits and e.data_type is not DataType.BOOL:
        return f"a {e.table.value} entity has type bool, not {e.data_type.value}"
    if e.data_type is DataType.BOOL and e.bit is not None:
        return "a bit field is a boolean already: drop type bool"
    if e.table is Table.DISCRETE and e.writable:
        return "discrete inputs are read-only"
    if e.table is Table.INPUT and e.writable:
        return "input registers are read-only"
    return None


def _check_shape(e: Entity) -> str | None:
    if (e.count is not None) != (e.data_type is DataType.ASCII):
        return "count is given for ascii values, and only for them"
    if e.bit is not None:
        if e.data_type not in (DataType.U16, DataType.S16):
            return "bit fields are taken from u16 registers"
        if e.bit + (e.width or 1) > 16:
            return f"bit {e.bit} + width {e.width} exceeds the 16-bit register"
    elif e.width is not None:
        return "width needs bit"
    if e.word_radix != 65536 and e.data_type is not DataType.U32:
        return "word_radix applies to u32 values only"
    return None


def _check_numeric(e: Entity) -> str | None:
    scaled = e.scale != 1.0 or e.offset != 0.0
    if e.scale == 0:
        return "scale cannot be 0"
    if scaled and e.kind != "number":
        return f"scale/offset apply to numbers, not to {e.kind} values"
    if e.scale_by is not None and (e.kind != "number" or e.data_type.is_float):
        return "scale_by scales an integer number (not a float, text, enum or boolean)"
    if e.scale_by is not None and e.dangerous_below is not None:
        return "dangerous_below is judged on a fixed scale: not with scale_by"
    if e.min is not None and e.max is not None and e.min > e.max:
        return f"min {e.min} is above max {e.max}"
    if e.sign_from and e.data_type is not DataType.U16:
        return "sign_from takes a magnitude from a u16 register"
    if (e.unit or e.unit_from) and e.kind != "number":
        return "unit applies to numbers"
    if e.unit and e.unit_from:
        return "give unit or unit_from, not both"
    if (e.clamp is not None or e.zero_suppress is not None) and (e.kind != "number" or e.writable):
        return "clamp/zero_suppress shape the readings of a read-only number"
    return None


def _check_words(e: Entity) -> str | None:
    """``words``: a whole-register switch that writes one word for ON, another for OFF."""
    if e.words is None:
        return None
    if e.data_type is not DataType.BOOL or e.table is not Table.HOLDING:
        return "words are for a switch on a holding register (type bool)"
    if not e.writable or e.press is not None or e.pulse:
        return "words are written: a switch with access rw or w (not a button or pulse)"
    if e.byte_order is not Order.BIG:
        return "words are given as on the wire: drop byte_order"
    if e.write_function not in (None, 6, 16):
        return "words are written to a register: write_function 6 or 16"
    return None


def _check_enum(e: Entity) -> str | None:
    if e.enum is None:
        return None
    if e.data_type is DataType.ASCII or e.data_type.is_float:
        return "enum needs an integer type"
    labels = list(e.enum.values())
    if len(set(labels)) != len(labels):
        return "enum labels must be unique"
    if any(not label.strip() for label in labels):
        return "enum labels cannot be empty"
    if any(_UNKNOWN_LABEL.match(label) for label in labels):
        return "enum labels 'code_<n>' are reserved for codes the mapping has no label for"
    return None


def _check_write(e: Entity) -> str | None:
    if e.press is not None and e.access is not Access.WRITE:
        return "press (a button) needs access: w"
    if e.pulse and (e.access is not Access.WRITE or (e.field_width != 1 and not e.table.is_bits)):
        return "pulse is for a write-only single bit or coil"
    if e.write_function is not None and e.write_function not in (5, 6, 15, 16):
        return "write_function is one of 5, 6, 15, 16"
    if not e.writable and (e.write_address is not None or e.write_function is not None):
        return "write_address/write_function need access rw or w"
    if (e.dangerous or e.eeprom) and not e.writable:
        return "dangerous/eeprom describe writes; the entity is read-only"
    if e.on_when is not None and e.writable:
        return "on_when derives a read-only boolean"
    if e.access is Access.WRITE and e.alarm:
        return "a write-only entity cannot be an alarm"
    if (e.requires or e.write_interval is not None) and not e.writable:
        return "requires/write_interval describe writes; the entity is read-only"
    if e.verify_delay is not None and not (e.writable and e.readable and e.verify):
        return "verify_delay delays the read back of a readable, written entity (verify on)"
    if e.toggle_of is not None and (
        e.table is not Table.COIL or e.access is not Access.WRITE or e.press is not None or e.pulse
    ):
        return "toggle_of is for a write-only coil that is not a button (a switch)"
    return _check_state_from(e) or _check_dangerous_below(e) or _check_simulated_state(e)


def _check_simulated_state(e: Entity) -> str | None:
    """``simulate.state`` is one of the enum's options."""
    state = e.simulate.state if e.simulate is not None else None
    if state is None:
        return None
    if state not in (e.enum or {}).values():
        return f"simulate.state: {state!r} is not one of the options"
    return None


def _check_state_from(e: Entity) -> str | None:
    """``state_from`` gives a write-only select a state, in its own options."""
    if e.state_from is None:
        return None
    if e.access is not Access.WRITE or e.component is not Component.SELECT:
        return "state_from is for a write-only select (a readable entity shows what it reads)"
    unknown = sorted(set(e.state_from.labels.values()) - set((e.enum or {}).values()))
    if unknown:
        return f"state_from.labels: {', '.join(map(repr, unknown))} is not one of the options"
    return None


def _check_dangerous_below(e: Entity) -> str | None:
    """``dangerous_below`` is judged on the raw word of one big-endian 16-bit register."""
    if e.dangerous_below is None:
        return None
    if not e.writable or e.kind != "number":
        return "dangerous_below guards writes of a number"
    if e.data_type not in (DataType.U16, DataType.S16) or e.bit is not None:
        return "dangerous_below applies to a whole u16 or s16 register"
    if e.sign_from is not None or e.byte_order is not Order.BIG or e.scale <= 0:
        return "dangerous_below needs the sign in the register itself and a positive scale"
    return None


def _check_presentation(e: Entity) -> str | None:
    if e.confidence is Confidence.LOW and e.ha.enabled:
        return "a low-confidence entity stays disabled by default (ha.enabled: false)"
    if e.ha.enabled_reason is not None and e.ha.enabled is not True:
        return "enabled_reason explains an explicit ha.enabled: true"
    if e.alarm and e.kind not in ("bool", "enum"):
        return "alarm entities are booleans or enums"
    if e.ha.entity_category == "config" and not e.writable:
        return "Home Assistant refuses entity_category config on read-only entities"
    if e.ha.state_class and e.kind != "number":
        return "state_class applies to numbers"
    return None


_FIELD_CHECKS = (
    _check_table_type,
    _check_shape,
    _check_numeric,
    _check_enum,
    _check_words,
    _check_write,
    _check_presentation,
)


def describe(entity: Entity) -> dict[str, Any]:
    """The entity's non-default fields, for ``mappings show``."""
    return entity.model_dump(exclude_defaults=True, mode="json")
