"""One device's write path (bridge/modbus/writer.py) over a fake bus.

``FakeBus`` stands in for the device's link (bridge/modbus/device_link.py): a unit holding
registers, which answers reads from them, stores the register writes it takes and records
every frame that went out. It drops a frame whose command expired before it went out, as
the bus scheduler does right before a frame, and answers the next requests with scripted
failures. The writer, the device's state and the mapping are the real ones."""

from __future__ import annotations

import time
from typing import Any

import pytest

from bridge.config import DeviceConfig
from bridge.core.device_state import DeviceState
from bridge.core.entity import Table
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.planner import Address
from bridge.core.request import Read, Write, WriteSequence
from bridge.core.timing import LinkTiming
from bridge.core.write_plan import stored
from bridge.errors import (
    CommandExpiredError,
    CommandRejectedError,
    DeviceExceptionError,
    DeviceTimeoutError,
    MissingDataError,
    ModbusError,
    PartialWriteError,
)
from bridge.modbus.device_link import Refused
from bridge.modbus.scheduler import Priority
from bridge.modbus.writer import DeviceWriter
from tests.factory import make_mapping

pytestmark = pytest.mark.asyncio
H = Table.HOLDING
ILLEGAL_VALUE = DeviceExceptionError(3, "illegal data value", "refused")
MAPPING = make_mapping(
    {
        "speed": {"name": "Speed", "address": 1, "access": "rw", "scale": 0.1, "max": 50},
        "run": {"name": "Run", "address": 2, "access": "rw", "bit": 0},
        "reverse": {"name": "Reverse", "address": 2, "access": "rw", "bit": 1},
        "mode": {"name": "Mode", "address": 3, "enum": {0: "local", 1: "remote"}},
        "start": {"name": "Start", "address": 4, "access": "rw", "requires": {"mode": "remote"}},
        "setpoint": {"name": "Setpoint", "address": 5, "access": "rw", "eeprom": True},
        "factory_reset": {"name": "Factory reset", "address": 6, "access": "w", "dangerous": True},
        "kick": {
            "name": "Kick",
            "address": 7,
            "access": "rw",
            "idempotent": False,
            "write_interval": 10,
        },
        "blind": {"name": "Blind", "address": 8, "access": "rw", "verify": False},
        "limit": {"name": "Limit", "address": 9, "access": "rw"},
    }
)


class FakeBus:
    """A unit on a bus, standing in for the link: ``registers`` it holds, ``sent`` the
    frames that went out (with their priority, retries and deadline), ``failures`` the
    answers to the next requests (an error to raise, or None: answered), ``ceiling`` the
    most a register keeps of what is written to it."""

    def __init__(self, state: DeviceState, registers: dict[int, int], **device: Any) -> None:
        fields = {"id": "drive", "bus": "rs485", "unit": 1, "mapping": "test"} | device
        self.device = DeviceConfig.model_validate(fields)
        self.retries = 2
        self.state = state
        self.registers: dict[Address, int] = {(H, a): v for a, v in registers.items()}
        self.sent: list[tuple[Read | Write | WriteSequence, Priority, int | None, float | None]]
        self.sent = []
        self.failures: list[ModbusError | None] = []
        self.ceiling: dict[Address, int] = {}

    async def submit(
        self,
        request: Read | Write | WriteSequence,
        priority: Priority,
        retries: int | None = None,
        deadline: float | None = None,
    ) -> tuple[int, ...]:
        if deadline is not None and time.monotonic() > deadline:
            raise CommandExpiredError("expired before it went out")
        self.sent.append((request, priority, retries, deadline))
        failure = self.failures.pop(0) if self.failures else None
        if failure is not None:
            raise failure
        if isinstance(request, Read):
            return tuple(self.registers.get((request.table, a), 0) for a in request.span)
        for write in request.writes if isinstance(request, WriteSequence) else (request,):
            for address, value in stored(write).items():
                self.registers[address] = min(value, self.ceiling.get(address, value))
        return ()

    async def read_block(
        self,
        read: Read,
        priority: Priority,
        fresh: set[Address],
        refused: list[Refused] | None = None,
    ) -> bool:
        try:
            values = await self.submit(read, priority)
        except ModbusError:
            return False
        self.state.keep(read, values, fresh)
        return True

    @property
    def frames(self) -> list[Read | Write | WriteSequence]:
        return [request for request, *_ in self.sent]

    @property
    def writes(self) -> list[Write | WriteSequence]:
        return [r for r in self.frames if not isinstance(r, Read)]


class Device:
    """A writer over a fake bus, with what it passed on."""

    def __init__(
        self, registers: dict[int, int] | None = None, guard: Guard = UNGUARDED, **device: Any
    ) -> None:
        self.state = DeviceState(MAPPING, {}, timing=LinkTiming(), recheck=60.0, guard=guard)
        self.bus = FakeBus(self.state, registers or {}, **device)
        self.changes: list[frozenset[str]] = []
        self.writer = DeviceWriter(self.state, self.bus, self.changes.append)

    async def write(self, deadline: float | None = None, **items: object) -> dict[str, Any]:
        return await self.writer.write_many(dict(items), deadline=deadline)


