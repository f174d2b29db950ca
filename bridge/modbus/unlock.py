"""The password unlock of one device (``protocol.unlock`` in its mapping, the password in its
config): the P2 drive answers exception 07 (system locked) to everything until its user
password is written to 1F00H.

``Unlocker.submit(attempt, send, locked_out)`` sends a request; when the device answers it
``locked``, ``unlock`` writes the password once (FC06, ahead of the polls; resent like
any idempotent write only after no answer or a "send again" exception, within the bus's
retries) and the request goes again. Requests that were locked together share one unlock. The device
is put in error, with the reason, and never unlocked again while this poller lives (a
mapping reload or a restart starts afresh) when

* no password is configured (nothing is written),
* the device answers the password write with ``wrong_password`` (P2: exception 01), or
* the device is still locked right after an unlock that it accepted.

A password write that gets no answer, a "send again" (CRC) or a busy answer is no
verdict: the next locked request tries again. So a wrong password costs one write, not
one per poll. The password is never logged,
published or put in an error message.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Awaitable, Callable

from bridge.config import DeviceConfig, is_register_number
from bridge.core.address import to_wire
from bridge.core.entity import Table
from bridge.core.protocol import Protocol
from bridge.core.request import Write
from bridge.errors import DeviceExceptionError, ModbusError

log = logging.getLogger(__name__)

Send = Callable[[Write], Awaitable[tuple[int, ...]]]


class Unlocker:
    """Unlocks one device with its password, at most once per lock."""

    def __init__(self, device: DeviceConfig, protocol: Protocol) -> None:
        self.device = device
        self.protocol = protocol
        self.unlocked_at = -math.inf  # time.monotonic() when the last unlock was accepted
        self.failed: str | None = None  # why the device stays locked (then: no more tries)
        self._lock = asyncio.Lock()

    async def submit(
        self,
        attempt: Callable[[], Awaitable[tuple[int, ...]]],
        send: Send,
        locked_out: Callable[[str], None],
    ) -> tuple[int, ...]:
        """``attempt()`` (one request); when the device answers ``locked``, unlock it with
        ``send`` and attempt once more. ``locked_out(reason)`` when it stays locked."""
        try:
            return await attempt()
        except DeviceExceptionError as exc:
            if exc.action != "locked":
                raise
            if not await self.unlock(time.monotonic(), send):
                if self.failed is not None:
                    locked_out(self.failed)
                raise
        try:
            return await attempt()
        except DeviceExceptionError as exc:
            if exc.action == "locked":
                locked_out(self.still_locked())
            raise

    async def unlock(self, answered: float, send: Send) -> bool:
        """After a ``locked`` answer that came at ``answered`` (monotonic): True when the
        request should be sent again (this call or another one unlocked the device). One
        frame is in flight per bus, so an unlock accepted after that answer covers it; a
        locked answer after the last unlock (the device locked again: a power cycle) needs
        the password again, even for a request queued before that unlock."""
        async with self._lock:
            if self.failed is not None:
                return False
            if self.unlocked_at > answered:
                return True  # unlocked meanwhile by another request
            return await self._write_password(send)

    def still_locked(self) -> str:
        """The request sent again after an unlock was answered ``locked`` again."""
        self.failed = (
            "still locked after its password was accepted: check the password and the "
            "device's lock (parameter lock command)"
        )
        return self.failed

    async def _write_password(self, send: Send) -> bool:
        spec = self.protocol.unlock
        where = f"devices.{self.device.id}"
        if spec is None:
            self.failed = "locked by a password, and its mapping has no password unlock"
            return False
        password = self.device.password_value()
        if password is None or not is_register_number(password):
            self.failed = (
                f"locked by a password, and {where}.password_* cannot be read now or is not a "
                "number 0..65535"
                if self.device.has_password
                else f"locked by a password: set {where}.password_env or {where}.password_file "
                "(a number 0..65535)"
            )
            return False
        address = to_wire(spec.address, self.protocol.addressing)
        try:
            echo = await send(Write(6, Table.HOLDING, address, (int(password),)))
        except DeviceExceptionError as exc:
            if exc.code == spec.wrong_password:
                self.failed = (
                    f"wrong password: the device answered exception {exc.code:02X}h to the "
                    f"password written to {address:04X}h; fix {where}.password_* and restart "
                    "or reload the mapping"
                )
            elif exc.action in ("retry", "busy"):  # line noise, EEPROM busy: not a verdict
                log.warning("%s: unlocking failed for now: %s", self.device.id, exc)
            else:
                self.failed = f"the password write to {address:04X}h was refused ({exc})"
            return False
        except ModbusError as exc:  # no answer: the next locked request tries again
            log.warning("%s: unlocking failed: %s", self.device.id, exc)
            return False
        self.unlocked_at = time.monotonic()
        if spec.success is None or (echo and echo[0] == spec.success):
            log.info("%s: unlocked with its password", self.device.id)
        else:
            log.info(
                "%s: password written; the answer was not the success code %04Xh",
                self.device.id,
                spec.success,
            )
        return True
