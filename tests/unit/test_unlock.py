"""The password unlock's verdicts (bridge/modbus/unlock.py), with the device's answers to
the password write scripted: ``send`` is the bus the poller hands the unlocker."""

from __future__ import annotations

import asyncio

import pytest

from bridge.config import DeviceConfig
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.core.request import Write
from bridge.errors import DeviceExceptionError, DeviceTimeoutError
from bridge.modbus.unlock import Unlocker

LOCKED = DeviceExceptionError(7, "system locked", "locked")
P2 = load_mapping(builtin_mapping_path("p2_vfd")).protocol


def drive(**fields: object) -> DeviceConfig:
    base = {"id": "drive", "bus": "rs485", "unit": 1, "mapping": "p2_vfd"}
    return DeviceConfig.model_validate(base | fields)


class Drive:
    """A locked drive: answers ``locked`` until a password write succeeds; the password
    writes get ``answers`` in turn (an exception to raise, or the echo)."""

    def __init__(self, *answers: object) -> None:
        self.answers = list(answers)
        self.writes: list[Write] = []
        self.unlocked = False
        self.lockouts: list[str] = []

    async def request(self) -> tuple[int, ...]:
        if not self.unlocked:
            raise LOCKED
        return (1,)

    async def send(self, write: Write) -> tuple[int, ...]:
        self.writes.append(write)
        answer = self.answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        self.unlocked = True
        return answer  # type: ignore[return-value]


async def ask(unlocker: Unlocker, device: Drive) -> tuple[int, ...] | None:
    try:
        return await unlocker.submit(device.request, device.send, device.lockouts.append)
    except DeviceExceptionError:
        return None


@pytest.mark.asyncio
@pytest.mark.parametrize(
    "noise",
    [
        DeviceExceptionError(3, "CRC/LRC error", "retry"),
        DeviceExceptionError(8, "busy", "busy"),
        DeviceTimeoutError("unit 1 did not answer"),
    ],
)
async def test_noise_on_the_password_write_is_no_verdict(noise: Exception) -> None:
    """A garbled, busy or lost answer to the password write: the next locked request
    writes the password again and the drive is unlocked; no lockout."""
    device = Drive(noise, (0x8888,))
    unlocker = Unlocker(drive(password="12345"), P2)
    assert await ask(unlocker, device) is None
    assert device.lockouts == [] and unlocker.failed is None
    assert await ask(unlocker, device) == (1,)
    assert [w.values for w in device.writes] == [(12345,), (12345,)]


@pytest.mark.asyncio
async def test_a_wrong_password_is_a_verdict_written_once() -> None:
    device = Drive(DeviceExceptionError(1, "password error", "fail"))
    unlocker = Unlocker(drive(password="1"), P2)
    assert await ask(unlocker, device) is None
    assert await ask(unlocker, device) is None
    assert len(device.writes) == 1
    assert device.lockouts and all("wrong password" in r for r in device.lockouts)


@pytest.mark.asyncio
async def test_a_configured_password_that_cannot_be_read_is_said_so() -> None:
    device = Drive()
    unlocker = Unlocker(drive(password_env="NOT_SET_ANYWHERE_P2"), P2)
    assert await ask(unlocker, device) is None
    assert device.writes == []
    assert "devices.drive.password_* cannot be read now" in device.lockouts[0]


@pytest.mark.asyncio
async def test_a_request_answered_locked_after_a_relock_writes_the_password_again() -> None:
    """A request queued before another one's unlock but answered after the drive locked
    again (a power cycle) is not covered by that unlock: the password goes again, and the
    drive is not declared locked for good."""
    device = Drive((0x8888,), (0x8888,))
    unlocker = Unlocker(drive(password="12345"), P2)
    gate = asyncio.Event()

    async def queued() -> tuple[int, ...]:  # waits its turn on the bus
        await gate.wait()
        return await device.request()

    late = asyncio.create_task(unlocker.submit(queued, device.send, device.lockouts.append))
    await asyncio.sleep(0)
    assert await ask(unlocker, device) == (1,)  # locked, unlocked, answered
    device.unlocked = False  # power cycle: locked again
    gate.set()
    assert await late == (1,)
    assert len(device.writes) == 2 and device.lockouts == []