# --- one key -----------------------------------------------------------------------------


async def test_a_write_goes_out_ahead_of_polls_and_is_read_back() -> None:
    device = Device({1: 100})
    assert await device.write(speed=21.5) == {"speed": 21.5}
    write, priority, retries, deadline = device.bus.sent[0]
    assert write == Write(6, H, 1, (215,))
    assert (priority, retries, deadline) == (Priority.WRITE, 2, None)  # idempotent: resent
    assert device.bus.frames[1:] == [Read(H, 1, 1)]  # the read back
    assert device.state.image[(H, 1)] == 215
    assert device.state.values["speed"] == 21.5
    assert device.changes == [frozenset({"speed"})]  # acknowledged; the read back agreed
    assert device.writer.counters.done == 1


async def test_the_read_back_says_what_the_device_holds() -> None:
    device = Device()
    device.bus.ceiling[(H, 1)] = 400  # the unit keeps 40.0, not 45.0
    assert await device.write(speed=45) == {"speed": 40.0}
    assert device.changes == [frozenset({"speed"}), frozenset({"speed"})]  # 45.0, then 40.0
    assert device.state.values["speed"] == 40.0


async def test_without_verify_the_value_sent_is_returned_unread() -> None:
    device = Device()
    assert await device.write(blind=3) == {"blind": 3}
    assert device.bus.frames == [Write(6, H, 8, (3,))]


async def test_a_toggle_is_never_resent_nor_sent_twice_within_its_interval() -> None:
    device = Device()
    await device.write(kick=1)
    assert device.bus.sent[0][2] == 0  # no resend: it may have acted
    sent = len(device.bus.sent)
    with pytest.raises(CommandRejectedError, match=r"kick was sent .* not again within 10 s"):
        await device.write(kick=1)
    assert len(device.bus.sent) == sent
    assert device.writer.counters.rejected == 1


async def test_a_toggle_that_timed_out_counts_as_sent() -> None:
    device = Device()
    device.bus.failures = [DeviceTimeoutError("no answer")]
    with pytest.raises(DeviceTimeoutError):
        await device.write(kick=1)
    assert device.writer.counters.failed == 1
    with pytest.raises(CommandRejectedError, match="not again within"):
        await device.write(kick=1)


# --- all or nothing, checked before anything goes out ------------------------------------


async def test_every_refused_key_is_named_and_nothing_is_sent_not_even_a_read() -> None:
    device = Device()
    with pytest.raises(CommandRejectedError) as refused:
        await device.write(run=True, mode="remote", nothing=1, factory_reset=1)
    assert set(refused.value.refused) == {"mode", "nothing", "factory_reset"}
    assert refused.value.refused["mode"] == "mode is read-only"
    assert "no such entity on drive" in refused.value.refused["nothing"]
    assert "guarded write" in refused.value.refused["factory_reset"]
    assert device.bus.sent == []  # not even the word of run's bit
    assert device.writer.counters.rejected == 1


async def test_a_guarded_write_goes_out_where_the_config_allows_it() -> None:
    device = Device(allow_dangerous_writes=True)
    await device.write(factory_reset=1)
    assert device.bus.frames == [Write(6, H, 6, (1,))]  # write-only: not read back


async def test_what_an_earlier_mapping_guarded_stays_guarded() -> None:
    earlier = make_mapping(
        {"wipe": {"name": "Wipe", "address": 9, "access": "w", "dangerous": True}}
    )
    device = Device(guard=Guard.of(earlier.points().values()))
    with pytest.raises(CommandRejectedError, match="limit is a guarded write"):
        await device.write(limit=8)
    assert device.bus.writes == []


async def test_a_value_out_of_range_refuses_the_whole_command_after_its_reads() -> None:
    device = Device({2: 0b10})
    with pytest.raises(CommandRejectedError) as refused:
        await device.write(run=True, speed=51)
    assert set(refused.value.refused) == {"speed"}
    assert device.bus.frames == [Read(H, 2, 1)]  # the word of the bit field: no write
    assert device.state.image == {(H, 2): 0b10}


async def test_a_condition_is_checked_on_a_fresh_read_of_what_it_requires() -> None:
    device = Device({3: 0})
    device.state.values["mode"] = "remote"  # as last polled: stale
    with pytest.raises(CommandRejectedError, match=r"Mode \(mode\) reads local, needs remote"):
        await device.write(start=1)
    assert device.bus.frames == [Read(H, 3, 1)]
    device.bus.registers[(H, 3)] = 1
    await device.write(start=1)
    assert Write(6, H, 4, (1,)) in device.bus.frames


async def test_a_key_with_conditions_goes_in_a_command_of_its_own() -> None:
    device = Device({3: 1})
    with pytest.raises(CommandRejectedError, match="send it in a command of its own"):
        await device.write(start=1, speed=1)
    assert device.bus.sent == []


async def test_a_read_the_write_depends_on_failing_fails_the_command() -> None:
    device = Device()
    device.bus.failures = [DeviceTimeoutError("no answer")]
    with pytest.raises(MissingDataError, match="cannot read holding 2"):
        await device.write(run=True)
    assert device.bus.writes == []
    assert device.writer.counters.failed == 1


# --- expiry: right before the frame ------------------------------------------------------


async def test_the_deadline_goes_with_the_write_frame_only() -> None:
    device = Device({2: 0})
    deadline = time.monotonic() + 60
    await device.write(deadline=deadline, run=True)
    deadlines = {type(request).__name__: d for request, _, _, d in device.bus.sent}
    assert deadlines == {"Read": None, "Write": deadline}


async def test_an_expired_command_is_dropped_and_its_spacing_left_as_it_was() -> None:
    device = Device()
    attempts = device.writer.counters.last_attempt
    long_ago = time.monotonic() - 11  # a kick sent before, outside its 10 s
    attempts[(H, 7)] = long_ago
    with pytest.raises(CommandExpiredError):
        await device.write(deadline=time.monotonic() - 1, kick=1)
    assert device.bus.sent == []
    assert device.state.image == {}
    assert device.writer.counters.expired == 1
    assert attempts == {(H, 7): long_ago}  # the kick that went out, not the one dropped
    await device.write(kick=1)
    assert device.bus.writes == [Write(6, H, 7, (1,))]


async def test_an_expired_resend_keeps_the_spacing_of_the_frame_that_went_out() -> None:
    device = Device()
    device.bus.failures = [CommandExpiredError("resend dropped", sent=True)]
    with pytest.raises(CommandExpiredError):
        await device.write(kick=1)
    with pytest.raises(CommandRejectedError, match="not again within"):
        await device.write(kick=1)


# --- compound writes ---------------------------------------------------------------------


async def test_two_bit_fields_of_one_word_go_out_as_one_frame_keeping_the_other_bits() -> None:
    device = Device({2: 0b1000_0000})
    assert await device.write(run=True, reverse=True) == {"run": True, "reverse": True}
    assert device.bus.writes == [Write(6, H, 2, (0b1000_0011,))]


async def test_keys_of_several_registers_go_out_as_one_sequence_with_its_undo() -> None:
    device = Device({1: 100, 9: 7})
    device.state.image |= {(H, 1): 100, (H, 9): 7}  # as polled
    await device.write(speed=20, limit=8)
    (sequence,) = device.bus.writes
    assert isinstance(sequence, WriteSequence)
    assert sequence.writes == (Write(6, H, 1, (200,)), Write(6, H, 9, (8,)))
    assert sequence.undo[0] == Write(6, H, 1, (100,))  # what the device held before


async def test_a_sequence_failing_half_way_says_what_the_device_holds_now() -> None:
    device = Device({1: 100, 9: 7})
    device.state.image |= {(H, 1): 100, (H, 9): 7}
    partial = PartialWriteError(1, 2, restored=True, cause=ILLEGAL_VALUE)
    device.bus.failures = [partial]
    with pytest.raises(PartialWriteError) as failed:
        await device.write(speed=20, limit=8)
    assert failed.value.restored
    assert str(failed.value).endswith("the device now reads speed=10.0, limit=7")
    assert device.state.image == {(H, 1): 100, (H, 9): 7}  # nothing stored as written
    assert device.writer.counters.failed == 1


async def test_a_write_the_device_refuses_leaves_the_image_as_it_was() -> None:
    device = Device()
    device.bus.failures = [ILLEGAL_VALUE]
    with pytest.raises(DeviceExceptionError):
        await device.write(limit=8)
    assert device.state.image == {}
    assert device.changes == []
    assert device.writer.counters.failed == 1


# --- EEPROM ------------------------------------------------------------------------------


async def test_an_unchanged_eeprom_parameter_is_not_written_again() -> None:
    device = Device({5: 30})
    assert await device.write(setpoint=30) == {"setpoint": 30}
    assert device.bus.frames == [Read(H, 5, 1)]  # read fresh to compare: no write
    assert device.writer.counters.skipped_unchanged == 1
    assert device.writer.counters.done == 0


async def test_an_eeprom_parameter_is_rewritten_at_most_once_per_interval() -> None:
    device = Device({5: 30})
    await device.write(setpoint=31)
    with pytest.raises(CommandRejectedError, match="stored in EEPROM: next write allowed"):
        await device.write(setpoint=32)
    assert device.bus.writes == [Write(6, H, 5, (31,))]


async def test_a_new_writer_inherits_the_spacing_of_the_one_it_replaces() -> None:
    device = Device()
    await device.write(kick=1)
    successor = Device()
    successor.writer.inherit(device.writer)
    with pytest.raises(CommandRejectedError, match="not again within"):
        await successor.write(kick=1)
